"""The dynamic and voltage-dependent loads (reference_models.models: motor.py Motor5, Motor3;
fload.py FLoad; zip.py, the ZIP load's current as a function of its bus voltage): their power at the
load flow, their rest, and against ANDES 2.0.0 (where installed) on the stock cases that use them:
the start gives ANDES' initial states and set points, and our derivatives and bus current at ANDES'
states and bus voltages mid-fault and after clearing equal ANDES' f / Tf and its power drawn."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from reference_models.component import ParameterError
from reference_models.models import STANDARD_MODELS
from reference_models.models.motor import Motor3, Motor5
from reference_models.models.zip import ZIPParams, coefficients, zip_current, zip_power

MOTORS = {"Motor5": Motor5, "Motor3": Motor3}
TIMES = (1.05, 2.5)  # s: mid-fault (1.0-1.1 s) and after clearing
# relative: ANDES solves the motor's stator currents Id, Iq (algebraic variables) by Newton to a residual
# of about 1e-10 (Id off ours by 3e-10 at tol 1e-9), which the rotor equations amplify by (x0 - x1) / T10 = 18
MOTOR_TOLERANCE = 1e-7


def _given(V, theta, P, Q):
    return {"V0": V, "theta0": theta, "P0": P, "Q0": Q, "Vs": V, "theta_vs": theta}


def _close(ours, theirs, rel=1e-9):
    ours, theirs = np.asarray(ours, dtype=float), np.asarray(theirs, dtype=float)
    scale = max(1.0, float(np.abs(theirs).max()))
    assert np.abs(ours - theirs).max() <= rel * scale, (ours, theirs)


# --- ZIP ----------------------------------------------------------------------------------------

def test_zip_draws_its_share_at_the_load_flow_voltage_split_by_its_percentages():
    p = ZIPParams(kpp=50.0, kpi=40.0, kpz=10.0, kqp=100.0, kqi=0.0, kqz=0.0, P0=-0.4, Q0=-0.2, V0=1.03)
    assert zip_power(1.03, p) == pytest.approx((-0.4, -0.2), rel=1e-15)
    # at half the voltage: the constant-current half scales with V, the impedance part with V^2
    P, Q = zip_power(0.515, p)
    assert P == pytest.approx(-0.4 * (0.5 + 0.4 * 0.5 + 0.1 * 0.25), rel=1e-14)
    assert Q == pytest.approx(-0.2, rel=1e-15)


def test_zip_current_carries_its_power_into_the_bus():
    p = ZIPParams(kpp=30.0, kpi=30.0, kpz=40.0, kqp=10.0, kqi=20.0, kqz=70.0, P0=-0.8, Q0=0.1, V0=0.97)
    for V, theta in ((0.97, 0.3), (0.4, -1.2)):
        I_re, I_im = zip_current(V, theta, p)
        S = V * complex(math.cos(theta), math.sin(theta)) * complex(I_re, -I_im)
        assert (S.real, S.imag) == pytest.approx(zip_power(V, p), rel=1e-14)
    I_np = zip_current(np.array([0.97, 0.4]), np.array([0.3, -1.2]), p, np)
    assert np.allclose(I_np, np.array([zip_current(0.97, 0.3, p), zip_current(0.4, -1.2, p)]).T, rtol=1e-15)


def test_zip_refuses_a_share_it_has_no_percentage_to_draw():
    with pytest.raises(ParameterError, match="parameter P0 "):
        ZIPParams(kpp=0.0, kpi=0.0, kpz=0.0, P0=-0.5)
    with pytest.raises(ParameterError, match="parameter kqz "):
        ZIPParams(kqz=120.0)


# --- FLoad --------------------------------------------------------------------------------------

def test_fload_starts_at_rest_drawing_its_share_at_nominal_frequency():
    component = STANDARD_MODELS["FLoad"]
    p = component.params({"ap": 1.5, "aq": 2.0, "bp": 1.3, "bq": -0.7, "Tf": 0.0})
    x0, u = component.start(_given(0.95, 0.2, -0.6, -0.25), p)
    u = np.array([u[n] for n in component.input_names])
    assert np.array_equal(x0, [0.2, 0.2])
    assert np.abs(component.rhs(x0, u, p)).max() == 0.0
    I_re, I_im, P, Q, f = component.output_values(x0, u, p)
    assert (P, Q, f) == pytest.approx((-0.6, -0.25, 1.0), rel=1e-15)


def test_fload_frequency_rises_with_a_rising_bus_angle():
    component = STANDARD_MODELS["FLoad"]
    p = component.params({"bp": 2.0})
    u = np.array([1.0, 0.1, 0.5, 0.2])
    x = np.array([0.0, 0.0])  # the angle stepped up by 0.1 rad from rest at 0
    rates = component.rhs(x, u, p)
    assert rates[0] > 0 and rates[1] == 0.0
    after = x + 1e-3 * rates
    assert component.output_values(after, u, p)[4] > 1.0


# --- motors -------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", sorted(MOTORS))
def test_motor_rest_turns_the_slip_back_and_draws_power(name):
    component = MOTORS[name]
    p = component.params_type()
    x = component.steady_state([0.95, 0.1], p)
    assert 0.0 < x[0] < 0.05
    I_re, I_im, P, Q, te = component.output_values(x, np.array([0.95, 0.1]), p)
    assert P < 0 and Q < 0  # drawn
    faster = x.copy()
    faster[0] -= 1e-3
    assert component.rhs(faster, np.array([0.95, 0.1]), p)[0] > 0  # a slip below rest rises back


@pytest.mark.parametrize("name", sorted(MOTORS))
def test_motor_start_refuses_a_load_flow_power_its_load_torque_does_not_draw(name):
    component = MOTORS[name]
    p = component.params_type()
    x = component.steady_state([1.0, 0.0], p)
    _, _, P, Q, _ = component.output_values(x, np.array([1.0, 0.0]), p)
    x0, _ = component.start(_given(1.0, 0.0, P, Q), p)
    assert np.array_equal(x0, x)
    with pytest.raises(ValueError, match=f"{name}: at V0 = 1.0 pu"):
        component.start(_given(1.0, 0.0, P - 0.1, Q), p)


@pytest.mark.parametrize("name", sorted(MOTORS))
def test_motor_stalls_refused_where_no_slip_carries_its_load(name):
    component = MOTORS[name]
    p = component.params({"c1": 5.0})
    with pytest.raises(ValueError, match=f"{name}: no stable rest"):
        component.steady_state([0.5, 0.0], p)


def test_motor_on_its_own_base_injects_the_system_base_current_andes_computes_on_the_system_base():
    """A motor rated 50 MVA at 110 kV on a 230 kV bus (ANDES: impedances times (Vn^2/Sn)/(Vb^2/Sb),
    Hm times Sn/Sb, states on the system base) and the same motor written on the system base."""
    own = Motor5.params({"Sn": 50.0, "Vn": 110.0, "Vb": 230.0})
    r, zk = 230.0 / 110.0, (110.0 ** 2 / 50.0) / (230.0 ** 2 / 100.0)
    system = Motor5.params({**{k: getattr(own, k) * zk for k in ("rs", "xs", "rr1", "xr1", "rr2", "xr2", "xm")},
                            "Hm": own.Hm * 0.5, "Sn": 100.0, "Vn": 230.0, "Vb": 230.0})
    u = np.array([0.97, 0.2])
    x_own, x_system = Motor5.steady_state(u, own), Motor5.steady_state(u, system)
    assert x_own[0] == pytest.approx(x_system[0], rel=1e-10)
    np.testing.assert_allclose(x_own[1:] / r, x_system[1:], rtol=1e-10)
    np.testing.assert_allclose(Motor5.output_values(x_own, u, own)[:4], Motor5.output_values(x_system, u, system)[:4],
                               rtol=1e-10)
    x = x_own + np.array([0.01, 0.1, -0.05, 0.02, 0.1])
    rates_own = Motor5.rhs(x, u, own)
    np.testing.assert_allclose(rates_own[1:] / r, Motor5.rhs(np.concatenate([x[:1], x[1:] / r]), u, system)[1:],
                               rtol=1e-10)


# --- against ANDES ------------------------------------------------------------------------------

def _andes():
    andes = pytest.importorskip("andes")
    from reference_models.grid.andes_case import configure_andes_logging

    configure_andes_logging(andes, 40)
    return andes


def _runs(source, fault_bus, tol=1e-6, pflow_start=None):
    """ANDES on `source` (a case path) with a bolted fault at `fault_bus` from 1.0 s to 1.1 s: yields
    the system after TDS.init and then at each of TIMES with its f, g evaluated there; tol: the
    tolerance of its Newton iterations in each step (ieee14's fault together with its generator trip
    at 1.0 s does not converge below 1e-6). pflow_start(ss): called after ANDES' power-flow initial
    guess (to give it a better one)."""
    andes = _andes()
    ss = andes.load(str(source), setup=False, no_output=True, default_config=True)
    if fault_bus is not None:
        ss.add("Fault", {"bus": fault_bus, "tf": 1.0, "tc": 1.1, "xf": 1e-4, "rf": 0.0})
    ss.setup()
    if pflow_start is not None:
        guess = ss.PFlow.init

        def init():
            guess()
            pflow_start(ss)

        ss.PFlow.init = init
    ss.PFlow.config.tol = 1e-12
    assert ss.PFlow.run()
    ss.TDS.init()
    yield ss
    ss.TDS.config.update(fixt=1, tstep=0.005, tol=tol, no_tqdm=1)
    for t in TIMES:
        ss.TDS.config.tf = t
        ss.TDS.run()
        ss.TDS.fg_update(ss.exist.tds)
        yield ss


def _bus(ss, idx):
    i = list(ss.Bus.idx.v).index(idx)
    return float(ss.Bus.v.v[i]), float(ss.Bus.a.v[i]), float(ss.Bus.Vn.v[i])


def _rates(ss, variables, i):
    return np.array([float(ss.dae.f[v.a[i]]) / float(ss.dae.Tf[v.a[i]]) for v in variables])


def _drawn(model, i):
    """(P, Q) drawn [pu, system base]: the device's terms of its bus's power equations."""
    return float(model.a.e[i]), float(model.v.e[i])


@pytest.mark.andes
def test_zip_coefficients_share_and_power_match_andes_through_a_fault():
    """ieee14_zip.json: ANDES switches PQ_1 off and its ZIP (50 % P, 40 % I of its P; 100 % P of
    its Q) draws from PQ_1's load-flow power; its power drawn at ANDES' bus voltage mid-fault and
    after clearing is ours."""
    andes = _andes()
    runs = _runs(andes.get_case("ieee14/ieee14_zip.json"), fault_bus=4)
    ss = next(runs)
    zp, pq = ss.ZIP, ss.PQ
    j = list(pq.idx.v).index(zp.pq.v[0])
    assert pq.u.v[j] == 0.0  # nothing stays on the PQ
    k = {n: float(getattr(zp, n).v[0]) for n in ("kpp", "kpi", "kpz", "kqp", "kqi", "kqz")}
    Ppf, Qpf = float(pq.Ppf.v[j]), float(pq.Qpf.v[j])
    V0 = float(zp.v0.v[0])
    p = ZIPParams(**k, P0=-Ppf * (k["kpp"] + k["kpi"] + k["kpz"]) / 100.0,
                  Q0=-Qpf * (k["kqp"] + k["kqi"] + k["kqz"]) / 100.0, V0=V0)
    _close(coefficients(p), [float(getattr(zp, n).v[0]) for n in ("pp0", "pi0", "pz0", "qp0", "qi0", "qz0")], 1e-14)
    for ss in runs:
        V, theta, _ = _bus(ss, zp.bus.v[0])
        assert V < 0.9 or ss.dae.t > 2.0
        _close([-v for v in zip_power(V, p)], _drawn(zp, 0), 1e-13)


def _fload_case(tmp_path):
    """ieee14_fload.json with exponents that make the load depend on voltage and frequency (ANDES'
    defaults ap = 1, aq = bp = bq = 0 leave the frequency unread)."""
    andes = _andes()
    data = json.loads(open(andes.get_case("ieee14/ieee14_fload.json")).read())
    data["FLoad"][0].update(ap=1.5, aq=2.0, bp=1.3, bq=-0.7)
    path = tmp_path / "ieee14_fload_exponents.json"
    path.write_text(json.dumps(data))
    return path


@pytest.mark.andes
def test_fload_start_and_rates_match_andes_and_its_bus_frequency_measurement_through_a_fault(tmp_path):
    """ieee14_fload.json (exponents set): the start gives ANDES' pv0, qv0 and its BusFreq's states
    (shifted by theta0); at ANDES' states mid-fault and after clearing, our d/dt equals its f / Tf,
    and our power drawn and frequency its own."""
    component = STANDARD_MODELS["FLoad"]
    runs = _runs(_fload_case(tmp_path), fault_bus=4)
    ss = next(runs)
    fl, pq, bf = ss.FLoad, ss.PQ, ss.BusFreq
    j, b = list(pq.idx.v).index(fl.pq.v[0]), list(bf.idx.v).index(fl.busfreq.v[0])
    assert pq.u.v[j] == 0.0
    p = component.params({**{n: float(getattr(bf, n).v[b]) for n in ("Tf", "Tw", "fn")},
                          **{n: float(getattr(fl, n).v[0]) for n in ("ap", "aq", "bp", "bq")}})
    V0, theta0, _ = _bus(ss, fl.bus.v[0])
    a0 = float(bf.a0.v[b])
    share = float(fl.kp.v[0]) / 100.0 * float(pq.Ppf.v[j]), float(fl.kq.v[0]) / 100.0 * float(pq.Qpf.v[j])
    x0, u = component.start(_given(V0, theta0, -share[0], -share[1]), p)
    _close([u["pv0"], u["qv0"]], [float(fl.pv0.v[0]), float(fl.qv0.v[0])], 1e-14)
    _close(x0, [float(bf.L_y.v[b]) + a0, float(bf.WO_x.v[b]) + a0], 1e-15)
    for ss in runs:
        V, theta, _ = _bus(ss, fl.bus.v[0])
        x = np.array([float(bf.L_y.v[b]) + a0, float(bf.WO_x.v[b]) + a0])
        inputs = np.array([V, theta, u["pv0"], u["qv0"]])
        theirs = _rates(ss, (bf.L_y, bf.WO_x), b)
        assert np.abs(theirs).max() > 1e-3  # not at rest
        _close(component.rhs(x, inputs, p), theirs, 1e-9)
        _, _, P, Q, f = component.output_values(x, inputs, p)
        # ANDES' f is an algebraic variable, solved by its Newton iterations (6e-12 off f = 1 + WO_y here)
        _close([-P, -Q, f], [*_drawn(fl, 0), float(fl.f.v[0])], 1e-10)


def _motor_case(tmp_path, name):
    """kundur_motor.xlsx with its Motor5 (or a Motor3 of the same data) in service from the start
    (the stock case switches it on at 2 s from zero states)."""
    andes = _andes()
    import pandas as pd

    sheets = pd.read_excel(andes.get_case("kundur/kundur_motor.xlsx"), sheet_name=None)
    motor = sheets.pop("Motor5").assign(u=1)
    sheets.pop("Toggler")
    sheets[name] = motor.drop(columns=[c for c in ("rr2", "xr2") if name == "Motor3"])
    path = tmp_path / f"kundur_{name}.xlsx"
    with pd.ExcelWriter(path) as writer:
        for sheet, frame in sheets.items():
            frame.to_excel(writer, sheet_name=sheet, index=False)
    return path


def _motor_params(ss, model, component, i):
    values = {n: float(getattr(model, n).vin[i]) for n in component.params_type.__dataclass_fields__
              if hasattr(model, n) and hasattr(getattr(model, n), "vin")}
    return component.params({**values, "Sb": float(ss.config.mva), "Vb": _bus(ss, model.bus.v[i])[2]})


def _motor_guess(name):
    """A power-flow start for ANDES (from its own guess, slip = 1, Motor5's power flow diverges on this
    case and Motor3's KLU factorisation crashes): our rest at the initial bus voltage, states and
    algebraic variables."""
    component = MOTORS[name]

    def start(ss):
        model = getattr(ss, name)
        p = _motor_params(ss, model, component, 0)
        i = list(ss.Bus.idx.v).index(model.bus.v[0])
        u = np.array([float(ss.dae.y[ss.Bus.v.a[i]]), float(ss.dae.y[ss.Bus.a.a[i]])])
        x = component.steady_state(u, p)
        for state, value in zip(component.state_names, x):
            ss.dae.x[getattr(model, state).a[0]] = value
        I_re, I_im, P, Q, te = component.output_values(x, u, p)  # system base = motor base in this case
        algebraic = {"Id": I_im, "Iq": -I_re, "p": -P, "q": -Q, "te": te, "tm": te,
                     "vd": -u[0] * math.sin(u[1]), "vq": u[0] * math.cos(u[1])}
        for var, value in algebraic.items():
            ss.dae.y[getattr(model, var).a[0]] = value

    return start


@pytest.mark.andes
@pytest.mark.parametrize("name", sorted(MOTORS))
def test_motor_start_and_rates_match_andes_through_a_fault(tmp_path, name):
    """kundur_motor.xlsx, the motor in service at bus 7 from the start (ANDES solves it in its power
    flow), a fault at bus 8: the start from ANDES' bus voltage and the motor's own power gives ANDES'
    states; at ANDES' states mid-fault and after clearing our d/dt equals its f / Tf and our bus
    current and torque its own."""
    component = MOTORS[name]
    runs = _runs(_motor_case(tmp_path, name), fault_bus=8, tol=1e-9, pflow_start=_motor_guess(name))
    ss = next(runs)
    model = getattr(ss, name)
    p = _motor_params(ss, model, component, 0)
    V0, theta0, _ = _bus(ss, model.bus.v[0])
    states = [getattr(model, s) for s in component.state_names]
    x0, _ = component.start(_given(V0, theta0, -float(model.p.v[0]), -float(model.q.v[0])), p)
    _close(x0, [float(v.v[0]) for v in states], 1e-12)
    for ss in runs:
        V, theta, _ = _bus(ss, model.bus.v[0])
        x, u = np.array([float(v.v[0]) for v in states]), np.array([V, theta])
        theirs = _rates(ss, states, 0)
        assert np.abs(theirs).max() > 1e-3
        _close(component.rhs(x, u, p), theirs, MOTOR_TOLERANCE)
        I_re, I_im, P, Q, te = component.output_values(x, u, p)
        _close([I_re, I_im, -P, -Q, te], [-float(model.Iq.v[0]), float(model.Id.v[0]), *_drawn(model, 0),
                                          float(model.te.v[0])], MOTOR_TOLERANCE)


@pytest.mark.andes
def test_motor5_rates_match_andes_while_it_starts_in_the_stock_case():
    """kundur_motor.xlsx as shipped: the Motor5 switched on at 2 s from zero states; at 2.5 s (after
    a fault at bus 8 cleared at 1.1 s) it is magnetising and accelerating, and our d/dt at ANDES'
    states equals its f / Tf."""
    andes = _andes()
    *_, ss = _runs(andes.get_case("kundur/kundur_motor.xlsx"), fault_bus=8, tol=1e-9)
    model = ss.Motor5
    p = _motor_params(ss, model, Motor5, 0)
    V, theta, _ = _bus(ss, model.bus.v[0])
    states = [getattr(model, s) for s in Motor5.state_names]
    theirs = _rates(ss, states, 0)
    assert np.abs(theirs).max() > 0.1
    _close(Motor5.rhs(np.array([float(v.v[0]) for v in states]), np.array([V, theta]), p), theirs, MOTOR_TOLERANCE)
