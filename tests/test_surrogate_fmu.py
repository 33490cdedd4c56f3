"""The native surrogate FMU under fmpy: FMI 2.0 behaviour and the step semantics of docs/design.md ("The FMUs").

The FMUs here are built from tiny operators trained for a few epochs on tiny datasets (SM4, four
inputs, working in the window frame): the damped default machine (conftest's cosim_tiny) and an
undamped one (D = 0). Their answers are far from the machine's, which is what the step-by-step
comparisons with the Python mirror (fmu_export.step_mirror) need: they pin the FMU's semantics, not
its accuracy. The tests of accuracy against RK45 need a trained operator: they use the shipped one,
and are skipped while it does not load under the current contract (it must be retrained for four
inputs and the window frame)."""
import json
import subprocess
import sys
import zipfile

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu

from fmu_export.step_mirror import StepMirror, affine_step, equilibrium, fmu_settings, jacobian, slow_mode
from cosim.fmu import FMU as Slave
from kernel_mirror import on_the_fmus_kernel
from hand_made import operator_without_trunk
from reference_models.signals import Piecewise, Signal
from reference_models.simulate import simulate
from reference_models.sm4 import SM4, min_voltage_with_equilibrium
from surrogate.operator import DEFAULT_OPERATOR, Operator, OperatorInputError

START = SM4.start_inputs  # Vs, theta_vs, Pm, Efd
UNDAMPED = SM4.params({"D": 0.0})


def train_tiny(data, run, out):
    """A tiny anchored DeepONet (the shipped operator's kind) trained for 3 epochs on `data`, exported to out."""
    from surrogate.models import OperatorConfig
    from surrogate.onnx_export import export_onnx
    from surrogate.training import TrainConfig, train

    config = TrainConfig(model=OperatorConfig(width=16, depth=2, latent=8, anchored=True), epochs=3,
                         time_points=20, physics=True)
    train(data, config, run, progress=False)
    export_onnx(run, out)
    return out


def built(onnx_path, name):
    """The surrogate FMU (linux64, FMI 2.0) of an operator file, from the run's build cache."""
    from fmu_export.build_cache import cached_surrogate_fmu

    return cached_surrogate_fmu(onnx_path, name, n_check=4)


@pytest.fixture(scope="module")
def operator_path(cosim_tiny, tmp_path_factory):
    """A tiny operator of the default (damped, D = 2) machine."""
    directory = tmp_path_factory.mktemp("damped_operator")
    return train_tiny(cosim_tiny[1], directory / "run", directory / "op.onnx")


@pytest.fixture(scope="module")
def fmu_path(operator_path):
    """The surrogate FMU of the tiny damped operator (this module's, not conftest's shipped one)."""
    return built(operator_path, "SM4Surrogate")


@pytest.fixture(scope="module")
def undamped_path(tmp_path_factory):
    """A tiny operator of an undamped machine (D = 0: a speed offset is a symmetry), on its own tiny dataset."""
    from conftest import tiny

    from surrogate.data import generate

    directory = tmp_path_factory.mktemp("undamped_operator")
    generate(tiny("cosim", probes_per_family=2), directory / "data", seed=5, progress=False, params=UNDAMPED)
    return train_tiny(directory / "data", directory / "run", directory / "op.onnx")


@pytest.fixture(scope="module")
def undamped(undamped_path):
    path = built(undamped_path, "Undamped")
    return extract(str(path)), read_model_description(str(path))


@pytest.fixture(scope="module")
def unzipped(fmu_path):
    return extract(str(fmu_path)), read_model_description(str(fmu_path))


@pytest.fixture(scope="module")
def settings(unzipped):
    """The FMU's defaults of the settings the step mirror takes (rest_radius, slow_weight, ...)."""
    return fmu_settings(unzipped[1])


@pytest.fixture(scope="module")
def mirror(operator_path):
    return StepMirror(operator_path)


@pytest.fixture
def operator_reference(mirror, settings):
    """States after each (h, Vs, theta_vs, Pm, Efd) step by the FMU's step semantics in Python
    (fmu_export.step_mirror, onnxruntime), with the FMU's default settings changed by `changes` (its
    parameters of those names; u_init: the inputs set in initialization mode)."""
    def run(x0, steps, **changes):
        return mirror.run(x0, steps, **{**settings, **changes})
    return run


@pytest.fixture(scope="module")
def shipped():
    """The extracted FMU of the shipped operator, for the tests of accuracy; skipped while that
    operator does not load (made for two inputs, before the window frame: it needs retraining)."""
    try:
        Operator.load(DEFAULT_OPERATOR)
    except OperatorInputError as exc:
        pytest.skip(f"the shipped operator does not load under the current contract ({str(exc).split(': ', 1)[-1]})")
    path = built(DEFAULT_OPERATOR, "SM4Surrogate")
    return extract(str(path)), read_model_description(str(path))


def steady(Vs=1.0, theta_vs=0.0, Pm=START[2], Efd=START[3], p=None):
    return SM4.steady_state((Vs, theta_vs, Pm, Efd), p)


def held(n, h, Vs=1.0, theta_vs=0.0, Pm=START[2], Efd=START[3]):
    """n steps (h, Vs, theta_vs, Pm, Efd) of one held input."""
    return [(h, Vs, theta_vs, Pm, Efd)] * n


def initial(x0) -> dict:
    """The initial-state parameters {delta0: ..., ...} of a state x0 [4]."""
    return {f"{name}0": float(value) for name, value in zip(SM4.state_names, x0)}


def inputs_at_init(u) -> dict:
    """The inputs {Vs: ..., ...} to set in initialization mode (as fmpy's simulate_fmu does)."""
    return {name: float(value) for name, value in zip(SM4.input_names, u)}


def run_fmu(unzipped, steps, name="a", **start):
    slave = Slave(unzipped, name, **start)
    states = np.array([slave.step(*step) for step in steps])
    slave.close()
    return states


def test_the_mirrors_newton_finds_the_equilibrium_and_its_slow_mode_is_the_slowest_eigenvalue(mirror):
    u = np.array([0.95, 0.1, 0.7048, 1.08])
    rest = SM4.steady_state(u)
    np.testing.assert_allclose(equilibrium(mirror.f, rest + np.array([0.05, 0.01, 0.01, -0.01]), u), rest,
                               rtol=0, atol=1e-9)
    l, r = slow_mode(mirror.f, rest, u)
    J = jacobian(mirror.f, rest, u)
    values = np.linalg.eigvals(J)
    slowest = values[np.argmin(np.abs(values))]
    assert slowest.imag == 0 and slowest.real < 0
    assert l @ r == pytest.approx(1.0)
    np.testing.assert_allclose(J @ r, slowest.real * r, atol=1e-6 * np.abs(r).max())
    np.testing.assert_allclose(l @ J, slowest.real * l, atol=1e-6 * np.abs(l).max())


@pytest.mark.parametrize("k", [62.0, 0.0])
def test_the_exact_affine_step_solves_its_linear_equation(k):
    from scipy.integrate import solve_ivp

    h, start, g0, g1 = 0.02, 0.3, 5.0, -7.0
    exact = solve_ivp(lambda s, x: g0 + (g1 - g0) * s / h - k * x, (0, h), [start], rtol=1e-12, atol=1e-14).y[0, -1]
    assert affine_step(start, g0, g1, k, h) == pytest.approx(exact, abs=1e-10)


def test_the_mirror_takes_the_machine_and_the_frame_from_the_operators_metadata(operator_path, undamped_path,
                                                                                  tmp_path):
    import onnx

    proto = onnx.load(str(operator_path))
    for entry in proto.metadata_props:
        if entry.key == "params":
            entry.value = json.dumps({"H": 3.01})
    onnx.save(proto, str(tmp_path / "other.onnx"))
    assert StepMirror(tmp_path / "other.onnx").params == SM4.params({"H": 3.01})
    damped, undamped = StepMirror(operator_path), StepMirror(undamped_path)
    assert damped.params == SM4.params() and undamped.params == UNDAMPED
    # R: theta_vs turns with the frame; T: Pm is lowered by D c; A, W: delta turns, omega is the speed
    np.testing.assert_array_equal(damped.rates, [0, 1, 0, 0])
    np.testing.assert_array_equal(damped.torques, [0, 0, 2.0, 0])
    np.testing.assert_array_equal(undamped.torques, [0, 0, 0, 0])
    np.testing.assert_array_equal(damped.angles, [1, 0, 0, 0])
    np.testing.assert_array_equal(damped.speed, [0, 1, 0, 0])


def test_fmpy_validation_reports_no_problem(fmu_path):
    assert validate_fmu(str(fmu_path)) == []


def test_binary_needs_libc_and_libm_only(unzipped):
    binary = f"{unzipped[0]}/binaries/linux64/SM4Surrogate.so"
    libraries = {line.split()[0] for line in subprocess.run(["ldd", binary], capture_output=True, text=True,
                                                             check=True).stdout.splitlines()}
    assert {name.split(".so")[0] for name in libraries} <= {"linux-vdso", "libc", "libm", "/lib64/ld-linux-x86-64"}


def test_fmu_carries_the_operator_and_its_sources(fmu_path):
    names = zipfile.ZipFile(fmu_path).namelist()
    assert "resources/model.onnx" in names and "sources/operator_kernel.c" in names


def test_outputs_equal_the_operator_on_the_same_sensor_buffer(unzipped, operator_reference):
    # every input moving; the first step's input is not the one the FMU was initialised with
    rng = np.random.default_rng(0)
    steps = [(0.01, 1.0 + 0.05 * np.sin(k / 7), 0.1 * np.cos(k / 11), 0.7 + 0.05 * np.sin(k / 5),
              1.08 + 0.1 * np.cos(k / 9)) for k in range(60)]
    steps += [(float(h), float(v), float(a), float(p), float(e)) for h, v, a, p, e in
              zip(rng.choice([0.001, 0.004, 0.02, 0.05], 30), rng.uniform(0.9, 1.1, 30), rng.uniform(-0.2, 0.2, 30),
                  rng.uniform(0.5, 0.9, 30), rng.uniform(1.0, 2.0, 30))]
    got = run_fmu(unzipped, steps)
    expected = operator_reference(steady(), steps)
    assert sum(step[0] for step in steps) > 1.0  # the run crossed a window boundary
    np.testing.assert_allclose(got, expected, rtol=0, atol=2e-5)


def test_machine_at_rest_under_its_held_input_stays_exactly_at_rest(unzipped):
    slave = Slave(unzipped)
    states = np.array([slave.step(0.01) for _ in range(300)])  # over three windows
    slave.close()
    np.testing.assert_allclose(states, np.tile(steady(), (300, 1)), rtol=0, atol=1e-6)


def test_the_surrogate_starts_itself_from_the_load_flow_as_the_native_reference_does(unzipped, fmu_cache):
    """Given only a load flow off the built one (V_lf, theta_lf, P_lf, Q_lf), the surrogate FMU solves
    the same start as the machine's native reference FMU (fmu_export/c/self_start.c on the same
    equations): states, Pm and Efd (Pm_init, Efd_init), the bus voltage left unset at the flow's."""
    from fmu_export.build_cache import cached_native_reference_fmu

    flow = {"V_lf": 1.03, "theta_lf": 0.25, "P_lf": 0.75, "Q_lf": 0.1}
    native = Slave(cached_native_reference_fmu("SM4Reference", component=SM4, cache=fmu_cache), component=SM4,
                   start=flow)
    surrogate = Slave(unzipped, component=SM4, start=flow)
    names = list(SM4.state_names) + ["Pm_init", "Efd_init", "Vs", "theta_vs", "P_bus", "Q_bus"]
    ours, theirs = surrogate.get(*names), native.get(*names)
    native.close()
    np.testing.assert_allclose(ours, theirs, rtol=1e-12, atol=1e-12)
    assert list(ours[-2:]) == pytest.approx([flow["P_lf"], flow["Q_lf"]], rel=1e-10)
    assert ours[SM4.state_names.index("delta")] != pytest.approx(steady()[0], abs=0.1)  # not the built rest
    surrogate.close()


def test_without_the_rest_correction_the_machine_at_rest_moves_by_the_operators_error(unzipped, operator_reference):
    slave = Slave(unzipped, rest_radius=0.0)
    states = np.array([slave.step(0.01) for _ in range(300)])
    slave.close()
    np.testing.assert_allclose(states, operator_reference(steady(), held(300, 0.01), rest_radius=0.0),
                               rtol=0, atol=2e-5)
    assert np.abs(states - steady()).max() > 1e-5


def test_the_rest_correction_fades_with_the_distance_from_rest(unzipped, operator_reference):
    x0 = steady() + np.array([0.1, 0.0, 0.0, 0.02])  # weight 1 - 0.2 = 0.8 at the start
    steps = held(120, 0.01)
    got = run_fmu(unzipped, steps, **initial(x0))
    np.testing.assert_allclose(got, operator_reference(x0, steps), rtol=0, atol=2e-5)
    assert np.abs(got - operator_reference(x0, steps, rest_radius=0.0)).max() > 1e-5


def test_a_negative_rest_radius_is_refused_with_a_reason(unzipped):
    slave = Slave(unzipped, init=False)
    with pytest.raises(FMICallException):
        slave.set(rest_radius=-1.0)
    assert any("rest_radius" in m for _, m in slave.messages)
    slave.fmu.freeInstance()


def constant(value):
    return Piecewise((value,), ())


def fmu_and_rk45(unzipped, x0, signal, steps, **parameters):
    """(FMU states, RK45 states) [n, 4] after each (h, Vs, theta_vs, Pm, Efd) step from x0; the RK45
    reference solves under `signal`, the same inputs as functions of time."""
    reference = simulate(x0, signal, np.cumsum([0.0] + [step[0] for step in steps]))[1:]
    return run_fmu(unzipped, steps, **initial(x0), **parameters), reference


def undervoltage_run(unzipped, seconds=15.0, Vs=0.84, **parameters):
    """(FMU states, RK45 states) [n, 4] every 10 ms of a machine held at Vs below the lowest voltage with
    an equilibrium, from the equilibrium at that voltage: it slowly slips (delta rises by 0.14 rad)."""
    steps = held(int(round(seconds / 0.01)), 0.01, Vs)
    signal = Signal({"Vs": constant(Vs), "theta_vs": constant(0.0), "Pm": constant(START[2]),
                     "Efd": constant(START[3])})
    return fmu_and_rk45(unzipped, steady(min_voltage_with_equilibrium()), signal, steps, **parameters)


def test_the_slow_mode_correction_keeps_a_slow_drift_on_the_rk45_solution(shipped):
    corrected, reference = undervoltage_run(shipped)
    uncorrected, _ = undervoltage_run(shipped, slow_weight=0.0)
    error, error_without = np.abs(corrected - reference).max(0), np.abs(uncorrected - reference).max(0)
    assert error[0] < 0.5 * error_without[0] and error[3] < 0.5 * error_without[3]  # delta, Eq_p


def test_slow_weight_zero_is_the_operator_with_the_rest_correction_only(unzipped, operator_reference):
    x0 = steady() + np.array([0.1, 0.0, 0.0, 0.02])
    steps = held(120, 0.01, 0.95, 0.05)
    got = run_fmu(unzipped, steps, slow_weight=0.0, **initial(x0))
    np.testing.assert_allclose(got, operator_reference(x0, steps, slow_weight=0.0), rtol=0, atol=2e-5)
    assert np.abs(got - operator_reference(x0, steps)).max() > 1e-5


@pytest.mark.parametrize("name", ["slow_weight", "swing_weight"])
@pytest.mark.parametrize("value", [-0.1, 1.5])
def test_a_weight_outside_zero_to_one_is_refused_with_a_reason(unzipped, name, value):
    slave = Slave(unzipped, init=False)
    with pytest.raises(FMICallException):
        slave.set(**{name: value})
    assert any(f"{name} = {value:g} must lie in [0, 1]" in m for _, m in slave.messages)
    slave.fmu.freeInstance()


def deep_fault_run(unzipped, **parameters):
    """(FMU states, RK45 states) [n, 4] every 10 ms from the equilibrium at Vs = 1: 0.3 s at rest, a
    fault to Vs = 0.2 pu with an angle jump of 0.25 rad for 150 ms, then 0.55 s at Vs = 1.05 pu."""
    levels = [(30, 1.0, 0.0), (15, 0.2, 0.25), (55, 1.05, 0.25)]
    steps = [step for n, v, a in levels for step in held(n, 0.01, v, a)]
    signal = Signal({"Vs": Piecewise((1.0, 0.2, 1.05), (0.3, 0.45)), "theta_vs": Piecewise((0.0, 0.25), (0.3,)),
                     "Pm": constant(START[2]), "Efd": constant(START[3])})
    return fmu_and_rk45(unzipped, steady(), signal, steps, **parameters)


def test_the_exact_swing_step_keeps_omega_on_the_rk45_solution_through_a_deep_fault(shipped):
    corrected, reference = deep_fault_run(shipped)
    uncorrected, _ = deep_fault_run(shipped, swing_weight=0.0)
    error, error_without = np.abs(corrected - reference).max(0), np.abs(uncorrected - reference).max(0)
    assert error[1] < 0.5 * error_without[1] and error[1] < 0.005  # omega [rad/s]


def test_swing_weight_zero_leaves_the_operators_omega(unzipped, operator_reference):
    steps = held(10, 0.01) + held(30, 0.01, 0.5, 0.2)
    got = run_fmu(unzipped, steps, swing_weight=0.0)
    np.testing.assert_allclose(got, operator_reference(steady(), steps, swing_weight=0.0), rtol=0, atol=2e-5)
    assert np.abs(got[:, 1] - operator_reference(steady(), steps)[:, 1]).max() > 1e-4


def test_rollover_horizon_defaults_to_the_operators_own(unzipped, operator_path):
    slave = Slave(unzipped)
    horizon = slave.get("rollover_horizon")[0]
    slave.close()
    assert horizon == float(Operator.load(operator_path).metadata["rollover_horizon_s"])


def test_an_input_jump_above_restart_jump_starts_a_new_window_from_the_state_reached(unzipped, operator_reference):
    steps = held(30, 0.01) + held(20, 0.01, 0.6, 0.1) + held(30, 0.01, 1.0, 0.1) + held(20, 0.01, 1.0, 0.1, 0.8, 1.5)
    got = run_fmu(unzipped, steps)
    np.testing.assert_allclose(got, operator_reference(steady(), steps), rtol=0, atol=1e-5)
    without = operator_reference(steady(), steps, restart_jump=0.0)
    np.testing.assert_allclose(got[:30], without[:30], rtol=0, atol=1e-5)
    assert np.abs(got[30:] - without[30:]).max() > 1e-4


def test_restart_jump_zero_keeps_windows_at_the_rollover_horizon(unzipped, operator_reference):
    steps = held(30, 0.01) + held(20, 0.01, 0.6, 0.1)
    got = run_fmu(unzipped, steps, restart_jump=0.0)
    np.testing.assert_allclose(got, operator_reference(steady(), steps, restart_jump=0.0), rtol=0, atol=1e-5)


def test_a_step_crossing_the_window_boundary_equals_one_split_at_it(unzipped):
    # without the slow-mode correction and the exact swing step, whose integrals depend on how steps are cut
    off = {"slow_weight": 0.0, "swing_weight": 0.0, "rollover_horizon": 1.0}
    a, b = Slave(unzipped, "a", **off), Slave(unzipped, "b", **off)
    for h in (0.3, 0.3, 0.3):
        a.step(h, 0.95, 0.1)
        b.step(h, 0.95, 0.1)
    crossing = a.step(0.3, 0.95, 0.1)
    b.step(0.1, 0.95, 0.1)
    split = b.step(0.2, 0.95, 0.1)
    a.close(), b.close()
    np.testing.assert_allclose(crossing, split, rtol=0, atol=1e-12)


def test_shorter_rollover_horizon_starts_windows_more_often(unzipped, operator_reference):
    steps = held(20, 0.05, 0.97, 0.05)
    slave = Slave(unzipped, rollover_horizon=0.25)
    states = [slave.step(*step) for step in steps]
    horizon = slave.get("rollover_horizon")[0]
    slave.close()
    assert horizon == 0.25
    np.testing.assert_allclose(states, operator_reference(steady(), steps, rollover_horizon=0.25), rtol=0, atol=2e-5)


def test_corrupt_serialized_state_is_refused_with_a_reason(unzipped):
    slave = Slave(unzipped)
    with pytest.raises(FMICallException):
        slave.fmu.deSerializeFMUstate(b"\x00" * 64)
    assert any("wrong size" in m or "corrupt" in m for _, m in slave.messages)
    slave.close()


@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_non_finite_input_is_an_error_with_a_logged_reason(unzipped, value):
    slave = Slave(unzipped)
    with pytest.raises(FMICallException):
        slave.set(Vs=value)
    assert any("not a finite number" in m for _, m in slave.messages)
    assert slave.step(0.01)[0] == pytest.approx(steady()[0], abs=1e-2)  # still usable
    slave.close()


@pytest.mark.parametrize("h", [0.0, -0.01])
def test_non_positive_step_is_an_error_with_a_logged_reason(unzipped, h):
    slave = Slave(unzipped)
    with pytest.raises(FMICallException):
        slave.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=h)
    assert any("must be positive" in m for _, m in slave.messages)
    slave.close()


def test_step_before_initialization_is_an_error_with_a_logged_reason(unzipped):
    slave = Slave(unzipped, init=False)
    with pytest.raises(FMICallException):
        slave.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.01)
    assert any("fmi2DoStep is not allowed" in m for _, m in slave.messages)
    slave.fmu.freeInstance()


def test_step_from_the_wrong_time_is_an_error(unzipped):
    slave = Slave(unzipped)
    with pytest.raises(FMICallException):
        slave.fmu.doStep(currentCommunicationPoint=0.5, communicationStepSize=0.01)
    assert any("is not the FMU's time" in m for _, m in slave.messages)
    slave.close()


def test_setting_a_parameter_after_initialization_is_an_error(unzipped):
    slave = Slave(unzipped)
    with pytest.raises(FMICallException):
        slave.set(delta0=0.5)
    assert any("fixed after initialization" in m for _, m in slave.messages)
    slave.close()


def envelope_centre(operator_path):
    """(x0, u): the centre of the operator's envelope (omega 0, theta_vs 0, where the frame is the identity)."""
    box = Operator.load(operator_path).envelope
    x0 = np.array([np.mean(box["x0"][name]) for name in SM4.state_names])
    u = np.array([np.mean(box["u"][name]) for name in SM4.input_names])
    x0[0] -= np.round(x0[0] / (2 * np.pi)) * 2 * np.pi
    u[1], x0[1] = 0.0, 0.0
    return x0, u


def test_input_outside_the_envelope_turns_in_envelope_false_and_warns(unzipped, operator_path):
    x0, u = envelope_centre(operator_path)
    slave = Slave(unzipped, **initial(x0), **inputs_at_init(u))
    assert slave.get_boolean("in_envelope") is True
    slave.step(0.01, *u)
    assert slave.get_boolean("in_envelope") is True
    slave.step(0.01, 0.05, *u[1:])
    assert slave.get_boolean("in_envelope") is False
    assert any("left the trained envelope" in m for _, m in slave.messages)
    slave.step(0.01, *u)
    assert slave.get_boolean("in_envelope") is False  # sticky
    slave.close()


def test_residual_is_small_at_rest_and_large_on_an_inconsistent_state(unzipped):
    rest = Slave(unzipped)
    rest.step(0.01)
    small = rest.get("residual")[0]
    rest.close()
    odd = Slave(unzipped, delta0=0.2)  # far from the equilibrium, with nominal voltage
    odd.step(0.001)
    odd.set(Vs=0.5)  # an input the state does not belong to
    large = odd.get("residual")[0]
    odd.close()
    assert small < 0.5 < large


def test_the_residual_is_the_operators_own_whatever_the_swing_step_does_to_omega(unzipped):
    # within one window (no restart at the jumps), without the slow-mode correction (which reads the
    # state the swing step left)
    runs = {w: Slave(unzipped, f"w{w}", swing_weight=w, slow_weight=0.0, restart_jump=0.0) for w in (0.0, 1.0)}
    residuals, omegas = {0.0: [], 1.0: []}, {0.0: [], 1.0: []}
    for Vs, theta in [(1.0, 0.0)] * 10 + [(0.3, 0.2)] * 15 + [(1.0, 0.2)] * 20:
        for w, slave in runs.items():
            omegas[w].append(slave.step(0.01, Vs, theta)[1])
            residuals[w].append(slave.get("residual")[0])
    for slave in runs.values():
        slave.close()
    assert np.abs(np.subtract(omegas[1.0], omegas[0.0])).max() > 1e-3
    np.testing.assert_allclose(residuals[1.0], residuals[0.0], rtol=1e-9, atol=1e-12)


def warnings_logged(slave):
    return [m for status, m in slave.messages if status == 1 and "residual" in m]


def test_a_residual_above_the_limit_logs_one_warning_per_excursion(unzipped):
    slave = Slave(unzipped, residual_limit=1e-9)  # every moving state is "in trouble" at this limit
    slave.step(0.01, 0.9)
    slave.step(0.01, 0.9)
    assert len(warnings_logged(slave)) == 1
    assert "exceeds residual_limit 1e-09" in warnings_logged(slave)[0]
    slave.close()


def test_the_default_residual_limit_stays_quiet_on_a_quiet_run_and_zero_turns_the_check_off(unzipped):
    quiet = Slave(unzipped)
    for k in range(200):
        quiet.step(0.01, 1.0 + 0.02 * np.sin(k / 20))
    assert warnings_logged(quiet) == [] and quiet.get("residual_limit")[0] > 0
    quiet.close()
    off = Slave(unzipped, residual_limit=0.0, delta0=0.2)
    off.step(0.01, 0.5)
    assert warnings_logged(off) == []
    off.close()


@pytest.mark.platform_tools("valgrind")
def test_thousand_instantiate_free_cycles_and_reloads_leak_nothing(unzipped, tmp_path):
    from fmu_export.binaries import fmi_headers

    harness = tmp_path / "harness"
    source = __file__.rsplit("/", 1)[0] + "/c/lifecycle_harness.c"
    subprocess.run(["gcc", "-O1", "-g", "-I", str(fmi_headers()), source, "-o", str(harness), "-ldl"], check=True)
    binary = f"{unzipped[0]}/binaries/linux64/SM4Surrogate.so"
    result = subprocess.run(["valgrind", "--leak-check=full", "--errors-for-leak-kinds=definite,indirect,possible",
                             "--error-exitcode=3", str(harness), binary, unzipped[1].guid, "1000", "2"],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr[-3000:]
    assert "ERROR SUMMARY: 0 errors" in result.stderr


@pytest.mark.platform_tools  # one line whichever platforms' compilers are installed
def test_build_fmu_command_refuses_a_file_that_is_not_an_operator(tmp_path):
    bogus = tmp_path / "bogus.onnx"
    bogus.write_bytes(b"not onnx at all")
    result = subprocess.run([sys.executable, "-m", "opfmu", "build-fmu", str(bogus), "-o", str(tmp_path / "x.fmu")],
                            capture_output=True, text=True)
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
    assert "not a readable ONNX file" in result.stderr and not (tmp_path / "x.fmu").exists()


@pytest.mark.slow  # a build of the shipped operator through the command line (a 46 MB FMU)
def test_build_fmu_command_builds_the_shipped_operator_by_default(shipped, tmp_path):
    out = tmp_path / "Machine.fmu"
    result = subprocess.run([sys.executable, "-m", "opfmu", "build-fmu", "-o", str(out), "--name", "Machine",
                             "--platforms", "linux64"], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "matches onnxruntime" in result.stdout
    assert read_model_description(str(out)).coSimulation.modelIdentifier == "Machine"
    assert "binaries/linux64/Machine.so" in zipfile.ZipFile(out).namelist()


def test_build_fmu_command_builds_a_given_operator(operator_path, tmp_path):
    out = tmp_path / "Machine.fmu"
    result = subprocess.run([sys.executable, "-m", "opfmu", "build-fmu", str(operator_path), "-o", str(out),
                             "--name", "Machine", "--platforms", "linux64"], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "matches onnxruntime" in result.stdout
    assert read_model_description(str(out)).coSimulation.modelIdentifier == "Machine"


# --- the window frame: a drifting network, turned angles, a speed offset --------------------------------

def drifting(n, h, theta0, speed, Pm, Efd, dip=(50, 65), Vs_dip=0.7):
    """n steps of h of a zero-order-hold master on a network turning at `speed` [rad/s]: theta_vs =
    theta0 + speed t at each step's start; Vs dips to Vs_dip over the steps dip[0] to dip[1]."""
    return [(h, Vs_dip if dip[0] <= k < dip[1] else 1.0, theta0 + speed * k * h, Pm, Efd) for k in range(n)]


def fmu_states(unzipped, x0, steps, name="a", **parameters):
    """The FMU's states after each step from x0, with the first step's inputs set in initialization mode."""
    return run_fmu(unzipped, steps, name, **initial(x0), **inputs_at_init(steps[0][1:]), **parameters)


MACHINES = {"undamped": ("undamped", "undamped_path"), "damped": ("unzipped", "operator_path")}  # FMU, operator


@pytest.mark.parametrize("machine, speed", [("undamped", 12.0), ("damped", 3.0)])
def test_the_fmu_equals_the_mirror_with_a_drifting_network(machine, speed, request):
    """A machine turning at `speed` with its network (omega0 = speed, theta_vs = a + speed t held over
    each 10 ms step, Pm raised by D speed so the torque in the frame is the nominal one), through a
    dip: the FMU equals the mirror step by step over windows rolled over, restarted at the dip's jumps
    and in between: to round-off (1e-8) with the mirror on the FMU's kernel, to float32 (relative
    2e-5) on onnxruntime (the tiny network speeds the machine up to 30 rad/s, and the exact swing
    step, an integrator, carries the float32 differences along). Pins: the frame of each window (a,
    shift, c), the held-then-ramped slots, the state back from the frame, the rest correction in the
    frame, the slow-mode and swing corrections on raw values, the restart test with the frame's turn
    removed (the angle's advance of speed h per step is no jump), and for the undamped machine,
    inputs and window starts checked in the frame (theta_vs reaches 5 rad and omega is 12 rad/s, far
    outside the envelope's raw ranges)."""
    unzipped, operator = (request.getfixturevalue(name) for name in MACHINES[machine])
    mirror = StepMirror(operator)
    D, Pm, Efd = mirror.params.D, 0.7, 1.8
    steps = drifting(250, 0.01, 0.4, speed, Pm + D * speed, Efd)
    x0 = steady(1.0, 0.4, Pm, Efd, mirror.params) + np.array([0.0, speed, 0.0, 0.0])
    settings = {**fmu_settings(unzipped[1]), "u_init": steps[0][1:]}
    got = fmu_states(unzipped, x0, steps)
    assert got[-1, 0] - x0[0] > 0.5 * speed * 2.5  # delta turned with the network
    np.testing.assert_allclose(got, mirror.run(x0, steps, **settings), rtol=2e-5, atol=2e-5)
    # before the dip, within the first window: no restart at any step
    no_restart = mirror.run(x0, steps[:40], **{**settings, "restart_jump": 0.0})
    np.testing.assert_allclose(mirror.run(x0, steps[:40], **settings), no_restart, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(got, on_the_fmus_kernel(mirror, unzipped).run(x0, steps, **settings),
                               rtol=1e-8, atol=1e-8)
    if machine == "undamped":
        slave = Slave(unzipped, **initial(x0), **inputs_at_init(steps[0][1:]))
        for step in steps[:40]:
            slave.step(*step)
        assert slave.get_boolean("in_envelope") is True, slave.messages
        slave.close()


@pytest.mark.parametrize("machine", ["undamped", "damped"])
@pytest.mark.parametrize("offset", [3.0, -3.0, 30.0, -30.0])
def test_turned_angles_give_the_same_trajectories(machine, offset, request):
    """delta0 and theta_vs turned by `offset` [rad] (not a whole number of periods for +-3, about 4.8
    periods for +-30), the inputs set in initialization mode: the FMU's states are those of the run
    unturned, delta turned by the offset, to 1e-9 (1 + |x|) (the symmetry is exact in every part of the
    engine: the frame removes the offset before the network, the corrections on raw values see delta
    only through delta - theta_vs; the tolerance grows with the values, as their round-off does: at an
    offset of 30 rad delta is about 32), on a run whose frame turns (omega0 = 0.5 rad/s, theta_vs
    advancing with it) over a rollover and the restarts at a dip."""
    unzipped = request.getfixturevalue(MACHINES[machine][0])
    D = 0.0 if machine == "undamped" else SM4.params().D
    x0 = steady(1.0, 0.2, 0.7, 1.8, UNDAMPED if machine == "undamped" else None) + np.array([0.05, 0.5, 0.0, 0.0])
    steps = drifting(150, 0.01, 0.2, 0.5, 0.7 + 0.5 * D, 1.8)
    turned = [(h, Vs, theta + offset, Pm, Efd) for h, Vs, theta, Pm, Efd in steps]
    base = fmu_states(unzipped, x0, steps, "a")
    got = fmu_states(unzipped, x0 + np.array([offset, 0.0, 0.0, 0.0]), turned, "b")
    assert np.abs(base - steady(1.0, 0.2, 0.7, 1.8, UNDAMPED if machine == "undamped" else None)).max() > 1e-2
    np.testing.assert_allclose(got, base + np.array([offset, 0.0, 0.0, 0.0]), rtol=1e-9, atol=1e-9)


def speed_offset_miss(unzipped, offset: float, h: float, seconds: float = 1.2) -> float:
    """Max over the run of |x_B(t) - (x_A(t) + offset (t, 1, 0, 0))| of an undamped machine: A starts
    at omega0 = 0.5 under theta_vs = 0.2 + 0.5 t, B at omega0 = 0.5 + offset under theta_vs = 0.2 +
    (0.5 + offset) t, both held over steps of h (inputs set in initialization mode)."""
    n = int(round(seconds / h))
    x0 = steady(1.0, 0.2, 0.7, 1.8, UNDAMPED) + np.array([0.05, 0.5, 0.0, 0.0])
    dip = (int(round(0.3 / h)), int(round(0.4 / h)))
    a = fmu_states(unzipped, x0, drifting(n, h, 0.2, 0.5, 0.7, 1.8, dip, 0.8), "a")
    b = fmu_states(unzipped, x0 + np.array([0.0, offset, 0.0, 0.0]),
                   drifting(n, h, 0.2, 0.5 + offset, 0.7, 1.8, dip, 0.8), "b")
    t = h * np.arange(1, n + 1)
    return float(np.abs(b - a - offset * np.stack([t, np.ones(n), 0 * t, 0 * t], axis=1)).max())


@pytest.mark.parametrize("offset", [12.0, -12.0])
def test_a_speed_offset_of_an_undamped_machine_is_a_symmetry_as_the_steps_shrink(undamped, offset):
    """The network turning `offset` [rad/s] faster (omega0 and the speed of theta_vs, D = 0): under a
    zero-order-hold master this is not an exact symmetry (the held angle stands still for a step while
    the frame turns, a sawtooth of offset h, which the reference sees too; and a window rolled over at
    a communication point takes its angle origin from the step before). Pins: the FMU's states miss
    the shifted ones by an amount of first order in h and nothing else (halved with the step, from 2
    to 1 to 0.5 ms; a part independent of h, such as a wrong speed or torque in the frame, would not
    halve), through a rollover and the restarts at a dip. The size of the miss is the tiny network's
    sensitivity to the sawtooth, not a property of the FMU."""
    misses = [speed_offset_miss(undamped, offset, h) for h in (0.002, 0.001, 0.0005)]
    assert 0.45 < misses[1] / misses[0] < 0.55 and 0.45 < misses[2] / misses[1] < 0.55, misses


@pytest.fixture(scope="module")
def without_trunk(operator_path, tmp_path_factory):
    """(onnx path, extracted FMU) of a hand-made operator whose sensors enter through one dense layer
    but whose answer does not split into trunk and coefficients (t multiplies the branch's sum
    directly): the FMU's kernel then tracks the sensor layer's output alone (OPFMU_TRUNK_SIZE 0).
    x = x0 + t sum_i(b_i / 10) b, b = tanh(W [x0, u] + c); the tiny operator's metadata and frame."""
    directory = tmp_path_factory.mktemp("without_trunk")
    operator_without_trunk(operator_path, directory / "op.onnx", "without_trunk")
    path = built(directory / "op.onnx", "WithoutTrunk")
    assert "OPFMU_TRUNK_SIZE 0" in zipfile.ZipFile(path).read("sources/config.h").decode()
    return directory / "op.onnx", (extract(str(path)), read_model_description(str(path)))


@pytest.mark.parametrize("speed", [3.0, 0.0])
def test_the_fmu_equals_the_mirror_on_a_kernel_without_a_trunk(without_trunk, speed):
    """The same semantics where the FMU keeps the sensor buffer and the sensor layer's output instead
    of coefficients: held inputs, then a change, then held again, in a frame turning at `speed`."""
    onnx_path, unzipped = without_trunk
    mirror = StepMirror(onnx_path)
    x0 = steady() + np.array([0.0, speed, 0.0, 0.0])
    steps = held(20, 0.01) + held(20, 0.01, 0.9, 0.1, 0.7, 1.2) + held(20, 0.02, 0.9, 0.1, 0.7, 1.2)
    got = run_fmu(unzipped, steps, **initial(x0))
    np.testing.assert_allclose(got, mirror.run(x0, steps, **fmu_settings(unzipped[1])), rtol=2e-5, atol=2e-5)
