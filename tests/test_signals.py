"""Input families: closed forms against their ODEs, holds, faults, serialisation."""
import json

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from reference_models.families import BASE_FAMILIES, DIP, FAST, SLOW, family
from reference_models.signals import Signal, held

T = np.linspace(0.0, 1.0, 1001)


def sample(fam, n=6, seed=0):
    return fam.sample(np.random.default_rng(seed).random((n, fam.dim)), 1.0)


def test_slow_family_signal_solves_its_first_order_ode():
    for s in sample(SLOW):
        for ch in (s.channels["Vs"], s.channels["theta_vs"]):
            ode = lambda t, y: [-ch.k * (y[0] - ch.y_ref) + ch.A * np.sin(ch.w * t)]
            sol = solve_ivp(ode, (0, 1), [ch.y0], method="DOP853", t_eval=T, rtol=1e-12, atol=1e-13)
            np.testing.assert_allclose(ch(T), sol.y[0], rtol=0, atol=1e-9)


def test_fast_family_signal_solves_its_second_order_ode():
    for s in sample(FAST):
        for ch in (s.channels["Vs"], s.channels["theta_vs"]):
            ode = lambda t, y: [y[1], -2 * ch.zeta * ch.wn * y[1] - ch.wn**2 * (y[0] - ch.y_ref)]
            sol = solve_ivp(ode, (0, 1), [ch.y0, ch.dy0], method="DOP853", t_eval=T, rtol=1e-12, atol=1e-13)
            np.testing.assert_allclose(ch(T), sol.y[0], rtol=0, atol=1e-9)


def test_paper_family_parameters_lie_in_the_paper_ranges():
    for s in sample(SLOW, 50):
        assert 1 <= s.channels["Vs"].k <= 2 and 0 <= s.channels["Vs"].A <= 0.03 and 0.5 <= s.channels["Vs"].w <= 1.5 and 0.7 <= s.channels["Vs"].y0 <= 1.2
        assert 1 <= s.channels["theta_vs"].k <= 3 and 0 <= s.channels["theta_vs"].A <= 0.05 and 0.1 <= s.channels["theta_vs"].w <= 0.5
        assert s.channels["Vs"].y_ref == 1.0 and s.channels["theta_vs"].y_ref == 0.0
    for s in sample(FAST, 50):
        assert 0.6 <= s.channels["Vs"].zeta <= 0.8 and 8 <= s.channels["Vs"].wn <= 12 and -0.2 <= s.channels["Vs"].dy0 <= 0.2
        assert 0.2 <= s.channels["theta_vs"].zeta <= 0.4 and 10 <= s.channels["theta_vs"].wn <= 18 and -0.8 <= s.channels["theta_vs"].dy0 <= 0.8
        assert -0.5 <= s.channels["theta_vs"].y0 <= 0.5


def test_zero_order_hold_keeps_the_value_of_the_last_sample_instant():
    base = sample(FAST, 1)[0]
    s = held(base, 0.01)
    t = np.array([0.0, 0.004, 0.0099, 0.01, 0.0151, 0.5])
    expected = base(np.array([0.0, 0.0, 0.0, 0.01, 0.01, 0.5]))
    np.testing.assert_allclose(s(t), expected, rtol=0, atol=1e-15)
    np.testing.assert_allclose(s.breakpoints(0.05), [0.01, 0.02, 0.03, 0.04])


def test_dip_drops_holds_and_recovers():
    s = DIP.build({"Vs0": 1.0, "Vs_fault": 0.3, "t_fault": 0.2, "duration": 0.1, "post_shift": 0.02,
                   "tau": 0.05, "theta0": 0.1, "jump": 0.2, "jump_post": 0.05, "Pm": 0.7, "Efd": 1.1}, 1.0)
    Vs = s(np.array([0.19, 0.2, 0.29, 0.3, 0.35, 1.0]))[:, 0]
    np.testing.assert_allclose(Vs[:4], [1.0, 0.3, 0.3, 0.3])
    assert Vs[4] == pytest.approx(1.02 + (0.3 - 1.02) * np.exp(-1.0))
    assert Vs[5] == pytest.approx(1.02, abs=1e-6)
    np.testing.assert_allclose(s(np.array([0.1, 0.25, 0.5]))[:, 1], [0.1, 0.3, 0.15])
    np.testing.assert_allclose(s.breakpoints(1.0), [0.2, 0.3])


def levels_at(seeds):
    """Unit-cube points of the seed families (mix, jump): the seeds, Pm and Efd mid-range."""
    return np.column_stack([seeds, np.full_like(seeds, 0.5), np.full_like(seeds, 0.5)])


@pytest.mark.parametrize("name", ["slow", "fast", "step", "dip", "ramp", "zoh-fast", "zoh-ramp", "mix", "jump",
                                  "governor", "exciter", "avr", "drift", "zoh-exciter"])
def test_signal_round_trips_through_json(name):
    for s in sample(family(name), 3):
        back = Signal.from_dict(json.loads(json.dumps(s.to_dict())))
        np.testing.assert_array_equal(back(T), s(T))
        assert back == s


@pytest.mark.parametrize("name", ["slow", "fast", "step", "dip", "ramp", "zoh-slow", "governor", "exciter", "avr",
                                  "drift"])
def test_scalar_and_array_evaluation_agree(name):
    for s in sample(family(name), 3):
        scalar = np.array([s.at(float(t)) for t in T])
        np.testing.assert_allclose(scalar, s(T), rtol=0, atol=1e-14)


def test_zoh_family_holds_at_steps_between_1_and_50_ms():
    holds = [s.hold for s in sample(family("zoh-slow"), 40)]
    assert 0.001 <= min(holds) and max(holds) <= 0.05


def test_unknown_family_is_refused_with_the_known_names():
    with pytest.raises(ValueError, match="unknown input family 'sine'.*slow, fast"):
        family("sine")


def test_mix_family_holds_levels_and_faults_within_one_window():
    signals = family("mix").sample(levels_at(np.linspace(0.05, 0.95, 20)), 1.0)
    changes = [len(s.channels["Vs"].times) for s in signals]
    assert min(changes) >= 1 and max(changes) >= 3
    t = np.linspace(0, 1, 1001)
    values = np.array([s(t) for s in signals])
    assert values[..., 0].min() < 0.9 and values[..., 0].max() <= 1.15  # some fault; levels <= 1.15 pu
    assert np.abs(values[..., 1]).max() <= 0.5


def test_jump_family_starts_each_window_with_a_change_a_fault_two_times_in_five():
    signals = family("jump").sample(levels_at(np.linspace(0.01, 0.99, 60)), 1.0)
    assert all(s.channels["Vs"].times[0] > 0.0 for s in signals)  # the change is at t = 0: no breakpoint there
    first = np.array([s.at(0.0)[0] for s in signals])
    assert first.min() >= 0.2 and first.max() <= 1.15
    assert 0.2 <= np.mean(first < 0.85) <= 0.6  # faults (0.2-0.9 pu) start about two windows in five


def test_every_family_drives_all_four_inputs_of_sm4_in_order():
    for name in BASE_FAMILIES:
        for s in sample(family(name), 2):
            assert s.names == ("Vs", "theta_vs", "Pm", "Efd")


def test_bus_families_hold_pm_and_efd_at_levels_from_the_given_ranges():
    levels = {"Pm": (1.5, 1.7), "Efd": (1.7, 1.9)}
    for name in ("slow", "fast", "dip", "mix", "jump"):
        fam = family(name)
        for s in fam.sample(np.random.default_rng(1).random((5, fam.dim)), 1.0, levels):
            u = s(T)
            assert np.ptp(u[:, 2]) == 0 and 1.5 <= u[0, 2] <= 1.7
            assert np.ptp(u[:, 3]) == 0 and 1.7 <= u[0, 3] <= 1.9


def test_paper_levels_pin_pm_and_efd_to_the_table_one_operating_point():
    from surrogate.data.presets import preset

    levels = preset("paper").levels
    for s in SLOW.sample(np.random.default_rng(0).random((4, SLOW.dim)), 1.0, levels):
        np.testing.assert_array_equal(s(T)[:, 2:], np.tile([0.7048, 1.08], (T.size, 1)))


def test_governor_moves_pm_between_two_levels_and_holds_efd():
    fam = family("governor")
    signals = fam.sample(np.random.default_rng(2).random((20, fam.dim)), 1.0)
    moved = [np.ptp(s(T)[:, 2]) for s in signals]
    assert max(moved) > 0.2 and all(np.ptp(s(T)[:, 3]) == 0 for s in signals)


def test_exciter_forces_the_field_up_during_the_fault_and_returns_after_it():
    s = family("exciter").build({"Vs0": 1.0, "Vs_fault": 0.2, "t_fault": 0.2, "duration": 0.1, "post_shift": 0.0,
                                 "tau": 0.0, "theta0": 0.0, "jump": 0.1, "jump_post": 0.0, "Pm": 0.7, "E0": 1.1,
                                 "rise": 3.0, "tau_rise": 0.1, "E_post": 1.3, "tau_return": 0.5}, 1.0)
    efd = s(np.array([0.1, 0.2, 0.25, 0.3, 0.8, 1.0]))[:, 3]
    assert efd[0] == efd[1] == 1.1
    peak = 1.1 + 3.0 * (1 - np.exp(-1.0))
    assert efd[2] == pytest.approx(1.1 + 3.0 * (1 - np.exp(-0.5)))
    assert efd[3] == pytest.approx(peak)
    assert efd[4] == pytest.approx(1.3 + (peak - 1.3) * np.exp(-1.0))
    np.testing.assert_allclose(s.breakpoints(1.0), [0.2, 0.3])


def test_drift_angle_is_the_sawtooth_a_held_master_delivers_seen_from_the_turning_frame():
    from reference_models.signals import Sawtooth

    saw = Sawtooth(0.0, 12.0, 0.01)
    t = np.array([0.0, 0.005, 0.0099, 0.01, 0.015])
    np.testing.assert_allclose(saw(t), [0.0, -0.06, -0.1188, 0.0, -0.06], atol=1e-12)
    s = family("drift").sample(np.random.default_rng(0).random((1, family("drift").dim)), 1.0)[0]
    period = s.channels["theta_vs"].period
    assert 0.002 <= period <= 0.02 and len(s.breakpoints(1.0)) >= int(1.0 / period) - 1
