"""Hostile inputs to `opfmu grid run|cct|screen`, each run as a user runs it (`python -m opfmu` in a
process of its own, with a fresh TMPDIR): a scheduler address that is malformed, of another
scheme, unreachable or not a dask scheduler, too many workers, an --out that names no folder —
each one line on stderr, exit code 2, no traceback, nothing printed before it, nothing left in
TMPDIR and no output folder made; Ctrl-C while the local workers start or during a run ends in one
line and leaves nothing; the CCT is also printed after the fault start; result.csv carries its
units and times on the step."""
import json
import os
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from conftest import interrupt_and_wait, opfmu_process, signal_dispositions
from opfmu.cli import usable_cores

WAIT_S = 120  # s: a process not at the awaited point by then fails the test with its stderr


def _run(argv, tmp_path):
    """(exit code, stdout, stderr, TMPDIR) of `python -m opfmu argv` in `tmp_path` with a fresh TMPDIR."""
    scratch = tmp_path / "tmp"
    scratch.mkdir(exist_ok=True)
    done = subprocess.run([sys.executable, "-m", "opfmu", *map(str, argv)], cwd=tmp_path, capture_output=True,
                          text=True, env=dict(os.environ, TMPDIR=str(scratch)), timeout=300)
    return done.returncode, done.stdout, done.stderr, scratch


def _refused(argv, tmp_path, message):
    code, out, err, scratch = _run(argv, tmp_path)
    assert code == 2, err
    assert out == "" and err.startswith("error: ") and err.count("\n") == 1 and "Traceback" not in err, err
    assert message in err, err
    assert list(scratch.iterdir()) == []
    assert not (tmp_path / "out").exists()
    return err


SCREEN = ["grid", "screen", "--fmus", "monolithic", "--faults", "7", "--trips", "none", "--stop", "0.5",
          "--resolution", "0.05", "--out", "out"]


@pytest.mark.parametrize("address, message", [
    ("http://localhost:8786", "not a 'http' address"),
    ("ftp://example.org:21", "not a 'ftp' address"),
    ("/tmp/scheduler.json", "is not an address"),
    ("::::", "is not an address"),
    ("", "is not an address"),
    ("tcp://localhost:99999", "the port must be a number in [1, 65535]"),
    ("tcp://localhost:port", "the port must be a number"),
    ("tcp://[::1:8786", "is not an address"),
    ("tcp://host name:8786", "is not an address"),
    ("no-such-host.invalid:8786", "cannot resolve no-such-host.invalid"),
])
def test_a_scheduler_address_that_is_no_tcp_address_is_one_line_and_exit_code_2(address, message, tmp_path):
    _refused(SCREEN + ["--scheduler", address], tmp_path, message)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_scheduler_that_is_not_there_is_one_line_and_exit_code_2(tmp_path):
    _refused(SCREEN + ["--scheduler", f"tcp://127.0.0.1:{_free_port()}"], tmp_path, "cannot reach 127.0.0.1")


@pytest.fixture
def server():
    """A TCP server on 127.0.0.1 that greets each connection with `greeting` (None: says nothing),
    as another protocol's server does; yields a function of the greeting giving its port."""
    listeners = []

    def serve(greeting):
        listener = socket.socket()
        listener.bind(("127.0.0.1", 0))
        listener.listen()
        listeners.append(listener)

        def accept():
            held = []
            while True:
                try:
                    connection, _ = listener.accept()
                except OSError:
                    return
                held.append(connection)  # kept open, silent or after the greeting
                if greeting is not None:
                    connection.sendall(greeting)

        threading.Thread(target=accept, daemon=True).start()
        return listener.getsockname()[1]

    yield serve
    for listener in listeners:
        listener.close()


@pytest.mark.parametrize("greeting, message", [
    (b"SSH-2.0-OpenSSH_9.6\r\n", "is not a dask scheduler"),  # read as a dask frame: a length of exabytes
    (None, "no dask scheduler answered"),  # an HTTP server waits for a request
])
def test_a_server_that_is_not_a_dask_scheduler_is_one_line_and_exit_code_2(greeting, message, server, tmp_path):
    _refused(SCREEN + ["--scheduler", f"127.0.0.1:{server(greeting)}"], tmp_path, message)


@pytest.mark.parametrize("workers", [-1, 100000, usable_cores() + 1])
def test_more_workers_than_cores_or_fewer_than_none_is_one_line_and_exit_code_2(workers, tmp_path):
    _refused(SCREEN + ["--workers", str(workers)], tmp_path, f"--workers must lie in [0, {usable_cores()}]")


@pytest.mark.parametrize("command", [
    ["grid", "run", "--fmus", "monolithic", "--fault", "7", "--clear", "0.1", "--stop", "0.3", "--compare", "none"],
    SCREEN[:-2],
])
def test_an_out_that_names_no_folder_is_one_line_and_exit_code_2(command, tmp_path):
    _refused(command + ["--out", ""], tmp_path, "--out must name a folder, got ''")
    _refused(command + ["--out", "  "], tmp_path, "--out must name a folder")
    (tmp_path / "a_file").write_text("")
    _refused(command + ["--out", "a_file"], tmp_path, "--out a_file is a file, not a folder")
    _refused(command + ["--out", "a_file/out"], tmp_path, "a_file is a file")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file", "tmp"]


def _wait_until(condition, process, what: str) -> None:
    deadline = time.monotonic() + WAIT_S
    while not condition():
        if process.poll() is not None or time.monotonic() > deadline:
            process.kill()
            pytest.fail(f"{what} never came: {process.stderr.read()[-3000:]}")
        time.sleep(0.05)


def _children(pid: int) -> list:
    """The processes whose parent is `pid`."""
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    parent = int(f.read().rsplit(")", 1)[1].split()[1])
            except OSError:
                continue
            if parent == pid:
                found.append(int(entry))
    return found


def _gone(pids) -> bool:
    return not any(os.path.exists(f"/proc/{p}") for p in pids)


@pytest.mark.parametrize("command", [["grid", "run", "--compare", "none", "--stop", "0.1"], ["grid", "export"]])
def test_an_empty_case_or_dynamic_data_nested_past_the_parser_is_one_line_and_exit_code_2(command, tmp_path):
    _refused(command + ["--case", "", "--out", "out"], tmp_path, "--case must name a case")
    (tmp_path / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    _refused(command + ["--case", "ieee14", "--dynamic-data", "deep.json", "--out", "out"], tmp_path,
             "deep.json is not a readable JSON file (maximum recursion depth exceeded")


@pytest.mark.skipif(not os.path.isdir("/proc"), reason="finds the command's child processes in /proc")
def test_ctrl_c_while_the_local_workers_start_ends_in_one_line_and_leaves_nothing(tmp_path):
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    # every bus faulted with every trip, each to 30 s at a fine resolution: far more work than the
    # moments between the fork server's start and the interrupt, so that the run cannot end first
    long = ["grid", "screen", "--fmus", "monolithic", "--stop", "30", "--resolution", "0.0005",
            "--out", tmp_path / "out", "--workers", str(min(2, usable_cores()))]
    screening = opfmu_process(long, env=dict(os.environ, TMPDIR=str(scratch)))
    _wait_until(lambda: _children(screening.pid), screening, "the fork server of the local workers")
    started = _children(screening.pid)
    code, err = interrupt_and_wait(screening, WAIT_S)
    lines = err.splitlines()
    assert code == 130 and lines[-1] == "interrupted" and err.count("interrupted") == 1, err
    assert all(line.startswith("contingencies: ") for line in lines[:-1]), err  # no warning, no traceback
    assert list(scratch.iterdir()) == [] and not (tmp_path / "out").exists()
    deadline = time.monotonic() + WAIT_S  # the fork server and its workers end with the command
    while not _gone(started) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _gone(started)


def test_ctrl_c_during_a_run_leaves_no_extracted_fmus_and_no_output_folder(tmp_path):
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    run = opfmu_process(["grid", "run", "--fmus", "reference", "--fault", "7", "--clear", "0.1", "--stop", "600",
                         "--compare", "none", "--out", tmp_path / "out"], env=dict(os.environ, TMPDIR=str(scratch)))
    # os.walk passes over a folder removed while it looks (an FMU build's, done): rglob raised there
    _wait_until(lambda: any(d.startswith("opfmu_fmu_") for _, dirs, _ in os.walk(scratch) for d in dirs), run,
                "the FMUs' extraction")
    signals = signal_dispositions(run.pid)  # said where the run did not take the Ctrl-C
    code, err = interrupt_and_wait(run, WAIT_S)
    assert code == 130 and err.splitlines()[-1] == "interrupted" and "Traceback" not in err, f"{signals}\n{err}"
    assert list(scratch.iterdir()) == [] and not (tmp_path / "out").exists()


def test_cct_is_also_printed_after_the_fault_start(tmp_path):
    argv = ["grid", "cct", "--fmus", "monolithic", "--fault", "9", "--trip", "8-9", "--fault-start", "0.5",
            "--stop", "2.5", "--resolution", "0.01"]
    code, out, err, _ = _run(argv, tmp_path)
    assert code == 0, err
    code, text, err, _ = _run(argv + ["--json"], tmp_path)
    found = json.loads(text)
    assert found["bounded"] and found["cct_after_fault_start_s"] == round(found["cct_s"] - 0.5, 9)
    assert (f"critical clearing time {found['cct_s']:.4f} s, CCT {found['cct_after_fault_start_s']:.4f} s after "
            "the fault start at 0.5 s") in out


def test_result_csv_names_its_units_and_gives_times_on_the_step(tmp_path):
    import pandas as pd

    code, _, err, _ = _run(["grid", "run", "--fmus", "monolithic", "--fault", "7", "--clear", "0.0717", "--step",
                            "0.1", "--stop", "1", "--compare", "none", "--out", "out"], tmp_path)
    assert code == 0, err
    path = tmp_path / "out" / "result.csv"
    names, units, *rows = path.read_text().splitlines()
    assert units.startswith("# ") and len(units[2:].split(",")) == len(names.split(","))
    unit = dict(zip(names.split(","), units[2:].split(",")))
    assert (unit["time"], unit["delta_2"], unit["omega_2"], unit["Efd_2"], unit["V_7"], unit["theta_7"]) == (
        "s", "rad", "rad/s", "pu", "pu", "rad")
    assert unit["SM4_2_Eq_p"] == "pu" and unit["SM4_2_P"] == "pu"
    times = [r.split(",", 1)[0] for r in rows]
    assert times[:3] == ["0", "0.0717", "0.1"] or times[:2] == ["0", "0.0717"]
    assert {"0.3", "0.7", "1"} <= set(times)  # 3 * 0.1 is 0.30000000000000004 in binary
    table = pd.read_csv(path, comment="#")
    assert list(table.columns) == names.split(",") and all(pd.api.types.is_numeric_dtype(t) for t in table.dtypes)
    data = np.genfromtxt(path, delimiter=",", names=True)
    assert data.dtype.names[:2] == ("time", "delta_1") and len(data) == len(rows)
