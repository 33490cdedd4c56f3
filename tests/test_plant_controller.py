"""The plant controller REPCA1: its freeze, line-drop compensation, frequency droop and start as the
third device of an inverter's unit (after REGCA1 and REECA1), and ANDES 2.0.0 on
ieee14/ieee14_solar.xlsx (initial states and set points from the references ANDES' REECA1 demands
and ANDES' measured inputs; dx/dt and outputs at ANDES' states mid-fault and after clearing, the
measured inputs computed from ANDES' bus voltages and the line's data as ANDES computes them)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from reference_models.models.reeca1 import REECA1
from reference_models.models.regca1 import REGCA1
from reference_models.models.repca1 import REPCA1

MEASURED = REPCA1.input_names[:6]  # Vm, theta_m, Pbr, Qbr, Ibr_re, Ibr_im


def _branch(V1: complex, V2: complex, z: complex, sign: float = 1.0) -> dict:
    """The measured inputs of a device on a line's bus1 (sign 1) or bus2 (sign -1) measuring its own
    bus, as ANDES computes them: Ibr = sign (V1 - V2) / z, Pbr + j Qbr = sign V1 conj((V1 - V2) / z)."""
    I = (V1 - V2) / z
    S = sign * V1 * np.conj(I)
    Vm = V1 if sign > 0 else V2
    return dict(Vm=abs(Vm), theta_m=float(np.angle(Vm)), Pbr=S.real, Qbr=S.imag, Ibr_re=sign * I.real,
                Ibr_im=sign * I.imag)


def _at_rest(p, measured: dict, Pext=0.5, Qext=0.1):
    x, inputs = REPCA1.start({**measured, "Pext": Pext, "Qext": Qext}, p)
    return x, np.array([inputs[n] for n in REPCA1.input_names])


def test_line_drop_compensation_with_the_line_impedance_regulates_the_far_end_voltage():
    """VCFlag = 1 with Rc + j Xc the monitored line's impedance (ieee14_solar: the transformer 8-7):
    VCsel = |V1 - z (V1 - V2) / z| = |V2|, so the start's Vref is the far bus's voltage."""
    z = complex(0.01, 0.17615)
    V1, V2 = 1.03 * np.exp(0.2j), 0.98 * np.exp(0.1j)
    p = REPCA1.params({"Rc": z.real, "Xc": z.imag})
    x, u = _at_rest(p, _branch(V1, V2, z))
    assert u[REPCA1.input_names.index("Vref")] == pytest.approx(0.98, rel=1e-14)
    assert x[2] == pytest.approx(0.98, rel=1e-14)
    # at bus2 of the same line ANDES' measured power is minus the power at bus1 (not the power at bus2)
    at_bus2 = _branch(V1, V2, z, sign=-1.0)
    assert complex(at_bus2["Pbr"], at_bus2["Qbr"]) == pytest.approx(-V1 * np.conj((V1 - V2) / z), rel=1e-14)


def test_droop_mode_adds_kc_times_the_branch_reactive_power_to_the_voltage():
    p = REPCA1.params({"VCFlag": 0.0, "Kc": 0.5})
    measured = _branch(1.02 + 0.0j, 1.0 + 0.0j, 0.1j)
    _, u = _at_rest(p, measured)
    assert u[REPCA1.input_names.index("Vref")] == pytest.approx(1.02 + 0.5 * measured["Qbr"], rel=1e-14)


def test_start_leaves_the_controller_at_rest_giving_the_references_demanded():
    p = REPCA1.params({"Rc": 0.0, "Xc": 0.2})
    x, u = _at_rest(p, _branch(1.01 * np.exp(0.1j), 0.99, 0.2j), Pext=0.42, Qext=-0.07)
    np.testing.assert_array_equal(REPCA1.rhs(x, u, p), 0.0)
    assert tuple(REPCA1.output_values(x, u, p)) == (0.42, -0.07, 1.0)
    np.testing.assert_allclose(REPCA1.steady_state(u, p), x, rtol=0, atol=1e-15)


def test_start_where_a_limit_keeps_a_pi_output_off_zero_is_refused():
    with pytest.raises(ValueError, match=r"REPCA1: no rest at the start \(s2_xi, s3_x move\)"):
        _at_rest(REPCA1.params({"Qmin": 0.1, "Qmax": 0.5}), _branch(1.0, 0.99, 0.2j))


def test_below_vfrz_the_reactive_pi_runs_on_the_error_held_from_the_dip_s_start():
    """The filtered voltage s0_y has fallen to a dip (0.3 below Vref, 0.2 beyond the dead band) while
    s_hold kept its value from rest (0 error): above Vfrz the PI integrates the live error and its
    output carries Kp times it, and s_hold follows s0_y; below Vfrz (ANDES' eHld) the PI runs on the
    held error, 0, and s_hold stands still; with freeze = 0 it always takes the live error."""
    from reference_models.models.repca1 import HOLD_SYNC_S

    for freeze in (1.0, 0.0):
        p = REPCA1.params({"freeze": freeze, "Kp": 2.0, "Ki": 0.5})
        x, u = _at_rest(p, _branch(1.0 + 0.0j, 0.99, 0.2j))
        x[4] = 0.05  # s2_xi
        x[2] -= 0.3  # s0_y; s_hold (x[9]) at rest
        for Vm, frozen in ((0.9, False), (0.7, bool(freeze))):
            u[0] = Vm
            rates = REPCA1.rhs(x, u, p)
            assert rates[4] == (0.0 if frozen else pytest.approx(0.5 * 0.2))
            follows = rates[2] + (x[2] - x[9]) / HOLD_SYNC_S
            assert rates[9] == (0.0 if frozen else pytest.approx(follows, rel=1e-12))
            s2_y = 0.05 + (0.0 if frozen else 2.0 * 0.2)  # Tft = Tfv: the lead-lag passes it to Qext
            assert REPCA1.output_values(x, u, p)[1] == pytest.approx(u[-1] + s2_y, rel=1e-14)


def test_held_measurement_follows_the_live_one_and_comes_back_to_it_after_a_dip():
    """Above Vfrz s_hold moves as s0_y does, plus (s0_y - s_hold) / HOLD_SYNC_S: equal ones move
    together, a gap left by a dip closes with that time constant."""
    from reference_models.models.repca1 import HOLD_SYNC_S

    p = REPCA1.params()
    x, u = _at_rest(p, _branch(1.0 + 0.0j, 0.99, 0.2j))
    u[0] = 0.95  # a live voltage the filter moves toward
    rates = REPCA1.rhs(x, u, p)
    assert rates[9] == rates[2] != 0.0
    x[9] = x[2] - 0.1  # s_hold left behind by a dip
    assert REPCA1.rhs(x, u, p)[9] == pytest.approx(rates[2] + 0.1 / HOLD_SYNC_S, rel=1e-12)


def test_frequency_error_beyond_its_dead_band_drives_the_active_power_with_ddn_or_dup_up_to_femax():
    """Over-frequency (ferr < 0) takes Ddn, under-frequency Dup; the power error is clipped to
    [femin, femax] before the PI. A frequency deviation is held in the measurement's states."""
    p = REPCA1.params({"PLflag": 0.0, "Ddn": 20.0, "Dup": 5.0, "fdbd1": -0.001, "fdbd2": 0.001, "Kig": 1.0})
    x, u = _at_rest(p, _branch(1.0 + 0.0j, 0.99, 0.2j))
    K = 2 * math.pi * p.busf_fn * p.busf_Tw  # f = 1 + (theta_f - theta_w) / K
    for df, expected in ((0.002, 20.0 * -0.001), (-0.002, 5.0 * 0.001), (0.01, -p.femax)):
        x[0] = x[1] + df * K
        assert REPCA1.output_values(x, u, p)[2] == pytest.approx(1.0 + df, rel=1e-14)
        assert REPCA1.rhs(x, u, p)[7] == pytest.approx(expected, rel=1e-9)  # Kig feout


def test_without_fflag_the_active_power_reference_ignores_the_plant_command():
    p = REPCA1.params({"Fflag": 0.0})
    x, u = _at_rest(p, _branch(1.0 + 0.0j, 0.99, 0.2j), Pext=0.3)
    x[8] = 0.2  # s6_y
    assert REPCA1.output_values(x, u, p)[0] == 0.3
    assert REPCA1.output_values(x, u, REPCA1.params({"Fflag": 1.0}))[0] == pytest.approx(0.5)


def test_unit_start_converter_then_electrical_then_plant_controller_is_at_rest():
    """The order a unit starts in: REGCA1 solves its commands from the load flow, REECA1 its
    references from them, REPCA1 its set points from those references (its outputs Pext, Qext
    demanded) and the network's measurements; every device then rests."""
    V0, theta0, P0, Q0 = 1.02, 0.1, 0.35, 0.05
    pg, pr, pp = REGCA1.params(), REECA1.params(), REPCA1.params({"Xc": 0.17615})
    xg, ug = REGCA1.start(dict(V0=V0, theta0=theta0, P0=P0, Q0=Q0, Vs=V0, theta_vs=theta0), pg)
    ug = np.array([ug[n] for n in REGCA1.input_names])
    y = dict(zip(REGCA1.output_names, REGCA1.output_values(xg, ug, pg)))
    xr, ur = REECA1.start(dict(V=V0, Pe=y["Pe"], Qe=y["Qe"], Ipcmd=ug[2], Iqcmd=ug[3]), pr)
    V1 = V0 * np.exp(1j * theta0)
    measured = _branch(V1, V1 - 0.17615j * np.conj(complex(P0, Q0) / V1), 0.17615j)
    xp, up = _at_rest(pp, measured, Pext=ur["Pref"], Qext=ur["Qref"])
    assert measured["Pbr"] == pytest.approx(P0, rel=1e-14) and measured["Qbr"] == pytest.approx(Q0, rel=1e-14)
    np.testing.assert_array_equal(REPCA1.rhs(xp, up, pp), 0.0)
    ur = np.array([ur[n] for n in REECA1.input_names])
    assert np.abs(REECA1.rhs(xr, ur, pr)).max() == 0.0
    np.testing.assert_array_equal(REPCA1.output_values(xp, up, pp)[:2], ur[3:5])


# --- ANDES 2.0.0 --------------------------------------------------------------------------------

CASE = "ieee14/ieee14_solar.xlsx"
FAULT_BUS = 7  # the inverter's (bus 8) only neighbour; ANDES does not converge with the fault on bus 8
# REPCA1 data (and ANDES' configuration) changed from the case's (voltage control with line-drop
# compensation, Fflag = PLflag = 0): the reactive power control with the Kc droop, the branch
# power and frequency control with narrower dead bands; no freeze, the PI input and output limited
MODES = {"stock": ({}, {}),
         "Q control, droop, P and f": ({"VCFlag": 0.0, "RefFlag": 0.0, "Fflag": 1.0, "PLflag": 1.0, "Kc": 0.5,
                                        "fdbd1": -0.001, "fdbd2": 0.001, "dbd1": -0.01, "dbd2": 0.01}, {}),
         "no freeze, limits": ({"emax": 0.5, "Qmax": 0.3}, {"freeze": 0})}


def _andes_case(mode: str, fault: bool):
    """ANDES' system of the case in `mode`, a fault at FAULT_BUS 1.0-1.1 s where `fault`, after its
    power flow."""
    andes = pytest.importorskip("andes")
    from reference_models.grid.andes_case import configure_andes_logging

    configure_andes_logging(andes, 40)
    data, config = MODES[mode]
    ss = andes.load(andes.get_case(CASE), setup=False, no_output=True, default_config=True)
    for name, value in data.items():
        getattr(ss.REPCA1, name).v[0] = value
    for name, value in config.items():
        setattr(ss.REPCA1.config, name, value)
    if fault:
        ss.add("Fault", {"bus": FAULT_BUS, "tf": 1.0, "tc": 1.1, "xf": 1e-4, "rf": 0.0})
    ss.setup()
    ss.PFlow.run()
    return ss


def _andes_measured(ss) -> dict:
    """Our measured inputs from ANDES' bus voltages and the monitored line's data (ANDES' formulas:
    its series impedance only, the sign by which end the converter's bus is)."""
    r, line, bus = ss.REPCA1, ss.Line, ss.Bus
    V = dict(zip(bus.idx.v, bus.v.v * np.exp(1j * bus.a.v)))
    k = list(line.idx.v).index(r.line.v[0])
    converter_bus = ss.REGCA1.bus.v[list(ss.REGCA1.idx.v).index(r.reg.v[0])]
    sign = 1.0 if converter_bus == line.bus1.v[k] else -1.0
    measured = _branch(V[line.bus1.v[k]], V[line.bus2.v[k]], complex(line.r.v[k], line.x.v[k]), sign)
    Vm = V[r.buss.v[0]]
    return {**measured, "Vm": abs(Vm), "theta_m": float(np.angle(Vm))}


def _andes_point(ss) -> dict:
    """Our parameters, states and inputs at ANDES' present point, ANDES' rates of the same states
    (f / Tf), its outputs (REECA1's Pref, Qref, the BusFreq's f) and its own Pline, Qline, Iline."""
    from andes_reference import params

    r, e, bf = ss.REPCA1, ss.REECA1, ss.BusFreq
    j = list(bf.idx.v).index(r.busfreq.v[0])
    p = params(r, REPCA1, 0, {"Rc": float(r.Rcs.v[0]), "Xc": float(r.Xcs.v[0]), "kqs": r.config.kqs,
                              "ksg": r.config.ksg, "freeze": r.config.freeze, "busf_Tf": float(bf.Tf.v[j]),
                              "busf_Tw": float(bf.Tw.v[j]), "busf_fn": float(bf.fn.v[j])})
    theta0 = float(bf.a0.v[j])  # ANDES' BusFreq filters the angle less its initial value
    variables = [(bf.L_y, j), (bf.WO_x, j)] + [(getattr(r, n), 0) for n in REPCA1.state_names[2:9]]
    x = np.array([float(v.v[i]) for v, i in variables]) + np.array([theta0, theta0] + [0.0] * 7)
    # s_hold: the live measurement, or frozen, the one whose error (below the dead band's upper edge
    # or above its lower one) is ANDES' held eHld
    held = float(r.eHld.v[0])
    s_hold = x[2 if p.RefFlag else 3]
    if float(r.zf.v[0]):
        reference = float(r.Vref.v[0] if p.RefFlag else r.Qlinef.v[0])
        s_hold = reference - (held + (p.dbd2 if held > 0 else p.dbd1 if held < 0 else 0.0))
    x = np.append(x, s_hold)
    rates = np.array([float(ss.dae.f[int(v.a[i])]) / float(ss.dae.Tf[int(v.a[i])]) for v, i in variables])
    measured = _andes_measured(ss)
    u = np.array([measured[n] for n in MEASURED] + [float(v) for v in (r.Vref.v[0], r.Qlinef.v[0], r.Plant_pref.v[0],
                                                                      e.Pref0.v[0], -e.qref0.v[0])])
    Iline = complex(r.Iline.v[0])
    return dict(p=p, x=x, u=u, rates=rates, measured=measured,
                outputs=np.array([e.Pref.v[0], e.Qref.v[0], bf.f.v[j]], dtype=float),
                services=np.array([r.Pline.v[0], r.Qline.v[0], Iline.real, Iline.imag], dtype=float),
                frozen=float(r.zf.v[0]), held=float(r.eHld.v[0]), enf=float(r.enf.v[0]),
                PI_limited=(float(r.s2_y.v[0]) != float(r.s2_ys.v[0]), float(r.s5_y.v[0]) != float(r.s5_ys.v[0])),
                Perr=float(r.Perr.v[0]))


@pytest.mark.andes
@pytest.mark.parametrize("mode", MODES)
def test_start_from_the_references_andes_reeca1_demands_gives_andes_initial_states_and_set_points(mode):
    """Our chain REGCA1 -> REECA1 -> REPCA1 from ANDES' load flow: REECA1's solved references are
    REPCA1's demanded outputs; with the measured inputs from ANDES' voltages REPCA1's states and set
    points are ANDES' (its measured inputs are ANDES' own Pline, Qline, Iline)."""
    from andes_reference import params

    ss = _andes_case(mode, fault=False)
    ss.TDS.init()
    g, e = ss.REGCA1, ss.REECA1
    point = _andes_point(ss)
    np.testing.assert_allclose(point["u"][2:6], point["services"], rtol=0, atol=1e-15)
    bus = list(ss.Bus.idx.v).index(g.bus.v[0])
    V0, theta0 = float(ss.Bus.v.v[bus]), float(ss.Bus.a.v[bus])
    pg = params(g, REGCA1, 0, {"Sb": ss.config.mva})
    pr = params(e, REECA1, 0, {"Sb": ss.config.mva, "Sn": float(g.Sn.v[0])})
    xg, commands = REGCA1.start(dict(V0=V0, theta0=theta0, P0=float(g.p0.v[0]), Q0=float(g.q0.v[0]), Vs=V0,
                                     theta_vs=theta0), pg)
    ug = np.array([V0, theta0, commands["Ipcmd"], commands["Iqcmd"]])
    y = dict(zip(REGCA1.output_names, REGCA1.output_values(xg, ug, pg)))
    _, references = REECA1.start(dict(V=V0, Pe=y["Pe"], Qe=y["Qe"], **commands), pr)
    x, inputs = REPCA1.start({**point["measured"], "Pext": references["Pref"], "Qext": references["Qref"]},
                             point["p"])
    scale = np.abs(point["x"]).max()
    np.testing.assert_allclose(x, point["x"], rtol=0, atol=1e-14 * scale)
    np.testing.assert_allclose([inputs[n] for n in REPCA1.input_names], point["u"], rtol=0, atol=1e-14)
    np.testing.assert_array_equal(REPCA1.rhs(x, point["u"], point["p"]), 0.0)
    np.testing.assert_allclose(REPCA1.output_values(x, point["u"], point["p"]), point["outputs"], rtol=0, atol=1e-14)


@pytest.fixture(scope="module", params=list(MODES))
def andes_faulted(request):
    """(mode, {t: ANDES' point}) at 1.05 s (mid-fault at bus 7, 1.0-1.1 s) and 2.5 s."""
    from andes_reference import run_to

    ss = _andes_case(request.param, fault=True)
    return request.param, {t: _andes_point(ss) for t in run_to(ss, (1.05, 2.5))}


@pytest.mark.andes
@pytest.mark.parametrize("t", [1.05, 2.5])
def test_derivatives_and_outputs_match_andes_mid_fault_and_after_clearing(andes_faulted, t):
    """At ANDES' states and inputs our dx/dt equals ANDES' f / Tf and our Pext, Qext, f equal ANDES'
    REECA1 Pref, Qref and BusFreq f (relative to the largest value compared). Mid-fault the voltage
    at bus 8 lies below Vfrz: with the freeze ANDES holds the PI input at its value from rest (0)
    while the live error is far from 0 (ours: the error of s_hold, 0, and s_hold stopped); without it the PI runs
    into Qmax on the clipped error emax; in the P and f mode the power error is clipped to femax."""
    mode, points = andes_faulted
    point = points[t]
    if t == 1.05:
        assert point["u"][0] < point["p"].Vfrz and abs(point["enf"]) > 0.1
        if mode == "no freeze, limits":
            assert point["frozen"] == 0.0 and point["enf"] == 0.5 and point["PI_limited"][0]
        else:
            assert point["frozen"] == 1.0 and point["held"] == 0.0
        if mode == "Q control, droop, P and f":
            assert point["Perr"] > point["p"].femax
    p, x, u = point["p"], point["x"], point["u"]
    np.testing.assert_allclose(u[2:6], point["services"], rtol=0, atol=1e-12 * np.abs(point["services"]).max())
    theirs = point["rates"]
    assert np.abs(theirs).max() > 1e-2  # not at rest
    ours = REPCA1.rhs(x, u, p)
    np.testing.assert_allclose(ours[:9], theirs, rtol=0, atol=1e-9 * np.abs(theirs).max())
    assert ours[9] == (0.0 if point["frozen"] else ours[2 if p.RefFlag else 3])  # s_hold: held, or the live one's
    np.testing.assert_allclose(REPCA1.output_values(x, u, p), point["outputs"], rtol=0, atol=1e-9)
