"""The inverter chain REGCA1 (converter) + REECA1 (electrical controller): their start from the load
flow, the voltage-dip logic (frozen states, the injected reactive current, the hold timers), the
current limits with their priority, and ANDES 2.0.0 on ieee14/ieee14_solar.xlsx (initial states
and set points; dx/dt and outputs at ANDES' states mid-fault, with the dip logic and the current
limits active, and after clearing)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from reference_models.models.reeca1 import REECA1
from reference_models.models.regca1 import REGCA1, low_voltage_power_limit

REECA1_ANDES_STATES = REECA1.state_names[:7]  # the rest are ours: tdip, Ipmaxh, dIpcmd


def _chain_start(V0=0.98, theta0=0.1, P0=0.6, Q0=0.2, regca1=None, reeca1=None):
    """(REGCA1 (x, u, p), REECA1 (x, u, p)) started from a load-flow point as a unit starts them: the
    converter solves its commands, the controller is given them and the converter's measurements."""
    pg, pr = REGCA1.params(regca1), REECA1.params(reeca1)
    xg, ug = REGCA1.start(dict(V0=V0, theta0=theta0, P0=P0, Q0=Q0, Vs=V0, theta_vs=theta0), pg)
    ug = np.array([ug[n] for n in REGCA1.input_names])
    y = dict(zip(REGCA1.output_names, REGCA1.output_values(xg, ug, pg)))
    xr, ur = REECA1.start(dict(V=V0, Pe=y["Pe"], Qe=y["Qe"], Ipcmd=ug[2], Iqcmd=ug[3]), pr)
    return (xg, ug, pg), (xr, np.array([ur[n] for n in REECA1.input_names]), pr)


def test_converter_start_delivers_the_load_flow_power_at_rest():
    (xg, ug, pg), _ = _chain_start(regca1={"Lvpnt1": 1.0})
    y = dict(zip(REGCA1.output_names, REGCA1.output_values(xg, ug, pg)))
    assert (y["P"], y["Q"]) == (pytest.approx(0.6, abs=1e-15), pytest.approx(0.2, abs=1e-15))
    assert complex(y["I_re"], y["I_im"]) == pytest.approx(complex(0.6, -0.2) / (0.98 * np.exp(-0.1j)), abs=1e-15)
    np.testing.assert_array_equal(REGCA1.rhs(xg, ug, pg), 0.0)
    # 0.98 pu lies below Lvpnt1 = 1: the low-voltage gain 0.9667 raises the active current command
    assert ug[2] == pytest.approx(0.6 / 0.98 / ((0.98 - 0.4) / 0.6), rel=1e-15)


def test_controller_start_gives_the_converter_its_commands_at_rest_with_andes_offset():
    """ANDES' converter command is Ipcmd0_LVG + IpHL_y - p0 / V0: the controller's held offset
    dIpcmd carries it, so its output is the converter's command at the start."""
    (_, ug, _), (xr, ur, pr) = _chain_start(regca1={"Lvpnt1": 1.0})
    np.testing.assert_allclose(REECA1.output_values(xr, ur, pr), ug[2:], rtol=1e-15)
    assert xr[9] == pytest.approx(ug[2] - 0.6 / 0.98, rel=1e-15) and xr[9] > 0
    np.testing.assert_array_equal(REECA1.rhs(xr, ur, pr), 0.0)


def test_controller_start_with_both_pi_controllers_has_no_rest_and_is_refused():
    """VFLAG = QFLAG = 1: ANDES' start feeds the voltage PI the reactive power PI's output (0) as a
    voltage error, so its command misses the converter's (ANDES' initialisation fails there too)."""
    with pytest.raises(ValueError, match="REECA1: its reactive current command"):
        _chain_start(reeca1={"VFLAG": 1.0, "QFLAG": 1.0})


def test_converter_start_cut_by_its_reactive_current_floor_is_refused():
    with pytest.raises(ValueError, match="REGCA1: the reactive current"):
        REGCA1.start(dict(V0=1.0, theta0=0.0, P0=0.5, Q0=-0.2, Vs=1.0, theta_vs=0.0), REGCA1.params({"Iolim": 0.0}))


def test_a_voltage_dip_freezes_the_controller_and_injects_reactive_current_beyond_the_dead_band():
    _, (xr, ur, pr) = _chain_start(reeca1={"Kqv": 2.0, "Vref0": 1.0})
    dip = ur.copy()
    dip[0] = 0.6  # below Vdip = 0.8
    rates = REECA1.rhs(xr, dip, pr)
    frozen = [REECA1.state_names.index(n) for n in ("PIQ_xi", "s4_y", "s5_y", "PIV_xi")]
    np.testing.assert_array_equal(rates[frozen], 0.0)
    assert rates[0] == pytest.approx((0.6 - xr[0]) / pr.Trv)  # the voltage filter goes on
    # Iqinj = Kqv db(Vref - s0_y) with s0_y still at 0.98: 2 (0.02 - 0.02) = 0 in the band; at s0_y = 0.7
    low = xr.copy()
    low[0] = 0.7
    Iqcmd_dip = REECA1.output_values(low, dip, pr)[1]
    Iqcmd_normal = REECA1.output_values(low, ur, pr)[1]
    assert Iqcmd_normal - Iqcmd_dip == pytest.approx(2.0 * (1.0 - 0.7 - 0.02), rel=1e-12)


def test_the_held_active_current_limit_is_sampled_during_a_dip_only():
    _, (xr, ur, pr) = _chain_start(reeca1={"Kqv": 2.0, "Vref0": 1.0, "Thld": -0.5, "Thld2": 0.3, "Imax": 1.0})
    x = xr.copy()
    x[8] = 0.3  # a value sampled long ago
    assert REECA1.reset_states(x, ur, pr)[8] == 0.3  # no dip: kept (the moving limit is not followed)
    dip = ur.copy()
    dip[0] = 0.6
    sampled = REECA1.reset_states(x, dip, pr)[8]
    assert sampled != 0.3 and sampled == pytest.approx(xr[8], rel=1e-12)  # the limit of now, at rest's states


def test_after_a_dip_the_hold_timer_counts_and_keeps_the_injection_and_the_active_current_limit():
    p = {"Kqv": 2.0, "Vref0": 1.0, "Thld": -0.5, "Thld2": 0.3, "Imax": 1.0}
    _, (xr, ur, pr) = _chain_start(reeca1=p)
    assert xr[7] == 0.5  # at rest: the timer at its cap, no hold
    x = xr.copy()
    x[0] = 0.7  # s0_y, filtered voltage still low
    dip = ur.copy()
    dip[0] = 0.6
    placed = REECA1.reset_states(x, dip, pr)
    assert placed[7] == 0.0  # a dip resets the timer, which stays there
    assert REECA1.rhs(placed, dip, pr)[7] == 0.0
    after = placed.copy()
    after[7], after[8] = 0.2, 0.42  # 0.2 s after the dip (within Thld2 and |Thld|), Ipmax sampled 0.42
    assert REECA1.rhs(after, ur, pr)[7] == 1.0
    assert REECA1.reset_states(after, ur, pr)[8] == 0.42  # held, not resampled
    Ipcmd, Iqcmd = REECA1.output_values(after, ur, pr)
    assert Ipcmd == pytest.approx(0.42 + xr[9], rel=1e-15)  # s5_y / vp = 0.612 held under Ipmaxh = 0.42
    injected = 2.0 * (1.0 - 0.7 - 0.02)
    assert -Iqcmd == pytest.approx(min(xr[3] + injected, 1.0), rel=1e-12)  # Thld < 0: Iqv kept
    later = after.copy()
    later[7] = 0.4  # Thld2 over: Ipmax = sqrt(Imax^2 - IqHL^2) again; the injection still held
    Ipcmd, Iqcmd = REECA1.output_values(later, ur, pr)
    assert Ipcmd == pytest.approx(min(0.6 / 0.98, math.sqrt(1.0 - Iqcmd ** 2)) + xr[9], rel=1e-12)
    assert REECA1.rhs(np.r_[later[:7], 0.5, later[8:]], ur, pr)[7] == 0.0  # the timer stops at its cap


@pytest.mark.parametrize("PQFLAG", [0.0, 1.0])
def test_the_current_limit_serves_the_priority_axis_first(PQFLAG):
    """Imax = 0.7 pu with a 0.612 pu active and a 0.5 pu reactive demand: Q priority keeps Iq and
    cuts Ip to sqrt(Imax^2 - Iq^2); P priority the other way round. In a deep dip the priority axis
    is capped by its VDL table (2 + 10 (s0_y - 0.2) below 0.4 pu), the other takes the rest of Imax."""
    _, (xr, ur, _) = _chain_start(Q0=0.49)
    pr = REECA1.params({"Imax": 0.7, "PQFLAG": PQFLAG})
    Ipcmd, Iqcmd = REECA1.output_values(xr, ur, pr)
    demand_p, demand_q = 0.6 / 0.98, 0.49 / 0.98
    if PQFLAG:
        assert Ipcmd == pytest.approx(demand_p, rel=1e-15)
        assert -Iqcmd == pytest.approx(math.sqrt(0.49 - demand_p ** 2), rel=1e-12)
    else:
        assert -Iqcmd == pytest.approx(demand_q, rel=1e-15)
        assert Ipcmd == pytest.approx(math.sqrt(0.49 - demand_q ** 2), rel=1e-12)
    # s0_y = 0.25 pu: both tables give 2.5 pu; V = 0.2 pu: the active demand s5_y / vp = 3 pu, the
    # reactive demand 0.5 + Iqinj = 0.5 + 40 (1 - 0.25 - 0.02) = 29.7 pu; Imax = 999
    pr = REECA1.params({"PQFLAG": PQFLAG, "Kqv": 40.0, "Vref0": 1.0})
    low, dip = xr.copy(), ur.copy()
    low[0], dip[0], dip[5] = 0.25, 0.2, 1.0
    Ipcmd, Iqcmd = REECA1.output_values(low, dip, pr)
    if PQFLAG:
        assert (Ipcmd, -Iqcmd) == (pytest.approx(2.5, rel=1e-12), pytest.approx(29.7, rel=1e-12))
    else:
        assert (Ipcmd, -Iqcmd) == (pytest.approx(3.0, rel=1e-12), pytest.approx(2.5, rel=1e-12))


def test_active_current_is_held_on_the_low_voltage_power_limit_and_placed_on_it():
    (xg, ug, pg), _ = _chain_start()
    x = xg.copy()
    x[2] = 0.6  # filtered voltage 0.6: LVPL = (0.6 - 0.5) / (1.0 - 0.5) = 0.2
    assert low_voltage_power_limit(math, 0.6, pg) == pytest.approx(0.2)
    x[0] = 0.25
    at_rest = ug.copy()
    at_rest[0] = 0.6  # the bus voltage at the filtered one: LVPL rests
    placed = REGCA1.reset_states(x, at_rest, pg)
    assert placed[0] == pytest.approx(0.2)
    assert REGCA1.rhs(placed, at_rest, pg)[0] == 0.0  # pushed up: held
    below = at_rest.copy()
    below[2] = 0.1
    assert REGCA1.rhs(placed, below, pg)[0] < 0.0  # released downward


@pytest.mark.parametrize("V", [0.55, 0.7], ids=["falling", "rising"])
def test_active_current_on_a_moving_low_voltage_power_limit_moves_with_it(V):
    """On LVPL while its free rate pushes up, S0_y moves as LVPL does (its slope times the filtered
    voltage's rate), so that Model Exchange and co-simulation hold it alike; a free rate below the
    limit's releases it."""
    (xg, ug, pg), _ = _chain_start()
    x = xg.copy()
    x[2], x[0] = 0.6, 0.2  # on LVPL = 0.2
    u = ug.copy()
    u[0] = V
    limit_rate = (pg.Lvpl1 / (pg.Brkpt - pg.Zerox)) * (V - 0.6) / pg.Tfltr
    u[2] = 10.0  # the command far above: the free rate exceeds the limit's either way
    assert REGCA1.rhs(x, u, pg)[0] == pytest.approx(limit_rate, rel=1e-12)
    u[2] = 0.2 - 1.0 if V < 0.6 else 0.2  # a free rate below the limit's: released
    free = min(u[2] - 0.2, pg.Rrpwr) / pg.Tg
    assert free < limit_rate
    assert REGCA1.rhs(x, u, pg)[0] == pytest.approx(free, rel=1e-12)


def test_rate_limits_bound_tg_times_the_rate_and_the_reactive_one_acts_in_the_start_power_direction():
    """ANDES' RateLimiter clips the lag's T dx/dt: Rrpwr above for the active current; Iqrmax above
    only where the start's reactive power q0 > 0, Iqrmin below only where q0 < 0."""
    p = REGCA1.params({"Tg": 0.1, "Rrpwr": 1.0, "Iqrmax": 0.5, "Iqrmin": -0.5, "Sn": 200.0})  # Sn / Sb = 2
    x = np.array([0.5, 0.1, 1.0, 0.1])  # q0 > 0
    up = REGCA1.rhs(x, np.array([1.0, 0.0, 2.5, -2.1]), p)  # Ipcmd - S0_y = 2, -Iqcmd - S1_y = 2
    down = REGCA1.rhs(x, np.array([1.0, 0.0, -1.5, 1.9]), p)
    assert (up[0], up[1]) == (pytest.approx(1.0 / 0.1), pytest.approx(2 * 0.5 / 0.1))  # Iqrmax on base Sn
    assert (down[0], down[1]) == (pytest.approx(-2.0 / 0.1), pytest.approx(-2.0 / 0.1))
    x[3] = -0.1  # q0 < 0
    assert REGCA1.rhs(x, np.array([1.0, 0.0, 2.5, -2.1]), p)[1] == pytest.approx(2.0 / 0.1)
    assert REGCA1.rhs(x, np.array([1.0, 0.0, 2.5, 1.9]), p)[1] == pytest.approx(-2 * 0.5 / 0.1)


# --- ANDES 2.0.0 --------------------------------------------------------------------------------

CASE = "ieee14/ieee14_solar.xlsx"
FAULT_BUS = 7  # the inverter's (bus 8) only neighbour; ANDES does not converge with the fault on bus 8
# REECA1 data changed from the case's (all flags 0, Vref0 = 1.03): the power factor control with the
# reactive power PI (ANDES converges through the fault with these), and the voltage PI with P priority
MODES = {"stock": {}, "power factor, Q PI, Vref0 = V0": {"PFFLAG": 1.0, "VFLAG": 1.0, "Vref0": 0.0},
         "V PI, P priority": {"QFLAG": 1.0, "PQFLAG": 1.0}}


def _andes_chain(ss):
    """(REGCA1 (x, u, p), REECA1 (x, u, p)) at ANDES' present point, our states and inputs from
    ANDES' variables: the converter's q0; the controller's timer from ANDES' ExtendedEvent fThld
    (0 during a dip, the time since its end, capped), its held Ipmaxh, its offset
    Ipcmd0_LVG - Ipcmd0. A state ANDES holds on its LVPL limit is placed on ours (ANDES' LVPL is
    an algebraic variable, within its Newton tolerance of ours)."""
    from andes_reference import params

    g, r = ss.REGCA1, ss.REECA1
    pg = params(g, REGCA1, 0, {"Sb": ss.config.mva})
    pr = params(r, REECA1, 0, {"Sb": ss.config.mva, "Sn": float(g.Sn.v[0])})
    bus = list(ss.Bus.idx.v).index(g.bus.v[0])
    V, theta = float(ss.Bus.v.v[bus]), float(ss.Bus.a.v[bus])
    xg = np.array([g.S0_y.v[0], g.S1_y.v[0], g.S2_y.v[0], g.q0.v[0]], dtype=float)
    if g.S0_lim.zu[0]:
        xg[0] = low_voltage_power_limit(math, xg[2], pg)
    ug = np.array([V, theta, g.Ipcmd.v[0], g.Iqcmd.v[0]], dtype=float)
    ended = float(r.fThld.t_final[0]) - abs(pr.Thld)
    tdip = 0.0 if r.Volt_dip.v[0] else (pr.timer_cap if r.fThld.t_final[0] == 0 else
                                        min(float(ss.dae.t) - ended, pr.timer_cap))
    xr = np.array([float(getattr(r, n).v[0]) for n in REECA1_ANDES_STATES]
                  + [tdip, float(r.Ipmaxh.v[0]), float(g.Ipcmd0_LVG.v[0] - r.Ipcmd0.v[0])])
    ur = np.array([V, g.Pe.v[0], g.Qe.v[0], r.Pref.v[0], r.Qref.v[0], r.Vref0r.v[0], r.pfaref.v[0]], dtype=float)
    return (xg, ug, pg), (xr, ur, pr)


def _andes_rates(ss, model, names) -> np.ndarray:
    """ANDES' dx/dt (f / Tf) of the named states of its (only) device of `model`."""
    return np.array([float(ss.dae.f[int(getattr(model, n).a[0])]) / float(ss.dae.Tf[int(getattr(model, n).a[0])])
                     for n in names])


def _andes_case(reeca1: dict, fault: bool):
    """ANDES' system of the case with REECA1's data changed, a fault at FAULT_BUS 1.0-1.1 s where
    `fault`, after its power flow."""
    andes = pytest.importorskip("andes")
    from reference_models.grid.andes_case import configure_andes_logging

    configure_andes_logging(andes, 40)
    ss = andes.load(andes.get_case(CASE), setup=False, no_output=True, default_config=True)
    for name, value in reeca1.items():
        getattr(ss.REECA1, name).v[0] = value
    if fault:
        ss.add("Fault", {"bus": FAULT_BUS, "tf": 1.0, "tc": 1.1, "xf": 1e-4, "rf": 0.0})
    ss.setup()
    ss.PFlow.run()
    return ss


@pytest.mark.andes
@pytest.mark.parametrize("mode", MODES)
def test_chain_start_gives_andes_initial_states_and_set_points(mode):
    ss = _andes_case(MODES[mode], fault=False)
    ss.TDS.init()
    g, r = ss.REGCA1, ss.REECA1
    (xa_g, ua_g, pg), (xa_r, ua_r, pr) = _andes_chain(ss)
    given = dict(V0=ua_g[0], theta0=ua_g[1], P0=float(g.p0.v[0]), Q0=float(g.q0.v[0]), Vs=ua_g[0], theta_vs=ua_g[1])
    xg, commands = REGCA1.start(given, pg)
    np.testing.assert_allclose(xg, xa_g, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose([commands["Ipcmd"], commands["Iqcmd"]], ua_g[2:], rtol=1e-12, atol=1e-14)
    y = dict(zip(REGCA1.output_names, REGCA1.output_values(xg, ua_g, pg)))
    np.testing.assert_allclose([y["Pe"], y["Qe"]], [g.Pe.v[0], g.Qe.v[0]], rtol=1e-12, atol=1e-14)
    xr, set_points = REECA1.start(dict(V=ua_g[0], Pe=y["Pe"], Qe=y["Qe"], Ipcmd=commands["Ipcmd"],
                                       Iqcmd=commands["Iqcmd"]), pr)
    np.testing.assert_allclose(xr, xa_r, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose([set_points[n] for n in ("Pref", "Qref", "Vref", "pfaref")], ua_r[3:],
                               rtol=1e-12, atol=1e-14)
    assert np.abs(REGCA1.rhs(xg, ua_g, pg)).max() == 0.0
    assert np.abs(REECA1.rhs(xr, ua_r, pr)).max() < 1e-13  # QFLAG = 1: Vref1 + Qref - V rounds (ANDES' too)


@pytest.fixture(scope="module", params=list(MODES)[:2])
def andes_faulted(request):
    """ANDES' states at 1.05 s (mid-fault at bus 7, 1.0-1.1 s) and 2.5 s, our chain there (the stock
    case, and the power factor control with the Q PI; ANDES does not converge through the fault
    with P priority)."""
    from andes_reference import run_to

    ss = _andes_case(MODES[request.param], fault=True)
    points = {}
    for t in run_to(ss, (1.05, 2.5)):
        chain = _andes_chain(ss)
        g, r = ss.REGCA1, ss.REECA1
        points[t] = dict(chain=chain, regca1_rates=_andes_rates(ss, g, ("S0_y", "S1_y", "S2_y")),
                         reeca1_rates=_andes_rates(ss, r, REECA1_ANDES_STATES),
                         PQ=np.array([g.Pe.v[0], g.Qe.v[0]], dtype=float),
                         dip=float(r.Volt_dip.v[0]), Iqinj=float(r.Iqinj.v[0]), Iqmax=float(r.Iqmax.v[0]),
                         at_lvpl=bool(g.S0_lim.zu[0]))
    return points


@pytest.mark.andes
@pytest.mark.parametrize("t", [1.05, 2.5])
def test_chain_derivatives_and_outputs_match_andes_mid_fault_and_after_clearing(andes_faulted, t):
    """At ANDES' states and inputs: our dx/dt equals ANDES' f / Tf (but on the LVPL limit, where ours
    follows the limit and ANDES' is 0 between its placements) and our converter's P, Q and the
    controller's commands equal ANDES' (relative to the values compared). Mid-fault the dip logic
    is on (frozen states, reactive current injection capped by VDL1, the active current on LVPL);
    at 2.5 s the dip is over and its injection held (Thld = -2 s)."""
    point = andes_faulted[t]
    (xg, ug, pg), (xr, ur, pr) = point["chain"]
    if t == 1.05:
        assert point["dip"] == 1.0 and point["at_lvpl"] and point["Iqinj"] > point["Iqmax"] > 0.0
    else:
        assert point["dip"] == 0.0 and 0.0 < xr[7] < pr.timer_cap
    ours_g = REGCA1.rhs(xg, ug, pg)[:3]
    if point["at_lvpl"]:  # S0_y on LVPL: ANDES holds it (rate 0, placed at each step); ours moves with the limit
        assert point["regca1_rates"][0] == 0.0
        assert ours_g[0] == pytest.approx(pg.Lvpl1 / (pg.Brkpt - pg.Zerox) * ours_g[2], rel=1e-12)
        ours_g[0] = 0.0
    for ours, theirs in ((ours_g, point["regca1_rates"]),
                         (REECA1.rhs(xr, ur, pr)[:7], point["reeca1_rates"])):
        assert np.abs(theirs).max() > 1e-4  # not at rest
        np.testing.assert_allclose(ours, theirs, rtol=0.0, atol=1e-9 * np.abs(theirs).max())
    y = REGCA1.output_values(xg, ug, pg)
    np.testing.assert_allclose(y[2:4], point["PQ"], rtol=0.0, atol=1e-9 * np.abs(point["PQ"]).max())
    np.testing.assert_allclose(REECA1.output_values(xr, ur, pr), ug[2:], rtol=0.0, atol=1e-9 * np.abs(ug[2:]).max())


def test_native_fmu_holds_the_injection_and_the_active_current_limit_after_a_dip(fmu_cache):
    """REECA1's native FMU (FMI 2.0) through a dip 0.1-0.3 s (V = 0.6 pu) with Thld = 0.275 s,
    Iqfrz = 0.5 pu, Thld2 = 0.175 s, Imax = 0.9 pu, steps of 50 ms: it follows the independent
    solver of tests/test_standard_model_fmus.py (the resets at each step's start and located
    switching); the timer stays at 0 through the dip, then counts to its cap; after the dip the
    active current stays under the limit sampled in the dip for Thld2 and the reactive current
    carries Iqfrz for Thld."""
    from test_standard_model_fmus import H, locked_solution, run_inputs

    from cosim.fmu import FMU
    from fmu_export.build_cache import cached_native_reference_fmu

    values = {"Thld": 0.275, "Iqfrz": 0.5, "Thld2": 0.175, "Imax": 0.9, "Kqv": 2.0}
    p = REECA1.params(values)
    path = cached_native_reference_fmu("REECA1Hold", REECA1, values, fmi_version=2, cache=fmu_cache)
    inputs = run_inputs(REECA1, ((0.1, {}), (0.3, {"V": 0.6}), (0.8, {})))
    x = REECA1.steady_state(None, p)
    slave = FMU(path, component=REECA1)
    rows = []
    for u in inputs:
        x, _ = locked_solution(REECA1, p, x, tuple(u), H)
        got = np.concatenate([slave.step(H, *u), slave.get(*REECA1.output_names)])
        expected = np.concatenate([x, REECA1.output_values(x, u, p)])
        assert np.all(np.abs(got - expected) <= 1e-8 * np.maximum(1.0, np.abs(expected))), (got, expected)
        rows.append(got)
    slave.close()
    t = H * np.arange(1, len(rows) + 1) + 1e-9  # each step's end (just after, against rounding)
    rows = np.array(rows)
    tdip, Ipcmd, Iqcmd = rows[:, REECA1.state_names.index("tdip")], rows[:, -2], rows[:, -1]
    assert np.all(tdip[(t > 0.15) & (t < 0.3)] == 0.0) and tdip[-1] == pytest.approx(0.275, abs=1e-9)
    after = (t > 0.35) & (t < 0.55)
    np.testing.assert_allclose(tdip[after], t[after] - 0.3, atol=1e-8)
    # the limit sampled at the dip's last step start (ANDES: at its last iterate), held for Thld2
    held = (t > 0.35) & (t < 0.475)
    assert np.all(Ipcmd[held] == Ipcmd[held][0]) and Ipcmd[held][0] < 0.3
    assert Ipcmd[t > 0.5][0] == pytest.approx(0.5, rel=1e-6)  # released: s5_y / vp
    np.testing.assert_allclose(-Iqcmd[(t > 0.35) & (t < 0.575)], 0.1 + 0.5, rtol=1e-6)  # s4_y + Iqfrz
    np.testing.assert_allclose(-Iqcmd[t > 0.6], 0.1, rtol=1e-6)
