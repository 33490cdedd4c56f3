"""Small dataset recipes, the SM4 FMUs (surrogate, native and pythonfmu reference) and the FMU build
cache, shared by the tests; the `platform_tools` marker's skips.

Every native FMU the tests build goes through the content-keyed build cache (fmu_export.build_cache)
of the run, so each distinct FMU is built once per run: the fixtures here, the tests' own builds, the
grid tests and the commands the tests run (`opfmu demo`, `opfmu grid`), which find the cache through
$OPFMU_FMU_CACHE."""
import importlib.util
import json
import os
import shutil
import signal
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

# The suite's processes (its workers and the commands the tests start) keep the package's bytecode in
# __pycache__ as an installed package does: where the shell sets PYTHONDONTWRITEBYTECODE, each of
# them would compile the package's modules again (0.4-0.5 s of CPU a process).
os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
sys.dont_write_bytecode = False

from opfmu.cli import usable_cores  # noqa: E402
from surrogate.data import generate, preset  # noqa: E402


def tiny(name="paper", **changes):
    """A few trajectories of a named preset (chunks of 3 unless changed)."""
    changes = {"counts": {"train": 8, "collocation": 4, "val": 3, "test": 3}, "chunk_size": 3, **changes}
    return replace(preset(name), **changes)


def preset_file(path, recipe):
    """Writes a preset as the JSON file `opfmu data --preset FILE.json` reads."""
    path.write_text(json.dumps(recipe.to_dict()))
    return path


@pytest.fixture(scope="session")
def paper_tiny(tmp_path_factory):
    """(recipe, directory) of a tiny paper-preset dataset, generated once."""
    recipe = tiny("paper")
    out = tmp_path_factory.mktemp("paper_tiny")
    generate(recipe, out, seed=7, progress=False)
    return recipe, out


@pytest.fixture(scope="session")
def cosim_tiny(tmp_path_factory):
    """(recipe, directory) of a tiny cosim-preset dataset (2 probes per family), generated once."""
    recipe = tiny("cosim", probes_per_family=2)
    out = tmp_path_factory.mktemp("cosim_tiny")
    generate(recipe, out, seed=3, progress=False)
    return recipe, out


@pytest.fixture(scope="session", autouse=True)
def fmu_cache(tmp_path_factory):
    """The FMU build cache of this run: $OPFMU_FMU_CACHE where it is set (CI shares one folder between
    its two runs), else a folder in the run's temporary directory. Set as $OPFMU_FMU_CACHE for the
    whole run, so the commands the tests start use it too; under pytest-xdist one folder for all the
    run's workers. Tests read its FMUs and never write them."""
    given = os.environ.get("OPFMU_FMU_CACHE")
    if given:
        path = Path(given)
    elif os.environ.get("PYTEST_XDIST_WORKER"):  # one cache for the run's workers (builds are atomic)
        path = tmp_path_factory.getbasetemp().parent / "fmu_cache"
        path.mkdir(exist_ok=True)
    else:
        path = tmp_path_factory.mktemp("fmu_cache")
    environment = pytest.MonkeyPatch()
    environment.setenv("OPFMU_FMU_CACHE", str(path))
    yield path
    environment.undo()


@pytest.fixture(scope="session")
def fmu_path(fmu_cache):
    """The surrogate FMU (FMI 2.0, linux64) of the shipped operator, from the run's build cache."""
    from fmu_export.build_cache import cached_surrogate_fmu
    from surrogate.operator import DEFAULT_OPERATOR

    return cached_surrogate_fmu(DEFAULT_OPERATOR, "SM4Surrogate", n_check=4, cache=fmu_cache)


@pytest.fixture(scope="session")
def native_reference_path(fmu_cache):
    """The native reference FMU (Dormand-Prince 5(4) in C) of the default machine, from the run's build cache."""
    from fmu_export.build_cache import cached_native_reference_fmu

    return cached_native_reference_fmu("SM4Reference", cache=fmu_cache)


@pytest.fixture(scope="session")
def reference_path(tmp_path_factory):
    """The pythonfmu reference FMU (scipy RK45) of the default machine, built once."""
    from fmu_export.python_reference_fmu import build_reference_fmu

    path = tmp_path_factory.mktemp("reference") / "SM4Reference.fmu"
    build_reference_fmu(path)
    return path


@pytest.fixture(scope="session")
def grid_fmu_cache(fmu_cache):
    """The FMU cache of the grid tests (cosim.fmus): the run's build cache."""
    return fmu_cache


def _interrupts_as_at_a_terminal():
    """SIGINT back to its default and unblocked in the child before it starts: a suite run in a
    background job (`pytest &`: the shell ignores SIGINT there, and every program started from it
    inherits that) or from a thread that blocks it (the signal mask survives fork and exec) still
    starts its commands as a terminal does."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def signal_dispositions(pid: int) -> str:
    """The process's blocked, ignored and caught signal masks (/proc/PID/status; '' where it is gone
    or not on Linux): what a test of Ctrl-C reports where the command did not take one."""
    try:
        with open(f"/proc/{pid}/status") as f:
            return " ".join(line.strip() for line in f if line.startswith(("SigBlk", "SigIgn", "SigCgt")))
    except OSError:
        return ""


def opfmu_process(argv, **popen):
    """`python -m opfmu argv` in its own process group with Ctrl-C at its default (as a terminal
    starts a command), text pipes for stdout and stderr, Python's fault handler on
    (interrupt_and_wait's report)."""
    env = dict(popen.pop("env", os.environ), PYTHONFAULTHANDLER="1")
    return subprocess.Popen([sys.executable, "-m", "opfmu", *map(str, argv)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True, env=env,
                            preexec_fn=_interrupts_as_at_a_terminal, **popen)


def interrupt_and_wait(process, timeout: float):
    """(exit code, stderr) of `process` (opfmu_process) after Ctrl-C (SIGINT to its process group, as
    a terminal sends it). A process still running after `timeout` [s] fails the test with what it
    was doing: SIGABRT makes Python's fault handler print every thread's stack, and the processes
    of its group are listed."""
    os.killpg(process.pid, signal.SIGINT)
    try:
        _, err = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        group = subprocess.run(["ps", "-o", "pid,ppid,stat,etime,args", "-g", str(process.pid)],
                               capture_output=True, text=True).stdout
        process.send_signal(signal.SIGABRT)
        _, err = process.communicate(timeout=60)
        os.killpg(process.pid, signal.SIGKILL)
        pytest.fail(f"still running {timeout:g} s after Ctrl-C; its group:\n{group}\nits stderr:\n{err[-6000:]}")
    return process.returncode, err


def pytest_xdist_auto_num_workers(config):
    """`-n auto` (pyproject's addopts): a worker per core, at most 4 (each holds torch and the FMUs
    its tests load; the CI machine has 2 cores)."""
    return max(1, min(4, usable_cores()))


def pytest_configure(config):
    """Under pytest-xdist each worker's torch takes its share of the cores, not all of them."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "0"))
    if workers > 1:
        import torch

        torch.set_num_threads(max(1, usable_cores() // workers))


# the modules that take longest on 2 workers (pytest --durations on a 2-core machine: FMU builds for every
# model, whole commands, trainings in module fixtures), heaviest first: they start first, so that
# at the end no worker waits idle behind one of them while the other runs it (pyproject: loadscope,
# without xdist's reorder by test count, which put the modules of few long tests last); test_self_start
# after the standard models' FMUs, most of whose builds it then takes from the run's build cache
LONGEST_FIRST = ("test_standard_model_fmus.py", "test_compare.py", "test_surrogate_fmu.py", "test_self_start.py",
                 "test_user_machine.py", "test_grid_cli.py", "test_onnx_export.py", "test_operator_command.py",
                 "test_subsystem_operator.py", "test_any_machine_commands.py", "test_native_reference.py",
                 "test_grid_cli_hostile.py", "test_grid_master.py")


def pytest_collection_modifyitems(config, items):
    """LONGEST_FIRST's modules first, in its order; the others after them in the order collected (a
    stable sort keeps each module's tests together and in order)."""
    rank = {name: k for k, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


def optional_tools() -> dict:
    """{program: Debian package} of the optional tools: the cross compilers and emulators of the
    other platforms (fmu_export.platforms), and valgrind."""
    from fmu_export.platforms import optional_tools as platform_tools

    return {**platform_tools(), "valgrind": "valgrind"}


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item):
    """A test marked platform_tools("prog", ...) is skipped, before its fixtures are built, unless
    every program named is on PATH; the reason names the Debian packages to install. A test marked
    andes is skipped, saying how to install it, where ANDES is not installed."""
    marker = item.get_closest_marker("platform_tools")
    missing = [tool for tool in (marker.args if marker else ()) if shutil.which(tool) is None]
    if missing:
        packages = optional_tools()
        pytest.skip(f"no {', '.join(missing)}: install Debian's "
                    f"{', '.join(dict.fromkeys(packages.get(tool, tool) for tool in missing))}")
    if item.get_closest_marker("andes") and importlib.util.find_spec("andes") is None:
        pytest.skip("no ANDES (the optional reference, GPL-3.0-or-later): .venv/bin/pip install -e '.[andes]'")
