"""The native reference FMU (Dormand-Prince 5(4) in C) under fmpy and under a C importer: accuracy
against an independent solver, input derivatives, solver refusals, FMI behaviour, leaks and fuzzing."""
import math
import shutil
import subprocess
import zipfile
from xml.etree import ElementTree

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu
from scipy.integrate import solve_ivp

from fmu_export.binaries import fmi_headers
from fmu_export.native_reference_fmu import (SOLVER_STARTS, NativeReferenceError, build_native_reference_fmu,
                                         native_reference_variables)
from fmu_export.python_reference_fmu import reference_variables
from fmu_export.variables import BUS_OUTPUTS, rate_unit
from cosim.fmu import FMU as Slave
from reference_models.models.genrou import GENROU
from reference_models.ports import ports_of_model_description
from reference_models.scenarios import scenario
from reference_models.sm4 import SM4

from machines import wscc9_machine

# WSCC generator 3 as shipped, a machine other than the default: no damping, no external reactance, 60 Hz
MACHINE = wscc9_machine(3)
DEFAULT, OTHER = SM4.params(), SM4.params(MACHINE)
HARNESSES = __file__.rsplit("/", 1)[0] + "/c"


@pytest.fixture(scope="module")
def other_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("native_other") / "Machine2.fmu"
    build_native_reference_fmu(path, model_name="Machine2", params=MACHINE)
    return path


@pytest.fixture(scope="module")
def unzipped(native_reference_path):
    return extract(str(native_reference_path)), read_model_description(str(native_reference_path))


@pytest.fixture(scope="module")
def other(other_path):
    return extract(str(other_path)), read_model_description(str(other_path))


def binary(fmu) -> str:
    return f"{fmu[0]}/binaries/linux64/{fmu[1].coSimulation.modelIdentifier}.so"


def held_solution(x0, inputs, h, p):
    """States after each step of length h by scipy's DOP853 (rtol = atol = 1e-11) with the input
    row inputs[k] held over step k: an independent solver of the component's equations."""
    x, out = np.array(x0, dtype=float), []
    for u in inputs:
        u = tuple(float(v) for v in u)
        x = solve_ivp(lambda _t, y: SM4.derivatives(y.tolist(), u, p, math), (0.0, h), x, method="DOP853",
                      rtol=1e-11, atol=1e-11).y[:, -1]
        out.append(x)
    return np.array(out)


def run(fmu, x0, inputs, h, **start):
    slave = Slave(fmu, **{f"{n}0": float(v) for n, v in zip(SM4.state_names, x0)}, **start)
    got = np.array([slave.step(h, *u) for u in inputs])
    slave.close()
    return got


@pytest.mark.parametrize("fixture", ["native_reference_path", "other_path"])
def test_fmpy_validation_reports_no_problem(request, fixture):
    assert validate_fmu(str(request.getfixturevalue(fixture))) == []


def test_binary_needs_libc_and_libm_only_and_exports_only_fmi_functions(unzipped):
    needed = subprocess.run(["readelf", "-d", binary(unzipped)], capture_output=True, text=True, check=True).stdout
    libraries = {line.split("[")[1].rstrip("]") for line in needed.splitlines() if "(NEEDED)" in line}
    assert libraries <= {"libc.so.6", "libm.so.6"}
    symbols = subprocess.run(["nm", "-D", "--defined-only", binary(unzipped)], capture_output=True, text=True,
                             check=True).stdout.split()
    assert [s for s in symbols[2::3] if not s.startswith("fmi2")] == []


def test_fmu_carries_its_sources_and_machine(native_reference_path, other_path):
    names = zipfile.ZipFile(native_reference_path).namelist()
    assert {"sources/dopri5.c", "sources/reference_model.c", "sources/fmi2_cs.c", "sources/equations.c",
            "sources/derivatives.c", "resources/machine.json", "binaries/linux64/SM4Reference.so"} <= set(names)
    assert "binaries/linux64/Machine2.so" in zipfile.ZipFile(other_path).namelist()


def test_variables_and_value_references_are_the_reference_fmus(unzipped):
    md = unzipped[1]
    got = [(v.name, v.valueReference, v.causality) for v in md.modelVariables]
    python = [(v.name, v.vr, v.causality) for v in reference_variables(SM4, DEFAULT)]
    # the pythonfmu reference's table, the bus port's outputs, the start from the load flow, the
    # parameters, Model Exchange's state derivatives (SM4 has no switching functions: no event indicators)
    assert got[:len(python)] == python
    start = ["V_lf", "theta_lf", "P_lf", "Q_lf", "Pm_init", "Efd_init"]
    assert [name for name, _, _ in got[len(python):]] == [name for name, _ in BUS_OUTPUTS] + start \
        + list(DEFAULT.to_dict()) + [f"der({name})" for name in SM4.state_names]
    assert got == [(v.name, v.vr, v.causality) for v in native_reference_variables(SM4, DEFAULT)]
    starts = {v.name: float(v.start) for v in md.modelVariables if v.start is not None}
    assert starts["rtol"] == SOLVER_STARTS["rtol"] <= 1e-8 and starts["atol"] == SOLVER_STARTS["atol"] <= 1e-10
    assert [starts[n] for n in SM4.input_names] == [1.0, 0.0, 0.7048, 1.08]  # the operating point of Table I
    assert md.coSimulation.canInterpolateInputs and md.coSimulation.providesDirectionalDerivative
    by_vr = {v.valueReference: v.name for v in md.modelVariables}
    deps = {by_vr[o.variable.valueReference]: [d.name for d in o.dependencies] for o in md.outputs}
    assert all(deps[s] == [] for s in SM4.state_names) and deps["P"] == ["Vs", "theta_vs"]


def test_the_speed_in_pu_is_one_plus_omega_over_wb_and_means_what_a_standard_machines_omega_does(unzipped, other):
    for fmu, p in ((unzipped, DEFAULT), (other, OTHER)):
        root = ElementTree.parse(f"{fmu[0]}/modelDescription.xml").getroot()
        linked = ports_of_model_description(root).output("rotor_speed")
        units = {v.name: v.unit for v in fmu[1].modelVariables}
        # a governor or stabiliser linked to SM4 gets what GENROU gives it: pu, 1 at synchronous speed
        assert linked == "rotor_speed" and units[linked] == "pu" == {q.name: q.unit for q in GENROU.states}["omega"]
        slave = Slave(fmu)
        assert slave.get("rotor_speed")[0] == 1.0  # at rest
        Vs, theta_vs, Pm, Efd = slave.get(*SM4.input_names)
        speeds = []
        for k in range(50):  # a voltage dip and more mechanical power: the machine speeds up
            slave.step(0.01, 0.8 if k < 10 else Vs, theta_vs, Pm + 0.2, Efd)
            speeds.append(slave.get("omega", "rotor_speed"))
        omega, in_pu = np.array(speeds).T
        assert np.abs(omega).max() > 0.05  # rad/s
        np.testing.assert_allclose(in_pu, 1.0 + omega / p.Wb, rtol=0, atol=1e-15)
        slave.close()


def test_each_state_derivative_declares_its_states_unit_per_second(unzipped):
    units = {v.name: v.unit for v in unzipped[1].modelVariables}
    assert [units[f"der({n})"] for n in SM4.state_names] == ["rad/s", "rad/s2", "pu/s", "pu/s"]
    root = ElementTree.parse(f"{unzipped[0]}/modelDescription.xml").getroot()
    assert root.find("UnitDefinitions/Unit[@name='rad/s2']/BaseUnit").attrib == {"rad": "1", "s": "-2"}
    assert (rate_unit("s"), rate_unit("1"), rate_unit("-")) == ("1", "1/s", "1/s")  # a timer's rate: 1


def test_default_initial_state_is_that_machines_equilibrium_and_stays_at_rest(unzipped, other):
    for fmu, p in ((unzipped, DEFAULT), (other, OTHER)):
        rest = SM4.steady_state(None, p)
        slave = Slave(fmu)
        np.testing.assert_allclose(slave.state(), rest, rtol=0, atol=1e-12)
        for _ in range(100):
            x = slave.step(0.05)
        np.testing.assert_allclose(x, rest, rtol=0, atol=1e-10)
        slave.close()


@pytest.mark.parametrize("machine", ["default", "other"])
@pytest.mark.parametrize("name", ["dip", "mix", "step", "governor", "drift"])
def test_states_agree_with_dop853_on_60_s_of_held_inputs(unzipped, other, name, machine):
    fmu, p = (unzipped, DEFAULT) if machine == "default" else (other, OTHER)
    h, s = 0.01, scenario(name, 0, 60.0, params=p)
    inputs = s.inputs(np.arange(6000) * h)
    got = run(fmu, s.initial_state(), inputs, h)
    worst = np.abs(got - held_solution(s.initial_state(), inputs, h, p)).max(axis=0)
    assert worst.max() < 1e-8, dict(zip(SM4.state_names, worst))


def test_the_pythonfmu_reference_agrees_with_dop853_too(reference_path):
    fmu = extract(str(reference_path)), read_model_description(str(reference_path))
    h, s = 0.01, scenario("mix", 1, 10.0)
    inputs = s.inputs(np.arange(1000) * h)
    got = run(fmu, s.initial_state(), inputs, h)
    assert np.abs(got - held_solution(s.initial_state(), inputs, h, DEFAULT)).max() < 1e-8


def test_inputs_are_linear_over_a_step_where_their_derivatives_are_set(unzipped):
    slave = Slave(unzipped)
    refs = [slave.vr[n] for n in SM4.input_names]
    x, got, expected = slave.state(), [], []
    for u, du in [((0.9, 0.1, 0.75, 1.1), (2.0, -3.0, 0.4, -1.0)), ((1.1, -0.2, 0.65, 1.2), (-1.5, 0.5, -0.6, 2.0)),
                  ((0.95, 0.0, 0.7048, 1.08), (0.0, 0.0, 0.0, 0.0))]:
        slave.fmu.setRealInputDerivatives(refs, [1] * len(refs), list(du))
        got.append(slave.step(0.05, *u))
        x = solve_ivp(lambda t, y: SM4.derivatives(y.tolist(), [a + b * t for a, b in zip(u, du)], DEFAULT, math),
                      (0.0, 0.05), x, method="DOP853", rtol=1e-12, atol=1e-12).y[:, -1]
        expected.append(x)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9)
    held = Slave(unzipped, "held")  # without derivatives: another answer
    assert np.abs(held.step(0.05, 0.9, 0.1, 0.75, 1.1) - got[0]).max() > 1e-4
    held.close()
    slave.close()


def test_inputs_are_quadratic_over_a_step_where_their_second_derivatives_are_set(unzipped):
    slave = Slave(unzipped)
    refs = [slave.vr[n] for n in SM4.input_names]
    u, du, d2u = (0.9, 0.1, 0.75, 1.1), (2.0, -3.0, 0.4, -1.0), (-30.0, 40.0, 8.0, -20.0)
    slave.fmu.setRealInputDerivatives(refs, [1] * len(refs), list(du))
    slave.fmu.setRealInputDerivatives(refs, [2] * len(refs), list(d2u))
    x0 = slave.state()
    got = slave.step(0.05, *u)
    expected = solve_ivp(lambda t, y: SM4.derivatives(y.tolist(), [a + b * t + 0.5 * c * t * t
                                                                  for a, b, c in zip(u, du, d2u)], DEFAULT, math),
                         (0.0, 0.05), x0, method="DOP853", rtol=1e-12, atol=1e-12).y[:, -1]
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9)
    ends = [a + 0.05 * (b + 0.5 * c * 0.05) for a, b, c in zip(u, du, d2u)]  # the inputs at the step's end
    np.testing.assert_allclose(slave.get(*SM4.input_names), ends, rtol=0, atol=1e-15)
    slave.close()


def test_after_a_step_with_input_derivatives_the_inputs_are_those_at_its_end(unzipped):
    slave = Slave(unzipped)
    slave.fmu.setRealInputDerivatives([slave.vr["Vs"]], [1], [-2.0])
    slave.set(Vs=0.9)
    slave.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.01)
    assert slave.get("Vs")[0] == pytest.approx(0.88, abs=1e-15)
    y = slave.get(*SM4.output_names)
    u = np.array([0.88, 0.0, *SM4.start_inputs[2:]])
    np.testing.assert_allclose(y, SM4.output_values(slave.state(), u, DEFAULT), atol=1e-14)
    slave.fmu.doStep(currentCommunicationPoint=0.01, communicationStepSize=0.01)  # the derivative still holds
    assert slave.get("Vs")[0] == pytest.approx(0.86, abs=1e-15)
    slave.close()


@pytest.mark.parametrize("vr_name, order, value, reason", [
    ("delta", 1, 1.0, "is not an input"), ("Vs", 3, 1.0, "derivatives of order 1 and 2 are supported"),
    ("Vs", 1, float("nan"), "not a finite number"), ("rtol", 1, 1.0, "is not an input")])
def test_bad_input_derivatives_are_refused_with_a_reason(unzipped, vr_name, order, value, reason):
    slave = Slave(unzipped)
    with pytest.raises(FMICallException):
        slave.fmu.setRealInputDerivatives([slave.vr[vr_name]], [order], [value])
    assert any(reason in m for _, m in slave.messages)
    slave.close()


def test_an_input_derivative_that_would_take_vs_below_zero_refuses_the_step(unzipped):
    slave = Slave(unzipped)
    slave.set(Vs=0.1)
    slave.fmu.setRealInputDerivatives([slave.vr["Vs"]], [1], [-20.0])
    with pytest.raises(FMICallException):
        slave.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.01)
    assert any("below its lower bound" in m for _, m in slave.messages)
    slave.fmu.freeInstance()


def test_tolerances_are_parameters_and_looser_ones_move_the_answer_within_them(unzipped):
    h, s = 0.01, scenario("dip", 2, 3.0)
    inputs = s.inputs(np.arange(300) * h)
    tight = run(unzipped, s.initial_state(), inputs, h)
    loose = run(unzipped, s.initial_state(), inputs, h, rtol=1e-5, atol=1e-7)
    assert 1e-9 < np.abs(loose - tight).max() < 1e-3


@pytest.mark.parametrize("name, value", [("rtol", 0.0), ("rtol", 1e-16), ("rtol", 1.0), ("atol", 0.0),
                                         ("atol", -1e-9), ("rtol", float("nan"))])
def test_unusable_tolerances_are_refused_with_a_reason(unzipped, name, value):
    slave = Slave(unzipped, init=False)
    slave.fmu.setupExperiment(startTime=0.0)
    slave.fmu.enterInitializationMode()
    with pytest.raises(FMICallException):
        slave.set(**{name: value})
    assert any(name in m or "not a finite number" in m for _, m in slave.messages)
    slave.fmu.freeInstance()


def test_a_step_the_solver_cannot_complete_is_an_error_with_the_reason_and_keeps_the_state(unzipped):
    # a state whose rate overflows: non-finite
    slave = Slave(unzipped, Ed_p0=1e200, Eq_p0=1e200)
    before = slave.state()
    with pytest.raises(FMICallException):
        slave.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.01)
    assert any("Dormand-Prince 5(4) cannot complete the step" in m and "not finite" in m for _, m in slave.messages)
    np.testing.assert_array_equal(slave.state(), before)
    with pytest.raises(FMICallException):  # the FMU is in its error state now, as after any failed step
        slave.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.01)
    slave.fmu.freeInstance()
    # a tolerance the oscillating machine cannot meet in the steps allowed: too many steps
    slave = Slave(unzipped, delta0=0.3, rtol=1e-14, atol=1e-300)
    with pytest.raises(FMICallException):
        slave.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e4)
    assert any("more steps than the limit" in m for _, m in slave.messages)
    slave.fmu.freeInstance()


def refused(slave, call, reason):
    with pytest.raises(FMICallException):
        call()
    assert any(reason in m for _, m in slave.messages), slave.messages


def test_bad_calls_and_values_are_answered_as_the_surrogate_answers_them(unzipped):
    slave = Slave(unzipped)
    refused(slave, lambda: slave.set(Vs=float("nan")), "not a finite number")
    refused(slave, lambda: slave.set(Vs=-0.1), "is below its lower bound")
    refused(slave, lambda: slave.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.0),
            "must be positive")
    refused(slave, lambda: slave.fmu.doStep(currentCommunicationPoint=0.5, communicationStepSize=0.01),
            "is not the FMU's time")
    refused(slave, lambda: slave.set(delta0=0.5), "fixed after initialization")
    refused(slave, lambda: slave.fmu.getReal([99]), "no Real variable with value reference 99")
    refused(slave, lambda: slave.fmu.setReal([slave.vr["P"]], [1.0]), "is not an input or parameter")
    refused(slave, lambda: slave.fmu.deSerializeFMUstate(b"\x00" * 64), "wrong size")
    refused(slave, lambda: slave.fmu.getBoolean([0]), "unknown value reference")
    assert slave.step(0.01)[0] == pytest.approx(SM4.steady_state(None, DEFAULT)[0], abs=1e-12)  # still usable
    slave.close()
    early = Slave(unzipped, init=False)
    refused(early, lambda: early.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.01),
            "fmi2DoStep is not allowed")
    early.fmu.freeInstance()



def test_many_instances_of_two_machines_live_side_by_side(unzipped, other):
    slaves = [Slave(fmu, f"i{k}") for k in range(3) for fmu in (unzipped, other)]
    results = [s.step(0.01, 0.9) for s in slaves]
    for s in slaves:
        s.close()
    assert np.abs(results[0] - results[1]).max() > 1e-3  # each instance runs its own machine
    np.testing.assert_array_equal(results[0], results[2])


@pytest.mark.parametrize("changes, reason", [
    ({"model_name": "1bad"}, "must be a C identifier"), ({"params": {"Xd_p": 2.0}}, "Xd_p"),
    ({"params": {"bogus": 1}}, "unknown sm4 parameter"), ({"params": {"Pm": 0.7}}, "unknown sm4 parameter(s) 'Pm'"),
    # a machine behind a long line (2 pu) cannot deliver the start Pm at the start Efd
    ({"params": {"Xep": 2.0}}, "no equilibrium")])
def test_a_build_that_cannot_be_done_is_a_one_line_error(tmp_path, changes, reason):
    with pytest.raises(NativeReferenceError) as info:
        build_native_reference_fmu(tmp_path / "x.fmu", **changes)
    assert reason in str(info.value) and "\n" not in str(info.value) and isinstance(info.value, ValueError)
    assert not (tmp_path / "x.fmu").exists()


def compile_harness(name, tmp_path):
    out = tmp_path / name
    subprocess.run(["gcc", "-O1", "-g", "-I", str(fmi_headers()), f"{HARNESSES}/{name}.c", "-o", str(out), "-ldl",
                    "-lm"], check=True)
    return out


@pytest.mark.platform_tools("valgrind")
@pytest.mark.skipif(not shutil.which("valgrind"), reason="valgrind is not installed")
def test_thousand_instantiate_free_cycles_and_reloads_leak_nothing(unzipped, tmp_path):
    harness = compile_harness("lifecycle_harness", tmp_path)
    result = subprocess.run(["valgrind", "--leak-check=full", "--errors-for-leak-kinds=definite,indirect,possible",
                             "--error-exitcode=3", str(harness), binary(unzipped), unzipped[1].guid, "1000", "2"],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr[-3000:]
    assert "ERROR SUMMARY: 0 errors" in result.stderr


def test_the_integrator_on_problems_with_known_solutions_and_its_error_codes(tmp_path):
    check = tmp_path / "dopri5_check"
    c_dir = __file__.rsplit("/", 2)[0] + "/fmu_export/c"
    subprocess.run(["gcc", "-O2", "-Wall", "-Werror", "-I", c_dir, f"{HARNESSES}/dopri5_check.c", f"{c_dir}/dopri5.c",
                    "-o", str(check), "-lm"], check=True)
    result = subprocess.run([str(check)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0 and result.stdout.strip() == "ok", result.stdout
