"""The native surrogate FMU under fmpy: FMI 2.0 behaviour and the step semantics of DESIGN section 5."""
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
from fmu_slave import Slave
from reference_models.signals import Piecewise, Signal
from reference_models.simulate import simulate
from reference_models.sm4 import SM4, min_voltage_with_equilibrium, steady_state
from surrogate.operator import DEFAULT_OPERATOR, Operator


@pytest.fixture(scope="session")
def unzipped(fmu_path):
    return extract(str(fmu_path)), read_model_description(str(fmu_path))


@pytest.fixture(scope="session")
def settings(unzipped):
    """The FMU's defaults of the settings the step mirror takes (rest_radius, slow_weight, ...)."""
    return fmu_settings(unzipped[1])


@pytest.fixture(scope="session")
def mirror():
    return StepMirror(DEFAULT_OPERATOR)


@pytest.fixture
def operator_reference(mirror, settings):
    """States after each (h, Vs, theta) step by the FMU's step semantics in Python (fmu_export.step_mirror,
    onnxruntime), with the FMU's default settings changed by `changes` (its parameters of those names)."""
    def run(x0, steps, **changes):
        return mirror.run(x0, steps, **{**settings, **changes})
    return run


def initial(x0) -> dict:
    """The initial-state parameters {delta0: ..., ...} of a state x0 [4]."""
    return {f"{name}0": float(value) for name, value in zip(SM4.state_names, x0)}


def test_the_mirrors_newton_finds_the_equilibrium_and_its_slow_mode_is_the_slowest_eigenvalue(mirror):
    u = np.array([0.95, 0.1])
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


def test_the_mirror_takes_the_machine_from_the_operators_metadata(tmp_path):
    import onnx

    proto = onnx.load(str(DEFAULT_OPERATOR))
    for entry in proto.metadata_props:
        if entry.key == "params":
            entry.value = json.dumps({"H": 3.01, "D": 0.0})
    onnx.save(proto, str(tmp_path / "other.onnx"))
    assert StepMirror(tmp_path / "other.onnx").params == SM4.params({"H": 3.01, "D": 0.0})
    assert StepMirror(DEFAULT_OPERATOR).params == SM4.params()


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
    rng = np.random.default_rng(0)
    steps = [(0.01, 1.0 + 0.05 * np.sin(k / 7), 0.1 * np.cos(k / 11)) for k in range(60)]
    steps += [(float(h), float(v), float(a)) for h, v, a in
              zip(rng.choice([0.001, 0.004, 0.02, 0.05], 30), rng.uniform(0.9, 1.1, 30), rng.uniform(-0.2, 0.2, 30))]
    slave = Slave(unzipped)
    got = np.array([slave.step(*s) for s in steps])
    slave.close()
    expected = operator_reference(steady_state(1.0, 0.0), steps)
    assert sum(h for h, _, _ in steps) > 1.0  # the run crossed a window boundary
    np.testing.assert_allclose(got, expected, rtol=0, atol=2e-5)


def test_machine_at_rest_under_its_held_input_stays_exactly_at_rest(unzipped):
    slave = Slave(unzipped)
    states = np.array([slave.step(0.01) for _ in range(300)])  # over three windows
    slave.close()
    np.testing.assert_allclose(states, np.tile(steady_state(1.0, 0.0), (300, 1)), rtol=0, atol=1e-6)


def test_without_the_rest_correction_the_machine_at_rest_moves_by_the_operators_error(unzipped, operator_reference):
    slave = Slave(unzipped, rest_radius=0.0)
    states = np.array([slave.step(0.01) for _ in range(300)])
    slave.close()
    np.testing.assert_allclose(states, operator_reference(steady_state(1.0, 0.0), [(0.01, 1.0, 0.0)] * 300,
                                                          rest_radius=0.0), rtol=0, atol=2e-5)
    assert np.abs(states - steady_state(1.0, 0.0)).max() > 1e-5


def test_the_rest_correction_fades_with_the_distance_from_rest(unzipped, operator_reference):
    x0 = steady_state(1.0, 0.0) + np.array([0.1, 0.0, 0.0, 0.02])  # weight 1 - 0.2 = 0.8 at the start
    steps = [(0.01, 1.0, 0.0)] * 120
    slave = Slave(unzipped, **initial(x0))
    got = np.array([slave.step(*step) for step in steps])
    slave.close()
    np.testing.assert_allclose(got, operator_reference(x0, steps), rtol=0, atol=2e-5)
    assert np.abs(got - operator_reference(x0, steps, rest_radius=0.0)).max() > 1e-5


def test_a_negative_rest_radius_is_refused_with_a_reason(unzipped):
    slave = Slave(unzipped, init=False)
    with pytest.raises(FMICallException):
        slave.set(rest_radius=-1.0)
    assert any("rest_radius" in m for _, m in slave.messages)
    slave.fmu.freeInstance()


def fmu_and_rk45(unzipped, x0, signal, steps, **parameters):
    """(FMU states, RK45 states) [n, 4] after each (h, Vs, theta) step from x0; the RK45 reference
    solves under `signal`, the same inputs as functions of time."""
    reference = simulate(x0, signal, np.cumsum([0.0] + [h for h, _, _ in steps]))[1:]
    slave = Slave(unzipped, **initial(x0), **parameters)
    got = np.array([slave.step(*step) for step in steps])
    slave.close()
    return got, reference


def undervoltage_run(unzipped, seconds=15.0, Vs=0.84, **parameters):
    """(FMU states, RK45 states) [n, 4] every 10 ms of a machine held at Vs below the lowest voltage with
    an equilibrium, from the equilibrium at that voltage: it slowly slips (delta rises by 0.14 rad)."""
    steps = [(0.01, Vs, 0.0)] * int(round(seconds / 0.01))
    signal = Signal({"Vs": Piecewise((Vs,), ()), "theta_vs": Piecewise((0.0,), ())})
    return fmu_and_rk45(unzipped, steady_state(min_voltage_with_equilibrium(), 0.0), signal, steps, **parameters)


def test_the_slow_mode_correction_keeps_a_slow_drift_on_the_rk45_solution(unzipped):
    corrected, reference = undervoltage_run(unzipped)
    uncorrected, _ = undervoltage_run(unzipped, slow_weight=0.0)
    error, error_without = np.abs(corrected - reference).max(0), np.abs(uncorrected - reference).max(0)
    assert error[0] < 0.5 * error_without[0] and error[3] < 0.5 * error_without[3]  # delta, Eq_p


def test_slow_weight_zero_is_the_operator_with_the_rest_correction_only(unzipped, operator_reference):
    x0 = steady_state(1.0, 0.0) + np.array([0.1, 0.0, 0.0, 0.02])
    steps = [(0.01, 0.95, 0.05)] * 120
    slave = Slave(unzipped, slow_weight=0.0,
                  **initial(x0))
    got = np.array([slave.step(*step) for step in steps])
    slave.close()
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
    steps = [(0.01, v, a) for n, v, a in levels for _ in range(n)]
    signal = Signal({"Vs": Piecewise((1.0, 0.2, 1.05), (0.3, 0.45)), "theta_vs": Piecewise((0.0, 0.25), (0.3,))})
    return fmu_and_rk45(unzipped, steady_state(1.0, 0.0), signal, steps, **parameters)


def test_the_exact_swing_step_keeps_omega_on_the_rk45_solution_through_a_deep_fault(unzipped):
    corrected, reference = deep_fault_run(unzipped)
    uncorrected, _ = deep_fault_run(unzipped, swing_weight=0.0)
    error, error_without = np.abs(corrected - reference).max(0), np.abs(uncorrected - reference).max(0)
    assert error[1] < 0.5 * error_without[1] and error[1] < 0.005  # omega [rad/s]


def test_swing_weight_zero_leaves_the_operators_omega(unzipped, operator_reference):
    steps = [(0.01, 1.0, 0.0)] * 10 + [(0.01, 0.5, 0.2)] * 30
    slave = Slave(unzipped, swing_weight=0.0)
    got = np.array([slave.step(*step) for step in steps])
    slave.close()
    x0 = steady_state(1.0, 0.0)
    np.testing.assert_allclose(got, operator_reference(x0, steps, swing_weight=0.0), rtol=0, atol=2e-5)
    assert np.abs(got[:, 1] - operator_reference(x0, steps)[:, 1]).max() > 1e-4


def test_rollover_horizon_defaults_to_the_operators_own(unzipped):
    slave = Slave(unzipped)
    horizon = slave.get("rollover_horizon")[0]
    slave.close()
    assert horizon == float(Operator.load(DEFAULT_OPERATOR).metadata["rollover_horizon_s"]) == 0.8


def test_an_input_jump_above_restart_jump_starts_a_new_window_from_the_state_reached(unzipped, operator_reference):
    steps = [(0.01, 1.0, 0.0)] * 30 + [(0.01, 0.6, 0.1)] * 20 + [(0.01, 1.0, 0.1)] * 30
    slave = Slave(unzipped)
    got = np.array([slave.step(*step) for step in steps])
    slave.close()
    x0 = steady_state(1.0, 0.0)
    np.testing.assert_allclose(got, operator_reference(x0, steps), rtol=0, atol=1e-5)
    without = operator_reference(x0, steps, restart_jump=0.0)
    np.testing.assert_allclose(got[:30], without[:30], rtol=0, atol=1e-5)
    assert np.abs(got[30:] - without[30:]).max() > 1e-4


def test_restart_jump_zero_keeps_windows_at_the_rollover_horizon(unzipped, operator_reference):
    steps = [(0.01, 1.0, 0.0)] * 30 + [(0.01, 0.6, 0.1)] * 20
    slave = Slave(unzipped, restart_jump=0.0)
    got = np.array([slave.step(*step) for step in steps])
    slave.close()
    np.testing.assert_allclose(got, operator_reference(steady_state(1.0, 0.0), steps, restart_jump=0.0),
                               rtol=0, atol=1e-5)


def test_a_step_crossing_the_window_boundary_equals_one_split_at_it(unzipped):
    # without the slow-mode correction and the exact swing step, whose integrals depend on how steps are cut
    off = {"slow_weight": 0.0, "swing_weight": 0.0}
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
    slave = Slave(unzipped, rollover_horizon=0.25)
    states = [slave.step(0.05, 0.97, 0.05) for _ in range(20)]
    horizon = slave.get("rollover_horizon")[0]
    slave.close()
    expected = operator_reference(steady_state(1.0, 0.0), [(0.05, 0.97, 0.05)] * 20, rollover_horizon=0.25)
    assert horizon == 0.25
    np.testing.assert_allclose(states, expected, rtol=0, atol=2e-5)


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
    assert slave.step(0.01)[0] == pytest.approx(steady_state(1.0, 0.0)[0], abs=1e-2)  # still usable
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


def test_input_outside_the_envelope_turns_in_envelope_false_and_warns(unzipped):
    slave = Slave(unzipped)
    slave.step(0.01)
    assert slave.get_boolean("in_envelope") is True
    slave.step(0.01, Vs=0.05)
    assert slave.get_boolean("in_envelope") is False
    assert any("left the trained envelope" in m for _, m in slave.messages)
    slave.step(0.01)
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


@pytest.mark.skipif(not __import__("shutil").which("valgrind"), reason="valgrind is not installed")
def test_thousand_instantiate_free_cycles_and_reloads_leak_nothing(unzipped, tmp_path):
    from fmu_export.builder import fmi_headers

    harness = tmp_path / "harness"
    source = __file__.rsplit("/", 1)[0] + "/c/lifecycle_harness.c"
    subprocess.run(["gcc", "-O1", "-g", "-I", str(fmi_headers()), source, "-o", str(harness), "-ldl"], check=True)
    binary = f"{unzipped[0]}/binaries/linux64/SM4Surrogate.so"
    result = subprocess.run(["valgrind", "--leak-check=full", "--errors-for-leak-kinds=definite,indirect,possible",
                             "--error-exitcode=3", str(harness), binary, unzipped[1].guid, "1000", "2"],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr[-3000:]
    assert "ERROR SUMMARY: 0 errors" in result.stderr


def test_build_fmu_command_refuses_a_file_that_is_not_an_operator(tmp_path):
    bogus = tmp_path / "bogus.onnx"
    bogus.write_bytes(b"not onnx at all")
    result = subprocess.run([sys.executable, "-m", "opfmu", "build-fmu", str(bogus), "-o", str(tmp_path / "x.fmu")],
                            capture_output=True, text=True)
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
    assert "not a readable ONNX file" in result.stderr and not (tmp_path / "x.fmu").exists()


def test_build_fmu_command_builds_the_shipped_operator_by_default(tmp_path):
    out = tmp_path / "Machine.fmu"
    result = subprocess.run([sys.executable, "-m", "opfmu", "build-fmu", "-o", str(out), "--name", "Machine"],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "matches onnxruntime" in result.stdout
    assert read_model_description(str(out)).coSimulation.modelIdentifier == "Machine"
    assert "binaries/linux64/Machine.so" in zipfile.ZipFile(out).namelist()
