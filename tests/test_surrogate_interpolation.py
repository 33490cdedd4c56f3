"""Input derivatives of the native surrogate FMU (canInterpolateInputs, fmi2SetRealInputDerivatives of
order 1): over fmi2DoStep(t, h) an input with derivative du is u(t) + du (s - t) instead of held, with
the native reference FMU's FMI semantics (the derivatives stay set across steps; after a step the
inputs read as their values at t + h). docs/fmu.md, "A step", says what the engine does with a ramp.

The FMUs are those of two shipped operators: wscc9_gen2.onnx (D = 0, a frame that turns at each
window's start speed, 0.16 s windows of 201 sensors) and sm4_cosim.onnx (the paper's machine, 0.8 s
windows of 1001 sensors); and, for the kernels that track no trunk or no sensor layer, hand-made
operators with sm4_cosim's metadata and frame."""
import math
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu

from fmu_export.step_mirror import StepMirror, fmu_settings
from cosim.fmu import FMU as Slave
from kernel_mirror import on_the_fmus_kernel
from hand_made import operator_without_trunk
from reference_models.sm4 import SM4
from surrogate.operator import Operator

DEFAULT = Path(__file__).parents[1] / "surrogate" / "default"
GEN2, COSIM = DEFAULT / "wscc9_gen2.onnx", DEFAULT / "sm4_cosim.onnx"
INPUTS = SM4.input_names  # Vs, theta_vs, Pm, Efd
OFF = {"rest_radius": 0.0, "slow_weight": 0.0, "swing_weight": 0.0}  # the bare operator


class Built:
    """An FMU built from an operator file (linux64, FMI 2.0, from the run's build cache): its path,
    extracted directory and model description."""

    def __init__(self, onnx_path, name):
        from fmu_export.build_cache import cached_surrogate_fmu

        self.onnx = Path(onnx_path)
        self.path = cached_surrogate_fmu(self.onnx, name, n_check=4)
        self.unzipped = extract(str(self.path)), read_model_description(str(self.path))
        self.md = self.unzipped[1]
        self.starts = {v.name: float(v.start) for v in self.md.modelVariables if v.type == "Real" and v.start is not None}
        self.u0 = np.array([self.starts[n] for n in INPUTS])  # the operator's operating point

    def kernel_mirror(self) -> StepMirror:
        """The step mirror with its network evaluated by this FMU's compiled kernel (in double): what
        is left between it and the FMU is round-off."""
        return on_the_fmus_kernel(StepMirror(self.onnx), self.unzipped)


@pytest.fixture(scope="module")
def gen2():
    return Built(GEN2, "Gen2Surrogate")


@pytest.fixture(scope="module")
def cosim():
    return Built(COSIM, "SM4Surrogate")


class Master(Slave):
    """A Slave driven by a master that interpolates its outputs: per step it may set the inputs and
    their first derivatives (fmi2SetRealInputDerivatives, order 1), or leave either as it is."""

    def derivatives(self, du, names=INPUTS):
        self.fmu.setRealInputDerivatives([self.vr[n] for n in names], [1] * len(names), [float(d) for d in du])

    def advance(self, h, u=None, du=None):
        """Sets the inputs u (unless None), their derivatives du (unless None), steps by h; the states after it."""
        if u is not None:
            self.set(**dict(zip(INPUTS, map(float, u))))
        if du is not None:
            self.derivatives(du)
        self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=h)
        self.t += h
        return self.state()


def initial(x0, u) -> dict:
    """Initial state and the inputs, set in initialization mode (so the first window takes its frame from u)."""
    return {**{f"{n}0": float(v) for n, v in zip(SM4.state_names, x0)}, **dict(zip(INPUTS, map(float, u)))}


def master(fmu: Built, x0, u, name="a", **parameters) -> Master:
    return Master(fmu.unzipped, name, **initial(x0, u), **parameters)


def drive(fmu: Built, x0, steps, rates=None, name="a", carry=(), observe=False, **parameters) -> np.ndarray:
    """The states [n, 4] after each (h, Vs, theta_vs, Pm, Efd) step from x0 (with observe: and the
    inputs, derived outputs and residual read after it), the first step's inputs set in
    initialization mode; rates [n, 4]: the derivatives set before each step (None: never called);
    carry: the steps whose inputs the master does not set (the FMU carries on from where the ramp
    ended)."""
    slave = master(fmu, x0, steps[0][1:], name, **parameters)
    rows = []
    for k, (h, *u) in enumerate(steps):
        x = slave.advance(h, None if k in carry else u, None if rates is None else rates[k])
        rows.append(np.concatenate([x, slave.get(*INPUTS, *SM4.output_names, "residual")]) if observe else x)
    slave.close()
    return np.array(rows)


def ramp(u0, rates, hs) -> list:
    """Steps (h, u) whose inputs continue each ramp: u at a step's start is u0 + the sum of du h before it
    (the arithmetic the FMU uses to carry an input to a step's end)."""
    steps, u = [], np.array(u0, dtype=float)
    for h, du in zip(hs, rates):
        steps.append((h, *u))
        u = np.where(np.asarray(du) != 0, u + np.asarray(du) * h, u)
    return steps


def steady(fmu: Built, u=None, speed=0.0):
    """The machine's equilibrium under u (default: the operator's operating point), turning at `speed`."""
    params = Operator.load(fmu.onnx).params
    return SM4.steady_state(tuple(fmu.u0 if u is None else u), params) + np.array([0.0, speed, 0.0, 0.0])


def dip_run(fmu: Built, speed: float):
    """(x0, steps): steps of 10, 13, 5 and 30 ms of a master turning with a network at `speed` (theta_vs
    advanced at that speed, held over each step), a dip of Vs by 0.3 pu (restarts) and rollovers."""
    params = Operator.load(fmu.onnx).params
    u0 = fmu.u0 + np.array([0.0, 0.0, params.D * speed, 0.0])
    steps, t = [], 0.0
    for k in range(90):
        h = (0.01, 0.013, 0.005, 0.03)[k % 4]
        steps.append((h, u0[0] - (0.3 if 40 <= k < 48 else 0.0), u0[1] + speed * t, u0[2], u0[3]))
        t += h
    return steady(fmu, speed=speed), steps


# --- the capability ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["gen2", "cosim"])
def test_the_model_description_declares_can_interpolate_inputs_and_validates(name, request):
    fmu = request.getfixturevalue(name)
    assert fmu.md.coSimulation.canInterpolateInputs
    assert "#define OPFMU_CAN_INTERPOLATE_INPUTS 1" in zipfile.ZipFile(fmu.path).read("sources/config.h").decode()
    assert validate_fmu(str(fmu.path)) == []


@pytest.mark.parametrize("vr_name, order, value, reason", [
    ("delta", 1, 1.0, "is not an input"), ("P", 1, 1.0, "is not an input"), ("residual", 1, 1.0, "is not an input"),
    ("restart_jump", 1, 1.0, "is not an input"), ("Vs", 2, 1.0, "derivatives of order 1 only are supported"),
    ("theta_vs", 0, 1.0, "derivatives of order 1 only are supported"), ("Vs", 1, float("nan"), "not a finite number"),
    ("Pm", 1, float("inf"), "not a finite number")])
def test_bad_input_derivatives_are_refused_with_a_reason(gen2, vr_name, order, value, reason):
    slave = Master(gen2.unzipped)
    with pytest.raises(FMICallException):
        slave.fmu.setRealInputDerivatives([slave.vr[vr_name]], [order], [value])
    assert any(status == 3 and reason in m for status, m in slave.messages), slave.messages
    slave.close()


def test_a_derivative_that_would_take_vs_below_its_bound_refuses_the_step_and_keeps_the_state(gen2):
    slave = Master(gen2.unzipped)
    slave.set(Vs=0.1)
    slave.derivatives([-20.0], ["Vs"])
    x = slave.state()
    with pytest.raises(FMICallException):
        slave.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.01)
    assert any("below its lower bound" in m for _, m in slave.messages), slave.messages
    np.testing.assert_array_equal(slave.state(), x)
    assert slave.get("Vs")[0] == 0.1
    slave.fmu.freeInstance()


def test_a_ramp_that_leaves_the_envelope_by_the_end_of_its_step_warns_at_that_step(gen2):
    """Vs from 1.2 pu at +5 pu/s over a step of 20 ms ends at 1.3 pu, above the envelope's 1.238: the
    step warns and in_envelope turns false; held at 1.2 pu it stays quiet."""
    assert gen2.u0[0] == 1.0
    for du, leaves in ((5.0, True), (0.0, False)):
        slave = master(gen2, steady(gen2), gen2.u0, f"du{du}")
        slave.advance(0.02, [1.2, *gen2.u0[1:]], [du, 0.0, 0.0, 0.0])
        assert slave.get_boolean("in_envelope") is not leaves
        assert any("left the trained envelope" in m for _, m in slave.messages) is leaves, slave.messages
        slave.close()


def test_after_a_step_the_inputs_and_derived_outputs_are_those_at_its_end_as_for_the_reference_fmu(
        cosim, native_reference_path):
    """The surrogate and the native reference FMU under the same calls: the inputs read after each step
    are u + du h, bit for bit alike; the derivatives stay set over the next steps, through an
    fmi2SetReal of the input; the derived outputs are those of the state and the inputs at the end."""
    reference = Master((extract(str(native_reference_path)), read_model_description(str(native_reference_path))), "r")
    surrogate = Master(cosim.unzipped, "s")
    params = Operator.load(cosim.onnx).params
    calls = [({"Vs": 0.9}, {"Vs": -2.0, "theta_vs": 0.5}), ({}, {}), ({"Vs": 0.95}, {}), ({}, {"Vs": 0.0, "Pm": 0.1})]
    expected = [(0.88, 0.005, 0.7048), (0.86, 0.01, 0.7048), (0.93, 0.015, 0.7048), (0.93, 0.02, 0.7058)]
    for (values, rates), (Vs, theta, Pm) in zip(calls, expected):
        for slave in (reference, surrogate):
            slave.set(**values)
            if rates:
                slave.derivatives(list(rates.values()), list(rates))
            slave.advance(0.01)
        u = surrogate.get(*INPUTS)
        np.testing.assert_array_equal(u, reference.get(*INPUTS))
        np.testing.assert_allclose(u[:3], [Vs, theta, Pm], rtol=0, atol=1e-15)
        np.testing.assert_allclose(surrogate.get(*SM4.output_names), SM4.output_values(surrogate.state(), u, params),
                                   rtol=0, atol=1e-14)
    reference.close()
    surrogate.close()


def test_the_fmu_state_keeps_the_input_derivatives(gen2):
    slave = Master(gen2.unzipped)
    slave.derivatives([-1.0, 2.0, 0.0, 0.0])
    slave.advance(0.01)
    snapshot = slave.fmu.getFMUState()
    slave.derivatives([0.0, 0.0, 0.0, 0.0])  # changed after the snapshot; restored with it
    first = slave.advance(0.01)
    slave.fmu.setFMUState(snapshot)
    slave.t = 0.01
    again = slave.advance(0.01)
    slave.fmu.freeFMUState(snapshot)
    slave.close()
    fresh = Master(gen2.unzipped, "fresh")
    fresh.derivatives([-1.0, 2.0, 0.0, 0.0])
    fresh.advance(0.01)
    np.testing.assert_array_equal(fresh.advance(0.01), again)  # the snapshot's derivatives
    assert np.abs(again - first).max() > 1e-6
    fresh.close()


# --- with every derivative 0: the held inputs, bit for bit --------------------------------------------------

@pytest.mark.parametrize("name, speed", [("gen2", 3.0), ("gen2", 0.0), ("cosim", 2.0)])
def test_zero_derivatives_step_bit_for_bit_as_held_inputs(name, speed, request):
    """States, inputs, derived outputs and residual after every step of a run with restarts at a dip,
    rollovers, steps off the sensor grid and (speed != 0) a turning frame: the same bits whether the
    master never calls fmi2SetRealInputDerivatives, sets every derivative to 0 before each step, or sets
    them to 1 and back to 0 before each step. The held run is also the mirror's (on the FMU's kernel)."""
    fmu = request.getfixturevalue(name)
    x0, steps = dip_run(fmu, speed)
    held = drive(fmu, x0, steps, observe=True)
    zeros = np.zeros((len(steps), 4))
    np.testing.assert_array_equal(drive(fmu, x0, steps, zeros, "b", observe=True), held)
    slave, rows = master(fmu, x0, steps[0][1:], "c"), []
    for h, *u in steps:
        slave.derivatives(np.ones(4))
        rows.append(np.concatenate([slave.advance(h, u, zeros[0]), slave.get(*INPUTS, *SM4.output_names, "residual")]))
    slave.close()
    np.testing.assert_array_equal(np.array(rows), held)
    settings = {**fmu_settings(fmu.md), "u_init": steps[0][1:]}
    np.testing.assert_allclose(held[:, :4], fmu.kernel_mirror().run(x0, steps, **settings), rtol=1e-8, atol=1e-8)


# --- a ramp ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name, h", [("gen2", 0.05), ("gen2", 0.0125), ("cosim", 0.05)])
def test_a_ramp_over_a_step_is_the_operator_on_sensors_that_hold_the_ramp(name, h, request):
    """One step of h from the window start, every input ramped, the corrections off: the state is the
    operator (Operator.predict, onnxruntime, float32) on sensors that ramp from u0 until h and hold
    u0 + du h after it, to the kernel's float32 rounding; held inputs give another state (by far
    more than that). h = 12.5 ms ends between sensor times (1 ms apart for gen2)."""
    fmu = request.getfixturevalue(name)
    du = np.array([-2.0, 3.0, 0.5, -1.0])
    x0 = steady(fmu)
    slave = master(fmu, x0, fmu.u0, **OFF)
    got = slave.advance(h, du=du)
    assert np.abs(slave.get(*INPUTS) - (fmu.u0 + du * h)).max() < 1e-15
    slave.close()
    operator = Operator.load(fmu.onnx)
    s = np.minimum(operator.sensor_times, h)[:, None]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        expected = operator.predict(x0[None], (fmu.u0 + du * s)[None], np.array([h]))[0, -1]
        held = operator.predict(x0[None], np.tile(fmu.u0, (operator.n_sensors, 1))[None], np.array([h]))[0, -1]
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=2e-5)
    assert np.abs(held - expected).max() > 100 * 2e-5


@pytest.mark.parametrize("name, speed", [("gen2", 3.0), ("gen2", 0.0), ("cosim", 2.0)])
def test_ramped_steps_equal_the_step_mirror_with_input_derivatives(name, speed, request):
    """60 steps of 10, 13, 5 and 30 ms (off the sensor grid, splits at rollovers) with the corrections
    on, every input ramping (theta_vs faster than a frame turning at `speed`), slopes changed twice,
    the master setting the inputs on some steps and carrying on from the ramps' ends on others: the
    FMU equals the step mirror with the same derivatives to round-off on the FMU's kernel and to
    float32 on onnxruntime, and is far from the mirror with the inputs held."""
    fmu = request.getfixturevalue(name)
    params = Operator.load(fmu.onnx).params
    rates = [np.array([-0.5 if k < 30 else 0.4, speed + (0.3 if k > 10 else 0.0), 0.05 if k > 20 else 0.0,
                       0.1 if k > 20 else 0.0]) for k in range(60)]
    hs = [(0.01, 0.013, 0.005, 0.03)[k % 4] for k in range(60)]
    u0 = fmu.u0 + np.array([0.0, 0.0, params.D * speed, 0.0])
    steps = ramp(u0, rates, hs)
    x0 = steady(fmu, speed=speed)
    got = drive(fmu, x0, steps, rates, carry=range(1, 60, 3))
    settings = {**fmu_settings(fmu.md), "u_init": steps[0][1:]}
    np.testing.assert_allclose(got, fmu.kernel_mirror().run(x0, steps, derivatives=rates, **settings), rtol=1e-8,
                               atol=1e-8)
    mirror = StepMirror(fmu.onnx)
    np.testing.assert_allclose(got, mirror.run(x0, steps, derivatives=rates, **settings), rtol=2e-5, atol=2e-5)
    assert np.abs(got - mirror.run(x0, steps, **settings)).max() > 1e-3


@pytest.mark.parametrize("name", ["gen2", "cosim"])
def test_an_input_set_back_after_a_ramp_is_held_from_there(name, request):
    """A ramp over one step, then the master sets the input back to the value it started from and its
    derivative to 0: from there on the input is held (the sensors the ramp wrote after its step are
    overwritten, not reused), as the mirror on the FMU's kernel has it. The ramp moves each input by
    less than restart_jump over its step, so setting it back restarts no window."""
    fmu = request.getfixturevalue(name)
    du = np.array([-0.5, 1.0, 0.0, 0.2])
    steps = [(0.01, *fmu.u0)] * 6
    rates = [np.zeros(4), du, np.zeros(4), np.zeros(4), du, np.zeros(4)]
    x0 = steady(fmu)
    got = drive(fmu, x0, steps, rates)
    settings = {**fmu_settings(fmu.md), "u_init": steps[0][1:]}
    np.testing.assert_allclose(got, fmu.kernel_mirror().run(x0, steps, derivatives=rates, **settings), rtol=0,
                               atol=1e-9)


def smooth_inputs(u0, t):
    """A smooth trajectory through u0: Vs swinging by 0.08 pu at 2 Hz, theta_vs by 0.3 rad at 1 Hz; and its derivative."""
    w1, w2 = 2 * math.pi * 2.0, 2 * math.pi * 1.0
    u = u0 + np.array([-0.08 * math.sin(w1 * t), 0.3 * math.sin(w2 * t), 0.0, 0.0])
    return u, np.array([-0.08 * w1 * math.cos(w1 * t), 0.3 * w2 * math.cos(w2 * t), 0.0, 0.0])


def smooth_run(fmu: Built, h: float, interpolate: bool, name: str, seconds=1.0) -> np.ndarray:
    """States every 10 ms (every h, if longer) of the machine under smooth_inputs, sampled by the master
    every h (and their derivatives set, if interpolate), from the equilibrium at u0; over a rollover at
    0.8 s."""
    slave = master(fmu, steady(fmu), fmu.u0, name)
    n, every, rows = int(round(seconds / h)), max(1, int(round(0.01 / h))), []
    for k in range(n):
        u, du = smooth_inputs(fmu.u0, k * h)
        x = slave.advance(h, u, du if interpolate else None)
        if (k + 1) % every == 0:
            rows.append(x)
    slave.close()
    return np.array(rows)


def test_ramped_inputs_are_second_order_in_the_step(cosim):
    """A smooth voltage trajectory sampled every 10 ms with its derivatives set ends far closer to the
    run sampled every 1 ms (held, or with derivatives too) than the held 10 ms run: measured, max over
    the run per state, ramped 10 ms vs held 1 ms (4e-5, 1e-3, 2e-5, 2e-5) against held 10 ms vs held
    1 ms (1.5e-3, 1.1e-2, 4.4e-4, 9.6e-4); and doubling h to 20 ms multiplies the ramped run's miss of
    the 1 ms ramped run by 4 to 5 (h squared)."""
    fine_held, fine_ramped = smooth_run(cosim, 0.001, False, "a"), smooth_run(cosim, 0.001, True, "b")
    held, ramped = smooth_run(cosim, 0.01, False, "c"), smooth_run(cosim, 0.01, True, "d")
    for fine in (fine_held, fine_ramped):
        miss_ramped, miss_held = np.abs(ramped - fine).max(0), np.abs(held - fine).max(0)
        assert np.all(miss_ramped < miss_held / 8), (miss_ramped, miss_held)
        assert np.all(np.abs(ramped[-1] - fine[-1]) < np.abs(held[-1] - fine[-1]) / 4)
    coarse = smooth_run(cosim, 0.02, True, "e")
    ratio = np.abs(coarse - fine_ramped[1::2]).max(0) / np.abs(ramped - fine_ramped).max(0)[None]
    assert np.all(ratio > 3.0), ratio


# --- restarts and rollovers ----------------------------------------------------------------------------

def test_a_continuous_ramp_does_not_restart_the_window_while_a_jump_does(gen2):
    """Ramps the FMU carries from step to step (the master sets only the derivatives), in a frame
    turning at 3 rad/s: Vs at -3 pu/s (0.03 pu a step, above restart_jump 0.02: compared with the
    step's start value it would restart every step) and theta_vs at exactly the frame's speed (no
    allowance for the frame's turn applies to it). The run equals the one with restart_jump = 0 bit
    for bit; a jump of Vs by 0.1 pu on top of the ramp restarts the window there (the mirror on the
    FMU's kernel agrees on where), and the runs part from then on."""
    speed, n, jump = 3.0, 24, 12
    rates = np.tile([-3.0, speed, 0.0, 0.0], (n, 1))
    assert 3.0 * 0.01 > gen2.starts["restart_jump"]
    x0 = steady(gen2, speed=speed)
    steps = ramp(gen2.u0, rates, [0.01] * n)  # over the rollover at 0.16 s
    carried = range(1, n)
    smooth = drive(gen2, x0, steps, rates, carry=carried)
    np.testing.assert_array_equal(drive(gen2, x0, steps, rates, "b", carry=carried, restart_jump=0.0), smooth)
    jumped = [(h, Vs + (0.1 if k >= jump else 0.0), *rest) for k, (h, Vs, *rest) in enumerate(steps)]
    carried = [k for k in carried if k != jump]  # the master sets the jumped input
    got = drive(gen2, x0, jumped, rates, "c", carry=carried)
    without = drive(gen2, x0, jumped, rates, "d", carry=carried, restart_jump=0.0)
    np.testing.assert_array_equal(got[:jump], without[:jump])
    assert np.abs(got[jump:] - without[jump:]).max() > 1e-3
    settings = {**fmu_settings(gen2.md), "u_init": jumped[0][1:]}
    np.testing.assert_allclose(got, gen2.kernel_mirror().run(x0, jumped, derivatives=rates, **settings), rtol=0,
                               atol=1e-8)


def test_a_ramp_across_the_rollover_horizon_goes_on_in_the_new_window(gen2):
    """A step of 30 ms across gen2's rollover at 0.16 s, Vs and theta_vs ramping: split at the horizon,
    the new window starts from the inputs there and the ramp goes on in it, so the step equals two steps
    split at the horizon with the ramp carried on (to round-off; the corrections are cut there as
    well), the inputs after it are those at its end, the next step is no jump, and the whole run is the
    mirror's on the FMU's kernel."""
    du = np.array([-1.5, 2.0, 0.0, 0.0])
    x0 = steady(gen2)
    crossing, split = master(gen2, x0, gen2.u0, "a"), master(gen2, x0, gen2.u0, "b")
    steps = [0.05, 0.05, 0.05]
    for h in steps:
        crossing.advance(h, du=du)
        split.advance(h, du=du)
    a = crossing.advance(0.03)
    split.advance(0.01)
    b = split.advance(0.02)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
    np.testing.assert_allclose(crossing.get(*INPUTS), gen2.u0 + du * 0.18, rtol=0, atol=1e-14)
    after = crossing.advance(0.02)
    crossing.close(), split.close()
    no_restart = master(gen2, x0, gen2.u0, "c", restart_jump=0.0)
    for h in steps + [0.03]:
        no_restart.advance(h, du=du)
    np.testing.assert_array_equal(no_restart.advance(0.02), after)
    no_restart.close()
    rates, hs = [du] * 5, steps + [0.03, 0.02]
    settings = fmu_settings(gen2.md)
    expected = gen2.kernel_mirror().run(x0, ramp(gen2.u0, rates, hs), derivatives=rates, **settings)
    np.testing.assert_allclose(np.array([a, after]), expected[3:], rtol=0, atol=1e-9)


# --- kernels that write the sensors themselves -----------------------------------------------------------

def hand_made(directory, name, squash: bool) -> Built:
    """An FMU of a hand-made operator (tests/hand_made.py) with sm4_cosim's metadata and frame: with
    squash, one without a sensor layer (OPFMU_FIRST_LAYER 0), else one without a trunk
    (OPFMU_TRUNK_SIZE 0)."""
    path = directory / f"{name}.onnx"
    operator_without_trunk(COSIM, path, name, squash)
    return Built(path, name)


@pytest.fixture(scope="module")
def sensor_kernels(tmp_path_factory):
    """{config line: FMU} of the two hand-made operators."""
    directory = tmp_path_factory.mktemp("sensor_kernels")
    fmus = {"OPFMU_TRUNK_SIZE 0": hand_made(directory, "WithoutTrunk", False),
            "OPFMU_FIRST_LAYER 0": hand_made(directory, "WithoutFirstLayer", True)}
    for line, fmu in fmus.items():
        assert line in zipfile.ZipFile(fmu.path).read("sources/config.h").decode()
    return fmus


@pytest.mark.parametrize("kernel", ["OPFMU_TRUNK_SIZE 0", "OPFMU_FIRST_LAYER 0"])
@pytest.mark.parametrize("speed", [3.0, 0.0])
def test_kernels_without_a_trunk_or_a_sensor_layer_take_the_ramp(sensor_kernels, kernel, speed):
    """Ramped steps (carried on and set, off the sensor grid, across a rollover) on the kernels that
    write the sensor buffer themselves: the mirror's states on the FMU's kernel, to round-off; not the
    held ones."""
    fmu = sensor_kernels[kernel]
    params = Operator.load(fmu.onnx).params
    rates = [np.array([-0.5 if k < 30 else 0.4, speed + 0.5, 0.05, -0.1]) for k in range(60)]
    hs = [(0.01, 0.013, 0.005, 0.03)[k % 4] for k in range(60)]  # 0.87 s: over the rollover at 0.8 s
    steps = ramp(fmu.u0 + np.array([0.0, 0.0, params.D * speed, 0.0]), rates, hs)
    x0 = steady(fmu, speed=speed)
    got = drive(fmu, x0, steps, rates, carry=range(1, 60, 3))
    settings = {**fmu_settings(fmu.md), "u_init": steps[0][1:]}
    mirror = fmu.kernel_mirror()
    np.testing.assert_allclose(got, mirror.run(x0, steps, derivatives=rates, **settings), rtol=1e-9, atol=1e-9)
    assert np.abs(got - mirror.run(x0, steps, **settings)).max() > 1e-4
