"""The distributed PV (PVD1) and storage (ESD1) of ANDES 2.0.0: their start from the load flow, the
trip factors, the frequency and voltage droops, the current limits with their priority, the state of
charge and its limits, their bases; and ANDES on ieee14/ieee14_pvd1.xlsx, ieee14_pvd1u.xlsx and
ieee14_esd1.xlsx (ten devices at bus 4 sharing static generator 6): initial states and set points, and
dx/dt, P, Q and the measured frequency at ANDES' states mid-fault (a bolted fault at bus 9, next to
bus 4, 1.0-1.1 s) and after clearing.

Measured against ANDES (ANDES' Newton tolerance 1e-6 in each step: the fault does not converge
tighter): initial states, set points and dx/dt there equal; dx/dt mid-fault within 5.6e-10 (of
ANDES' up to 2.6 rad/s), after clearing within 4.3e-9 (of 0.12): ANDES' algebraic variables lie
~1e-10 off their solution and the current lags' 1 / tip = 50 amplifies them; P, Q equal; f within
1e-10 (ANDES' f is a Newton-solved variable).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from reference_models.models.esd1 import ESD1
from reference_models.models.pvd1 import PVD1

START = dict(V0=1.01, theta0=-0.08, P0=0.05, Q0=-0.03, Vs=1.01, theta_vs=-0.08)
FAULT_BUS = 9  # next to bus 4, where the devices are: bus 4 at 0.5 pu mid-fault, between Vql and v0
TIMES = (1.05, 2.5)  # s: mid-fault and after clearing
RATE_TOLERANCE = 2e-8  # relative to the largest of ANDES' |dx/dt| and 1 (docstring)
# ANDES computes PVD1's Vcomp as the abs of a complex number into a real array
ANDES_COMPLEX_WARNING = pytest.mark.filterwarnings("ignore:Casting complex values to real")


def _start(component, given=START, **values):
    p = component.params(values)
    x, u = component.start(given, p)
    return x, np.array([u[n] for n in component.input_names]), p


def _outputs(component, x, u, p) -> dict:
    return dict(zip(component.output_names, component.output_values(x, u, p)))


def _frequency_states(theta, f, p):
    """(theta_f, theta_w) at bus angle theta with the measurement reading f [pu]."""
    return theta, theta - (f - 1.0) * 2.0 * math.pi * p.busf_fn * p.busf_Tw


def _command(component, x, u, p, state):
    """The command a current lag follows: its state plus tip (tiq) times its rate."""
    k = component.state_names.index(state)
    return x[k] + component.rhs(x, u, p)[k] * (p.tip if state == "Ipout_y" else p.tiq)


@pytest.mark.parametrize("component", [PVD1, ESD1], ids=["PVD1", "ESD1"])
def test_start_delivers_its_share_of_the_load_flow_with_the_currents_at_rest(component):
    x, u, p = _start(component, xc=0.02, Sn=10.0)
    y = _outputs(component, x, u, p)
    assert (u[2], u[3]) == (0.05, -0.03)  # pref0, qref0: the share itself
    assert (y["P"], y["Q"]) == (pytest.approx(0.05, rel=1e-15), pytest.approx(-0.03, rel=1e-15))
    assert complex(y["I_re"], y["I_im"]) == pytest.approx(complex(0.05, 0.03) / (1.01 * np.exp(0.08j)), rel=1e-15)
    assert (x[0], x[1], y["f"]) == (-0.08, -0.08, 1.0)
    np.testing.assert_array_equal(component.rhs(x, u, p)[:4], 0.0)


def test_storage_starts_at_its_initial_charge_and_discharges_at_the_power_it_delivers():
    x, u, p = _start(ESD1, SOCinit=0.7, En=2.0, Tf=0.5, EtaD=0.8, Sb=100.0)
    assert x[4] == 0.7
    assert ESD1.rhs(x, u, p)[4] == pytest.approx(-100.0 / (3600.0 * 2.0) * 0.05 / 0.8 / 0.5, rel=1e-15)
    charging = START | {"P0": -0.05}
    x, u, p = _start(ESD1, charging, En=2.0, EtaC=0.9)
    assert ESD1.rhs(x, u, p)[4] == pytest.approx(100.0 / (3600.0 * 2.0) * 0.05 * 0.9, rel=1e-15)


@pytest.mark.parametrize("values, match", [({"ialim": 0.04}, "current limits"), ({"vt1": 1.02, "vt0": 1.0}, ""),
                                           ({"v0": 1.05, "v1": 1.2}, "")])
def test_a_start_where_a_limit_a_droop_or_a_trip_factor_acts_is_refused(values, match):
    """The active current 0.0495 above ialim = 0.04; the bus at 1.01 pu under vt1 (trip factor < 1);
    the voltage droop's band above the bus voltage: ANDES starts off its load flow there."""
    with pytest.raises(ValueError, match=f"PVD1: no rest at the load flow.*{match}"):
        _start(PVD1, **values)


def test_voltage_trip_scales_both_commands_between_its_points_unless_recovery_is_off():
    x, u, p = _start(PVD1)
    Ip, Iq = x[2], x[3]
    for V, factor in ((0.89, 0.5), (0.87, 0.0), (1.15, 0.5), (1.25, 0.0)):
        dip = u.copy()
        dip[0] = V
        assert _command(PVD1, x, dip, p, "Ipout_y") == pytest.approx(factor * 0.05 / V, rel=1e-12, abs=1e-15)
        if V < 1.0:  # within the voltage droop's band [v0, v1]: the reactive command alike
            assert _command(PVD1, x, dip, p, "Iqout_y") == pytest.approx(factor * -0.03 / V, rel=1e-12, abs=1e-15)
    assert (Ip, Iq) == (0.05 / 1.01, -0.03 / 1.01)
    p_off = PVD1.params({"recflag": 0.0})
    dip = u.copy()
    dip[0] = 0.87
    assert _command(PVD1, x, dip, p_off, "Ipout_y") == pytest.approx(0.05 / 0.87, rel=1e-12)


def test_frequency_trip_and_the_over_frequency_droop_beyond_its_dead_band():
    """fn = 60 Hz: 60.4 Hz halves the commands (ft2 = 60.3, ft3 = 60.5); the droop ddn (pu/Hz)
    lowers the power by ddn (f - 60 - 0.017) above 60.017 Hz; under-frequency changes nothing down
    to ft1 = 59.7 Hz, below which the commands fall."""
    x, u, p = _start(PVD1, ddn=0.02)
    for fHz, power, factor in ((60.01, 0.05, 1.0), (60.1, 0.05 - 0.02 * (0.1 - 0.017), 1.0),
                               (60.4, 0.05 - 0.02 * (0.4 - 0.017), 0.5), (59.8, 0.05, 1.0), (59.6, 0.05, 0.5)):
        x[:2] = _frequency_states(u[1], fHz / 60.0, p)
        assert _outputs(PVD1, x, u, p)["f"] == pytest.approx(fHz / 60.0, rel=1e-14)
        expected = factor * max(power, 0.0) / 1.01
        assert _command(PVD1, x, u, p, "Ipout_y") == pytest.approx(expected, rel=1e-10, abs=1e-15), fHz


def test_reactive_droop_below_v0_and_above_v1_as_andes_writes_it():
    """Vcomp = V (xc = 0). Below v0 = 0.8: qmx + dqdv (Vqu - V), Vqu = v1 - (qref0 - qmn) / dqdv
    (ANDES' expression: it is not qmx at Vql nor 0 at v0); qmx at and below Vql; above v1 = 1.1 the
    slope dqdv (v1 - V) up to Vqu, qmn beyond. The voltage trip is off to see the droop alone."""
    x, u, p = _start(PVD1, recflag=0.0, ialim=5.0)
    qref0 = u[3]
    Vqu, Vql = 1.1 - (qref0 + 0.33) / -1.0, 0.8 + (0.33 - qref0) / -1.0
    for V, droop in ((0.7, 0.33 - (Vqu - 0.7)), (Vql - 0.01, 0.33), (1.15, -(1.1 - 1.15)), (Vqu + 0.01, -0.33),
                     (1.0, 0.0)):
        point = u.copy()
        point[0] = V
        assert _command(PVD1, x, point, p, "Iqout_y") == pytest.approx((qref0 + droop) / V, rel=1e-12), V


@pytest.mark.parametrize("pqflag", [1.0, 0.0])
def test_the_priority_axis_takes_the_current_limit_and_the_other_what_it_leaves(pqflag):
    """ialim = 0.5 (the voltage droop held off: v0 = 0.05, qmx = 1). At 0.06 pu both commands exceed
    it: P priority gives Ip = 0.5, Iq = 0, Q priority Iq = 0.5, Ip = 0. At 1 pu the priority axis
    keeps its command and the other is cut to sqrt(ialim^2 - command^2)."""
    x, u, p = _start(PVD1, START | {"Q0": 0.4}, ialim=0.5, pqflag=pqflag, recflag=0.0, v0=0.05, qmx=1.0)
    low = u.copy()
    low[0] = 0.06
    one = np.array([1.0, u[1], 0.05, 1.0] if pqflag else [1.0, u[1], 0.5, 0.4])
    at_one = (0.05, math.sqrt(0.25 - 0.0025)) if pqflag else (math.sqrt(0.25 - 0.16), 0.4)
    for point, Ip, Iq in ((low, 0.5 * pqflag, 0.5 * (1.0 - pqflag)), (one, *at_one)):
        assert _command(PVD1, x, point, p, "Ipout_y") == pytest.approx(Ip, rel=1e-12, abs=1e-15)
        assert _command(PVD1, x, point, p, "Iqout_y") == pytest.approx(Iq, rel=1e-12, abs=1e-15)


def test_an_empty_store_delivers_no_active_current_and_a_full_one_takes_none():
    x, u, p = _start(ESD1, SOCmin=0.2, SOCmax=0.8)
    for SOC, pref0, Ip in ((0.2, 0.05, 0.0), (0.2, -0.05, -0.05 / 1.01), (0.8, -0.05, 0.0), (0.8, 0.05, 0.05 / 1.01)):
        state, point = x.copy(), u.copy()
        state[4], point[2] = SOC, pref0
        assert _command(ESD1, state, point, p, "Ipout_y") == pytest.approx(Ip, rel=1e-14, abs=1e-16), (SOC, pref0)


def test_storage_rests_where_its_charge_runs_to_with_no_active_current():
    p = ESD1.params({"SOCmin": 0.1, "SOCmax": 0.9})
    for pref0, SOC in ((0.5, 0.1), (-0.5, 0.9), (0.0, 0.5)):
        x = ESD1.steady_state(np.array([1.0, 0.0, pref0, 0.1]), p)
        assert (x[2], x[4]) == (0.0, SOC)
        np.testing.assert_array_equal(ESD1.rhs(x, np.array([1.0, 0.0, pref0, 0.1]), p), 0.0)


def test_parameters_on_the_device_base_are_the_system_base_ones_scaled_as_andes_scales_them():
    """A 2 MVA device on a 100 MVA system and the same device written on the system base: powers and
    currents times Sn / Sb, the coupling reactance times Sb / Sn."""
    own = dict(Sn=2.0, Sb=100.0, xc=0.1, qmx=0.4, qmn=-0.3, pmx=0.9, dqdv=-2.0, ddn=3.0, ialim=1.2)
    k = 2.0 / 100.0
    system = dict(Sn=100.0, Sb=100.0, xc=0.1 / k, qmx=0.4 * k, qmn=-0.3 * k, pmx=0.9 * k, dqdv=-2.0 * k, ddn=3.0 * k,
                  ialim=1.2 * k)
    given = START | {"P0": 0.01, "Q0": -0.002}
    x, u, p_own = _start(PVD1, given, **own)
    rng = np.random.default_rng(3)
    xs = x + np.array([0.01, 0.01, 0.005, 0.005]) * rng.standard_normal((20, 4))
    us = u + np.array([0.3, 0.05, 0.0, 0.0]) * rng.standard_normal((20, 4))
    np.testing.assert_allclose(PVD1.rhs(xs, us, p_own), PVD1.rhs(xs, us, PVD1.params(system)), rtol=1e-12, atol=1e-14)


# --- ANDES ----------------------------------------------------------------------------------------

# device position -> changes (ANDES' set, on the device's base) that put its logic to work mid-fault:
# the trip off with the droop off on a P-priority (1) and a Q-priority (6) device (so the limits and the
# priority act), partial trip curves and a smaller droop (3)
PVD1_CHANGES = {1: {"recflag": 0.0, "ddn": 0.0}, 6: {"recflag": 0.0, "ddn": 0.0},
                3: {"vt0": 0.3, "vt1": 0.6, "ddn": 0.5}}
# and for ESD1: a charging device and a discharging one with stores of 1 kWh, which reach SOCmax,
# SOCmin before the fault (the shares still summing to the generator's power)
ESD1_CHANGES = {1: {"recflag": 0.0, "ddn": 0.0}, 6: {"recflag": 0.0, "ddn": 0.0},
                2: {"gammap": -0.1, "En": 0.001, "SOCmax": 0.55}, 3: {"gammap": 0.2, "En": 0.001, "SOCmin": 0.3},
                4: {"gammap": 0.2}}


def _andes_runs(case, changes, times=TIMES):
    """ANDES on a stock case with the devices' `changes`, a bolted fault at FAULT_BUS from 1.0 s to
    1.1 s: yields the system after TDS.init (f, g evaluated there) and at each of `times`."""
    andes = pytest.importorskip("andes")
    from reference_models.grid.andes_case import configure_andes_logging

    configure_andes_logging(andes, 40)
    ss = andes.load(andes.get_case(case), setup=False, no_output=True, default_config=True)
    if times:
        ss.add("Fault", {"bus": FAULT_BUS, "tf": 1.0, "tc": 1.1, "xf": 1e-4, "rf": 0.0})
    ss.setup()
    model = ss.ESD1 if ss.ESD1.n else ss.PVD1
    for i, values in changes.items():
        for name, value in values.items():
            model.set(name, model.idx.v[i], value, base="device")
    ss.PFlow.config.tol = 1e-12
    assert ss.PFlow.run()
    ss.TDS.init()
    ss.TDS.fg_update(ss.exist.tds)
    yield ss
    ss.TDS.config.update(fixt=1, tstep=0.005, tol=1e-6, no_tqdm=1)
    for t in times:
        ss.TDS.config.tf = t
        ss.TDS.run()
        assert ss.dae.t == pytest.approx(t)
        ss.TDS.fg_update(ss.exist.tds)
        yield ss


def _devices(ss):
    """Per device in service: (model, i, component, params, x, u, ANDES' dx/dt) with ANDES' states as
    ours (the measurement's shifted by the load flow's bus angle a0) and its inputs."""
    from andes_reference import params

    model = ss.ESD1 if ss.ESD1.n else ss.PVD1
    component = ESD1 if model is ss.ESD1 else PVD1
    bf = ss.BusFreq
    for i in range(model.n):
        if model.u.v[i] == 0:
            continue
        b = list(bf.idx.v).index(model.busfreq.v[i])
        a0 = float(bf.a0.v[b])
        p = params(model, component, i, {"Sb": float(ss.config.mva), **{f"busf_{n}": float(getattr(bf, n).v[b])
                                                                          for n in ("Tf", "Tw", "fn")}})
        variables = [(bf.L_y, b), (bf.WO_x, b), (model.Ipout_y, i), (model.Iqout_y, i)]
        if component is ESD1:
            variables.append((model.pIG_y, i))
        x = np.array([float(v.v[j]) for v, j in variables])
        x[:2] += a0
        rates = np.array([float(ss.dae.f[v.a[j]]) / float(ss.dae.Tf[v.a[j]]) for v, j in variables])
        u = np.array([float(model.v.v[i]), float(model.a.v[i]), float(model.pref0.v[i]), float(model.qref0.v[i])])
        yield model, i, component, p, x, u, rates


def _check_start(ss):
    """Our start from ANDES' bus voltage and the share gamma p0s, gamma q0s of its static generator's
    load-flow power gives ANDES' states, set points and dx/dt (the SOC's not 0)."""
    count = 0
    for model, i, component, p, x_andes, u_andes, rates in _devices(ss):
        V0, theta0 = u_andes[:2]
        P0, Q0 = (float(model.gammap.v[i]) * float(model.p0s.v[i]), float(model.gammaq.v[i]) * float(model.q0s.v[i]))
        x, u = component.start(dict(V0=V0, theta0=theta0, P0=P0, Q0=Q0, Vs=V0, theta_vs=theta0), p)
        np.testing.assert_allclose(x, x_andes, rtol=1e-15, atol=0)
        assert (u["pref0"], u["qref0"]) == (pytest.approx(u_andes[2], rel=1e-15), pytest.approx(u_andes[3], rel=1e-15))
        ours = component.rhs(x, np.array([u[n] for n in component.input_names]), p)
        np.testing.assert_allclose(ours, rates, rtol=1e-12, atol=1e-18)
        count += 1
    return count


def _check_transient(ss) -> dict:
    """Our dx/dt, P, Q and f at ANDES' states and inputs equal ANDES'; returns the devices' bus
    voltage V, ANDES' Vcomp, Ipcmd, Iqcmd and the state of charge (ESD1) there, arrays by device."""
    seen = []
    for model, i, component, p, x, u, rates in _devices(ss):
        ours = component.rhs(x, u, p)
        scale = max(1.0, float(np.abs(rates).max()))
        assert np.abs(ours - rates).max() <= RATE_TOLERANCE * scale, (model.idx.v[i], ours, rates)
        y = _outputs(component, x, u, p)
        assert (y["P"], y["Q"]) == (pytest.approx(-float(model.a.e[i]), rel=1e-14, abs=1e-18),
                                    pytest.approx(-float(model.v.e[i]), rel=1e-14, abs=1e-18))
        assert y["f"] == pytest.approx(float(model.f.v[i]), abs=1e-9)
        seen.append((u[0], float(model.Vcomp.v[i]), float(model.Ipcmd_y.v[i]), float(model.Iqcmd_y.v[i]),
                     x[4] if component is ESD1 else math.nan))
    return dict(zip(("V", "Vcomp", "Ipcmd", "Iqcmd", "SOC"), np.array(seen).T))


@pytest.mark.andes
@ANDES_COMPLEX_WARNING
@pytest.mark.parametrize("case", ["ieee14/ieee14_pvd1.xlsx", "ieee14/ieee14_pvd1u.xlsx"])
def test_pvd1_start_gives_andes_states_and_set_points(case):
    """ieee14_pvd1u has device 1 out of service and device 2 on a 2 MVA base with a larger share."""
    ss = next(_andes_runs(case, {}, times=()))
    assert ss.PV.u.v[list(ss.PV.idx.v).index(6)] == 0.0  # ANDES switches the static generator off
    assert _check_start(ss) == (9 if "pvd1u" in case else 10)


@pytest.mark.andes
@ANDES_COMPLEX_WARNING
@pytest.mark.parametrize("case, changes", [("ieee14/ieee14_pvd1.xlsx", PVD1_CHANGES),
                                           ("ieee14/ieee14_esd1.xlsx", ESD1_CHANGES)], ids=["PVD1", "ESD1"])
def test_start_and_rates_match_andes_mid_fault_with_the_voltage_logic_active_and_after_clearing(case, changes):
    runs = _andes_runs(case, changes)
    assert _check_start(next(runs)) == 10
    mid_fault = _check_transient(next(runs))
    assert np.all((0.3 < mid_fault["V"]) & (mid_fault["V"] < 0.88))  # under vt0: the stock trip factor is 0
    assert np.all(mid_fault["Vcomp"] < 0.8)  # under v0: the voltage droop acts
    Ipcmd, Iqcmd = mid_fault["Ipcmd"], mid_fault["Iqcmd"]
    stock = [i for i in range(10) if i not in changes]
    np.testing.assert_array_equal(Ipcmd[stock], 0.0)
    np.testing.assert_array_equal(Iqcmd[stock], 0.0)
    ialim = 0.011  # pu on the system base: the Q-priority device's reactive current at the limit
    assert Iqcmd[6] == pytest.approx(-ialim, rel=1e-12) and Ipcmd[6] == 0.0
    assert 0.0 < Ipcmd[1] < ialim and Iqcmd[1] < 0.0  # P priority, Iq within what Ip leaves
    after = _check_transient(next(runs))
    assert np.all(np.abs(after["V"] - 1.0) < 0.02)
    if "esd1" in case:  # the full store takes no current, the empty one gives none
        assert after["SOC"][2] >= 0.55 and after["SOC"][3] <= 0.3
        assert after["Ipcmd"][2] == 0.0 and after["Ipcmd"][3] == 0.0 and after["Ipcmd"][4] > 0.0
    else:  # the partial trip curve and the smaller droop of device 3 acted mid-fault
        assert 0.0 < Ipcmd[3] < 0.005 / 0.5
