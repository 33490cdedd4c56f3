"""The reference RK45 FMU (pythonfmu) under fmpy: any machine's ODE, the one variable table, FMI behaviour."""
import json
import subprocess
import sys
import zipfile

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu
from scipy.integrate import solve_ivp

from fmu_export.python_reference_fmu import ReferenceBuildError, build_reference_fmu, reference_variables
from fmu_export.variables import REFERENCE_EXTRAS, fmu_variables
from cosim.fmu import FMU as Slave
from reference_models.component import ParameterError
from reference_models.sm4 import SM4

from machines import wscc9_machine

# (h, Vs, theta_vs, Pm, Efd): a dip at the start operating point, then new bus, mechanical and field levels
STEPS = ([(0.01, 1.0, 0.0, 0.7048, 1.08)] * 5 + [(0.02, 0.6, 0.1, 0.7048, 1.08)] * 10
         + [(0.005, 0.95, 0.25, 0.6, 1.3)] * 40 + [(0.05, 1.05, 0.2, 0.75, 1.0)] * 6)
# WSCC generator 3 as shipped, a machine other than the default: no damping, no external reactance, 60 Hz
MACHINE = wscc9_machine(3)
DEFAULT, OTHER = SM4.params(), SM4.params(MACHINE)


@pytest.fixture(scope="session")
def unzipped(reference_path):
    return extract(str(reference_path)), read_model_description(str(reference_path))


@pytest.fixture(scope="module")
def machine_path(tmp_path_factory):
    """The reference FMU of MACHINE, model name Machine2."""
    path = tmp_path_factory.mktemp("machine") / "Machine2.fmu"
    build_reference_fmu(path, model_name="Machine2", params=MACHINE)
    return path


@pytest.fixture(scope="module")
def machine(machine_path):
    return extract(str(machine_path)), read_model_description(str(machine_path))


def held_input_solution(x0, steps, p=DEFAULT):
    """States after each (h, Vs, theta_vs[, Pm, Efd]) step by solve_ivp (DOP853, tight) with the inputs
    held over the step (an input not given at its start value, as Slave.step sets it)."""
    x, out = np.array(x0, dtype=float), []
    for h, *u in steps:
        u = np.concatenate([u, SM4.start_inputs[len(u):]])
        x = solve_ivp(lambda _t, y: SM4.rhs(y, u, p), (0.0, h), x, method="DOP853", rtol=1e-12, atol=1e-13).y[:, -1]
        out.append(x)
    return np.array(out)


def package_files(fmu_path) -> dict:
    """{file name: bytes} of the model package in the FMU's resources (resources/sm4_reference_*/)."""
    with zipfile.ZipFile(fmu_path) as z:
        names = [n for n in z.namelist() if n.startswith("resources/sm4_reference_")]
        return {n.rsplit("/", 1)[1]: z.read(n) for n in names}


@pytest.mark.parametrize("fixture", ["reference_path", "machine_path"])
def test_fmpy_validation_reports_no_problem(request, fixture):
    assert validate_fmu(str(request.getfixturevalue(fixture))) == []


def test_variables_and_value_references_are_the_tables(unzipped):
    md = unzipped[1]
    got = {v.name: (v.valueReference, v.causality) for v in md.modelVariables}
    assert got == {v.name: (v.vr, v.causality) for v in reference_variables(SM4, DEFAULT)}
    # the component's own variables have the value references every FMU of it has (the surrogate's too)
    core = fmu_variables(SM4, DEFAULT, SM4.steady_state(None, DEFAULT))
    assert all(got[v.name][0] == v.vr for v in core)
    assert [n for n in got if n not in {v.name for v in core}] == [e.name for e in REFERENCE_EXTRAS]
    by_vr = {v.valueReference: v.name for v in md.modelVariables}
    deps = {by_vr[o.variable.valueReference]: [d.name for d in o.dependencies] for o in md.outputs}
    assert all(deps[s] == [] for s in SM4.state_names) and deps["P"] == ["Vs", "theta_vs"]
    starts = {v.name: v.start for v in md.modelVariables}
    assert [float(starts[n]) for n in SM4.input_names] == [1.0, 0.0, 0.7048, 1.08]  # Table I's operating point


def test_fmu_carries_the_model_code_and_the_machine_it_runs(reference_path, machine_path):
    files = package_files(reference_path)
    assert {"sm4.py", "component.py", "slave.py", "machine.json", "fmu.json", "__init__.py"} <= set(files)
    assert "binaries/linux64/SM4Reference.so" in zipfile.ZipFile(reference_path).namelist()
    assert json.loads(files["machine.json"]) == DEFAULT.to_dict()
    assert json.loads(package_files(machine_path)["machine.json"]) == OTHER.to_dict()
    layout = json.loads(files["fmu.json"])
    assert [v["name"] for v in layout["variables"]] == [v.name for v in reference_variables()]


def test_default_initial_state_is_that_machines_equilibrium(unzipped, machine):
    for fmu, p in ((unzipped, DEFAULT), (machine, OTHER)):
        rest = SM4.steady_state(None, p)
        starts = {v.name: float(v.start) for v in fmu[1].modelVariables if v.start is not None}
        np.testing.assert_allclose([starts[f"{s}0"] for s in SM4.state_names], rest, rtol=0, atol=1e-12)
        slave = Slave(fmu)
        np.testing.assert_allclose(slave.state(), rest, rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.abs(SM4.rhs(slave.state(), SM4.start_inputs, p)), 0, atol=1e-9)
        np.testing.assert_allclose(slave.step(0.05), rest, rtol=0, atol=1e-9)  # at rest, it stays there
        slave.close()
    assert np.abs(SM4.steady_state(None, OTHER) - SM4.steady_state(None, DEFAULT)).max() > 0.01


def test_states_equal_a_direct_solve_with_the_inputs_held_over_each_step(unzipped):
    slave = Slave(unzipped)
    got = np.array([slave.step(*step) for step in STEPS])
    slave.close()
    np.testing.assert_allclose(got, held_input_solution(SM4.steady_state(None, DEFAULT), STEPS), rtol=0, atol=1e-6)


def test_another_machine_runs_its_own_equations(machine):
    x0 = SM4.steady_state(None, OTHER)
    slave = Slave(machine)
    got = np.array([slave.step(*step) for step in STEPS])
    slave.close()
    np.testing.assert_allclose(got, held_input_solution(x0, STEPS, OTHER), rtol=0, atol=1e-6)
    assert np.abs(got - held_input_solution(x0, STEPS, DEFAULT)).max() > 1e-2  # the machine matters


@pytest.mark.parametrize("which", ["default", "other"])
def test_derived_outputs_follow_the_inputs_set_after_a_step(unzipped, machine, which):
    fmu, p = (unzipped, DEFAULT) if which == "default" else (machine, OTHER)
    slave = Slave(fmu)
    x = slave.step(0.01, 0.9, 0.1)
    slave.set(Vs=0.8, theta_vs=-0.2, Pm=0.5, Efd=1.5)
    got = slave.get(*SM4.output_names)
    slave.close()
    u = np.array([0.8, -0.2, 0.5, 1.5])
    np.testing.assert_allclose(got, SM4.output_values(x, u, p), rtol=1e-12, atol=1e-12)
    other = DEFAULT if p is OTHER else OTHER
    assert np.abs(got - SM4.output_values(x, u, other)).max() > 1e-3


def test_initial_state_parameters_start_the_run(unzipped):
    x0 = SM4.steady_state((0.95, 0.1, 0.7048, 1.08), DEFAULT)
    start = dict(zip(SM4.state_names, x0), omega=0.05)
    slave = Slave(unzipped, **{f"{n}0": v for n, v in start.items()})
    np.testing.assert_allclose(slave.state(), list(start.values()))
    got = slave.step(0.01, 0.95, 0.1)
    slave.close()
    np.testing.assert_allclose(got, held_input_solution(list(start.values()), [(0.01, 0.95, 0.1)])[0],
                               rtol=0, atol=1e-6)


def test_fmus_of_two_machines_live_side_by_side_in_one_process(unzipped, machine):
    a, b = Slave(unzipped, "default"), Slave(machine, "other")
    xa, xb = a.step(0.02, 0.9, 0.1), b.step(0.02, 0.9, 0.1)
    a.close(), b.close()
    np.testing.assert_allclose(xa, held_input_solution(SM4.steady_state(None, DEFAULT), [(0.02, 0.9, 0.1)])[0],
                               atol=1e-6)
    np.testing.assert_allclose(xb, held_input_solution(SM4.steady_state(None, OTHER), [(0.02, 0.9, 0.1)], OTHER)[0],
                               atol=1e-6)


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


def with_machine_resource(fmu_path, out, content):
    """A copy of the FMU whose machine.json holds `content` (bytes), or lacks it (None)."""
    with zipfile.ZipFile(fmu_path) as source, zipfile.ZipFile(out, "w") as target:
        for info in source.infolist():
            if info.filename.endswith("/machine.json"):
                if content is None:
                    continue
                target.writestr(info, content)
            else:
                target.writestr(info, source.read(info))
    return out


@pytest.mark.parametrize("content, reason", [
    (None, "cannot read machine file"),
    (b"{not json", "cannot read machine file"),
    (b'{"H": -1}', "parameter H = -1.0 must be > 0"),
    (b'{"inertia": 5}', "unknown sm4 parameter(s) 'inertia'"),
])
def test_a_missing_or_corrupt_machine_resource_is_refused_with_a_reason(machine_path, tmp_path, content, reason):
    broken = with_machine_resource(machine_path, tmp_path / "Machine2.fmu", content)
    slave = Slave((extract(str(broken)), read_model_description(str(broken))), logging_on=True)
    with pytest.raises(FMICallException):
        slave.step(0.01)
    errors = [m for status, m in slave.messages if status == 3]  # fmi2Error
    assert errors and all("cannot start the reference FMU" in m for m in errors)
    assert any(reason in m for m in errors)
    assert np.isnan(slave.state()).all()  # no machine, no made-up state
    slave.close()


def test_the_builder_refuses_an_unknown_parameter_and_a_machine_without_equilibrium(tmp_path):
    with pytest.raises(ParameterError, match="unknown sm4 parameter"):
        build_reference_fmu(tmp_path / "x.fmu", params={"inertia": 5.0})
    with pytest.raises(ParameterError, match="unknown sm4 parameter\\(s\\) 'Pm'"):  # an input, no parameter
        build_reference_fmu(tmp_path / "x.fmu", params={"Pm": 0.7})
    with pytest.raises(ReferenceBuildError, match="no equilibrium at the start inputs"):  # behind a 2 pu line
        build_reference_fmu(tmp_path / "x.fmu", params={"Xep": 2.0})
    with pytest.raises(ValueError, match="Python identifier"):
        build_reference_fmu(tmp_path / "x.fmu", model_name="not-a-name")
    assert not (tmp_path / "x.fmu").exists()


def test_load_free_load_cycles_in_one_process_do_not_crash(reference_path, machine_path, tmp_path):
    script = f"""
import sys
for name in ("reference_models", "fmu_export", "surrogate", "opfmu"):
    sys.modules[name] = None  # the FMU must not need the repository's code
from fmpy import simulate_fmu
for k in range(3):
    result = simulate_fmu({str(reference_path)!r}, stop_time=0.05, output_interval=0.01)
    other = simulate_fmu({str(machine_path)!r}, stop_time=0.05, output_interval=0.01)
print(result["delta"][-1], other["delta"][-1])
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    got = [float(v) for v in done.stdout.split()[-2:]]
    np.testing.assert_allclose(got, [SM4.steady_state(None, DEFAULT)[0], SM4.steady_state(None, OTHER)[0]],
                               rtol=0, atol=1e-9)


def test_three_hundred_instantiations_in_one_process_do_not_crash(reference_path, machine_path, tmp_path):
    # pythonfmu's binary releases a reference it never took at every instantiation (the slave's
    # _NAMESPACE_REFERENCES balances it): without that, a few instantiations in one process crash
    script = f"""
import sys
sys.path.insert(0, {str(__file__.rsplit('/', 1)[0])!r})
from fmpy import extract, read_model_description
from cosim.fmu import FMU as Slave
fmus = [(extract(p), read_model_description(p)) for p in ({str(reference_path)!r}, {str(machine_path)!r})]
for k in range(300):
    slave = Slave(fmus[k % 2], f"i{{k}}")
    last = slave.step(0.01)[0]
    slave.close()
print(last)
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    assert abs(float(done.stdout.split()[-1]) - SM4.steady_state(None, OTHER)[0]) < 1e-9


def test_the_linux64_binary_returns_at_once_from_pythonfmus_exit_release(reference_path):
    """pythonfmu's finalizePythonInterpreter releases its state a second time at process exit (a
    use-after-free); the builder makes it return at once, and a binary already changed, or any
    function that does not start as the known build's, is refused rather than patched again."""
    from fmu_export.pythonfmu_exit import KNOWN_PROLOGUE, SYMBOL, ExitPatchError, _symbol_offset, without_exit_release

    with zipfile.ZipFile(reference_path) as fmu:
        binary = fmu.read(next(n for n in fmu.namelist() if n.startswith("binaries/linux64/") and n.endswith(".so")))
    offset = _symbol_offset(binary, SYMBOL)
    assert offset is not None
    assert binary[offset:offset + len(KNOWN_PROLOGUE)] == KNOWN_PROLOGUE[:-1] + b"\xc3"
    with pytest.raises(ExitPatchError, match="not the known build"):
        without_exit_release(binary)
    assert without_exit_release(b"\x7fELF\x02\x01" + bytes(0x3A)) == b"\x7fELF\x02\x01" + bytes(0x3A)
