"""FMI 3.0 co-simulation of both native FMUs: the same model code behind another plumbing, so under fmpy
its outputs, FMU states and directional derivatives equal the FMI 2.0 FMU's on the same inputs."""
import json
import shutil
import subprocess
import sys
import zipfile
from xml.etree import ElementTree

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu

from cosim.fmu import FMU
from fmu_export.native_reference_fmu import build_native_reference_fmu
from fmu_export.platforms import PLATFORMS
from surrogate.operator import DEFAULT_OPERATOR
from tests.test_platforms import random_machine

DERIVED = ("Id", "Iq", "I_re", "I_im", "P", "Q")
INPUTS = ("Vs", "theta_vs", "Pm", "Efd")
STATES = ("delta", "omega", "Ed_p", "Eq_p")


def derivatives(instance, unknowns, knowns, seed):
    """The directional derivative of the named outputs along `seed` over the named inputs."""
    u, k = [instance.vr[n] for n in unknowns], [instance.vr[n] for n in knowns]
    return np.array(instance.fmu.getDirectionalDerivative(u, k, list(seed)))


def drive(instance, rng, n=120):
    """Random held input levels at random step sizes (1-25 ms) on a cosim.fmu.FMU; returns the outputs
    after each step."""
    rows = []
    for k in range(n):
        if k % 9 == 0:
            levels = {name: start * (1 + rng.uniform(-0.04, 0.04)) if start else rng.uniform(-0.05, 0.05)
                      for name, start in ((name, instance.starts[name]) for name in instance.inputs)}
        instance.step(float(rng.choice([0.001, 0.004, 0.01, 0.025])), **levels)
        rows.append(instance.get(*STATES, *DERIVED))
    return np.array(rows)


@pytest.fixture(scope="module")
def reference_pair(tmp_path_factory):
    """FMI 2.0 and FMI 3.0 native reference FMUs of one random machine."""
    tmp = tmp_path_factory.mktemp("fmi3_reference")
    params = random_machine(303)
    two, three = tmp / "R2.fmu", tmp / "R3.fmu"
    build_native_reference_fmu(two, model_name="Machine", params=params)
    info = build_native_reference_fmu(three, model_name="Machine", params=params, fmi_version=3)
    return two, three, info


GEN2 = DEFAULT_OPERATOR.parent / "wscc9_gen2.onnx"  # a small shipped operator (201 sensors)


@pytest.fixture(scope="module")
def surrogate_fmi3(fmu_cache):
    """(path, what its build returned) of the FMI 3.0 surrogate FMU of a small shipped operator
    (wscc9_gen2.onnx), with a win64 binary where MinGW-w64 is here (then run under wine at build time
    where wine is); from the run's build cache."""
    from fmu_export.build_cache import build_report, cached_surrogate_fmu

    chosen = ["linux64"] + (["win64"] if PLATFORMS["win64"].compiler_found() else [])
    path = cached_surrogate_fmu(GEN2, "Gen2Surrogate", platforms=chosen, fmi_version=3, n_check=4, cache=fmu_cache)
    return path, build_report(path)


@pytest.fixture(scope="module")
def surrogate_fmi2(fmu_cache):
    """The FMI 2.0 surrogate FMU of the same operator, from the run's build cache."""
    from fmu_export.build_cache import cached_surrogate_fmu

    return cached_surrogate_fmu(GEN2, "Gen2Surrogate", n_check=4, cache=fmu_cache)


def test_the_fmi3_reference_validates_and_declares_what_it_does(reference_pair):
    _, three, info = reference_pair
    assert validate_fmu(str(three)) == []
    md = read_model_description(str(three))
    assert md.fmiVersion == "3.0" and md.instantiationToken == info["guid"]
    cs = ElementTree.fromstring(zipfile.ZipFile(three).read("modelDescription.xml")).find("CoSimulation").attrib
    for flag in ("canHandleVariableCommunicationStepSize", "canGetAndSetFMUState", "canSerializeFMUState",
                 "providesDirectionalDerivatives", "providesAdjointDerivatives"):
        assert cs[flag] == "true", flag
    assert cs["hasEventMode"] == "false" and cs["modelIdentifier"] == "Machine"
    kinds = {v.name: (v.type, v.causality) for v in md.modelVariables}
    assert kinds["time"] == ("Float64", "independent") and kinds["Vs"] == ("Float64", "input")
    assert zipfile.ZipFile(three).namelist().count("binaries/x86_64-linux/Machine.so") == 1
    refs = [v.valueReference for v in md.modelVariables]
    assert len(set(refs)) == len(refs)


def test_the_fmi3_reference_equals_the_fmi2_one_at_variable_steps(reference_pair, tmp_path):
    two, three, _ = reference_pair
    a, b = FMU(two, scratch=tmp_path), FMU(three, scratch=tmp_path)
    ya, yb = drive(a, np.random.default_rng(5)), drive(b, np.random.default_rng(5))
    np.testing.assert_allclose(yb, ya, rtol=0, atol=1e-12)
    assert np.ptp(ya[:, 1]) > 1e-3  # the machine moved
    assert b.get("time")[0] == pytest.approx(a.t)
    a.close(), b.close()


def test_fmi3_directional_and_adjoint_derivatives_equal_the_fmi2_ones(reference_pair, tmp_path):
    two, three, _ = reference_pair
    a, b = FMU(two, scratch=tmp_path), FMU(three, scratch=tmp_path)
    rng = np.random.default_rng(8)
    drive(a, np.random.default_rng(9), 30), drive(b, np.random.default_rng(9), 30)
    for _ in range(4):
        seed = rng.normal(size=len(INPUTS))
        np.testing.assert_allclose(derivatives(b, DERIVED, INPUTS, seed), derivatives(a, DERIVED, INPUTS, seed),
                                   rtol=0, atol=1e-12)
    # adjoint: seed over the unknowns, sensitivity over the knowns, = J^T seed
    jacobian = np.array([derivatives(a, DERIVED, INPUTS, np.eye(len(INPUTS))[k]) for k in range(len(INPUTS))]).T
    weights = rng.normal(size=len(DERIVED))
    adjoint = b.fmu.getAdjointDerivative([b.vr[n] for n in DERIVED], [b.vr[n] for n in INPUTS], list(weights),
                                         nSensitivity=len(INPUTS))  # one per known (fmpy's default: per unknown)
    np.testing.assert_allclose(adjoint, jacobian.T @ weights, rtol=1e-14, atol=1e-14)
    assert not np.any(derivatives(b, STATES, INPUTS, np.ones(len(INPUTS))))  # states: no direct dependence
    a.close(), b.close()


def test_an_fmi3_state_restored_from_bytes_in_another_instance_repeats_the_run(reference_pair, tmp_path):
    _, three, _ = reference_pair
    a = FMU(three, "a", scratch=tmp_path)
    drive(a, np.random.default_rng(1), 40)
    state = a.fmu.getFMUState()
    saved = a.fmu.serializeFMUState(state)
    t_saved = a.t
    first = drive(a, np.random.default_rng(2), 30)
    a.fmu.setFMUState(state)
    a.t = t_saved
    np.testing.assert_array_equal(drive(a, np.random.default_rng(2), 30), first)
    a.fmu.freeFMUState(state)
    b = FMU(three, "b", scratch=tmp_path)
    b.fmu.setFMUState(b.fmu.deserializeFMUState(saved))
    b.t = t_saved
    np.testing.assert_array_equal(drive(b, np.random.default_rng(2), 30), first)
    a.close(), b.close()


def test_bad_fmi3_values_and_calls_are_errors_with_a_logged_reason(reference_pair, tmp_path):
    _, three, _ = reference_pair
    a = FMU(three, scratch=tmp_path)
    with pytest.raises(Exception, match="fmi3SetFloat64"):
        a.set(Vs=float("nan"))
    with pytest.raises(Exception, match="fmi3DoStep"):
        a.fmu.doStep(0.0, 0.0)
    with pytest.raises(Exception, match="fmi3DoStep"):
        a.fmu.doStep(1.0, 0.01)  # not the FMU's time
    with pytest.raises(Exception, match="fmi3SetFloat64"):
        a.fmu.setFloat64([a.vr["time"]], [1.0])
    assert len(a.messages) >= 4 and all(status == 3 for status, _ in a.messages)
    assert any("not finite" in m or "finite" in m for _, m in a.messages)
    a.step(0.01)  # the FMU still works
    a.close()


def test_fmpy_simulates_the_fmi3_reference_like_the_fmi2_one(reference_pair):
    two, three, _ = reference_pair
    signal = np.array([(0.0, 1.0), (0.3, 0.8), (0.6, 1.0), (1.0, 1.0)], dtype=[("time", float), ("Vs", float)])
    runs = [simulate_fmu(str(p), stop_time=1.0, output_interval=0.01, input=signal, output=list(STATES))
            for p in (two, three)]
    for name in STATES:
        np.testing.assert_allclose(runs[1][name], runs[0][name], rtol=0, atol=1e-12)
    assert np.ptp(runs[0]["omega"]) > 1e-3


@pytest.mark.platform_tools  # with a win64 binary where MinGW-w64 is here
def test_the_fmi3_surrogate_equals_the_fmi2_one_on_the_same_inputs(surrogate_fmi3, surrogate_fmi2, tmp_path):
    path, info = surrogate_fmi3
    assert validate_fmu(str(path)) == []
    if "win64" in info["checks"]:
        assert info["checks"]["win64"].startswith(("ran under wine", "not run here"))
    a, b = FMU(surrogate_fmi2, scratch=tmp_path), FMU(path, scratch=tmp_path)
    ya, yb = drive(a, np.random.default_rng(21), 150), drive(b, np.random.default_rng(21), 150)
    np.testing.assert_allclose(yb, ya, rtol=0, atol=1e-12)
    md = read_model_description(str(path))
    flag = next(v for v in md.modelVariables if v.name == "in_envelope")
    assert flag.type == "Boolean" and b.fmu.getBoolean([flag.valueReference]) == [True]
    seed = np.random.default_rng(3).normal(size=len(INPUTS))
    np.testing.assert_allclose(derivatives(b, DERIVED, INPUTS, seed), derivatives(a, DERIVED, INPUTS, seed),
                               rtol=0, atol=1e-12)
    a.close(), b.close()


@pytest.mark.platform_tools
def test_build_fmu_fmi3_writes_the_fmi3_folders(surrogate_fmi3):
    path, info = surrogate_fmi3
    names = zipfile.ZipFile(path).namelist()
    assert "binaries/x86_64-linux/Gen2Surrogate.so" in names and "sources/fmi3_cs.c" in names
    assert "sources/fmi2_cs.c" not in names
    if "win64" in info["binaries"]:
        assert "binaries/x86_64-windows/Gen2Surrogate.dll" in names


def test_the_pythonfmu_reference_is_fmi2_only(tmp_path):
    import subprocess
    import sys

    if shutil.which("gcc") is None:
        pytest.skip("no gcc")
    result = subprocess.run([sys.executable, "-m", "opfmu", "build-reference-fmu", "--python", "--fmi-version", "3",
                             "-o", str(tmp_path / "P.fmu")], capture_output=True, text=True)
    assert result.returncode == 2 and result.stderr.count("\n") == 1 and "--python builds an FMI 2.0" in result.stderr


@pytest.mark.platform_tools(PLATFORMS["win64"].compiler, PLATFORMS["win64"].emulator[0])
def test_the_fmi3_surrogate_dll_under_wine_gives_the_linux64_outputs(surrogate_fmi3, tmp_path):
    from fmu_export import cross_check, platforms
    from fmu_export.surrogate_fmu import load_operator, surrogate_variables
    from tests.test_platforms import extract_binary

    win64 = platforms.PLATFORMS["win64"]
    path, info = surrogate_fmi3
    _, meta = load_operator(GEN2)
    variables = surrogate_variables(meta, GEN2)
    script = cross_check.scenario_script(variables, info["guid"], 3, seed=404, steps=100)
    host = platforms.host()
    base = cross_check.run_script(host, extract_binary(path, host, 3, "Gen2Surrogate", tmp_path), script, tmp_path, 3)
    other = cross_check.run_script(win64, extract_binary(path, win64, 3, "Gen2Surrogate", tmp_path), script, tmp_path, 3)
    assert cross_check.compare(base, other).mismatch == ""
    gaps = dict(zip([v.name for v in variables if v.kind == "Real" and v.causality == "output"],
                    cross_check.column_differences(base, other)))
    # every state and bus output to 1e-12; the residual diagnostic, a difference of nearly equal
    # rates, to 1e-10 (docs/portable-fmus.md)
    assert max(g for n, g in gaps.items() if n != "residual") <= 1e-12, gaps
    assert gaps["residual"] <= 1e-10
    assert np.all(cross_check.column_differences(base, other, "dd") <= 1e-12)
    assert sum(line.startswith("getbool 0 1") for line in base) > 100  # in the envelope throughout


@pytest.fixture(scope="module")
def small_surrogate_fmi3(fmu_cache):
    """The FMI 3.0 surrogate FMU of a small shipped operator (wscc9_gen2.onnx), from the run's build cache."""
    from fmu_export.build_cache import cached_surrogate_fmu

    return cached_surrogate_fmu(GEN2, "Gen2Surrogate", n_check=4,
                                fmi_version=3, cache=fmu_cache)


@pytest.fixture(scope="module", params=["reference", "surrogate"])
def fmi3_native(request, reference_pair, small_surrogate_fmi3):
    """(FMI 3.0 native FMU, its parameter whose slot the state checks corrupt, a distinctive value for it)."""
    if request.param == "reference":
        return reference_pair[1], "rtol", 1.2345678e-7
    return small_surrogate_fmi3, "rollover_horizon", 0.1234567


# Run in a process of its own (a state the FMU wrongly accepted could make a step hang, a pointer it
# wrongly freed abort the process): prints one JSON object of what each FMU-state call returned.
STATE_CHECKS = r"""
import ctypes, json, struct, sys
from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Slave, fmi3FMUState
path, probe, value = sys.argv[1], sys.argv[2], float(sys.argv[3])
md = read_model_description(path)
vr = {v.name: v.valueReference for v in md.modelVariables}
messages = []
fmu = FMU3Slave(guid=md.instantiationToken, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier)
fmu.instantiate(logMessage=lambda env, status, category, message: messages.append(message.decode()))
fmu.enterInitializationMode(startTime=0.0)
fmu.setFloat64([vr[probe]], [value])
fmu.exitInitializationMode()
for k in range(20):
    fmu.doStep(0.01 * k, 0.01)
state = fmu.getFMUState()
data = bytes(fmu.serializeFMUState(state))
found = {}
offset = data.find(struct.pack("<d", value))
for bad in ("nan", "0", "-1", "inf"):
    corrupt = bytearray(data)
    corrupt[offset:offset + 8] = struct.pack("<d", float(bad))
    try:
        fmu.deserializeFMUState(bytes(corrupt))
        found[bad] = "accepted"
    except Exception:
        found[bad] = messages[-1]
lookalike = ctypes.create_string_buffer(data)
foreign = fmi3FMUState(ctypes.addressof(lookalike))
found["free"] = fmu.dll.fmi3FreeFMUState(fmu.component, ctypes.byref(foreign))
found["free_untouched"] = foreign.value == ctypes.addressof(lookalike)
found["free_message"] = messages[-1]
found["set"] = fmu.dll.fmi3SetFMUState(fmu.component, foreign)
found["time"] = fmu.getFloat64([vr["time"]])[0]
fmu.freeFMUState(state)
fmu.terminate()
fmu.freeInstance()
print(json.dumps(found))
"""


@pytest.fixture(scope="module")
def fmi3_state_checks(fmi3_native):
    path, probe, value = fmi3_native
    done = subprocess.run([sys.executable, "-c", STATE_CHECKS, str(path), probe, repr(value)], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    return probe, json.loads(done.stdout)


def test_an_fmi3_state_with_an_out_of_range_parameter_is_refused_with_a_reason(fmi3_state_checks):
    """The rollover horizon (surrogate) or rtol (reference) of a serialized FMI 3.0 state set to NaN, 0,
    -1 or inf: fmi3DeserializeFMUState refuses it, naming the parameter."""
    probe, found = fmi3_state_checks
    for bad in ("nan", "0", "-1", "inf"):
        assert found[bad].startswith("fmi3DeserializeFMUState: corrupt state") and probe in found[bad], found[bad]


def test_fmi3_state_calls_refuse_a_pointer_the_instance_did_not_hand_out(fmi3_state_checks):
    _, found = fmi3_state_checks
    assert found["free"] == 3 and found["free_untouched"] and "not freed" in found["free_message"]
    assert found["set"] == 3 and found["time"] == pytest.approx(0.2)  # the instance is where it was


def test_fmi3_enter_initialization_mode_refuses_a_tolerance_that_is_not_positive_and_finite(fmi3_native, tmp_path):
    path, _, _ = fmi3_native
    instance = FMU(path, init=False, scratch=tmp_path)
    with pytest.raises(Exception):
        instance.fmu.enterInitializationMode(tolerance=-1.0, startTime=0.0)
    assert [text for _, text in instance.messages] == [
        "fmi3EnterInitializationMode: tolerance -1 must be positive and finite"]
    instance.fmu.enterInitializationMode(tolerance=1e-6, startTime=0.0)  # the instance is still usable
    instance.fmu.exitInitializationMode()
    instance.close()
