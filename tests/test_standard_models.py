"""The standard dynamic models (reference_models.models): at rest at their equilibrium, the same
derivatives on every math namespace, limiters that hold and release, the resets of non-windup
limits (ANDES' anti-windup: a state pushed outward at or beyond a limit is placed on it), lead-lags
that degenerate to gains, and ANDES' initial states and trajectories of its shipped cases (where
ANDES is installed)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from reference_models import blocks
from reference_models.models import STANDARD_MODELS
from reference_models.models import genrou, ieeex1, sexs

MODELS = sorted(STANDARD_MODELS)


def _rest(name):
    component = STANDARD_MODELS[name]
    p = component.params_type()
    u = component.start_inputs
    return component, p, u, component.steady_state(u, p)


@pytest.mark.parametrize("name", MODELS)
def test_equilibrium_makes_every_derivative_zero(name):
    component, p, u, x = _rest(name)
    rates = component.rhs(x, u, p)
    assert np.all(np.abs(rates) <= 1e-10 * (1.0 + np.abs(x).max(initial=0.0))), rates


@pytest.mark.parametrize("name", MODELS)
def test_numpy_torch_and_math_derivatives_agree(name):
    torch = pytest.importorskip("torch")
    component, p, u, x = _rest(name)
    rng = np.random.default_rng(7)
    xs = x + 0.1 * np.array(component.state_scales) * rng.standard_normal((5, component.n_states))
    us = u + 0.01 * rng.standard_normal((5, component.n_inputs))
    by_numpy = component.rhs(xs, us, p)
    by_torch = component.rhs(torch.tensor(xs, dtype=torch.float64), torch.tensor(us, dtype=torch.float64), p).numpy()
    by_math = np.array([component.derivatives(list(a), list(b), p, math) for a, b in zip(xs, us)], dtype=float)
    np.testing.assert_allclose(by_torch, by_numpy, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(by_math, by_numpy, rtol=1e-12, atol=1e-12)
    outputs = component.output_values(xs, us, p)
    np.testing.assert_allclose(
        np.array([component.output_equations(list(a), list(b), p, math) for a, b in zip(xs, us)], dtype=float),
        outputs, rtol=1e-12, atol=1e-12)


def test_non_windup_holds_a_state_pushed_outward_at_its_limit_and_releases_it_inward():
    assert blocks.non_windup(math, 2.0, 1.0, -1.0, 1.0) == 0.0
    assert blocks.non_windup(math, -2.0, 1.0, -1.0, 1.0) == -2.0
    assert blocks.non_windup(math, -2.0, -1.0, -1.0, 1.0) == 0.0
    assert blocks.non_windup(math, 2.0, -1.0, -1.0, 1.0) == 2.0
    assert blocks.non_windup(math, 2.0, 0.5, -1.0, 1.0) == 2.0


def test_non_windup_reset_places_a_state_pushed_outward_at_or_beyond_its_limit_on_it():
    reset = blocks.non_windup_reset
    assert reset(math, 0.0, 1.3, -1.0, 1.0) == 1.0  # beyond the upper limit, rate 0 counts as outward
    assert reset(math, 2.0, 1.0, -1.0, 1.0) == 1.0
    assert reset(math, -2.0, 1.3, -1.0, 1.0) == 1.3  # pushed back inward: left to leave on its own
    assert reset(math, -0.5, -1.2, -1.0, 1.0) == -1.0
    assert reset(math, 0.5, -1.2, -1.0, 1.0) == -1.2
    assert reset(math, 2.0, 0.4, -1.0, 1.0) == 0.4  # within the limits: unchanged
    assert reset(math, 2.0, 3e7, -blocks.NO_LIMIT, blocks.NO_LIMIT) == 3e7  # no limit beyond the marker
    # limits of the namespace (moving with an input): each element against its own limits
    high = np.array([1.0, 0.5, 0.5, 0.5])
    placed = reset(np, np.array([1.0, 1.0, -1.0, 0.0]), np.array([1.0, 1.0, 1.0, 0.2]), -high, high)
    np.testing.assert_array_equal(placed, [1.0, 0.5, 1.0, 0.2])
    # its derivative counterpart holds the same states there while pushed outward
    rates = blocks.non_windup_between(np, np.array([1.0, 1.0, -1.0, 1.0]), np.array([1.0, 1.0, 1.0, 0.2]), -high, high)
    np.testing.assert_array_equal(rates, [0.0, 0.0, -1.0, 1.0])


def test_a_lag_with_zero_time_constant_keeps_its_held_state_on_reset():
    assert blocks.lag_non_windup_reset(math, 5.0, 7.0, 1.0, 0.0, -1.0, 1.0) == 7.0
    assert blocks.lag_non_windup_reset(math, 9.0, 7.0, 1.0, 0.1, -1.0, 1.0) == 1.0
    assert blocks.lag_non_windup_reset(math, 5.0, 7.0, 1.0, 0.1, -1.0, 1.0) == 7.0


def test_ieeex1_regulator_beyond_its_ceiling_is_placed_on_it_while_pushed_up_whatever_the_voltage():
    """IEEEX1's LA_y beyond VRMAX while its regulator pushes up: the reset puts it on VRMAX, at a
    terminal voltage of 1 or 0.5 pu alike (ANDES 2.0.0's limits are constant, ieeex1.py); pushed
    down, it stays where it is and falls on its own; the floor VRMIN likewise."""
    component, p = ieeex1.IEEEX1, ieeex1.IEEEX1Params()
    rest = component.steady_state(None, p)
    above = np.array([*rest[:2], p.VRMAX + 0.4, *rest[3:]])
    for Vt in (1.0, 0.5):
        pushed_up, pushed_down = np.array([Vt, 2.0, 0.0]), np.array([Vt, 0.0, 0.0])
        assert component.reset_states(above, pushed_up, p)[2] == p.VRMAX
        assert component.reset_states(above, pushed_down, p)[2] == p.VRMAX + 0.4
        below = np.array([*rest[:2], p.VRMIN - 0.4, *rest[3:]])
        assert component.reset_states(below, pushed_down, p)[2] == p.VRMIN
        assert component.reset_states(below, pushed_up, p)[2] == p.VRMIN - 0.4
    np.testing.assert_array_equal(np.delete(component.reset_states(above, pushed_up, p), 2), np.delete(above, 2))


# limits within reach of the points driven far: SEXS's ceiling (99 pu by default); ESST1A's regulator
# ceiling (999 pu), which its input limit VIMAX keeps it from ever reaching at the defaults
LIMITS_WITHIN_REACH = {"SEXS": {"EMAX": 3.0, "EMIN": 0.0}, "ESST1A": {"VAMAX": 8.0, "VAMIN": -8.0}}


@pytest.mark.parametrize("name", MODELS)
def test_reset_is_the_same_on_every_namespace_and_leaves_states_within_their_limits_alone(name):
    """Random points near rest (within the limits): the reset changes nothing; points driven far
    beyond (each state 0.1 to 1000 of its scales from rest, inputs anywhere in their operating
    ranges): numpy, torch and math place them alike. A model without non-windup limits (GENCLS,
    GENROU, EXST1, IEEEST) declares no reset: reset_states is x itself."""
    torch = pytest.importorskip("torch")
    component, _, u, _ = _rest(name)
    p = component.params(LIMITS_WITHIN_REACH.get(name))
    x = component.steady_state(u, p)
    rng = np.random.default_rng(11)
    near = x + 0.01 * np.array(component.state_scales) * rng.standard_normal((5, component.n_states))
    us = u + 0.01 * rng.standard_normal((5, component.n_inputs))
    if component.reset is None:
        assert component.reset_states(near, us, p) is near
        return
    np.testing.assert_array_equal(component.reset_states(near, us, p), near)
    size = (1000, component.n_states)  # each state 0.1 to 1000 of its scales from rest
    far = x + np.array(component.state_scales) * rng.standard_normal(size) * 10.0 ** rng.uniform(-1.0, 3.0, size)
    low, high = np.array([q.operating_range for q in component.inputs]).T
    us = low + (high - low) * rng.random((1000, component.n_inputs))
    by_numpy = component.reset_states(far, us, p)
    by_torch = component.reset_states(torch.tensor(far), torch.tensor(us), p).numpy()
    by_math = np.array([component.reset(list(a), list(b), p, math) for a, b in zip(far, us)], dtype=float)
    np.testing.assert_array_equal(by_torch, by_numpy)
    np.testing.assert_array_equal(by_math, by_numpy)
    assert np.any(by_numpy != far)  # some were placed on a limit


def test_components_without_non_windup_limits_declare_no_reset_and_reset_to_themselves():
    from reference_models.components import COMPONENTS

    assert {n for n, c in COMPONENTS.items() if c.reset is None} == {
        "sm4", "ieee1", "gencls", "genrou", "exst1", "ieeest", "exac4", "esst4b", "ieeevc", "tg2", "ieesgo", "st2cut",
        "fload", "motor3", "motor5", "zip", "pvd1", "esd1", "repca1", "wtdta1", "wtara1", "wtds", "shaft5", "pll1",
        "pll2", "pv", "slack", "subsystem", "subsystem_pc", "subsystem_mem", "subsystem_pc_mem",
        "subsystem_uf", "subsystem_lvg", "subsystem_pc_lvg", "subsystem_dip", "subsystem_pc_dip", "subsystem_lvg_dip",
        "subsystem_pc_lvg_dip"}
    for name in ("sm4", "ieee1"):
        component = COMPONENTS[name]
        x = component.steady_state()
        assert component.reset_states(x, component.start_inputs, component.params_type()) is x


def test_windup_limiter_clips_and_no_limit_beyond_the_marker():
    assert blocks.clip(math, 3.0, -1.0, 1.0) == 1.0
    assert blocks.clip(math, -3.0, -1.0, 1.0) == -1.0
    assert blocks.clip(math, 0.3, -1.0, 1.0) == 0.3
    assert blocks.clip(math, 3e7, -blocks.NO_LIMIT, blocks.NO_LIMIT) == 3e7


def test_lead_lag_with_zero_lag_time_is_its_gain_and_holds_its_state():
    rate, y = blocks.lead_lag(math, 0.7, 5.0, 3.0, 2.0, 0.0)
    assert (rate, y) == (0.0, 3.0 * 0.7)
    rate, y = blocks.lag(math, 0.7, 5.0, 2.0, 0.0)
    assert (rate, y) == (0.0, 1.4)


def test_exciter_output_at_its_ceiling_is_held_while_pushed_up_and_falls_when_pushed_down():
    p = sexs.SEXSParams(EMAX=3.0)
    at_ceiling = np.array([0.0, 3.0])
    up = sexs.SEXS.rhs(at_ceiling, np.array([0.8, 1.2, 0.0]), p)  # K LL_y = 3.2 > EMAX
    down = sexs.SEXS.rhs(at_ceiling, np.array([1.2, 1.0, 0.0]), p)
    assert up[1] == 0.0
    assert down[1] < 0.0


def test_genrou_saturation_coefficients_pass_through_their_two_points():
    A, B = blocks.quadratic_saturation_coefficients(1.0, 0.05, 1.2, 0.3)
    assert B * (1.0 - A) ** 2 / 1.0 == pytest.approx(0.05, rel=1e-12)
    assert B * (1.2 - A) ** 2 / 1.2 == pytest.approx(0.3, rel=1e-12)


def test_genrou_operating_point_delivers_the_load_flow_power():
    p = genrou.GENROUParams(S10=0.05, S12=0.3)
    x, Pm, Efd = genrou.operating_point(1.03, 0.2, 7.0, 1.5, p)
    u = np.array([1.03, 0.2, Pm, Efd])
    _, _, P, Q, _, _ = genrou.GENROU.output_values(x, u, p)
    assert (P, Q) == (pytest.approx(7.0, abs=1e-12), pytest.approx(1.5, abs=1e-12))
    np.testing.assert_allclose(genrou.GENROU.steady_state(u, p), x, atol=1e-10)


def test_rectifier_loading_is_continuous_at_its_breakpoints():
    for point in (0.0, 0.433, 0.75, 1.0):
        below, above = (blocks.rectifier_loading(math, point + d) for d in (-1e-9, 1e-9))
        assert abs(below - above) < 2e-3


ANDES_CASES = ["kundur/kundur_full.xlsx", "kundur/kundur_sexs.xlsx", "kundur/kundur_exst1.xlsx",
               "kundur/kundur_esst3a.xlsx", "kundur/kundur_ieeeg1.xlsx", "kundur/kundur_ieeest.xlsx",
               "ieee14/ieee14_full.xlsx", "ieee39/ieee39_full.xlsx", "npcc/npcc.xlsx"]


@pytest.mark.andes
@pytest.mark.parametrize("case", ANDES_CASES)
def test_initial_states_and_set_points_match_andes_and_are_at_rest(case):
    pytest.importorskip("andes")
    from andes_reference import compare

    results = compare(case)
    assert results
    for name, r in results.items():
        assert r["devices"] > 0
        assert r["state"] < 1e-8, (name, r)
        assert r["set_point"] < 1e-8, (name, r)
        assert r["our_rate"] < 1e-8, (name, r)


FAULTED_CASES = [("kundur/kundur_full.xlsx", 8), ("kundur/kundur_sexs.xlsx", 8), ("kundur/kundur_exst1.xlsx", 8),
                 ("kundur/kundur_esst3a.xlsx", 8), ("kundur/kundur_ieeeg1.xlsx", 8),
                 ("kundur/kundur_ieeest.xlsx", 8), ("ieee14/ieee14_full.xlsx", 4),
                 ("ieee39/ieee39_full.xlsx", 16), ("npcc/npcc.xlsx", None)]


@pytest.mark.andes
@pytest.mark.parametrize("t", [1.05, 2.5])
@pytest.mark.parametrize("case, fault_bus", FAULTED_CASES)
def test_derivatives_and_outputs_match_andes_during_and_after_a_fault(case, fault_bus, t):
    """Mid-fault (1.05 s: exciters at their ceilings) and after clearing (2.5 s), at ANDES' states
    and inputs: our dx/dt equals ANDES' f / Tf to within what its Newton tolerance (1e-6) leaves
    in its algebraic variables (ESST3A's inner loop KM / TM = 5000 1/s amplifies it most)."""
    pytest.importorskip("andes")
    from andes_reference import compare_in_transient

    results = compare_in_transient(case, t, fault_bus)
    assert results
    for name, r in results.items():
        assert r["andes_rate"] > 1e-4, (name, r)  # the point is not at rest
        assert r["rate"] < 1e-4, (name, r)
        assert r["held_rate"] == 0.0, (name, r)
        assert r["output"] < 1e-6, (name, r)


@pytest.mark.parametrize("name", MODELS)
def test_declared_affine_states_are_affine_in_themselves_with_a_constant_non_negative_decay(name):
    component, p, u, x = _rest(name)
    rng = np.random.default_rng(3)
    for i in component.affine_states:
        decays = []
        for _ in range(4):
            point = x + 0.2 * np.array(component.state_scales) * rng.standard_normal(component.n_states)
            values = []
            for value in (-1.0, 0.0, 1.0):
                probe = point.copy()
                probe[i] = value
                values.append(component.rhs(probe, u, p)[i])
            assert values[0] - 2 * values[1] + values[2] == pytest.approx(0.0, abs=1e-9)
            decays.append(values[1] - values[2])
        assert min(decays) >= 0.0
        np.testing.assert_allclose(decays, decays[0], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("name", MODELS)
def test_every_standard_model_traces_into_c_equations_and_jacobians(name):
    from fmu_export.c_derivatives import jacobians_c_source
    from fmu_export.c_equations import equations_c_source

    component = STANDARD_MODELS[name]
    p = component.params_type()
    assert "static" in equations_c_source(component, p)
    assert "static" in jacobians_c_source(component, p)


@pytest.mark.parametrize("name", MODELS)
def test_an_out_of_range_parameter_is_refused_naming_it(name):
    from reference_models.component import ParameterError

    component = STANDARD_MODELS[name]
    first = next(iter(component.params_type.__dataclass_fields__))
    with pytest.raises(ParameterError, match=f"parameter {first} "):
        component.params({first: 1e9})


@pytest.mark.andes
@pytest.mark.slow
def test_device_trajectories_under_andes_inputs_follow_andes_through_a_fault():
    """Kundur with SEXS exciters, a fault at bus 8 for 100 ms, ANDES at h = 1 ms: each machine,
    exciter and governor integrated alone under ANDES' recorded inputs stays on ANDES' states to
    within ANDES' own integration error (GENROU 1.5e-5 of a 3.7 excursion)."""
    pytest.importorskip("andes")
    from andes_reference import compare_trajectories

    results = compare_trajectories("kundur/kundur_sexs.xlsx", 8, tf=1.5)
    assert set(results) == {"GENROU", "SEXS", "TGOV1"}
    for name, r in results.items():
        assert r["state"] < 1e-4 * r["scale"], (name, r)


@pytest.mark.andes
@pytest.mark.slow
def test_ieeex1_regulators_follow_andes_through_a_fault_that_drives_them_to_their_limits():
    """ieee39 (ten IEEEX1), a fault at bus 16 1.0-1.1 s, ANDES at h = 1 ms (tol 1e-6) to 1.2 s: each
    IEEEX1 integrated alone under ANDES' recorded inputs stays on ANDES' states to 9.7e-3 pu (vp
    just before clearing; its regulators swing 8.3 pu). Its limits are the constant VRMIN, VRMAX,
    as ANDES 2.0.0 computes them (ieeex1.py); with limits VRMIN Vt, VRMAX Vt LA_y was 3.2 pu off."""
    pytest.importorskip("andes")
    from andes_reference import compare_trajectories

    r = compare_trajectories("ieee39/ieee39_full.xlsx", 16, tf=1.2, names=["IEEEX1"], tol=1e-6)["IEEEX1"]
    assert r["devices"] == 10 and r["scale"] > 5.0, r
    assert r["state"] < 1.5e-2, r


def test_rectifier_loading_is_one_for_any_negative_input_on_every_namespace():
    """A negative exciter voltage in a transient makes IN = KC XadIfd / VE negative and large: FEX is 1
    there, and the middle piece's square root is defined whatever branch a solver has locked (math
    raised a domain error for IN < -0.866 in a monolithic run of ieee14_esac1a, its branches locked)."""
    torch = pytest.importorskip("torch")
    for IN in (-0.5, -0.9, -5.0, -1e3):
        assert blocks.rectifier_loading(math, IN) == 1.0
    values = np.array([-1e3, -0.9, 0.2, 0.6, 0.9, 2.0])
    np.testing.assert_allclose(blocks.rectifier_loading(torch, torch.tensor(values)).numpy(),
                               blocks.rectifier_loading(np, values), rtol=1e-15)
