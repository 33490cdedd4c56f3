"""The phase-locked loops PLL1, PLL2 and the converter REGCP1 working in a PLL's frame: their start at
rest on the bus angle, the lock onto a bus angle rotating at an offset frequency, REGCP1's power and
current in the measured frame (REGCA1 where the PLL has locked), and ANDES 2.0.0 on
ieee14/ieee14_regcp1.xlsx (REGCP1 with PLL1) and ieee14/ieee14_regcp1_nopll.json (REGCP1 without a
PLL, which is REGCA1; its PLL2 measures the same bus): initial states and commands, and dx/dt and
outputs at ANDES' states mid-fault and after clearing."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from reference_models.models.pll1 import PLL1, angle_speed
from reference_models.models.pll2 import PLL2
from reference_models.models.regca1 import REGCA1, low_voltage_power_limit
from reference_models.models.regcp1 import REGCP1


@pytest.mark.parametrize("pll", [PLL1, PLL2], ids=["PLL1", "PLL2"])
def test_pll_starts_at_rest_on_the_bus_angle_and_refuses_another_converter_angle(pll):
    given = {"Vt": 1.02, "theta_vs": -0.3, "am": -0.3}
    x0, inputs = pll.start(given)
    assert x0[pll.state_names.index("am")] == -0.3 and x0[pll.state_names.index("PI_xi")] == 0.0
    u = np.array([inputs[n] for n in pll.input_names])
    np.testing.assert_array_equal(pll.rhs(x0, u, pll.params()), 0.0)
    with pytest.raises(ValueError, match="measured angle"):
        pll.start({**given, "am": -0.2})


@pytest.mark.parametrize("pll", [PLL1, PLL2], ids=["PLL1", "PLL2"])
def test_pll_locks_onto_a_bus_angle_rotating_at_an_offset_frequency(pll):
    """The bus angle turns at 0.3 Hz above fn = 60 Hz: after 40 s the measured angle follows it
    (PLL1 with the lag of its input filter, 2 pi 0.3 Tf rad: its PI drives the filtered angle less
    the measured one to 0) and the PI output is the offset in pu of fn, 0.3 / 60."""
    p = pll.params({"Kp": 1.0, "Ki": 1.0})
    w = 2 * math.pi * 0.3

    def inputs(t):
        return np.array([1.0, 0.1 + w * t] if pll is PLL2 else [0.1 + w * t])

    x0, _ = pll.start({"Vt": 1.0, "theta_vs": 0.1})
    sol = solve_ivp(lambda t, x: pll.rhs(x, inputs(t), p), (0.0, 40.0), x0, rtol=1e-10, atol=1e-12)
    x, u = sol.y[:, -1], inputs(40.0)
    lag = w * p.Tf if pll is PLL1 else 0.0
    assert x[pll.state_names.index("am")] == pytest.approx(u[-1] - lag, abs=1e-6)
    assert pll.output_values(x, u, p)[0] == pytest.approx(0.3 / 60.0, rel=1e-5)


def test_regcp1_with_the_bus_angle_measured_is_regca1():
    p = REGCP1.params({"Lvpnt1": 1.0})
    x = np.array([0.5, 0.2, 0.7, 0.1])
    u = np.array([0.95, 0.3, 0.6, -0.25])
    up = np.r_[u, 0.3]
    np.testing.assert_array_equal(REGCP1.rhs(x, up, p), REGCA1.rhs(x, u, p))
    np.testing.assert_array_equal(REGCP1.reset_states(x, up, p), REGCA1.reset_states(x, u, p))
    np.testing.assert_allclose(REGCP1.output_values(x, up, p)[:8], REGCA1.output_values(x, u, p), rtol=1e-15)


def test_regcp1_injects_its_currents_in_the_measured_frame():
    """A measured angle 0.2 rad behind the bus angle: the current (Ipout - j Iqout) turns with am,
    vd + j vq = V exp(-j (theta - am)), and P + jQ = V conj(I) is vd Ip + vq Iq + j (vd Iq - vq Ip)."""
    p = REGCP1.params()
    x = np.array([0.5, 0.2, 1.0, 0.1])
    V, theta, am = 1.01, 0.4, 0.2
    y = dict(zip(REGCP1.output_names, REGCP1.output_values(x, np.array([V, theta, 0.5, -0.2, am]), p)))
    current = complex(y["I_re"], y["I_im"])
    assert current == pytest.approx(complex(0.5, -0.2) * np.exp(1j * am), abs=1e-15)
    assert complex(y["vd"], y["vq"]) == pytest.approx(V * np.exp(-1j * (theta - am)), abs=1e-15)
    assert complex(y["P"], y["Q"]) == pytest.approx(V * np.exp(1j * theta) * np.conj(current), abs=1e-15)
    assert (y["Pe"], y["Qe"]) == (y["P"], y["Q"])
    assert y["P"] != pytest.approx(0.5 * V)  # not REGCA1's Ipout V


def test_regcp1_start_solves_its_commands_and_the_angle_its_pll_gives():
    given = dict(V0=0.98, theta0=0.1, P0=0.6, Q0=0.2, Vs=0.98, theta_vs=0.1)
    x0, inputs = REGCP1.start(given, REGCP1.params())
    xa, ia = REGCA1.start(given, REGCA1.params())
    np.testing.assert_array_equal(x0, xa)
    assert inputs == {**ia, "am": 0.1}
    y = dict(zip(REGCP1.output_names, REGCP1.output_values(x0, np.array(list(inputs.values())), REGCP1.params())))
    assert (y["P"], y["Q"], y["vq"]) == (pytest.approx(0.6, abs=1e-15), pytest.approx(0.2, abs=1e-15), 0.0)


# --- ANDES 2.0.0 --------------------------------------------------------------------------------

FAULT_BUS = 7  # the converter's (bus 8) only neighbour; ANDES does not converge with the fault on bus 8
TIMES = (1.05, 2.5)


def _andes_run(case: str):
    """ANDES' system of `case` after TDS.init (its own fault moved to FAULT_BUS, 1.0-1.1 s, or one
    added there) and the points {"init", 1.05, 2.5}: per point, read(ss) of the system there."""
    andes = pytest.importorskip("andes")
    from andes_reference import run_to

    from reference_models.grid.andes_case import configure_andes_logging

    configure_andes_logging(andes, 40)
    ss = andes.load(andes.get_case(case), setup=False, no_output=True, default_config=True)
    if ss.Fault.n:  # the json cases' fault at the converter's bus 0.1-0.2 s, where ANDES does not converge
        ss.Fault.bus.v[0], ss.Fault.tf.v[0], ss.Fault.tc.v[0] = FAULT_BUS, 1.0, 1.1
    else:
        ss.add("Fault", {"bus": FAULT_BUS, "tf": 1.0, "tc": 1.1, "xf": 1e-4, "rf": 0.0})
    ss.setup()
    ss.PFlow.run()
    ss.TDS.init()
    points = {"init": _read(ss)}
    for t in run_to(ss, TIMES):
        points[t] = _read(ss)
    return points


def _rates(ss, model, names, i=0) -> np.ndarray:
    """ANDES' dx/dt (f / Tf) of the named states of device i of `model`."""
    return np.array([float(ss.dae.f[int(getattr(model, n).a[i])]) / float(ss.dae.Tf[int(getattr(model, n).a[i])])
                     for n in names])


def _read(ss) -> dict:
    """At ANDES' present point: per PLL model (x, u, p, rates, PI_y), rates and PI_y as ANDES' PI_y
    would give them on its equation (ANDES' f takes its algebraic PI_y, off its equation
    Kp e + PI_xi by the Newton residual g: 3e-11, 1e-8 in 2 pi fn PI_y); REGCP1's (x, u, p, rates, its Pe, Qe,
    vd, vq), its q0 and P0; REECA1's measured voltage. Our REGCP1 state on LVPL where ANDES' is
    (within its Newton tolerance)."""
    from andes_reference import params

    g = ss.REGCP1
    bus = list(ss.Bus.idx.v).index(g.bus.v[0])
    V, theta = float(ss.Bus.v.v[bus]), float(ss.Bus.a.v[bus])
    out = {"V": V, "theta": theta}
    for name, component in (("PLL1", PLL1), ("PLL2", PLL2)):
        model = getattr(ss, name)
        if model.n:
            assert model.bus.v[0] == g.bus.v[0]
            x = np.array([float(getattr(model, s).v[0]) for s in component.state_names])
            u = np.array([V, theta] if name == "PLL2" else [theta])
            p = params(model, component, 0)
            residual = float(ss.dae.g[int(model.PI_y.a[0])])
            rates = _rates(ss, model, component.state_names)
            rates[component.state_names.index("ae" if name == "PLL1" else "am")] += angle_speed(residual, p.fn)
            out[name] = (x, u, p, rates, float(model.PI_y.v[0]) + residual)
    pg = params(g, REGCP1, 0, {"Sb": ss.config.mva})
    x = np.array([g.S0_y.v[0], g.S1_y.v[0], g.S2_y.v[0], g.q0.v[0]], dtype=float)
    if g.S0_lim.zu[0]:
        x[0] = low_voltage_power_limit(math, x[2], pg)
    am = float(ss.PLL1.am.v[list(ss.PLL1.idx.v).index(g.pll.v[0])]) if g.pll.v[0] is not None else theta
    u = np.array([V, theta, g.Ipcmd.v[0], g.Iqcmd.v[0], am], dtype=float)
    out["REGCP1"] = (x, u, pg, _rates(ss, g, ("S0_y", "S1_y", "S2_y")),
                     np.array([g.Pe.v[0], g.Qe.v[0], g.vd.v[0], g.vq.v[0]], dtype=float))
    out["P0Q0"] = (float(g.p0.v[0]), float(g.q0.v[0]))
    out["controller_voltage"] = float(ss.REECA1.v.v[0])
    return out


@pytest.fixture(scope="module")
def with_pll1():
    return _andes_run("ieee14/ieee14_regcp1.xlsx")


@pytest.fixture(scope="module")
def without_pll():
    return _andes_run("ieee14/ieee14_regcp1_nopll.json")


def _converter_close(rates_ours, x, p, theirs):
    """The converter's dx/dt (S0_y, S1_y, S2_y) against ANDES': where S0_y sits on LVPL, ANDES' rate
    is 0 (it places the state on the limit after each step) and ours the limit's own
    (models/regca1.py: the slope of LVPL times dS2_y/dt); the others within _close."""
    ours = np.array(rates_ours[:3], dtype=float)
    if x[0] == low_voltage_power_limit(math, x[2], p):
        slope = p.Lvplsw * p.Lvpl1 / (p.Brkpt - p.Zerox) if p.Zerox < x[2] <= p.Brkpt else 0.0
        assert theirs[0] == 0.0 and ours[0] == pytest.approx(slope * ours[2], rel=1e-12, abs=1e-300)
        ours[0] = 0.0
    _close(ours, theirs)


def _close(ours, theirs, floor=1e-300):
    """ours equals theirs within 1e-9 of max(|theirs|, floor) (floor 1 pu for ANDES' algebraic
    variables, which carry their Newton residual: 7e-11 pu in Qe mid-fault)."""
    theirs = np.asarray(theirs, dtype=float)
    np.testing.assert_allclose(ours, theirs, rtol=0.0, atol=1e-9 * max(np.abs(theirs).max(), floor))


@pytest.mark.andes
def test_start_gives_andes_initial_pll_and_converter_states_and_commands(with_pll1, without_pll):
    for points, plls in ((with_pll1, ("PLL1",)), (without_pll, ("PLL1", "PLL2"))):
        a = points["init"]
        P0, Q0 = a["P0Q0"]
        xa, ua, pg, _, outputs = a["REGCP1"]
        given = dict(V0=a["V"], theta0=a["theta"], P0=P0, Q0=Q0, Vs=a["V"], theta_vs=a["theta"])
        x, inputs = REGCP1.start(given, pg)
        np.testing.assert_allclose(x, xa, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose([inputs[n] for n in REGCP1.input_names], ua, rtol=1e-12, atol=1e-14)
        y = dict(zip(REGCP1.output_names, REGCP1.output_values(x, ua, pg)))
        np.testing.assert_allclose([y["Pe"], y["Qe"], y["vd"], y["vq"]], outputs, rtol=1e-12, atol=1e-14)
        for name in plls:
            component = {"PLL1": PLL1, "PLL2": PLL2}[name]
            xp, up, pp, _, _ = a[name]
            x0, _ = component.start({"Vt": a["V"], "theta_vs": a["theta"], "am": inputs["am"]}, pp)
            np.testing.assert_allclose(x0, xp, rtol=1e-12, atol=1e-14)
            assert np.abs(component.rhs(x0, up, pp)).max() == 0.0


@pytest.mark.andes
@pytest.mark.parametrize("t", TIMES)
def test_pll_and_converter_derivatives_and_outputs_match_andes_mid_fault_and_after_clearing(with_pll1, t):
    """At ANDES' states and inputs: PLL1's dx/dt and PI_y, REGCP1's dx/dt and its Pe, Qe, vd, vq in
    the PLL's frame equal ANDES' (relative to the values compared). Mid-fault the converter's
    active current is on LVPL; at 2.5 s the measured angle still lags the bus angle by 0.014 rad."""
    point = with_pll1[t]
    x, u, p, rates, PI_y = point["PLL1"]
    assert np.abs(rates).max() > 1e-3  # not at rest
    _close(PLL1.rhs(x, u, p), rates)
    _close(PLL1.output_values(x, u, p), [PI_y])
    x, u, p, rates, outputs = point["REGCP1"]
    assert abs(u[1] - u[4]) > 2e-4
    _converter_close(REGCP1.rhs(x, u, p), x, p, rates)
    y = dict(zip(REGCP1.output_names, REGCP1.output_values(x, u, p)))
    _close([y["Pe"], y["Qe"], y["vd"], y["vq"]], outputs, floor=1.0)


@pytest.mark.andes
def test_andes_electrical_controller_of_regcp1_measures_its_d_axis_voltage_not_the_bus_voltage(with_pll1):
    """ANDES' REECA1 (and REECB1) take the converter's vd as their voltage: with REGCP1 and a PLL that
    is V cos(theta - am), 1e-4 pu below the bus voltage at 2.5 s (our REECA1 takes the bus voltage)."""
    point = with_pll1[2.5]
    vd = point["REGCP1"][4][2]
    assert point["controller_voltage"] == vd
    assert 5e-5 < point["V"] - vd < 2e-4


@pytest.mark.andes
@pytest.mark.parametrize("t", TIMES)
def test_andes_regcp1_without_pll_is_our_regca1_and_its_bus_pll2_matches_ours(without_pll, t):
    """ANDES' REGCP1 without a PLL (the conversion maps it to REGCA1): our REGCA1's dx/dt and Pe, Qe
    equal its own; the case's PLL2 at the same bus (which nothing uses) follows our PLL2."""
    point = without_pll[t]
    x, u, p, rates, outputs = point["REGCP1"]
    pa = REGCA1.params({f: getattr(p, f) for f in p.__dataclass_fields__})
    _converter_close(REGCA1.rhs(x, u[:4], pa), x, pa, rates)
    _close(REGCA1.output_values(x, u[:4], pa)[6:8], outputs[:2], floor=1.0)
    x, u, p, rates, PI_y = point["PLL2"]
    assert np.abs(rates).max() > 1e-3
    _close(PLL2.rhs(x, u, p), rates)
    _close(PLL2.output_values(x, u, p), [PI_y])
