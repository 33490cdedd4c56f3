"""The shipped operators of the three WSCC 9-bus machines: each is its machine's, takes any drift
of angle and speed exactly (D = 0), and reproduces the grid's own windows of a fault: the windows a
machine FMU starts in the monolithic run lie in its envelope (all but a few: machine 1's Efd dips
0.1 % below its trained range there), and the operator evaluated open loop from them stays on the
monolithic states."""
import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from reference_models.drift import to_frame
from reference_models.grid import wscc9
from reference_models.grid.contingency import Contingency
from reference_models.grid.monolithic import System, simulate
from reference_models.grid.windows import machine_windows, window_starts
from reference_models.sm4 import SM4
from surrogate import Operator

ROOT = Path(__file__).resolve().parents[1]
GENERATORS = (1, 2, 3)
FIVE_CYCLES = 5 / 60


@pytest.fixture(scope="module")
def operators():
    return {g: Operator.load(ROOT / "surrogate" / "default" / f"wscc9_gen{g}.onnx") for g in GENERATORS}


@pytest.fixture(scope="module")
def bus7_fault():
    """Bus 7 bolted, cleared after 5 cycles by tripping line 5-7: the grid issue's hardest case."""
    t = np.round(np.arange(0.0, 3.0 + 1e-9, 0.001), 9)
    return simulate(System(wscc9.case()), Contingency(7, FIVE_CYCLES, "5-7"), 3.0, t_eval=t, event_rows=True)


@pytest.mark.parametrize("gen", GENERATORS)
def test_each_operator_is_the_one_of_its_wscc_machine(operators, gen):
    op = operators[gen]
    machine = json.loads((ROOT / "reference_models" / "grid" / "data" / f"wscc9_gen{gen}.json").read_text())
    assert op.params == SM4.params(machine)
    assert op.params.D == 0.0 and op.frame.speed_step == 0.0  # D = 0: the frame turns at the start speed


@pytest.mark.parametrize("speed", [3.0, -7.3, 11.6])
def test_a_wscc_operator_takes_any_extra_speed_and_angle_exactly(operators, bus7_fault, speed):
    """D = 0: omega0 + c, theta_vs + a + c t give delta + a + c t, omega + c, the fluxes unchanged."""
    op = operators[2]
    grid = op.sensor_times
    x0, u, _ = machine_windows(bus7_fault, 1, window_starts(bus7_fault, op.horizon, 0.25), grid, grid[:1],
                               SM4.state_names, SM4.input_names)
    base = op.predict(x0, u, grid)
    offset = 30.0
    turned = op.predict(x0 + [offset, speed, 0, 0], u + [0, offset, 0, 0] + speed * grid[None, :, None] * [0, 1, 0, 0],
                        grid)
    expected = base + [offset, speed, 0, 0] + speed * grid[None, :, None] * [1, 0, 0, 0]
    np.testing.assert_allclose(turned, expected, atol=1e-4)


@pytest.mark.parametrize("gen", GENERATORS)
def test_the_bus7_fault_windows_lie_in_the_envelope_and_on_the_monolithic_reference(operators, bus7_fault, gen):
    op = operators[gen]
    k = bus7_fault.gen_buses.index(gen)
    grid = op.sensor_times
    used = grid[grid <= op.rollover_horizon + 1e-9]
    starts = window_starts(bus7_fault, op.horizon, 0.05, events=(FIVE_CYCLES,))
    x0, u, truth = machine_windows(bus7_fault, k, starts, grid, used, SM4.state_names, SM4.input_names)
    outside = [i for i in range(len(starts)) if op.outside_envelope(x0[i:i + 1], u[i:i + 1])]
    assert len(outside) <= 0.1 * len(starts), [op.outside_envelope(x0[i:i + 1], u[i:i + 1]) for i in outside[:3]]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the few windows just outside are counted above
        predicted = op.predict(x0, u, used).astype(np.float64)
    worst = np.abs(predicted - truth).max(axis=1)  # [windows, states]
    # the median window within a few thousandths (rad, rad/s / 10, pu), the worst within 0.1 rad
    assert np.all(np.median(worst, axis=0) < [0.005, 0.05, 0.003, 0.002]), np.median(worst, axis=0)
    assert np.all(worst.max(axis=0) < [0.1, 2.5, 0.05, 0.02]), worst.max(axis=0)
    x0_f, _, _, _ = to_frame(op.frame, x0, u, grid)
    np.testing.assert_array_equal(x0_f[:, 1], 0.0)  # the frame turns with the machine's own speed
