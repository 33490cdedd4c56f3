"""Screening on a dask scheduler whose worker shares no files with the client: a scheduler and a
worker started as processes of their own (dask's command-line entry points), the worker with its
own HOME, TMPDIR and working folder, and (where `unshare` can make a mount namespace) the client's
FMU cache hidden from it under an empty tmpfs. The FMUs travel by content; the rows equal those
of the same screening in the client's own process, and the worker keeps nothing once it is over."""
import json
import os
import shutil
import subprocess
import sys
import time

import pytest

from cosim.fmus import generator_files
from cosim.master import MasterSettings
from cosim.screening import ScreeningTask, contingencies, screen
from reference_models.grid import wscc9
from reference_models.grid.contingency import Contingency

START_TIMEOUT_S = 120  # s: the scheduler and the worker not up by then fails the test with their logs


def _namespaces() -> bool:
    """Whether this machine lets a process make a mount namespace and mount a tmpfs in it."""
    if shutil.which("unshare") is None:
        return False
    probe = subprocess.run(["unshare", "--mount", "--propagation", "private", "sh", "-c",
                            "mount -t tmpfs tmpfs /mnt"], capture_output=True)
    return probe.returncode == 0


def _wait_for(condition, what: str, logs) -> None:
    deadline = time.monotonic() + START_TIMEOUT_S
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"{what} not up within {START_TIMEOUT_S} s:\n" + "\n".join(p.read_text()[-3000:] for p in logs))
        time.sleep(0.2)


@pytest.fixture
def remote_worker(tmp_path, fmu_cache):
    """(scheduler address, worker's TMPDIR, whether the client's FMU cache is hidden from the worker):
    a dask scheduler and one worker of 2 threads, each a process of its own; the worker shares
    neither HOME, TMPDIR nor working folder with the client."""
    scheduler_file = tmp_path / "scheduler.json"
    worker_tmp, worker_home, worker_cwd = (tmp_path / name for name in ("worker_tmp", "worker_home", "worker_cwd"))
    for folder in (worker_tmp, worker_home, worker_cwd):
        folder.mkdir()
    logs = [tmp_path / "scheduler.log", tmp_path / "worker.log"]
    scheduler = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--scheduler-file",
                                  str(scheduler_file), "--host", "127.0.0.1", "--port", "0", "--no-dashboard"],
                                 stdout=subprocess.DEVNULL, stderr=logs[0].open("w"))
    processes = [scheduler]
    try:
        _wait_for(scheduler_file.exists, "the dask scheduler", logs[:1])
        address = json.loads(scheduler_file.read_text())["address"]
        env = {k: v for k, v in os.environ.items() if k != "OPFMU_FMU_CACHE"}
        env.update(HOME=str(worker_home), TMPDIR=str(worker_tmp), XDG_CACHE_HOME=str(worker_home / ".cache"))
        worker = [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "2", "--nworkers", "1",
                  "--no-dashboard"]
        hidden = _namespaces()
        if hidden:  # the client's FMU cache under an empty tmpfs in the worker's own mount namespace
            worker = ["unshare", "--mount", "--propagation", "private", "sh", "-c",  # $0: the cache; $@: the worker
                      'mount -t tmpfs tmpfs "$0" && exec "$@"', str(fmu_cache), *worker]
        processes.append(subprocess.Popen(worker, cwd=worker_cwd, env=env, stdout=subprocess.DEVNULL,
                                          stderr=logs[1].open("w")))
        _wait_for(lambda: "Registered to" in logs[1].read_text(), "the dask worker", logs)
        yield address, worker_tmp, hidden
    finally:
        for process in reversed(processes):
            process.terminate()
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()


def _tasks(fmu_cache):
    case = wscc9.case()
    files = tuple(generator_files(case, "reference", fmu_cache))
    pairs = contingencies(case.network, [5], "each")
    return [ScreeningTask(case, Contingency(bus, 0.1, trip, 0.0, complex(0, 1e-6), case.network), "reference",
                          files, MasterSettings(), 1.5, 0.004) for bus, trip in pairs]


def test_a_worker_without_the_clients_files_screens_the_same_rows_and_keeps_nothing(remote_worker, fmu_cache):
    address, worker_tmp, hidden = remote_worker
    tasks = _tasks(fmu_cache)  # the FMUs built into the client's cache
    if hidden:
        from dask.distributed import Client

        with Client(address) as client:  # the worker sees an empty folder where the client has them
            assert list(client.run(os.listdir, str(fmu_cache)).values()) == [[]] and any(fmu_cache.iterdir())
    local = screen(tasks, workers=0, progress=False)
    remote = screen(tasks, scheduler=address, progress=False)
    assert remote == local
    assert len(remote) == len(tasks) and all(r["bounded"] for r in remote)
    left = [p for p in worker_tmp.rglob("*") if p.name.startswith(("opfmu_", "opfmu-"))]
    assert left == []  # the files that travelled and the FMUs extracted from them removed on the worker
