"""GENROU's surrogate: the per-unit window frame (speed in pu, 1 at rest, angles turning at
2 pi fn (omega - 1)) is exact, the shipped Kundur operators carry it in their ONNX graphs, and the
surrogate FMU of a Kundur machine follows the native reference FMU through a fault."""
import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from reference_models.drift import Frame, frame_of, from_frame, to_frame, trajectories_to_frame
from reference_models.grid.case import shipped_case
from reference_models.models.genrou import GENROU
from reference_models.signals import Piecewise, Ramp, Signal
from reference_models.simulate import simulate

ROOT = Path(__file__).resolve().parents[1]
KUNDUR_OPERATORS = {"kundur_gen12.onnx": (0, 1), "kundur_gen34.onnx": (2, 3)}  # file: the units it is for
# deg: G1's surrogate FMU against its native FMU through the bus-8 fault below (measured 0.17 deg)
SURROGATE_FMU_BOUND_DEG = 0.5


@pytest.fixture(scope="module")
def kundur():
    return shipped_case("kundur")


def test_the_genrou_frame_turns_angles_at_2_pi_fn_per_pu_of_speed_above_1():
    frame = frame_of(GENROU.drift, GENROU.params({"fn": 50.0, "D": 0.0}))
    assert frame == Frame((0,), (1,), 1, ((2, 0.0),), 2 * math.pi, 0.0, 2 * math.pi * 50.0, 1.0)
    assert Frame.from_dict(frame.to_dict()) == frame
    np.testing.assert_array_equal(frame.input_ramps(4), [0, 2 * math.pi * 50.0, 0, 0])


@pytest.mark.parametrize("D", [0.0, 2.0])
def test_a_genrou_frame_round_trip_gives_the_states_back(D):
    frame = frame_of(GENROU.drift, GENROU.params({"D": D}))
    rng = np.random.default_rng(3)
    x0 = rng.uniform(-40, 40, (50, 6))
    x0[:, 1] = rng.uniform(0.97, 1.03, 50)
    u = rng.uniform(-40, 40, (50, 11, 4))
    s = np.linspace(0, 0.2, 11)
    x0_f, u_f, shift, c = to_frame(frame, x0, u, s)
    if D:  # whole steps of 0.005 pu: the speed left lies within half a step of 1
        assert np.all(np.abs(x0_f[:, 1] - 1.0) <= 0.0025 + 1e-12)
    else:  # the frame turns at the start speed: omega_f starts at rest
        np.testing.assert_allclose(x0_f[:, 1], 1.0, atol=1e-15)
    assert np.all((-np.pi <= x0_f[:, 0]) & (x0_f[:, 0] < np.pi))
    np.testing.assert_array_equal(x0_f[:, 2:], x0[:, 2:])  # the fluxes are no angles
    np.testing.assert_allclose(u_f[:, :, 1], u[:, :, 1] - u[:, :1, 1] - c[:, None] * frame.speed_scale * s, atol=1e-12)
    np.testing.assert_allclose(u_f[:, :, 2], u[:, :, 2] - D * c[:, None], atol=1e-12)
    np.testing.assert_allclose(from_frame(frame, x0_f[:, None], np.zeros(1), shift, c)[:, 0], x0, atol=1e-12)


def test_genrou_solved_in_a_turning_frame_is_the_same_window(kundur):
    """The symmetry the frame rests on, on the component's own equations: a Kundur machine through a
    fault, once as recorded and once with its speed 0.004 pu above and its bus angle turning with it
    (from 7 rad on), gives the same window in the frame, to the solver's tolerance."""
    unit = kundur.units[0]
    params = unit.machine.params
    x0 = np.array(kundur.starts[0][0].states)
    inputs = kundur.starts[0][0].inputs
    t = np.linspace(0.0, 0.2, 201)
    vs = Piecewise((inputs["Vs"], 0.1, inputs["Vs"]), (0.02, 0.1))
    base = Signal({"Vs": vs, "theta_vs": Piecewise((inputs["theta_vs"],), ()), "Pm": Piecewise((inputs["Pm"],), ()),
                   "Efd": Piecewise((inputs["Efd"],), ())})
    frame = frame_of(GENROU.drift, params)
    c, a = 0.004, 7.0
    theta = inputs["theta_vs"] + a
    turned = Signal({**base.channels, "theta_vs": Ramp(theta, theta + frame.speed_scale * c * 0.2, 0.0, 0.2)})
    x = simulate(x0, base, t, params, component=GENROU)
    x_turned = simulate(x0 + [a, c, 0, 0, 0, 0], turned, t, params, component=GENROU)
    u, u_turned = base(t)[None], turned(t)[None]
    _, _, in_frame = trajectories_to_frame(frame, x0[None], u, x[None], t)
    _, _, turned_in_frame = trajectories_to_frame(frame, (x0 + [a, c, 0, 0, 0, 0])[None], u_turned, x_turned[None], t)
    np.testing.assert_allclose(turned_in_frame, in_frame, atol=1e-6)



@pytest.mark.parametrize("extra, message", [
    ([], "--recipe case"),  # the SM4 recipes' families drive SM4
    (["--recipe", "case", "--case", "nowhere"], "no shipped case"),
    (["--recipe", "case", "--case", "wscc9"], "no unit of case wscc9"),
    (["--recipe", "case"], "--recipe case needs it"),
])
def test_a_genrou_operator_request_outside_the_case_recipe_ends_in_one_line_and_exit_code_2(
        tmp_path, capsys, kundur, extra, message):
    from opfmu.cli import main

    machine = tmp_path / "g.json"
    machine.write_text(json.dumps(kundur.units[0].machine.params.to_dict()))
    code = main(["operator", "--component", "genrou", "--machine", str(machine), "--out", str(tmp_path / "o"),
                 "--operating-point", "0.78", "1.9", "--quiet", *extra])
    err = capsys.readouterr().err.strip()
    assert code == 2 and message in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "o").exists()


@pytest.fixture(scope="module", params=sorted(KUNDUR_OPERATORS))
def shipped(request):
    from surrogate import Operator

    return request.param, Operator.load(ROOT / "surrogate" / "default" / request.param)


def test_each_kundur_operator_is_the_one_of_its_machines_with_the_per_unit_frame(kundur, shipped):
    name, op = shipped
    for k in KUNDUR_OPERATORS[name]:
        assert op.params == kundur.units[k].machine.params
    assert op.frame == frame_of(GENROU.drift, op.params)
    assert op.frame.speed_scale == 2 * math.pi * 60.0 and op.frame.speed_rest == 1.0 and op.frame.speed_step == 0.0


def test_a_kundur_operators_onnx_graph_does_the_per_unit_frame_as_numpy_does(shipped):
    """The whole file (its frame nodes around the network, float32) on windows turned by angles up to
    30 rad and speeds up to 0.03 pu (11 rad/s) gives what Operator.predict gives (the frame in
    float64 numpy, then the network), to the export's tolerance."""
    import onnxruntime as ort

    from surrogate.contract import TOLERANCE, drifted, random_inputs

    _, op = shipped
    grid = op.sensor_times
    rng = np.random.default_rng(5)
    x0_f, u_f, t = random_inputs(op.envelope, grid, 16, rng)
    x0, u = drifted(op.frame, x0_f, u_f, grid, rng.uniform(-30, 30, 16), rng.uniform(-0.03, 0.03, 16))
    whole = ort.InferenceSession(str(op.path), providers=["CPUExecutionProvider"]).run(
        ["x"], {"x0": x0, "u": u, "t": t})[0].astype(np.float64)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # random windows stray from the envelope: the frame is what is checked
        framed = op.predict(x0, u, t).astype(np.float64)
    assert np.max(np.abs(whole - framed) / np.maximum(1.0, np.abs(framed))) < TOLERANCE
    _, _, shift, c = to_frame(op.frame, x0.astype(np.float64), u.astype(np.float64), grid)
    assert np.max(np.abs(c)) > 0.02  # the windows do turn


def recorded_fault(kundur, k: int, stop: float = 3.0, step: float = 0.01):
    """(start state [6], fmpy input array, times) of unit k in the monolithic Kundur run of a fault at
    bus 8 (x = 1e-4 pu) from 1.0 to 1.1 s: the inputs the unit's machine saw, every `step` s and on
    both sides of the fault's events."""
    from reference_models.grid.contingency import Contingency
    from reference_models.grid.monolithic import System, simulate as simulate_grid

    result = simulate_grid(System(kundur), Contingency(8, 1.1, None, 1.0, 1e-4j, kundur.network), stop, step=step,
                           event_rows=True)
    names = GENROU.input_names
    rows = np.zeros(len(result.time), dtype=[("time", float)] + [(n, float) for n in names])
    rows["time"] = result.time
    for n in names:
        rows[n] = result.machine_inputs[n][:, k]
    return np.array(kundur.starts[k][0].states), rows, result


@pytest.mark.slow
def test_the_surrogate_fmu_of_a_kundur_machine_follows_the_native_fmu_through_a_fault(kundur, tmp_path):
    """G1's surrogate FMU and its native reference FMU, both under fmpy at h = 10 ms on the inputs
    G1 saw in the monolithic run of a bolted fault at bus 8 cleared after 100 ms, from its load-flow
    start: the rotor angles stay within SURROGATE_FMU_BOUND_DEG of each other over 3 s."""
    from fmpy import simulate_fmu

    from fmu_export.native_reference_fmu import build_native_reference_fmu
    from fmu_export.surrogate_fmu import build_surrogate_fmu

    x0, rows, _ = recorded_fault(kundur, 0)
    params = kundur.units[0].machine.params
    point = {n: float(rows[n][0]) for n in GENROU.input_names}
    build_surrogate_fmu(ROOT / "surrogate" / "default" / "kundur_gen12.onnx", tmp_path / "s.fmu", model_name="G1Surrogate")
    build_native_reference_fmu(tmp_path / "r.fmu", "G1Reference", GENROU, params, point)
    start = {f"{n}0": float(v) for n, v in zip(GENROU.state_names, x0)}
    runs = [simulate_fmu(str(tmp_path / f), stop_time=3.0, step_size=0.01, output_interval=0.01, input=rows,
                         start_values={**start, **point}, output=["delta", "omega"]) for f in ("s.fmu", "r.fmu")]
    gap = np.degrees(np.max(np.abs(runs[0]["delta"] - runs[1]["delta"])))
    swing = np.degrees(np.ptp(runs[1]["delta"]))
    assert swing > 20.0  # the fault does swing the machine
    assert gap < SURROGATE_FMU_BOUND_DEG, gap


def test_the_case_recipe_records_faults_past_the_cct_with_one_circuit_of_each_corridor_opened(kundur):
    """Kundur's CCT faults last 320-620 ms and may open a line at clearing: the case family's runs
    reach 700 ms, and open each corridor at the faulted bus once (7-8 has three circuits); every
    other clearing time carries the case's own 8-9:2 opening, unless it would cut buses 8 and 9
    apart (the trip of 8-9 opens the other circuit)."""
    from reference_models.families import CASE_CLEARING_S, case_contingencies, case_trips

    network = kundur.network
    assert case_trips(network, 7) == (None, "6-7", "7-8")
    assert case_trips(network, 1) == (None,)  # its one branch is G1's transformer
    runs = case_contingencies(kundur)
    assert max(c.clear_s - c.fault_start for c in runs) >= 0.7 - 1e-12
    at_7 = {(c.trip, round(c.clear_s - c.fault_start, 3)) for c in runs if c.fault_bus == 7}
    assert {(trip, clearing) for trip in (None, "6-7", "7-8") for clearing in (0.05, 0.7)} <= at_7
    assert len(runs) == len(CASE_CLEARING_S) * 2 * sum(len(case_trips(network, b)) for b in network.buses)
    with_events = {(c.fault_bus, c.trip, round(c.clear_s - c.fault_start, 3)) for c in runs if c.events}
    assert (7, None, 0.1) in with_events and (7, None, 0.05) not in with_events
    assert (8, "8-9", 0.1) not in with_events and (8, "7-8", 0.1) in with_events
    assert all(c.events == kundur.events for c in runs if c.events)
