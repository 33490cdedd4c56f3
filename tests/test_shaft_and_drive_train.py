"""The five-mass torsional shaft SHAFT5 of a turbine-generator and the single-mass wind drive train
WTDS: their rests and modes, and ANDES 2.0.0 on the stock cases that use them,
ieee14/ieee14_shaft5.json (SHAFT5 on GENROU_1, bus 1) and kundur/kundur_wtds.xlsx (WTDS in a type-3
wind turbine at bus 4): initial states and set points after TDS.init(), and dx/dt at ANDES' states
mid-fault (1.0-1.1 s at a neighbouring bus) and after clearing, with the stock data and with data
that exercise the dampings and a device base Sn other than Sb."""
from __future__ import annotations

import math

import numpy as np
import pytest

from reference_models.grid.case import Device, at_rest
from reference_models.models import genrou
from reference_models.models.genrou import GENROU
from reference_models.models.reeca1 import REECA1
from reference_models.models.regca1 import REGCA1
from reference_models.models.shaft5 import SHAFT5
from reference_models.models.tgov1 import TGOV1
from reference_models.models.wtara1 import WTARA1
from reference_models.models.wtds import WTDS
from reference_models.models.wtpta1 import WTPTA1
from reference_models.models.wttqa1 import WTTQA1

DAMPED = {"DHP": 0.1, "DIP": 0.2, "DLP": 0.3, "DEX": 0.05, "D12": 0.5, "D23": 0.6, "D34": 0.7, "D45": 0.08}


def _jacobian(component, x, u, p) -> np.ndarray:
    return np.array([(component.rhs(x + 1e-6 * e, u, p) - component.rhs(x - 1e-6 * e, u, p)) / 2e-6
                     for e in np.eye(component.n_states)]).T


def test_shaft_rests_with_each_spring_carrying_the_torque_and_gives_it_to_the_rotor():
    """tm = 0.8 pu through the HP-IP, IP-LP and LP-rotor springs (twists tm / K), the EX spring
    untwisted; the rotor gets Tsh = tm. With the rotor at 1.01 pu the mutual dampings D34 and D45
    add D34 (omega - 1) to the LP spring and D45 (omega - 1) to the EX spring: Tsh stays tm."""
    p = SHAFT5.params()
    x, solved = SHAFT5.start({"Tsh": 0.8, "omega": 1.0, "delta": 0.3}, p)
    assert solved["tm"] == 0.8
    assert x == pytest.approx([0.3 + 0.8 / p.KLP + 0.8 / p.KIP + 0.8 / p.KHP, 1.0, 0.3 + 0.8 / p.KLP + 0.8 / p.KIP, 1.0,
                               0.3 + 0.8 / p.KLP, 1.0, 0.3, 1.0], rel=1e-15)
    u = np.array([0.8, 1.0, 0.3])
    assert np.abs(SHAFT5.rhs(x, u, p)).max() < 1e-12
    assert SHAFT5.output_values(x, u, p)[0] == pytest.approx(0.8, rel=1e-12)
    damped = SHAFT5.params(DAMPED)
    u = np.array([0.8, 1.01, 0.3])
    x = SHAFT5.steady_state(u, damped)
    assert x[4] - 0.3 == pytest.approx((0.8 + 0.7 * 0.01) / damped.KLP, rel=1e-12)
    assert x[6] - 0.3 == pytest.approx(0.08 * 0.01 / damped.KEX, rel=1e-9)
    assert SHAFT5.output_values(x, u, damped)[0] == pytest.approx(0.8, rel=1e-12)


def test_shaft_with_the_rotor_held_has_three_torsional_modes_and_the_exciter_mode():
    """The rotor held (omega, delta inputs fixed), no damping: the HP-IP-LP chain on the LP-rotor spring
    oscillates at the square roots of the eigenvalues of wB M^-1 K (three modes), the EX mass alone
    at sqrt(wB KEX / MEX) rad/s; ANDES' stock data put them at 14.8 (EX), 19.9, 37.3 and 67.1 Hz."""
    p = SHAFT5.params()
    wB = 2.0 * math.pi * p.fn
    K = np.array([[p.KHP, -p.KHP, 0.0], [-p.KHP, p.KHP + p.KIP, -p.KIP], [0.0, -p.KIP, p.KIP + p.KLP]])
    chain = np.sqrt(np.linalg.eigvals(wB * np.diag(1.0 / np.array([p.MHP, p.MIP, p.MLP])) @ K).real)
    expected = sorted([*chain, math.sqrt(wB * p.KEX / p.MEX)])
    x = SHAFT5.steady_state(np.array([0.8, 1.0, 0.3]), p)
    frequencies = np.abs(np.linalg.eigvals(_jacobian(SHAFT5, x, np.array([0.8, 1.0, 0.3]), p)).imag)
    assert sorted(frequencies)[::2] == pytest.approx(expected, rel=1e-6)
    assert np.array(expected) / (2.0 * math.pi) == pytest.approx([14.75, 19.89, 37.33, 67.10], abs=0.01)


def test_single_mass_drive_train_rests_where_its_damping_takes_the_power_difference():
    """D d (1 + d) = Pm - Pe with d = s1_y - wr0: D = 0.5 pu on Sn = 2 Sb (1 pu on Sb), Pm - Pe = 0.1
    pu: d = (sqrt(1.4) - 1) / 2; without damping a power difference has no rest."""
    p = WTDS.params({"D": 0.5, "Sn": 200.0})
    u = np.array([0.6, 0.5, 0.9])
    x = WTDS.steady_state(u, p)
    assert x[0] == pytest.approx(0.9 + (math.sqrt(1.4) - 1.0) / 2.0, rel=1e-15)
    assert abs(WTDS.rhs(x, u, p)[0]) < 1e-15
    with pytest.raises(ValueError, match="without damping"):
        WTDS.steady_state(u, WTDS.params({"D": 0.0}))


def test_single_mass_drive_train_starts_at_its_torque_controllers_speed_or_w0():
    """The speed and its reference start where the torque controller demands (0.685 pu), else at w0;
    the aerodynamics have to give the converter's power; both speed outputs are the one mass's."""
    p = WTDS.params({"w0": 0.9})
    x, solved = WTDS.start({"Pe": 0.35, "wg": 0.685}, p)
    assert x == pytest.approx([0.685]) and (solved["Pm"], solved["wr0"]) == (0.35, 0.685)
    u = np.array([0.35, 0.35, 0.685])
    assert WTDS.rhs(x, u, p)[0] == 0.0 and tuple(WTDS.output_values(x, u, p)) == (0.685, 0.685, 0.9)
    assert WTDS.start({"Pe": 0.35}, p)[0] == pytest.approx([0.9])


# --- ANDES 2.0.0 --------------------------------------------------------------------------------

GAIN = 20.0  # bound on the gain of a rate to an algebraic variable ANDES solves (its Newton residual)


def _andes(case: str, changes: dict, fault_bus=None, xf: float = 1e-4):
    """ANDES' system of `case` with `changes` {model: {parameter: value}} to its first device, a fault
    at `fault_bus` 1.0-1.1 s (reactance xf) where given, after its power flow."""
    andes = pytest.importorskip("andes")
    from reference_models.grid.andes_case import configure_andes_logging

    configure_andes_logging(andes, 50)
    ss = andes.load(andes.get_case(case), setup=False, no_output=True, default_config=True)
    for model, values in changes.items():
        for name, value in values.items():
            getattr(getattr(ss, model), name).v[0] = value
    if fault_bus is not None:
        ss.add("Fault", {"bus": fault_bus, "tf": 1.0, "tc": 1.1, "xf": xf, "rf": 0.0})
    ss.setup()
    ss.PFlow.run()
    return ss


def _v(var, i: int = 0) -> float:
    return float(var.v[i])


def _andes_rates(ss, model, names, i: int = 0) -> np.ndarray:
    """ANDES' dx/dt (f / Tf) of the named states of device i."""
    return np.array([float(ss.dae.f[int(getattr(model, n).a[i])]) / float(ss.dae.Tf[int(getattr(model, n).a[i])])
                     for n in names])


def _run_to(ss, times):
    """ANDES' fixed-step TDS (5 ms, Newton tolerance 1e-6) through each of `times`, f evaluated there."""
    ss.TDS.config.update(tol=1e-6, fixt=1, tstep=0.005, no_tqdm=1)
    for t in times:
        ss.TDS.config.tf = t
        ss.TDS.run()
        ss.TDS.fg_update(ss.exist.tds)
        assert float(ss.dae.t) == pytest.approx(t)
        yield t


# SHAFT5 on ieee14_shaft5's GENROU_1 (bus 1, the slack, with TGOV1_1); the case opens line 1-2 from 1.0 to 1.1 s
# (Toggler); the fault at bus 2, a neighbour of bus 1 (at bus 5, the other one, ANDES' machines separate at 1.49 s)
SHAFT_CASE = "ieee14/ieee14_shaft5.json"
SHAFT_FAULT_BUS = 2
SHAFT_MODES = {"stock": {}, "dampings, machine Sn = 2 Sb": {"SHAFT5": DAMPED, "GENROU": {"Sn": 200.0}}}


def _shaft_unit(ss):
    """(machine position j, its parameters, the shaft's, the governor position and parameters)."""
    from andes_reference import params

    s = ss.SHAFT5
    j = list(ss.GENROU.idx.v).index(s.syn.v[0])
    Sb, Sn, fn = ss.config.mva, float(ss.GENROU.Sn.v[j]), float(ss.GENROU.fn.v[j])
    g = list(ss.TGOV1.syn.v).index(s.syn.v[0])
    return (j, params(ss.GENROU, GENROU, j, {"Sb": Sb, "Sn": Sn, "fn": fn}), params(s, SHAFT5, 0, {"fn": fn}),
            g, params(ss.TGOV1, TGOV1, g))


def _shaft_point(ss, j, pg, ps):
    """(shaft x, u, machine x, u) at ANDES' present point: the shaft's torque input is ANDES' tm, the
    machine's mechanical power our shaft's torque, both on the machine base."""
    m = ss.GENROU
    k = ss.config.mva / float(m.Sn.v[j])
    xs = np.array([_v(getattr(ss.SHAFT5, n)) for n in SHAFT5.state_names])
    us = np.array([_v(m.tm, j) * k, _v(m.omega, j), _v(m.delta, j)])
    xm = np.array([_v(getattr(m, n), j) for n in GENROU.state_names])
    bus = list(ss.Bus.idx.v).index(m.bus.v[j])
    um = np.array([float(ss.Bus.v.v[bus]), float(ss.Bus.a.v[bus]), SHAFT5.output_values(xs, us, ps)[0],
                   _v(m.vf, j)])
    return xs, us, xm, um


@pytest.mark.andes
@pytest.mark.parametrize("mode", SHAFT_MODES)
def test_shaft_start_gives_andes_initial_states_and_the_governors_torque(mode):
    """From ANDES' load flow: our machine's start (its Pm the torque the shaft must give its rotor),
    the shaft's start from it (ANDES' dHP .. wEX, its tm ANDES' tm0) and the governor's set point
    from that torque (ANDES' pref). Measured: states 0 (stock) and 2.2e-16 rad, torque 1.1e-16."""
    ss = _andes(SHAFT_CASE, SHAFT_MODES[mode])
    ss.TDS.init()
    j, pg, ps, g, pt = _shaft_unit(ss)
    m = ss.GENROU
    bus = list(ss.Bus.idx.v).index(m.bus.v[j])
    xm, Pm, _ = genrou.operating_point(float(ss.Bus.v.v[bus]), float(ss.Bus.a.v[bus]), _v(m.p0, j), _v(m.q0, j), pg)
    xs, solved = SHAFT5.start({"Tsh": Pm, "omega": xm[1], "delta": xm[0]}, ps)
    x_andes, u_andes, xm_andes, _ = _shaft_point(ss, j, pg, ps)
    np.testing.assert_allclose(xm, xm_andes, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(xs, x_andes, rtol=1e-12, atol=1e-14)
    assert solved["tm"] == pytest.approx(u_andes[0], rel=1e-12)
    assert np.abs(SHAFT5.rhs(xs, np.array([solved["tm"], xm[1], xm[0]]), ps)).max() < 1e-10
    _, governor = TGOV1.start({"omega": xm[1], "Pm": solved["tm"]}, pt)
    assert governor["Pref"] == pytest.approx(_v(ss.TGOV1.pref, g), rel=1e-12)


@pytest.fixture(scope="module", params=list(SHAFT_MODES))
def shaft_faulted(request):
    """ANDES' shaft and machine points, rates and Newton residual at 1.05 s (mid-fault at bus 2) and 2.5 s."""
    ss = _andes(SHAFT_CASE, SHAFT_MODES[request.param], SHAFT_FAULT_BUS)
    ss.TDS.init()
    j, pg, ps, _, _ = _shaft_unit(ss)
    points = {"params": (pg, ps)}
    for t in _run_to(ss, (1.05, 2.5)):
        points[t] = dict(point=_shaft_point(ss, j, pg, ps), shaft=_andes_rates(ss, ss.SHAFT5, SHAFT5.state_names),
                         machine=_andes_rates(ss, ss.GENROU, GENROU.state_names, j),
                         residual=float(np.abs(ss.dae.g).max()))
    return points


@pytest.mark.andes
@pytest.mark.parametrize("t", [1.05, 2.5])
def test_shaft_and_its_machine_rates_match_andes_mid_fault_and_after_clearing(shaft_faulted, t):
    """At ANDES' states and inputs our shaft's dx/dt equals ANDES' f / Tf (1e-12 of its largest rate:
    the same arithmetic on the same values), and our machine's, driven by our shaft's torque in place
    of the governor's, equals ANDES' rates of the machine whose swing equation SHAFT5 rewrites (1e-9
    of its largest rate plus GAIN times ANDES' largest algebraic residual: our machine recomputes its
    currents from the bus voltage). The torsional masses swing apart: the springs' torques differ."""
    point, (pg, ps) = shaft_faulted[t], shaft_faulted["params"]
    xs, us, xm, um = point["point"]
    theirs = point["shaft"]
    np.testing.assert_allclose(SHAFT5.rhs(xs, us, ps), theirs, rtol=0.0, atol=1e-12 * np.abs(theirs).max())
    assert np.abs(theirs[1::2]).max() > 1e-3  # the masses accelerate
    theirs = point["machine"]
    np.testing.assert_allclose(GENROU.rhs(xm, um, pg), theirs, rtol=0.0,
                               atol=1e-9 * np.abs(theirs).max() + GAIN * point["residual"])
    assert abs(um[2] - us[0]) > 1e-4  # the rotor's torque is not the governor's


# WTDS in kundur_wtds' type-3 wind turbine (REGCA1 at bus 4, REECA1, WTTQA1, WTPTA1, WTARA1); the
# fault at bus 10, the converter's only neighbour, through 0.05 pu (bolted, ANDES' Newton fails at
# 1.014 s). The stock converter base (Sn = Sb = 100 MVA) puts its 7 pu beyond the torque controller's
# characteristic (speed sp4 = 1 = w0) and its torque beyond Temax; Sn = 1000 MVA (the WTDS sheet's
# Sn, which ANDES ignores: it takes the converter's) puts it on the characteristic at 0.93 pu
WIND_CASE = "kundur/kundur_wtds.xlsx"
WIND_FAULT_BUS = 10
WIND_FAULT_REACTANCE = 0.05
WIND_MODES = {"stock": {}, "converter Sn = 1000 MVA, damping 2": {"REGCA1": {"Sn": 1000.0}, "WTDS": {"D": 2.0}}}
WIND = (WTTQA1, WTDS, WTPTA1, WTARA1)


def _plant_term(ss) -> float:
    """What ANDES' plant controller adds to its electrical controller's Pref (Fflag s6_y; 0 without one):
    our WTTQA1 takes it as Pext - Pref0."""
    plant = ss.REPCA1
    return float(plant.Fflag.v[0] * plant.s6_y.v[0]) if plant.n else 0.0


def _wind_params(ss) -> dict:
    from andes_reference import params

    Sb, Sn = ss.config.mva, float(ss.REGCA1.Sn.v[0])
    return {"regca1": params(ss.REGCA1, REGCA1, 0, {"Sb": Sb}),
            "reeca1": params(ss.REECA1, REECA1, 0, {"Sb": Sb, "Sn": Sn}),
            "wtds": params(ss.WTDS, WTDS, 0, {"Sb": Sb, "Sn": float(ss.WTDS.Sn.v[0])}),
            "wtara1": params(ss.WTARA1, WTARA1, 0), "wtpta1": params(ss.WTPTA1, WTPTA1, 0),
            "wttqa1": params(ss.WTTQA1, WTTQA1, 0, {"Sb": Sb, "Sn": float(ss.WTTQA1.Sn.v[0])})}


def _wind_points(ss) -> dict:
    """{component name: (x, u)} of the wind devices at ANDES' present point."""
    d, a, p, t, r, g = ss.WTDS, ss.WTARA1, ss.WTPTA1, ss.WTTQA1, ss.REECA1, ss.REGCA1
    return {"wtds": (np.array([_v(d.s1_y)]), np.array([_v(d.Pm), _v(g.Pe), _v(d.wr0)])),
            "wtara1": (np.zeros(0), np.array([_v(a.theta), _v(d.Pe0)])),
            "wtpta1": (np.array([_v(p.PIc_xi), _v(p.PIw_xi), _v(p.LG_y)]),
                       np.array([_v(d.s1_y), _v(r.s5_y), _v(r.Pref), _v(p.wref)])),
            "wttqa1": (np.array([_v(t.s1_y), _v(t.s2_y), _v(t.PI_xi), _v(t.Pref0)]),
                       np.array([_v(g.Pe), _v(d.s1_y), _v(t.Pref0) + _plant_term(ss)]))}


@pytest.mark.andes
def test_stock_wind_unit_starts_its_torque_controller_beyond_temax_and_the_drive_train_at_andes_point():
    """Stock kundur_wtds: 7 pu on the converter's 100 MVA, a torque of 7 pu at the speed 1 pu beyond
    Temax = 1.2, which ANDES raises to 7 pu at its initialisation (its limiters' allow_adjust) and ours
    refuses; WTDS alone, from the converter's power and the torque controller's speed, starts at
    ANDES' point."""
    from reference_models.grid.case import CaseError

    ss = _andes(WIND_CASE, {})
    ss.TDS.init()
    assert _v(ss.WTTQA1.PI_xi) == pytest.approx(7.0) == _v(ss.WTTQA1.Temax) and ss.WTTQA1.Temax.vin[0] == 1.2
    with pytest.raises(CaseError, match="outside \\[Temin, Temax\\]"):
        _wind_unit_start(ss)
    x, inputs = WTDS.start({"Pe": _v(ss.REGCA1.Pe), "wg": _v(ss.WTTQA1.fPe_y)}, _wind_params(ss)["wtds"])
    x_andes, u_andes = _wind_points(ss)["wtds"]
    np.testing.assert_allclose(x, x_andes, rtol=1e-13)
    np.testing.assert_allclose([inputs[n] for n in WTDS.input_names], u_andes, rtol=1e-13)


def _wind_unit_start(ss) -> dict:
    """{component name: (x, u)} of the converter, its electrical controller and the four wind devices
    started by at_rest from ANDES' load flow."""
    g = ss.REGCA1
    bus = list(ss.Bus.idx.v).index(g.bus.v[0])
    V, theta = float(ss.Bus.v.v[bus]), float(ss.Bus.a.v[bus])
    p = _wind_params(ss)
    devices = [Device(c.name, c, p[c.name]) for c in (REGCA1, REECA1, *WIND)]
    x0, inputs = REGCA1.start(dict(V0=V, theta0=theta, P0=_v(g.p0), Q0=_v(g.q0), Vs=V, theta_vs=theta), p["regca1"])
    return {d.name: (np.array(s.states), np.array([s.inputs[n] for n in d.component.input_names]))
            for d, s in zip(devices, at_rest(devices, x0, inputs))}


@pytest.mark.andes
def test_wind_unit_with_a_single_mass_drive_train_starts_at_andes_initial_point():
    """Converter base 1000 MVA: the converter, its electrical controller and the four wind devices
    started by at_rest from ANDES' load flow: WTDS's speed and inputs (the mechanical power, the speed
    reference fPe = 0.93 pu) and the torque, pitch and aerodynamic controls it feeds are ANDES' after
    TDS.init(), at rest."""
    ss = _andes(WIND_CASE, WIND_MODES["converter Sn = 1000 MVA, damping 2"])
    ss.TDS.init()
    p = _wind_params(ss)
    starts = _wind_unit_start(ss)
    for name, (x_andes, u_andes) in _wind_points(ss).items():
        x, u = starts[name]
        np.testing.assert_allclose(x, x_andes, rtol=1e-13, atol=1e-15, err_msg=name)
        np.testing.assert_allclose(u, u_andes, rtol=1e-13, atol=1e-15, err_msg=name)
        component = next(c for c in WIND if c.name == name)
        assert np.abs(component.rhs(x, u, p[name])).max(initial=0.0) < 1e-15, name
    assert starts["wtds"][0][0] == pytest.approx(0.93, rel=1e-12)


@pytest.fixture(scope="module", params=list(WIND_MODES))
def wind_faulted(request):
    """ANDES' WTDS point, rate, speeds and Newton residual at 1.05 s (mid-fault at bus 10) and 2.5 s."""
    ss = _andes(WIND_CASE, WIND_MODES[request.param], WIND_FAULT_BUS, WIND_FAULT_REACTANCE)
    ss.TDS.init()
    points = {"params": _wind_params(ss)}
    for t in _run_to(ss, (1.05, 2.5)):
        points[t] = dict(point=_wind_points(ss)["wtds"], rate=_andes_rates(ss, ss.WTDS, ("s1_y",))[0],
                         wge=_v(ss.REECA1.wg), fPe=_v(ss.WTTQA1.fPe_y), residual=float(np.abs(ss.dae.g).max()))
    return points


@pytest.mark.andes
@pytest.mark.parametrize("t", [1.05, 2.5])
def test_single_mass_drive_train_rate_matches_andes_mid_fault_and_after_clearing(wind_faulted, t):
    """At ANDES' states and inputs our ds1_y/dt equals ANDES' (1e-9 of it plus GAIN times ANDES'
    largest algebraic residual: ANDES divides by its electrical controller's speed wg, an algebraic
    variable, ours by 1 + s1_y - wr0, which ANDES' wg equals (its sum of the drive train's s1_y - 1
    and the torque controller's 1 - fPe) and wr0 is the torque controller's fPe."""
    point, p = wind_faulted[t], wind_faulted["params"]["wtds"]
    x, u = point["point"]
    assert u[2] == pytest.approx(point["fPe"], abs=1e-12)
    assert point["wge"] == pytest.approx(1.0 + x[0] - u[2], abs=1e-9)
    ours = WTDS.rhs(x, u, p)[0]
    assert abs(point["rate"]) > 1e-4  # not at rest
    assert ours == pytest.approx(point["rate"], rel=0.0, abs=1e-9 * abs(point["rate"]) + GAIN * point["residual"])


def test_a_shaft_sits_in_series_between_the_governor_and_the_rotor():
    from reference_models.grid.case import Source, unit_wiring
    from reference_models.models import STANDARD_MODELS

    machine, governor, shaft = (STANDARD_MODELS[n] for n in ("GENROU", "TGOV1", "SHAFT5"))
    wiring = unit_wiring([machine.ports, governor.ports, shaft.ports])
    pm = machine.ports.input("mechanical_power")
    assert wiring[0][pm] == Source("device", device=2, variable="Tsh")  # the rotor takes the shaft's torque
    assert wiring[2]["tm"] == Source("device", device=1, variable=governor.ports.output("mechanical_power"))
