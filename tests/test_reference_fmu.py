"""The reference RK45 FMU (pythonfmu) under fmpy: the same ODE, the same variables, FMI behaviour."""
import subprocess
import sys
import zipfile

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu
from scipy.integrate import solve_ivp

from fmu_slave import STATES, Slave
from reference_models.sm4 import outputs, rhs, steady_state

STEPS = [(0.01, 1.0, 0.0)] * 5 + [(0.02, 0.6, 0.1)] * 10 + [(0.005, 0.95, 0.25)] * 40 + [(0.05, 1.05, 0.2)] * 6


@pytest.fixture(scope="session")
def unzipped(reference_path):
    return extract(str(reference_path)), read_model_description(str(reference_path))


def held_input_solution(x0, steps):
    """States after each (h, Vs, theta) step by solve_ivp with the inputs held over the step."""
    x, out = np.array(x0, dtype=float), []
    for h, Vs, theta in steps:
        u = np.array([Vs, theta])
        x = solve_ivp(lambda _t, y: rhs(y, u), (0.0, h), x, method="DOP853", rtol=1e-12, atol=1e-13).y[:, -1]
        out.append(x)
    return np.array(out)


def test_fmpy_validation_reports_no_problem(reference_path):
    assert validate_fmu(str(reference_path)) == []


def test_variables_and_value_references_match_the_surrogate_less_its_diagnostics(unzipped):
    md = unzipped[1]
    names = {v.name: v.valueReference for v in md.modelVariables}
    assert names == {"Vs": 0, "theta_vs": 1, "delta": 2, "omega": 3, "Ed_p": 4, "Eq_p": 5, "Id": 6, "Iq": 7,
                     "I_re": 8, "I_im": 9, "P": 10, "Q": 11, "delta0": 12, "omega0": 13, "Ed_p0": 14,
                     "Eq_p0": 15, "rtol": 16, "atol": 17}
    deps = {md.modelVariables[o.variable.valueReference].name: [d.name for d in o.dependencies] for o in md.outputs}
    assert deps["delta"] == [] and deps["P"] == ["Vs", "theta_vs"]


def test_fmu_carries_the_model_code_it_runs(reference_path):
    names = zipfile.ZipFile(reference_path).namelist()
    assert {"resources/sm4_reference/sm4.py", "resources/sm4_reference/slave.py",
            "binaries/linux64/SM4Reference.so"} <= set(names)


def test_states_equal_a_direct_solve_with_the_inputs_held_over_each_step(unzipped):
    slave = Slave(unzipped)
    got = np.array([slave.step(*step) for step in STEPS])
    slave.close()
    np.testing.assert_allclose(got, held_input_solution(steady_state(1.0, 0.0), STEPS), rtol=0, atol=1e-6)


def test_derived_outputs_follow_the_inputs_set_after_a_step(unzipped):
    slave = Slave(unzipped)
    x = slave.step(0.01, 0.9, 0.1)
    slave.fmu.setReal([0, 1], [0.8, -0.2])
    got = slave.fmu.getReal([6, 7, 8, 9, 10, 11])
    slave.close()
    np.testing.assert_allclose(got, outputs(x, np.array([0.8, -0.2])), rtol=1e-12, atol=1e-12)


def test_initial_state_parameters_start_the_run(unzipped):
    x0 = steady_state(0.95, 0.1)
    slave = Slave(unzipped, delta0=x0[0], omega0=0.05, Ed_p0=x0[2], Eq_p0=x0[3])
    np.testing.assert_allclose(slave.fmu.getReal(STATES), [x0[0], 0.05, x0[2], x0[3]])
    got = slave.step(0.01, 0.95, 0.1)
    slave.close()
    np.testing.assert_allclose(got, held_input_solution([x0[0], 0.05, x0[2], x0[3]], [(0.01, 0.95, 0.1)])[0],
                               rtol=0, atol=1e-6)


@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_non_finite_input_is_refused_with_a_reason_logged_when_logging_is_on(unzipped, value):
    slave = Slave(unzipped, logging_on=True)  # pythonfmu passes messages on only with logging on
    with pytest.raises(FMICallException):
        slave.step(0.01, value)
    assert any("non-finite value: Vs" in m for _, m in slave.messages)
    slave.close()


def test_non_positive_step_is_refused_with_a_reason_logged_when_logging_is_on(unzipped):
    slave = Slave(unzipped, logging_on=True)
    with pytest.raises(FMICallException):
        slave.step(0.0)
    assert any("step size must be positive" in m for _, m in slave.messages)
    slave.close()


def test_load_free_load_cycles_in_one_process_do_not_crash(reference_path, tmp_path):
    script = f"""
import sys
sys.modules["reference_models"] = None  # the FMU must not need the repository's model code
from fmpy import simulate_fmu
for k in range(3):
    result = simulate_fmu({str(reference_path)!r}, stop_time=0.05, output_interval=0.01)
print(result["delta"][-1])
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    assert abs(float(done.stdout.split()[-1]) - steady_state(1.0, 0.0)[0]) < 1e-9


def test_serialized_state_restored_in_a_fresh_process_continues_the_run(unzipped, tmp_path):
    slave = Slave(unzipped)
    for _ in range(20):
        slave.step(0.01, 0.95, -0.1)
    state, t_saved = slave.fmu.getFMUstate(), slave.t
    (tmp_path / "state.bin").write_bytes(bytes(slave.fmu.serializeFMUstate(state)))
    expected = [slave.step(0.01, 1.02, 0.0) for _ in range(20)]
    slave.close()
    script = f"""
import numpy as np, sys
sys.path.insert(0, {str(__file__.rsplit('/', 1)[0])!r})
from fmu_slave import Slave
from fmpy import read_model_description
slave = Slave(({str(unzipped[0])!r}, read_model_description({str(unzipped[0])!r})))
slave.fmu.setFMUstate(slave.fmu.deSerializeFMUstate(open({str(tmp_path / 'state.bin')!r}, 'rb').read()))
slave.t = {t_saved!r}
np.save({str(tmp_path / 'out.npy')!r}, np.array([slave.step(0.01, 1.02, 0.0) for _ in range(20)]))
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    np.testing.assert_array_equal(np.load(tmp_path / "out.npy"), expected)
