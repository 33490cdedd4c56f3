"""A regulator time constant of 0 is no lag (ANDES' LagAntiWindup with T = 0 is algebraic): the
exciters EXDC2, IEEEX1, IEEET1, IEEET3, ESDC1A, ESDC2A, AC8B take TA = 0 (ei/EI_33 has an IEEET1 with
TA = 0), hold the regulator's state and feed the exciter its input times KA clipped to the limits;
and where ANDES is installed, EI_33's IEEET1s against ANDES' initialisation and its derivatives in
and after a fault. The monolithic DAE of a stiff case (kundur_esst3a's ESST3A inner loop) takes an
implicit method (reference_models/grid/monolithic.py: STIFF_RATE)."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from reference_models.models import STANDARD_MODELS

# model -> its regulator's state (the non-windup lag KA / (1 + s TA))
REGULATOR_STATE = {"EXDC2": "LA_y", "IEEEX1": "LA_y", "IEEET1": "LA_y", "IEEET3": "LA3_y", "ESDC1A": "LA_y",
                   "ESDC2A": "LA_y", "AC8B": "LA_y"}


def _rest(component, p):
    """(x, u): the model at rest at its inputs' start values."""
    u = np.array([q.start for q in component.inputs])
    return np.array(component.equilibrium(u, p), dtype=float), u


@pytest.mark.parametrize("name", sorted(REGULATOR_STATE))
def test_a_zero_regulator_time_constant_is_accepted_and_a_negative_one_refused(name):
    params_type = STANDARD_MODELS[name].params_type
    params_type(TA=0.0).check()
    with pytest.raises(ValueError, match="TA"):
        params_type(TA=-0.01).check()


@pytest.mark.parametrize("name", sorted(REGULATOR_STATE))
@pytest.mark.parametrize("push", [0.002, 5.0])  # pu on Vref: within the regulator's limits, far beyond its ceiling
def test_without_regulator_lag_the_exciter_takes_the_clipped_regulator_input_and_the_state_is_held(name, push):
    """TA = 0: the regulator's state has rate 0 and nothing reads it; every other rate equals that of
    the model with TA > 0 whose regulator state sits at KA times its input, placed on a limit it is
    beyond (the lag's reset): the output of a lag without lag."""
    component = STANDARD_MODELS[name]
    lagged = component.params_type(TA=0.04)
    lagless = replace(lagged, TA=0.0)
    x, u = _rest(component, lagged)
    u[component.input_names.index("Vref")] += push
    r = component.state_names.index(REGULATOR_STATE[name])
    rates = component.rhs(x, u, lagless)
    assert rates[r] == 0.0
    elsewhere = x.copy()
    elsewhere[r] += 0.37
    np.testing.assert_array_equal(component.rhs(elsewhere, u, lagless), rates)
    at_zero = x.copy()
    at_zero[r] = 0.0  # within every model's default limits: the lag's rate is KA input / TA there
    settled = x.copy()
    settled[r] = lagged.TA * component.rhs(at_zero, u, lagged)[r]
    settled = np.asarray(component.reset_states(settled, u, lagged), dtype=float)
    expected = component.rhs(settled, u, lagged)
    others = [i for i in range(component.n_states) if i != r]
    np.testing.assert_allclose(rates[others], expected[others], rtol=1e-12, atol=1e-12)
    if push > 1.0 and name != "AC8B":  # AC8B's PID output is clipped before the regulator
        assert settled[r] < lagged.TA * component.rhs(at_zero, u, lagged)[r]  # held at its ceiling


def test_esdc2a_without_regulator_lag_clips_at_limits_proportional_to_the_voltage():
    """ESDC2A, TA = 0, Vt = 0.5 pu, KA LL_y far above the ceiling: the exciter is driven by
    VRMAX Vt (ESDC1A: VRMAX)."""
    x = np.array([0.5, 0.5, 4.0, 2.0, 2.0])
    u = np.array([0.5, 1.2, 0.0])
    for name, driven in (("ESDC2A", 7.3 * 0.5), ("ESDC1A", 7.3)):
        component = STANDARD_MODELS[name]
        p = component.params_type(TA=0.0)
        assert component.rhs(x, u, p)[3] == pytest.approx((driven - p.KE * x[3]) / p.TE, rel=1e-12), name


def _recording_solvers(monkeypatch) -> list:
    """The names of the scipy solvers the monolithic solve makes, in order (DOP853, Radau)."""
    import scipy.integrate

    used = []
    for method in ("DOP853", "Radau"):
        solver = getattr(scipy.integrate, method)
        monkeypatch.setattr(scipy.integrate, method,
                            lambda *a, _solver=solver, _name=method, **k: used.append(_name) or _solver(*a, **k))
    return used


def test_the_monolithic_solve_takes_the_implicit_method_only_where_the_case_is_stiff(monkeypatch):
    """wscc9's largest rate at the start lies far below STIFF_RATE: DOP853; the same System taken
    as stiff: STIFF_METHOD, and it stays at rest."""
    from reference_models.grid import monolithic, wscc9
    from reference_models.grid.contingency import Contingency

    used = _recording_solvers(monkeypatch)
    system = monolithic.System(wscc9.case())
    assert 1.0 < system.largest_rate() < monolithic.STIFF_RATE / 10
    monolithic.simulate(system, Contingency(), 0.05)
    assert set(used) == {"DOP853"}
    used.clear()
    monkeypatch.setattr(system, "largest_rate", lambda controls=True: 2.0 * monolithic.STIFF_RATE)
    result = monolithic.simulate(system, Contingency(), 0.05)
    assert set(used) == {monolithic.STIFF_METHOD}
    np.testing.assert_allclose(result.rotor_angle[-1], result.rotor_angle[0], atol=1e-9)


@pytest.mark.andes
def test_kundur_esst3a_inner_loop_makes_the_monolithic_solve_implicit_and_it_reaches_its_stop(monkeypatch):
    """kundur_esst3a's ESST3A inner loop (KM = 500, TM = 0.1: rates about 2.2e4 1/s) stalled DOP853
    at rest (18,000 evaluations by 0.38 s); its solve is Radau's and ends at rest in a few hundred."""
    pytest.importorskip("andes")
    import andes

    from reference_models.grid import monolithic
    from reference_models.grid.andes_case import case_from_file
    from reference_models.grid.contingency import Contingency

    used = _recording_solvers(monkeypatch)
    system = monolithic.System(case_from_file(andes.get_case("kundur/kundur_esst3a.xlsx")))
    assert system.largest_rate() == pytest.approx(2.16e4, rel=0.01)
    result = monolithic.simulate(system, Contingency(), 2.0)
    assert set(used) == {"Radau"} and result.n_rhs < 1000
    np.testing.assert_allclose(result.rotor_angle[-1], result.rotor_angle[0], atol=1e-8)


# --- against ANDES 2.0.0 on ei/EI_33 ----------------------------------------------------------------

CASE = "ei/EI_33.xlsx"
LAGLESS_BUS = 147916  # the bus of EI_33's IEEET1 with TA = 0 (IEEET1_35, on GENROU_79)
TIMES = (1.05, 2.5)  # s: mid-fault (1.0-1.1 s) and after clearing


def _run(fault_reactance=None, times=()):
    """ANDES' EI_33 after its power flow and TDS initialisation (times empty), or with a fault of
    reactance `fault_reactance` [pu] at LAGLESS_BUS 1.0-1.1 s, paused at each of `times` (trapezoid,
    h = 5 ms, Newton tolerance 1e-8). Its power flow keeps ANDES' tolerance (at 1e-12 it does not
    converge)."""
    import andes

    from reference_models.grid.andes_case import configure_andes_logging

    configure_andes_logging(andes, 50)
    ss = andes.load(andes.get_case(CASE), setup=False, no_output=True, default_config=True)
    if fault_reactance is not None:
        ss.add("Fault", {"bus": LAGLESS_BUS, "tf": 1.0, "tc": 1.1, "xf": fault_reactance, "rf": 0.0})
    ss.setup()
    ss.PFlow.run()
    if not times:
        ss.TDS.init()
        yield ss
        return
    ss.TDS.config.update(tol=1e-8, fixt=1, tstep=0.005, no_tqdm=1)
    for t in times:
        ss.TDS.config.tf = t
        ss.TDS.run()
        assert ss.dae.t == pytest.approx(t), f"ANDES' TDS of {CASE} stopped at {ss.dae.t} s"
        ss.TDS.fg_update(ss.exist.tds)
        yield ss


def _lagless(ss) -> int:
    model = ss.IEEET1
    found = [i for i in range(model.n) if model.TA.v[i] == 0]
    assert len(found) == 1 and model.bus.v[found[0]] == LAGLESS_BUS
    return found[0]


def _ieeet1_rates(ss):
    """Per IEEET1 of ANDES' EI_33: (TA, largest |our dx/dt - ANDES' f / Tf| / (1 + largest |ANDES'|)
    over the states ANDES integrates (Tf > 0; TA = 0: its LA_y is algebraic, ours held with rate 0),
    ANDES' LA_y)."""
    from test_dc_exciters_and_compensator import _params, _signals

    model, component = ss.IEEET1, STANDARD_MODELS["IEEET1"]
    for i in range(model.n):
        s, p = _signals(ss, model, i), _params(model, component, i)
        u = np.array([s[n] for n in component.input_names])
        x = np.array([float(getattr(model, n).v[i]) for n in component.state_names])
        addresses = [int(getattr(model, n).a[i]) for n in component.state_names]
        Tf, f = ss.dae.Tf[addresses], ss.dae.f[addresses]
        integrated = Tf != 0
        theirs = f[integrated] / Tf[integrated]
        ours = component.rhs(x, u, p)[integrated]
        yield p.TA, float(np.abs(ours - theirs).max() / (1.0 + np.abs(theirs).max())), float(model.LA_y.v[i])


@pytest.mark.andes
@pytest.mark.filterwarnings("ignore:invalid value encountered in sqrt")  # ANDES' own EXAC1 code
def test_ei33_ieeet1_start_gives_andes_initial_states_and_set_point_with_and_without_regulator_lag():
    """All seven IEEET1s of EI_33 (one with TA = 0): Component.start from the field voltage gives
    ANDES' initial states (its held LA_y at the regulator output ANDES starts from) and Vref."""
    pytest.importorskip("andes")
    from test_dc_exciters_and_compensator import _params, _signals

    ss = next(_run())
    model, component = ss.IEEET1, STANDARD_MODELS["IEEET1"]
    assert model.n == 7 and model.TA.v[_lagless(ss)] == 0
    for i in range(model.n):
        s, p = _signals(ss, model, i), _params(model, component, i)
        x0, inputs = component.start({**s, "Vref": math.nan}, p)
        theirs = np.array([float(getattr(model, n).v[i]) for n in component.state_names])
        np.testing.assert_allclose(x0, theirs, rtol=1e-10, atol=1e-12)
        assert inputs["Vref"] == pytest.approx(s["Vref"], rel=1e-10)
        u = np.array([inputs[n] for n in component.input_names])
        assert np.abs(component.rhs(x0, u, p)).max() < 1e-10


@pytest.mark.andes
@pytest.mark.filterwarnings("ignore:invalid value encountered in sqrt")  # ANDES' own EXAC1 code
def test_ei33_lagless_regulator_follows_andes_in_and_after_a_fault_within_its_limits():
    """A fault of 0.2 pu at the bus of EI_33's TA = 0 IEEET1, 1.0-1.1 s: its regulator stays within
    [VRMIN, VRMAX] (ANDES' LA_y at most 2.3 pu, VRMAX = 5.6), and at 1.05 s and 2.5 s every IEEET1's
    dx/dt at ANDES' states and inputs equals ANDES' f / Tf: the exciter of the lagless one is driven
    by KA times its input, ANDES' algebraic LA_y (measured: 3.7e-8 and 2.3e-7 of ANDES' largest rate;
    the others up to 2.6e-6, the one with TA = 0.01 s mid-fault: ANDES' Newton tolerance 1e-8 on its
    step equations, Tf (x - x0) - h/2 (f + f0), allows 4e-6 / Tf in f / Tf)."""
    pytest.importorskip("andes")
    for t, ss in zip(TIMES, _run(0.2, TIMES)):
        lagless = _lagless(ss)
        for i, (TA, difference, LA_y) in enumerate(_ieeet1_rates(ss)):
            assert difference < (1e-6 if i == lagless else 1e-5), (t, i, TA, difference)
            if i == lagless:
                assert abs(LA_y) < ss.IEEET1.VRMAX.v[i], (t, LA_y)


@pytest.mark.andes
@pytest.mark.filterwarnings("ignore:invalid value encountered in sqrt")  # ANDES' own EXAC1 code
def test_andes_trapezoid_leaves_a_lagless_regulator_beyond_its_limits_after_a_close_fault():
    """Where ANDES' trapezoid differs from a lag without lag: with T = 0 its step equation of the lag,
    T (y - y0) - h/2 (f + f0) = 0, is f = -f0. A bolted fault at the TA = 0 IEEET1's bus holds its
    LA_y at VRMAX (5.6 pu) mid-fault, as ours (the rates agree at 1.05 s); the step that leaves the
    limit leaves f != 0, and f alternates in sign from step to step from then on, undamped: at 2.5 s
    and the step after it ANDES' LA_y lies on either side of the value about which it alternates,
    one of the two beyond VRMAX (the exciter integrates the two-step average, KA times the input,
    unclipped). Which of the two steps holds which value, and the amplitude (6.5 or 7.4 pu above),
    differ between machines with the round-off of ANDES' Newton iterations. The other IEEET1s agree
    with ANDES throughout; the lagless one's exciter there differs, ANDES' by its numerical
    alternation."""
    pytest.importorskip("andes")
    times = (TIMES[0], TIMES[1], TIMES[1] + 0.005)  # mid-fault, then two steps of h = 5 ms after clearing
    after = []
    for t, ss in zip(times, _run(1e-4, times)):
        lagless = _lagless(ss)
        VRMAX = float(ss.IEEET1.VRMAX.v[lagless])
        for i, (TA, difference, LA_y) in enumerate(_ieeet1_rates(ss)):
            if i != lagless or t == TIMES[0]:
                assert difference < 1e-5, (t, i, TA, difference)
            if i == lagless and t == TIMES[0]:
                assert LA_y == pytest.approx(VRMAX, rel=1e-12)
            if i == lagless and t > TIMES[0]:
                after.append((LA_y, difference))
    (first, d1), (second, d2) = after
    assert max(first, second) > VRMAX and min(first, second) < VRMAX - 5.0 and min(d1, d2) > 0.1, after