"""The native reference FMUs (FMI 2.0, 3.0) of the standard dynamic models (reference_models.models):
every model's FMI 2.0 FMU, and the FMI 3.0 FMUs of FMI3_MODELS (the same model code over the other
plumbing), build, validate, carry their ports, rest at their equilibrium, follow an independent solver of
their own equations through limit crossings (scipy's DOP853 with the same branches locked between
located crossings), give exact directional derivatives on either side of a limit, place a state
pushed beyond a non-windup limit on it (the component's reset, at each step's start and at each
located crossing), and their switching functions are those of the equations' conditions."""
import ctypes
import math
import subprocess

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.validation import validate_fmu
from scipy.integrate import solve_ivp

from cosim.fmu import FMU as Slave
from fmu_export.binaries import fmi_headers
from fmu_export.build_cache import cached_native_reference_fmu
from fmu_export.c_equations import reset_c_source, switching_c_source, switching_conditions
from fmu_export.variables import fmu_ports
from reference_models.models import STANDARD_MODELS
from reference_models.ports import ports_of_fmu

H = 0.05  # s: the communication step of the runs below
# per model: the inputs over the run, pieces (until [s], {input: value}) from the start inputs, chosen
# to drive the model's limiters (a terminal-voltage dip deep enough to hit an exciter's ceiling, a
# speed step that opens a governor's valve to its limit and one that closes it to the other)
VOLTAGE_DIP = ((0.1, {}), (0.6, {"Vt": 0.5}), (1.5, {}))
SPEED_STEPS = ((0.1, {}), (0.8, {"omega": 0.95}), (1.5, {"omega": 1.05}))
RUNS = {
    "GENCLS": ((0.1, {}), (0.3, {"Vs": 0.6}), (1.0, {})),
    "GENROU": ((0.1, {}), (0.3, {"Vs": 0.6}), (1.0, {})),
    "IEEEX1": VOLTAGE_DIP, "EXDC2": VOLTAGE_DIP, "EXST1": VOLTAGE_DIP, "ESST3A": VOLTAGE_DIP, "SEXS": VOLTAGE_DIP,
    "TGOV1": SPEED_STEPS, "TGOV1N": SPEED_STEPS,
    # the valve's rate limit at the speed step, and left within a step as the valve settles back
    "IEEEG1": ((0.1, {}), (0.8, {"omega": 0.95}), (1.5, {})),
    "IEEEST": ((0.1, {}), (0.6, {"omega": 1.01, "Vt": 0.5}), (1.2, {"omega": 0.99})),
    "EXAC1": VOLTAGE_DIP, "ESAC1A": VOLTAGE_DIP, "ESST1A": VOLTAGE_DIP, "ESDC1A": VOLTAGE_DIP, "AC8B": VOLTAGE_DIP,
    "EXAC4": ((0.1, {}), (0.6, {"Vt": 0.5}), (1.0, {"Vt": 1.2}), (1.5, {})),
    "ESST4B": ((0.1, {}), (0.8, {"Vref": 1.5}), (1.5, {"Vref": 0.8})),
    # at 0.5 pu ESDC2A's ceiling (VRMAX Vt) falls under the state, which is placed on it: 0.8 crosses it
    "ESDC2A": ((0.1, {}), (0.6, {"Vt": 0.8}), (1.5, {})),
    "IEEET1": ((0.1, {}), (0.6, {"Vref": 3.0}), (1.5, {})),  # its gain of 5 cannot reach 7.3 pu on a dip
    "IEEET3": ((0.1, {}), (0.6, {"Vt": 0.2}), (1.0, {"Vref": 3.0}), (1.5, {})),
    "IEEEVC": ((0.1, {}), (0.6, {"Vt": 0.5, "I_im": 0.5}), (1.0, {})),
    "TG2": ((0.1, {}), (0.8, {"omega": 0.95}), (1.5, {"Pref": -0.2})),
    "GAST": SPEED_STEPS, "HYGOV4": SPEED_STEPS,
    # not SPEED_STEPS: at 1.05 pu the gate closes to GMIN = 0 and the head q^2 / g^2 has no bound
    "HYGOV": ((0.1, {}), (0.8, {"Pref": 0.3}), (1.5, {"omega": 1.01})),
    "HYGOVDB": ((0.1, {}), (0.8, {"Pref": 0.3}), (1.5, {"omega": 1.01})),
    "IEESGO": ((0.1, {}), (0.8, {"omega": 0.95, "Pref": 4.9995}), (1.5, {"omega": 1.05, "Pref": 0.0005})),
    "ST2CUT": ((0.1, {}), (0.6, {"omega": 1.01, "Vt": 0.5}), (1.2, {"omega": 0.99})),
    "REGCA1": ((0.1, {}), (0.4, {"Vs": 0.45, "Iqcmd": -1.5}), (1.0, {})),  # LVPL and the Iq rate limit
    "REECA1": ((0.1, {}), (0.4, {"V": 0.6}), (0.7, {"Pref": -0.2}), (1.2, {})),  # the freeze, s5_y against PMIN
    "Motor5": ((0.1, {}), (0.3, {"Vs": 0.6}), (1.0, {})), "Motor3": ((0.1, {}), (0.3, {"Vs": 0.6}), (1.0, {})),
    "FLoad": ((0.1, {}), (0.3, {"Vs": 0.6, "theta_vs": 0.2}), (1.0, {})),
    "REPCA1": ((0.1, {}), (0.4, {"Vm": 0.6, "Vref": 1.2}), (0.8, {"Plant_pref": 0.7, "theta_m": 0.2}), (1.2, {})),
    "ZIP": ((0.1, {}), (0.3, {"Vs": 0.6}), (1.0, {})),
    "PV": ((0.1, {}), (0.3, {"Vs": 0.9}), (1.0, {})),
    "ShuntSw": ((0.1, {}), (0.3, {"Vs": 0.9}), (1.0, {"Vs": 1.1})),  # steps in below the band, out above it  # the voltage held: reactive power Kv (V0 - Vs)
    "Slack": ((0.1, {}), (0.3, {"Vs": 0.9, "theta_vs": 0.05}), (1.0, {})),
    "PLL1": ((0.1, {}), (0.6, {"theta_vs": 0.3}), (1.2, {})),
    "PLL2": ((0.1, {}), (0.6, {"theta_vs": 0.3, "Vt": 0.5}), (1.2, {})),
    "REGCP1": ((0.1, {}), (0.4, {"Vs": 0.45, "Iqcmd": -1.5}), (0.7, {"am": 0.3}), (1.0, {})),
    "REECB1": ((0.1, {}), (0.4, {"V": 0.6}), (0.7, {"Pref": -0.2}), (1.2, {})),
    "WTDS": ((0.1, {}), (0.5, {"Pe": 0.2}), (1.0, {"wr0": 0.9})),
    "SHAFT5": ((0.1, {}), (0.5, {"tm": 0.8}), (1.0, {"omega": 1.01, "delta": 0.05})),
    # the voltage trip curves, the reactive droop both ways and the frequency measurement
    "PVD1": ((0.1, {}), (0.4, {"Vs": 0.89}), (0.7, {"Vs": 0.5}), (0.9, {"Vs": 1.15}), (1.2, {"theta_vs": 0.3}),
             (1.6, {})),
    # as PVD1, then charging: the state of charge leaves its empty limit
    "ESD1": ((0.1, {}), (0.4, {"Vs": 0.89}), (0.7, {"Vs": 0.5}), (0.9, {"Vs": 1.15}), (1.2, {"theta_vs": 0.3}),
             (1.6, {"pref0": -0.5}), (1.8, {})),
    "WTDTA1": ((0.1, {}), (0.5, {"Pe": 0.2}), (1.0, {})), "WTARA1": ((0.1, {}), (0.5, {"theta": 10.0}), (1.0, {})),
    # errors of 450 and 300 pu drive both PIs onto thmax within the run, the pitch along its rate limit
    "WTPTA1": ((0.1, {}), (1.2, {"wt": 451.0, "Pord": 300.5}), (1.8, {"wt": -449.0})),
    "WTTQA1": ((0.1, {}), (0.6, {"Pe": 0.1}), (1.2, {"wg": 0.5})),  # the characteristic's bend at p1
    # auxiliary powers beyond the limits: Psig, Qsig onto Pmax, Qmin (short: on a fixed bus voltage nothing rests)
    # a grid-forming inverter has no rest on a held bus voltage off its set point: short, so that the
    # runaway stays where two solvers agree to 1e-8 (0.3 s: 1e-7 and scores of limit crossings)
    "REGF1": ((0.1, {}), (0.15, {"Paux": 1.5, "Qaux": -1.5})),
    "REGF2": ((0.1, {}), (0.15, {"Paux": 1.5, "Qaux": -1.5})),
    "REGF3": ((0.1, {}), (0.15, {"Paux": 1.5, "Qaux": -1.5})),
}


# parameters other than the defaults: SEXS's ceiling (99 pu by default) within reach of the dip; the
# regulator ceilings of ESAC1A and ESST1A (999 pu); ESST4B's gains (at its defaults it crosses no limit)
PARAMS = {"SEXS": {"EMAX": 3.0, "EMIN": 0.0}, "ESAC1A": {"VAMAX": 8.0, "VAMIN": -8.0},
          "ESST1A": {"VAMAX": 8.0, "VAMIN": -8.0}, "ESST4B": {"KPR": 10.0, "KIR": 20.0, "KIM": 2.0},
          "ShuntSw": {"B1": 0.05, "B2": 0.1, "B3": 0.15, "n": 3.0, "dt": 0.12}}  # ANDES' default: no step; a delay off the step grid


def params(name):
    return STANDARD_MODELS[name].params(PARAMS.get(name))


# the models also built for FMI 3.0: one of each kind of variables and FMI calls the FMI 2.0 FMUs of
# all of them have (no states: PV, Slack, ZIP on a bus, WTARA1 off it; bus devices with states and no
# switching: GENCLS, GENROU, Motor5, FLoad; with switching: PVD1, REGCA1, REGF2, ShuntSw, ESD1;
# controllers: the most inputs and switching functions, REPCA1, REECA1, ESST3A; a reset on a non-windup
# limit: IEEEX1, TGOV1; no limit and many states: IEEEST, SHAFT5; several outputs off a bus: IEEEG1, WTDS).
# Each FMU build costs about 2 s of compiling, and the FMI 3.0 plumbing is the same for every model.
FMI3_MODELS = ("ESD1", "ESST3A", "FLoad", "GENCLS", "GENROU", "IEEEG1", "IEEEST", "IEEEX1", "Motor5", "PV", "PVD1",
               "REECA1", "REGCA1", "REGF2", "REPCA1", "SHAFT5", "Slack", "ShuntSw", "TGOV1", "WTARA1", "WTDS", "ZIP")
BUILT = [(name, 2) for name in sorted(STANDARD_MODELS)] + [(name, 3) for name in FMI3_MODELS]


def versions(name) -> tuple:
    """The FMI versions `name`'s FMUs are built for here."""
    return (2, 3) if name in FMI3_MODELS else (2,)


@pytest.fixture(scope="session")
def standard_fmus(fmu_cache):
    """{(model, FMI version): path} of the native reference FMUs in BUILT (host platform, parameters
    `params(model)`), built once per run through the build cache."""
    return {(name, v): cached_native_reference_fmu(f"{name}Reference", STANDARD_MODELS[name], PARAMS.get(name),
                                                   fmi_version=v, cache=fmu_cache)
            for name, v in BUILT}


class Branches:
    """The math namespace of scalars with the conditions of `where` recorded in the order they are
    met (`truth`) and, with `modes`, each `where` taking the branch modes[k] instead of its condition's."""

    sin, cos, exp, sqrt = np.sin, np.cos, np.exp, np.sqrt

    def __init__(self, modes=None):
        self.modes, self.truth = modes, []

    def where(self, condition, a, b):
        k = len(self.truth)
        self.truth.append(bool(condition))
        return a if (self.modes[k] if self.modes is not None else condition) else b


def rhs(component, p, x, u, modes=None) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.array(component.derivatives(list(x), u, p, Branches(modes)), dtype=float)


def live_modes(component, p, x, u) -> list:
    ns = Branches()
    with np.errstate(invalid="ignore", divide="ignore"):
        component.derivatives(list(x), u, p, ns)
    return ns.truth


def crossed(component, p, x, u, locked) -> bool:
    """The branches that hold at x differ from `locked` and give another right-hand side."""
    now = live_modes(component, p, x, u)
    return now != locked and not np.array_equal(rhs(component, p, x, u, locked), rhs(component, p, x, u, now))


def locked_solution(component, p, x, u, h):
    """(state after h [s] with inputs u held, crossings located): scipy's DOP853 (rtol = atol = 1e-12)
    on the component's equations with their branches locked, the first crossing among its steps
    bracketed by bisection on its dense output to 1e-13 s, restarted there with the branches then
    holding, the component's reset applied at each (re)start: an independent solver of the same
    piecewise equations."""
    t, x, events = 0.0, np.array(x, dtype=float), 0
    while True:
        x = component.reset_states(x, np.array(u), p)
        modes = live_modes(component, p, x, u)
        sol = solve_ivp(lambda _t, y: rhs(component, p, y, u, modes), (t, h), x, method="DOP853", rtol=1e-12,
                        atol=1e-12, dense_output=True)
        assert sol.success, sol.message
        hit = next((i for i in range(1, len(sol.t)) if crossed(component, p, sol.y[:, i], u, modes)), None)
        if hit is None:
            return sol.y[:, -1], events
        lo, hi = sol.t[hit - 1], sol.t[hit]
        while hi - lo > 1e-13:
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if crossed(component, p, sol.sol(mid), u, modes) else (mid, hi)
        t, x, events = hi, sol.sol(hi), events + 1


def run_inputs(component, pieces):
    """The inputs [n_steps, n_u] held over each step of H of a run given as pieces."""
    start, rows = dict(zip(component.input_names, component.start_inputs)), []
    begin = 0.0
    for until, changes in pieces:
        values = [float({**start, **changes}[n]) for n in component.input_names]
        rows += [values] * int(round((until - begin) / H))
        begin = until
    return np.array(rows)


@pytest.mark.parametrize("name, version", BUILT)
def test_every_standard_model_fmu_validates_and_carries_its_ports(standard_fmus, name, version):
    path = standard_fmus[name, version]
    assert validate_fmu(str(path)) == []
    assert ports_of_fmu(path) == fmu_ports(STANDARD_MODELS[name])  # with the bus port's outputs, if on a bus


@pytest.mark.parametrize("name", sorted(STANDARD_MODELS))
def test_at_its_equilibrium_each_model_stays_at_rest(standard_fmus, name):
    component = STANDARD_MODELS[name]
    rest = component.steady_state(None, params(name))
    for version in versions(name):
        slave = Slave(standard_fmus[name, version], component=component)
        np.testing.assert_allclose(slave.state(), rest, rtol=0, atol=1e-12)
        for _ in range(20):
            x = slave.step(H)
        slave.close()
        np.testing.assert_allclose(x, rest, rtol=0, atol=1e-10)


@pytest.mark.parametrize("name", sorted(STANDARD_MODELS))
def test_states_and_outputs_follow_an_independent_solver_through_the_limits(standard_fmus, name):
    component, p = STANDARD_MODELS[name], params(name)
    inputs = run_inputs(component, RUNS[name])
    x = component.steady_state(None, p)
    expected, crossings = [], 0
    for u in inputs:
        x, events = locked_solution(component, p, x, tuple(u), H)
        crossings += events
        expected.append(np.concatenate([x, component.output_equations(list(x), tuple(u), p, Branches())]))
    expected = np.array(expected)
    for version in versions(name):
        slave = Slave(standard_fmus[name, version], component=component)
        got = []
        for u in inputs:
            got.append(np.concatenate([slave.step(H, *u), slave.get(*component.output_names)]))
        slave.close()
        scale = np.maximum(1.0, np.abs(expected).max(axis=0))
        worst = (np.abs(np.array(got) - expected) / scale).max(axis=0)
        assert worst.max() < 1e-8, dict(zip(component.state_names + component.output_names, worst))
    if switching_conditions(component, p):
        assert crossings > 0, f"{name}: the run crosses no switching function"


def test_the_switching_functions_are_the_conditions_of_the_right_hand_side():
    tgov1 = STANDARD_MODELS["TGOV1"]
    n, source = switching_c_source(tgov1, tgov1.params_type())
    assert n == 4 and "g[1] = x[0] - 1.2;" in source and "mode[3] = x[0] <= 0.0;" in source
    assert "mode[1] ? " in source  # the locked right-hand side selects on the modes
    gencls = STANDARD_MODELS["GENCLS"]
    assert switching_c_source(gencls, gencls.params_type()) == (0, "")


@pytest.mark.parametrize("name", sorted(STANDARD_MODELS))
def test_the_generated_reset_places_states_as_the_component_does(name, tmp_path):
    """model_reset compiled from the component's reset (gcc -Wall -Werror) gives numpy's
    reset_states (to rounding) at points far from rest (limited states beyond their limits, pushed
    either way); a model without a reset generates no source."""
    component, p = STANDARD_MODELS[name], params(name)
    source = reset_c_source(component, p)
    if component.reset is None:
        assert source == ""
        return
    path, library = tmp_path / "reset.c", tmp_path / "reset.so"
    path.write_text("#include <math.h>\n" + source.replace("static void model_reset", "void model_reset"))
    subprocess.run(["gcc", "-O2", "-Wall", "-Werror", "-shared", "-fPIC", str(path), "-o", str(library), "-lm"],
                   check=True)
    reset = ctypes.CDLL(str(library)).model_reset
    rng = np.random.default_rng(5)
    x0 = component.steady_state(None, p)
    low, high = np.array([q.operating_range for q in component.inputs]).T
    xs = x0 + np.array(component.state_scales) * rng.standard_normal((300, component.n_states)) * 30.0
    us = low + (high - low) * rng.random((300, component.n_inputs))
    expected = component.reset_states(xs, us, p)
    pointer = ctypes.POINTER(ctypes.c_double)
    for x, u, want in zip(xs, us, expected):
        x, u, out = np.ascontiguousarray(x), np.ascontiguousarray(u), np.empty(component.n_states)
        reset(x.ctypes.data_as(pointer), u.ctypes.data_as(pointer), out.ctypes.data_as(pointer))
        np.testing.assert_allclose(out, want, rtol=1e-13, atol=1e-13)
    assert np.any(expected != xs)


@pytest.mark.parametrize("version", [2, 3])
def test_directional_derivatives_are_exact_on_either_side_of_a_limit(standard_fmus, version):
    """IEEEST's Vss is its washout's output clipped to [LSMIN, LSMAX]: clipped, dVss/domega = 0;
    within the limits, KS / T6 times the lead-lags' gains. The FMU's derivatives match central
    differences of the component's outputs wherever both one-sided differences agree (away from
    the switch), on both sides of it."""
    component = STANDARD_MODELS["IEEEST"]
    p = component.params_type()
    slave = Slave(standard_fmus["IEEEST", version], component=component)
    slave.bind(component.input_names, component.output_names)
    compared, sides = 0, set()
    for u in run_inputs(component, RUNS["IEEEST"]):
        slave.set_inputs(list(u))
        slave.do_step(slave.t, H)
        slave.t += H
        x = slave.state()
        J = np.array(slave.output_jacobian([0], list(range(component.n_inputs))))
        for j in range(component.n_inputs):
            d = 1e-7 * max(1.0, abs(u[j]))
            plus, minus = u.copy(), u.copy()
            plus[j] += d
            minus[j] -= d
            out = [component.output_equations(list(x), tuple(v), p, math)[0] for v in (plus, u, minus)]
            right, left = (out[0] - out[1]) / d, (out[1] - out[2]) / d
            if abs(right - left) < 1e-5 * max(1.0, abs(right)):
                assert J[0, j] == pytest.approx(0.5 * (right + left), rel=1e-6, abs=1e-6)
                compared += 1
                if j == 0:
                    sides.add(J[0, 0] == 0.0)
    slave.close()
    assert compared >= len(run_inputs(component, RUNS["IEEEST"])) and sides == {True, False}


@pytest.mark.parametrize("version", [2, 3])
def test_a_non_windup_valve_stops_at_its_limit_and_leaves_it_when_its_rate_turns_back(standard_fmus, version):
    """TGOV1's valve LAG_y (non-windup within [VMIN, VMAX]) under an underspeed that demands more than
    VMAX: it rises to VMAX and stays there (not beyond, no chattering below) while the speed is low;
    an overspeed turns its rate back: it leaves VMAX at once and stops at VMIN."""
    component, p = STANDARD_MODELS["TGOV1"], params("TGOV1")
    slave = Slave(standard_fmus["TGOV1", version], component=component)
    valve = np.array([slave.step(0.01, *u)[0] for u in np.repeat(run_inputs(component, SPEED_STEPS), 5, axis=0)])
    slave.close()
    low_speed, high_speed = valve[10:80], valve[80:]
    at_max = low_speed[low_speed >= p.VMAX - 1e-9]
    assert len(at_max) > 20 and np.all(at_max <= p.VMAX + 1e-11)
    first = np.argmax(low_speed >= p.VMAX - 1e-9)
    assert np.all(low_speed[first:] >= p.VMAX - 1e-11)  # held from the first step it reached the limit
    assert high_speed[0] < p.VMAX - 1e-3 and np.all(np.diff(high_speed[high_speed > p.VMIN + 1e-9]) < 0)
    assert abs(high_speed[-1] - p.VMIN) <= 1e-11


@pytest.mark.parametrize("version", [2, 3])
def test_an_exciter_regulator_pushed_beyond_its_ceiling_is_placed_exactly_on_it(standard_fmus, version):
    """IEEEX1's LA_y (non-windup within [VRMIN, VRMAX], constant as ANDES computes it) started 0.5 pu
    above VRMAX while its regulator pushes up: after the first step it is VRMAX to the last bit (the
    reset at the step's start) and stays there; from rest with the set point raised it reaches VRMAX
    within a step and ends that step and every later one exactly on it (the reset at the located
    crossing, not the crossing's bracket beyond it), also when the terminal voltage then drops to
    0.5 pu; a set point back at rest brings it down."""
    component, p = STANDARD_MODELS["IEEEX1"], params("IEEEX1")
    slave = Slave(standard_fmus["IEEEX1", version], component=component, LA_y0=p.VRMAX + 0.5)
    assert slave.state()[2] == p.VRMAX + 0.5
    placed = [slave.step(H, 1.0, 2.0, 0.0)[2] for _ in range(3)]
    slave.close()
    assert placed == [p.VRMAX] * 3
    slave = Slave(standard_fmus["IEEEX1", version], component=component)
    rising = [slave.step(0.002, 1.0, 2.0, 0.0)[2] for _ in range(10)]  # steps shorter than the rise (~7 ms)
    dipped = [slave.step(H, 0.5, 2.0, 0.0)[2] for _ in range(4)]
    released = [slave.step(H, 1.0, component.start_inputs[1], 0.0)[2] for _ in range(4)]
    slave.close()
    reached = rising.index(p.VRMAX)
    assert 1 < reached < 8 and max(rising[:reached]) < p.VRMAX and rising[reached:] == [p.VRMAX] * (10 - reached)
    assert dipped == [p.VRMAX] * 4
    assert released[-1] < p.VRMAX - 1.0


@pytest.mark.parametrize("name", ["ESST3A", "TGOV1"])
def test_random_fmi_call_sequences_never_crash_a_model_with_limits(standard_fmus, name, tmp_path):
    """The C importer's random FMI calls (tests/c/fuzz_harness.c: NaN, inf, h <= 0, corrupt states,
    ...) on an FMI 2.0 FMU whose steps locate limit crossings: every call returns a valid status."""
    harness = tmp_path / "fuzz_harness"
    subprocess.run(["gcc", "-O1", "-I", str(fmi_headers()), __file__.rsplit("/", 1)[0] + "/c/fuzz_harness.c", "-o",
                    str(harness), "-ldl", "-lm"], check=True)
    directory = extract(str(standard_fmus[name, 2]), unzipdir=str(tmp_path / "fmu"))
    md = read_model_description(directory)
    n_reals = sum(v.type == "Real" for v in md.modelVariables)
    result = subprocess.run([str(harness), f"{directory}/binaries/linux64/{md.coSimulation.modelIdentifier}.so",
                             md.guid, "3000", "1", str(n_reals)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr[-2000:]
    counts = dict(zip(result.stdout.split()[0::2], map(int, result.stdout.split()[1::2])))
    assert counts["steps"] > 500 and counts["error"] > 300 and counts["invalid"] == counts["bad_messages"] == 0
