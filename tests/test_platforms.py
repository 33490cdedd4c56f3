"""Binaries for several platforms in one FMU: chosen by --platforms, linked against the C runtime only,
and run (win64 under wine, aarch64-linux under qemu-user) to the same numbers as the linux64 binary,
on machines and scenarios built here at random."""
import subprocess
import sys
import zipfile

import numpy as np
import pytest

from fmu_export import cross_check, platforms
from fmu_export.binaries import BuildError, fmi_headers
from fmu_export.native_reference_fmu import build_native_reference_fmu, native_reference_variables
from reference_models.sm4 import SM4

WIN64, ARM = platforms.PLATFORMS["win64"], platforms.PLATFORMS["aarch64-linux"]


def needs(p):
    """Skip (saying what to install) unless the platform's compiler and emulator are here."""
    if not p.compiler_found():
        pytest.skip(f"no {p.compiler}: install Debian's {p.package} to build {p.name} binaries")
    if not p.runs_here():
        pytest.skip(f"no {p.emulator[0]}: install Debian's {p.emulator_package} to run {p.name} binaries")


def random_machine(seed):
    """A machine that is in no file of the repository: paper Table I scaled at random."""
    rng = np.random.default_rng(seed)
    base = SM4.params().to_dict()
    changed = {k: base[k] * rng.uniform(0.7, 1.3) for k in ("H", "Xd", "Xq", "Td0_p", "Tq0_p")}
    changed["D"] = rng.uniform(0.0, 2.0)
    changed["Xd_p"], changed["Xq_p"] = base["Xd_p"] * rng.uniform(0.8, 1.2), base["Xq_p"] * rng.uniform(0.8, 1.0)
    return changed


def extract_binary(fmu, p, version, model, tmp_path):
    path = tmp_path / f"{p.name}-{version}{p.extension}"
    with zipfile.ZipFile(fmu) as z:
        path.write_bytes(z.read(p.binary_path(model, version)))
    return path


@pytest.fixture(scope="module")
def portable_reference(tmp_path_factory):
    """A native reference FMU (FMI 2.0) of a random machine with every platform whose compiler is here."""
    chosen, _ = platforms.select(None)
    params = random_machine(11)
    path = tmp_path_factory.mktemp("portable") / "Machine.fmu"
    info = build_native_reference_fmu(path, model_name="Machine", params=params, platforms=chosen)
    return path, info, params


def test_platform_names_take_fmi3_tuples_and_refuse_unknown_ones():
    assert platforms.by_name("x86_64-windows") is WIN64
    assert platforms.by_name("linux-aarch64") is ARM
    with pytest.raises(platforms.PlatformError, match="unknown platform 'win65'"):
        platforms.by_name("win65")


def test_default_selection_skips_a_platform_without_its_compiler_with_a_note(monkeypatch):
    found = {p.compiler for p in platforms.PLATFORMS.values()} - {WIN64.compiler}
    monkeypatch.setattr(platforms.shutil, "which", lambda name: f"/usr/bin/{name}" if name in found else None)
    chosen, notes = platforms.select(None)
    assert WIN64 not in chosen and platforms.host() in chosen
    assert notes == ["note: win64 skipped: no x86_64-w64-mingw32-gcc found (Debian package gcc-mingw-w64-x86-64)"]
    with pytest.raises(platforms.PlatformError, match="cannot build for win64: no x86_64-w64-mingw32-gcc"):
        platforms.select("linux64,win64")


@pytest.mark.platform_tools  # every platform whose compiler is here
def test_every_binary_sits_in_its_fmi2_folder_and_links_only_the_c_runtime(portable_reference, tmp_path):
    path, info, _ = portable_reference
    names = zipfile.ZipFile(path).namelist()
    for name, binary in info["binaries"].items():
        p = platforms.by_name(name)
        assert binary["path"] == f"binaries/{name}/Machine{p.extension}" and binary["path"] in names
        exports, imports = platforms.linkage(extract_binary(path, p, 2, "Machine", tmp_path), p)
        assert set(platforms.fmi_functions(fmi_headers(), 2)) <= exports
        assert imports <= set(p.allowed_imports)


@pytest.mark.platform_tools(WIN64.compiler)
def test_the_win64_dll_exports_every_fmi2_function_and_imports_only_kernel32_and_msvcrt(portable_reference,
                                                                                       tmp_path):
    path, _, _ = portable_reference
    exports, imports = platforms.linkage(extract_binary(path, WIN64, 2, "Machine", tmp_path), WIN64)
    assert set(platforms.fmi_functions(fmi_headers(), 2)) <= exports
    assert not {e for e in exports if not e.startswith("fmi2")}, "only the FMI functions are exported"
    assert imports == {"kernel32.dll", "msvcrt.dll"}


def test_a_binary_missing_an_fmi_function_is_refused(tmp_path):
    source = tmp_path / "half.c"
    source.write_text('#include "fmi2Functions.h"\nconst char *fmi2GetVersion(void) { return fmi2Version; }\n')
    binary = tmp_path / "half.so"
    subprocess.run(["gcc", "-shared", "-fPIC", "-I", str(fmi_headers()), str(source), "-o", str(binary)], check=True)
    with pytest.raises(platforms.PlatformError, match="does not export 33 FMI 2 functions"):
        platforms.check_linkage(binary, platforms.host(), fmi_headers(), 2)


@pytest.mark.platform_tools  # skipped per target by needs()
@pytest.mark.parametrize("target", [WIN64, ARM], ids=["win64-under-wine", "aarch64-under-qemu"])
@pytest.mark.parametrize("seed", [101, 202])
def test_the_reference_binary_gives_the_linux64_numbers_on_another_platform(portable_reference, tmp_path, target,
                                                                            seed):
    needs(target)
    path, info, params = portable_reference
    variables = native_reference_variables(SM4, params)
    script = cross_check.scenario_script(variables, info["guid"], 2, interpolates=True, seed=seed, steps=80)
    host = platforms.host()
    base = cross_check.run_script(host, extract_binary(path, host, 2, "Machine", tmp_path), script, tmp_path)
    other = cross_check.run_script(target, extract_binary(path, target, 2, "Machine", tmp_path), script, tmp_path)
    result = cross_check.compare(base, other)
    assert result.within(1e-12), result
    assert result.numbers > 3000
    # the scenarios ran what they say: a NaN input and h = 0 refused with a logged reason, the rest OK
    assert any(line.startswith("set 3") for line in base) and any(line.startswith("step 3") for line in base)
    assert sum(line.startswith("log 3 logStatusError") for line in other) >= 3
    assert sum(line.startswith("step 0") for line in base) > 300


def test_comparing_runs_finds_a_difference_and_a_changed_status():
    one = "3ff0000000000000"
    bumped = cross_check.hex_double(1.0 + 1e-11)
    same = cross_check.compare([f"get 0 {one}"], [f"get 0 {one}"])
    assert same.within() and same.numbers == 1 and same.differing == 0
    off = cross_check.compare([f"get 0 {one}"], [f"get 0 {bumped}"])
    assert not off.within() and off.max_difference == pytest.approx(1e-11, rel=1e-4)
    assert not cross_check.compare([f"get 0 {one}"], [f"get 3"]).within()
    assert not cross_check.compare(["step 0", "get 0"], ["step 0"]).within()


def test_the_harness_refuses_a_malformed_script_with_one_line(tmp_path, portable_reference):
    path, _, _ = portable_reference
    host = platforms.host()
    with pytest.raises(BuildError, match="did not run the check script to the end .*line 2: step takes <t> <h>"):
        cross_check.run_script(host, extract_binary(path, host, 2, "Machine", tmp_path),
                               "instantiate a {x} -\nstep 1.0 2.0\n", tmp_path)


@pytest.mark.platform_tools(WIN64.compiler, WIN64.emulator[0])
def test_build_reference_fmu_carries_the_platforms_asked_and_says_how_each_was_checked(tmp_path):
    out = tmp_path / "R.fmu"
    result = subprocess.run([sys.executable, "-m", "opfmu", "build-reference-fmu", "-o", str(out),
                             "--platforms", "linux64,win64"], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "binaries/win64/SM4Reference.dll" in result.stdout and "ran under wine" in result.stdout
    names = zipfile.ZipFile(out).namelist()
    assert "binaries/linux64/SM4Reference.so" in names and "binaries/win64/SM4Reference.dll" in names
    assert not any(n.startswith("binaries/aarch64") for n in names)


@pytest.mark.platform_tools  # one line whichever platforms' compilers are installed
def test_build_fmu_refuses_an_unknown_platform_in_one_line(tmp_path):
    result = subprocess.run([sys.executable, "-m", "opfmu", "build-fmu", "-o", str(tmp_path / "S.fmu"),
                             "--platforms", "linux64,solaris"], capture_output=True, text=True)
    assert result.returncode == 2
    assert result.stderr.strip() == "error: unknown platform 'solaris' (known: linux64, win64, aarch64-linux)"


SMALL_STACK = """
import sys, threading
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
path = sys.argv[1]
md = read_model_description(path)
unzipped = extract(path)
errors = []
def run():
    try:
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName="a")
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmu.doStep(0.0, 0.01)
        state = fmu.getFMUstate()
        fmu.setFMUstate(fmu.deSerializeFMUstate(fmu.serializeFMUstate(state)))
        fmu.doStep(0.01, 0.01)
        fmu.terminate()
        fmu.freeInstance()
    except Exception as exc:
        errors.append(exc)
threading.stack_size(256 * 1024)
thread = threading.Thread(target=run)
thread.start()
thread.join()
print("ok" if not errors else errors[0])
"""


def test_a_surrogate_instance_and_its_state_fit_a_thread_with_a_small_stack(fmu_path):
    """The surrogate's ModelState (its sensor buffers) is most of a megabyte, and Windows threads get
    1 MB of stack: instantiating and restoring a serialized state must not put one on the stack."""
    result = subprocess.run([sys.executable, "-c", SMALL_STACK, str(fmu_path)], capture_output=True, text=True)
    assert result.returncode == 0 and result.stdout.strip() == "ok", (result.returncode, result.stderr[-300:])


@pytest.mark.platform_tools  # every platform whose compiler is here
@pytest.mark.parametrize("version", [2, 3])
def test_the_exciter_fmu_without_feedthrough_runs_on_every_platform_here(tmp_path, version):
    """The second component (IEEE Type I exciter: no output depends directly on an input, so the
    scenarios read no directional derivatives) on every platform whose compiler is here."""
    from fmpy.validation import validate_fmu

    from reference_models.ieee1 import IEEE1

    chosen, _ = platforms.select(None)
    out = tmp_path / "Exciter.fmu"
    info = build_native_reference_fmu(out, model_name="Exciter", component=IEEE1, platforms=chosen,
                                      fmi_version=version)
    assert validate_fmu(str(out)) == []
    assert set(info["binaries"]) == {p.name for p in chosen}
    for p in chosen:
        if p != platforms.host() and p.runs_here():
            assert info["checks"][p.name].startswith("ran under"), info["checks"]
