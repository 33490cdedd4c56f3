"""What the surrogate, the pythonfmu reference and the native reference FMU must all do as FMI 2.0
co-simulation units."""
import shutil
import subprocess
import sys

import numpy as np
import pytest
from fmpy import extract, read_model_description

from fmu_export.binaries import fmi_headers
from cosim.fmu import FMU as Slave
from reference_models.sm4 import SM4

FUZZ_HARNESS = __file__.rsplit("/", 1)[0] + "/c/fuzz_harness.c"


@pytest.fixture(scope="module", params=["fmu_path", "reference_path", "native_reference_path"])
def unzipped(request):
    path = request.getfixturevalue(request.param)
    return extract(str(path)), read_model_description(str(path))


def test_many_instances_live_side_by_side_and_the_fmu_reloads(unzipped):
    slaves = [Slave(unzipped, f"i{k}") for k in range(4)]
    results = [s.step(0.01, 0.9 + 0.02 * k) for k, s in enumerate(slaves)]
    for s in slaves:
        s.close()
    again = Slave(unzipped, "again")
    np.testing.assert_array_equal(again.step(0.01, 0.9), results[0])
    again.close()


def test_get_and_set_fmu_state_reproduce_the_run(unzipped):
    slave = Slave(unzipped)
    for k in range(30):
        slave.step(0.01, 1.0 - 0.01 * k, 0.01 * k)
    saved, t_saved = slave.fmu.getFMUstate(), slave.t
    first = [slave.step(0.02, 0.9, 0.1) for _ in range(40)]
    slave.fmu.setFMUstate(saved)
    slave.t = t_saved
    again = [slave.step(0.02, 0.9, 0.1) for _ in range(40)]
    slave.fmu.freeFMUstate(saved)
    slave.close()
    np.testing.assert_array_equal(first, again)


def test_serialized_state_restored_in_a_fresh_process_continues_the_run(unzipped, tmp_path):
    slave = Slave(unzipped)
    for _ in range(50):
        slave.step(0.01, 0.95, -0.1)
    state, t_saved = slave.fmu.getFMUstate(), slave.t
    (tmp_path / "state.bin").write_bytes(bytes(slave.fmu.serializeFMUstate(state)))
    expected = [slave.step(0.01, 1.02, 0.0) for _ in range(80)]
    slave.close()
    script = f"""
import numpy as np, sys
sys.path.insert(0, {str(__file__.rsplit('/', 1)[0])!r})
from cosim.fmu import FMU as Slave
from reference_models.sm4 import SM4
from fmpy import read_model_description
slave = Slave(({str(unzipped[0])!r}, read_model_description({str(unzipped[0])!r})))
slave.fmu.setFMUstate(slave.fmu.deSerializeFMUstate(open({str(tmp_path / 'state.bin')!r}, 'rb').read()))
slave.t = {t_saved!r}
np.save({str(tmp_path / 'out.npy')!r}, np.array([slave.step(0.01, 1.02, 0.0) for _ in range(80)]))
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    np.testing.assert_array_equal(np.load(tmp_path / "out.npy"), expected)


def test_the_two_references_agree_on_held_inputs(reference_path, native_reference_path):
    runs = []
    for path in (reference_path, native_reference_path):
        slave = Slave((extract(str(path)), read_model_description(str(path))), rtol=1e-10, atol=1e-12)
        runs.append([slave.step(h, *u) for h, *u in [(0.01, 0.9, 0.1)] * 20 + [(0.05, 1.05, -0.2, 0.6, 1.4)] * 10])
        slave.close()
    np.testing.assert_allclose(runs[0], runs[1], rtol=0, atol=1e-9)


@pytest.fixture(scope="module", params=["fmu_path", "native_reference_path"])
def native(request):
    """A native FMU (the surrogate or the native reference), extracted."""
    path = request.getfixturevalue(request.param)
    return extract(str(path)), read_model_description(str(path))


def test_reset_returns_to_the_start(native):
    slave = Slave(native)
    for _ in range(20):
        slave.step(0.01, 0.9)
    slave.fmu.reset()
    slave.fmu.setupExperiment(startTime=0.0)
    slave.fmu.enterInitializationMode()
    slave.fmu.exitInitializationMode()
    slave.t = 0.0
    np.testing.assert_allclose(slave.state(), SM4.steady_state(), atol=1e-12)
    slave.close()


@pytest.fixture(scope="module")
def fuzz_harness(tmp_path_factory):
    out = tmp_path_factory.mktemp("fuzz") / "fuzz_harness"
    subprocess.run(["gcc", "-O1", "-g", "-I", str(fmi_headers()), FUZZ_HARNESS, "-o", str(out), "-ldl", "-lm"],
                   check=True)
    return out


def fuzz_command(native, calls: int, seed: int) -> list:
    directory, md = native
    n_reals = sum(v.type == "Real" for v in md.modelVariables)
    return [f"{directory}/binaries/linux64/{md.coSimulation.modelIdentifier}.so", md.guid, str(calls), str(seed),
            str(n_reals)]


@pytest.mark.parametrize("seed", [1, 2])
def test_random_fmi_call_sequences_from_a_c_importer_never_crash(native, fuzz_harness, seed):
    """A few thousand FMI calls in random order with random values (NaN, inf, h <= 0, wrong states,
    NULL arrays, unknown value references, corrupt states): every one returns a valid status."""
    result = subprocess.run([str(fuzz_harness), *fuzz_command(native, 5000, seed)], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr[-2000:]
    counts = dict(zip(result.stdout.split()[0::2], map(int, result.stdout.split()[1::2])))
    assert counts["steps"] > 1000 and counts["error"] > 500  # it stepped, and it was refused often


@pytest.mark.platform_tools("valgrind")
@pytest.mark.skipif(not shutil.which("valgrind"), reason="valgrind is not installed")
def test_random_fmi_call_sequences_under_valgrind_are_clean(native, fuzz_harness):
    calls = 600 if any(v.name == "residual" for v in native[1].modelVariables) else 3000  # the surrogate is slower
    result = subprocess.run(["valgrind", "--leak-check=full", "--errors-for-leak-kinds=definite,indirect,possible",
                             "--error-exitcode=3", str(fuzz_harness), *fuzz_command(native, calls, 7)],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr[-3000:]
    assert "ERROR SUMMARY: 0 errors" in result.stderr


STATE_FUZZ = __file__.rsplit("/", 1)[0] + "/c/state_fuzz.c"
# a parameter of each native FMU set to a value whose bit pattern marks its slot in the serialized state:
# the surrogate's rollover horizon [s] (a horizon of 0 once made a step never return) and the
# reference's rtol
PROBES = {"rollover_horizon": 0.1234567, "rtol": 1.2345678e-7}


@pytest.fixture(scope="module")
def state_fuzz(tmp_path_factory):
    out = tmp_path_factory.mktemp("state_fuzz") / "state_fuzz"
    subprocess.run(["gcc", "-O1", "-g", "-I", str(fmi_headers()), STATE_FUZZ, "-o", str(out), "-ldl", "-lm"],
                   check=True)
    return out


@pytest.fixture(scope="module")
def small_surrogate_path(fmu_cache):
    """The surrogate FMU (FMI 2.0) of a small shipped operator (wscc9_gen2.onnx, a trunk kernel a fifth
    of the default operator's size), from the run's build cache: a state the fuzzer can sweep."""
    from fmu_export.build_cache import cached_surrogate_fmu
    from surrogate.operator import DEFAULT_OPERATOR

    return cached_surrogate_fmu(DEFAULT_OPERATOR.parent / "wscc9_gen2.onnx", "Gen2Surrogate", n_check=4,
                                cache=fmu_cache)


def state_bytes(unzipped) -> bytes:
    """The serialized FMU state of an instance after 20 steps of 10 ms."""
    slave = Slave(unzipped)
    for _ in range(20):
        slave.step(0.01)
    state = slave.fmu.getFMUstate()
    data = bytes(slave.fmu.serializeFMUstate(state))
    slave.fmu.freeFMUstate(state)
    slave.close()
    return data


@pytest.fixture(scope="module", params=["small_surrogate_path", "native_reference_path"])
def fuzzed(request, tmp_path_factory):
    """(extracted FMU, the state fuzzer's command line for it with `cases` and `seed` to fill in): the
    FMU's probe parameter and, as the foreign state, the other native FMU's serialized state."""
    other = {"small_surrogate_path": "native_reference_path"}.get(request.param, "small_surrogate_path")
    path = request.getfixturevalue(request.param)
    unzipped = extract(str(path)), read_model_description(str(path))
    foreign = tmp_path_factory.mktemp("foreign_state") / "state.bin"
    other_path = request.getfixturevalue(other)
    foreign.write_bytes(state_bytes((extract(str(other_path)), read_model_description(str(other_path)))))
    directory, md = unzipped
    variables = {v.name: v for v in md.modelVariables}
    probe = next(name for name in PROBES if name in variables)
    n_reals = sum(v.type == "Real" for v in md.modelVariables)

    def command(cases: int, seed: int) -> list:
        return [f"{directory}/binaries/linux64/{md.coSimulation.modelIdentifier}.so", md.guid, str(seed), str(cases),
                str(n_reals), str(variables[probe].valueReference), repr(PROBES[probe]), str(foreign)]

    return unzipped, command


def run_state_fuzz(harness, command, timeout, prefix=()) -> tuple:
    """(counts, completed process) of a state fuzzer run, within `timeout` seconds."""
    result = subprocess.run([*prefix, str(harness), *command], capture_output=True, text=True, timeout=timeout)
    words = result.stdout.split()
    return dict(zip(words[0::2], map(int, words[1::2]))), result


@pytest.fixture(scope="module")
def state_fuzz_run(fuzzed, state_fuzz):
    """The state fuzzer's counts on one FMU: the first, last and 300 random 8-byte slots of its state
    with every bad value, random and half-random bytes, wrong sizes, another FMU's state."""
    _, command = fuzzed
    counts, result = run_state_fuzz(state_fuzz, command(300, 11), timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr[-2000:]
    return counts


def test_corrupt_serialized_states_are_refused_or_step_in_bounded_time(state_fuzz_run):
    """Every deserialized or set state with a broken field, random bytes, a wrong size or another FMU's
    bytes is refused (the instance unchanged, a reason logged) or steps with a valid status; the run
    ends within its timeout (a state once made a step never return)."""
    counts = state_fuzz_run
    assert counts["failures"] == 0
    assert counts["refused"] > 200 and counts["accepted"] > 100 and counts["steps"] > 100


def test_a_state_with_an_out_of_range_parameter_is_refused(state_fuzz_run):
    """The rollover horizon (surrogate) or rtol (reference) of a serialized state set to 0, -1, NaN,
    +-inf, +-1e308 or the smallest subnormal: each refused, as fmi2SetReal refuses the value."""
    assert state_fuzz_run["probe_cases"] == 8 and state_fuzz_run["probe_refused"] == 8


def test_fmu_state_calls_refuse_a_pointer_the_instance_did_not_hand_out(state_fuzz_run):
    """fmi2FreeFMUstate, fmi2SetFMUstate, the serialize calls and fmi2GetFMUstate/fmi2DeSerializeFMUstate
    into it refuse a pointer the instance did not allocate, and free nothing (valgrind below sees no
    double free)."""
    assert state_fuzz_run["foreign_refused"] == 6


def test_setup_experiment_refuses_a_tolerance_that_is_not_positive_and_finite(fuzzed, state_fuzz_run):
    assert state_fuzz_run["tolerance_refused"] == 4  # -1, 0, NaN, inf (the fuzzer's calls)
    slave = Slave(fuzzed[0], init=False)
    with pytest.raises(Exception):
        slave.fmu.setupExperiment(tolerance=-1.0, startTime=0.0)
    assert any("tolerance -1 must be positive and finite" in m for _, m in slave.messages)
    slave.fmu.setupExperiment(startTime=0.0)  # the instance is still usable
    slave.fmu.enterInitializationMode()
    slave.fmu.exitInitializationMode()
    slave.close()


@pytest.mark.platform_tools("valgrind")
def test_the_state_fuzzer_under_valgrind_is_clean(fuzzed, state_fuzz):
    _, command = fuzzed
    counts, result = run_state_fuzz(state_fuzz, command(8, 5), timeout=600,
                                    prefix=("valgrind", "--leak-check=full", "--error-exitcode=3",
                                            "--errors-for-leak-kinds=definite,indirect,possible"))
    assert result.returncode == 0, result.stdout + result.stderr[-3000:]
    assert "ERROR SUMMARY: 0 errors" in result.stderr and counts["failures"] == 0


# in a process of its own, so that a step that never returns fails the test by its timeout
FAR_START = r"""
import sys
from cosim.fmu import FMU
slave = FMU(sys.argv[1], init=False)
slave.fmu.setupExperiment(startTime=1e16)
slave.fmu.enterInitializationMode()
slave.fmu.exitInitializationMode()
try:
    slave.fmu.doStep(1e16, 4.0)
    print("stepped")
except Exception:
    print(slave.last_message())
"""


def test_a_step_whose_window_end_the_time_cannot_resolve_is_refused_not_endless(small_surrogate_path):
    """At t = 1e16 s a double does not resolve the 0.16 s rollover horizon: the window's end is the
    current time, which once made the step loop forever; now the step is an error with the reason."""
    done = subprocess.run([sys.executable, "-c", FAR_START, str(small_surrogate_path)], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "does not resolve the rollover horizon" in done.stdout, done.stdout


@pytest.mark.parametrize("name", ["small_surrogate_path", "native_reference_path"])
def test_every_state_a_run_passes_through_is_accepted_back(request, name):
    """The state checks refuse nothing a run makes: after each of 300 steps (random held and ramped
    inputs, steps of 1 ms to 0.3 s across window boundaries) the state is set back and round-trips
    through bytes."""
    path = request.getfixturevalue(name)
    slave = Slave(path)
    fmu, rng = slave.fmu, np.random.default_rng(4)
    refs = [slave.vr[n] for n in slave.inputs]
    for k in range(300):
        if k % 5 == 0:
            slave.set(**{n: slave.starts[n] * (1 + rng.uniform(-0.03, 0.03)) for n in slave.inputs})
            fmu.setRealInputDerivatives(refs, [1] * len(refs), list(rng.uniform(-0.1, 0.1, len(refs)) * (k % 10 == 0)))
        h = float(rng.choice([0.001, 0.0037, 0.01, 0.05, 0.3]))
        fmu.doStep(currentCommunicationPoint=slave.t, communicationStepSize=h)
        slave.t += h
        state = fmu.getFMUstate()
        fmu.setFMUstate(state)
        copy = fmu.deSerializeFMUstate(fmu.serializeFMUstate(state))
        fmu.setFMUstate(copy)
        fmu.freeFMUstate(state)
        fmu.freeFMUstate(copy)
    assert slave.t > 10.0 and not [m for status, m in slave.messages if status >= 3]
    slave.close()


EXAMPLE = __file__.rsplit("/", 2)[0] + "/examples/compare_with_fmpy.py"
# glibc's loader reads 8 bytes at a time past the end of an RPATH string it copied (strncmp in is_dst),
# while Python imports extension modules: not the FMUs' doing
LOADER_SUPPRESSION = """{
   ld.so-rpath-strncmp-overread
   Memcheck:Addr8
   fun:strncmp
   fun:is_dst
}
"""


@pytest.mark.platform_tools("valgrind")
@pytest.mark.parametrize("reference", ["native_reference_path", "reference_path"])
def test_the_surrogate_and_a_reference_fmu_run_by_plain_fmpy_in_one_process_leave_the_heap_intact(
        fmu_path, reference, request, tmp_path):
    """examples/compare_with_fmpy.py (fmpy's simulate_fmu on the surrogate, then on the native or the
    pythonfmu reference, in one process, to the process's exit) under valgrind: no invalid read,
    write or free anywhere, exit handlers included. A heap corruption there aborts such a run only
    now and then (pythonfmu's own exit-time double release: fmu_export/pythonfmu_exit.py)."""
    (tmp_path / "loader.supp").write_text(LOADER_SUPPRESSION)
    result = subprocess.run(["valgrind", "--error-exitcode=3", f"--suppressions={tmp_path / 'loader.supp'}",
                             sys.executable, EXAMPLE, str(fmu_path), str(request.getfixturevalue(reference))],
                            capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    assert "ERROR SUMMARY: 0 errors" in result.stderr and "max abs error" in result.stdout
