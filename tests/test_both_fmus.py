"""What the surrogate, the pythonfmu reference and the native reference FMU must all do as FMI 2.0
co-simulation units."""
import shutil
import subprocess
import sys

import numpy as np
import pytest
from fmpy import extract, read_model_description

from fmu_export.binaries import fmi_headers
from fmu_slave import Slave
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
from fmu_slave import Slave
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
