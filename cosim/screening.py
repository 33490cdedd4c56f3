"""Contingency screening: many faults and clearing actions as independent runs, on a dask cluster
(a LocalCluster of single-threaded worker processes, or an existing scheduler), with a progress
report (a bar on a terminal, a line every few seconds otherwise: reference_models.progress).

Each task is one contingency: its critical clearing time by bisection (stability.py), its verdict
when cleared at the screening's clearing time, and the first-swing peak of that run; a task runs
FMUs through the master, the monolithic DAE or ANDES' own simulation (kind "andes", where installed).
The default faults of a case (`default_fault_buses`) are its buses without a generator: wscc9's
4-9, Kundur's 5-10 (the two areas and the tie), and for ieee14, ieee39 and npcc every load and
transmission bus; a fault at a generator's own terminal is left out (a screening names it if wanted). FMUs are built
once, before any task is sent.

On dask the files a task needs (its FMUs, the case file ANDES reads) travel by content: the client
reads each once and scatters its bytes, keyed by their sha256, to every worker; a worker writes each
into a folder of its own (under its dask local directory, in its own temporary folder) the first
time a task needs it, so a worker needs no access to the client's disk. A worker opens the FMUs
once per thread and reuses them for every task it gets (the master rewinds them between runs); at
the end of a screening every worker closes them and removes its folder. In this process (workers
0) the files are used where they are. The client's own scratch folder (the local workers' folder,
and where FMUs are extracted without dask) is removed at the end whatever happened (also on an
interrupt). The local workers are forked from a fork server started with SIGINT blocked, which they
inherit: a Ctrl-C reaches the command alone (also while they start), and is reported once, by it.
"""
from __future__ import annotations

import hashlib
import ipaddress
import logging
import math
import re
import os
import shutil
import signal
import socket
import struct
import tempfile
import threading
from dataclasses import dataclass, replace
from pathlib import Path

from reference_models.files import atomic_path
from reference_models.grid.contingency import Contingency
from reference_models.interrupts import interrupts_held

from .master import MasterSettings
from .stability import critical_clearing_time, default_stop, first_swing_peak, run_verdict, runner_stable

DASK_SCHEDULER_PORT = 8786  # dask's default scheduler port: an address without one gets it
SCHEDULER_TIMEOUT_S = 5.0  # s: reaching a scheduler and its answer, each
_HANDSHAKE_LIMIT = 1 << 16  # bytes: a dask handshake is a few hundred; more is another protocol
_HOST_NAME = re.compile(r"[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?(\.[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?)*")


class SchedulerError(ValueError):
    """A dask scheduler address that cannot be used: malformed, of another scheme, unreachable, or
    not a dask scheduler (one line)."""


@dataclass(frozen=True)
class ScreeningTask:
    """What a worker needs: the case, the contingency (its clearing time is the screening's), the run
    kind ("monolithic", "andes" or an FMU kind) and FMU files (cosim.fmus.UnitFiles; () for the
    others), the master's settings (its step is also ANDES' step), the runs' stop [s] (None:
    stability.default_stop of the contingency) and the CCT's resolution [s], the scratch folder
    FMUs are extracted under, and `cct` (False: the verdict run only, no bisection)."""

    case: object
    contingency: Contingency
    kind: str
    files: tuple
    settings: MasterSettings
    stop: float | None
    resolution: float
    scratch: str | None = None
    cct: bool = True


@dataclass(frozen=True)
class Content:
    """A file that travels to the workers by its content: the sha256 of its bytes (hex) and its name
    (kept: ANDES reads a case file by its suffix)."""

    sha256: str
    name: str


def default_fault_buses(network) -> list:
    """The buses a screening faults unless told otherwise: every bus of `network` (case.Network)
    without a generator, in file order (wscc9: 4-9)."""
    generators = set(network.generator_buses)
    return [b for b in network.buses if b not in generators]


def contingencies(network, buses, trips: str = "each") -> list:
    """Faults at `buses` of `network` (case.Network), each without a trip and (trips "each") with
    every branch at the bus that can open without cutting a generator off; clearing times are set
    per screening. ValueError for an unknown bus."""
    out = []
    for bus in buses:
        network.bus_index(bus)
        out.append((bus, None))
        if trips == "each":
            out += [(bus, t) for t in network.trips_at(bus)]
    return out


def scheduler_address(text: str) -> tuple:
    """(host, port) of a dask scheduler address, `tcp://HOST:PORT` or `HOST:PORT` (the port may be
    left out: DASK_SCHEDULER_PORT; an IPv6 host in brackets); SchedulerError for anything else."""
    address = text.strip()
    scheme, sep, rest = address.partition("://")
    if not sep:
        scheme, rest = "tcp", address
    if scheme.lower() != "tcp":
        raise SchedulerError(f"--scheduler {text!r}: a dask scheduler address is tcp://HOST:PORT, not a {scheme!r} "
                             "address")
    if rest.startswith("["):
        host, bracket, tail = rest[1:].partition("]")
        if not bracket or (tail and not tail.startswith(":")):
            raise SchedulerError(f"--scheduler {text!r} is not an address (tcp://HOST:PORT)")
        port = tail[1:] if tail else None
        try:
            ipaddress.IPv6Address(host)
        except ValueError:
            raise SchedulerError(f"--scheduler {text!r}: {host!r} is not an IPv6 address") from None
    else:
        host, colon, port = rest.partition(":")
        port = port if colon else None
        if not _HOST_NAME.fullmatch(host) or len(host) > 253:
            raise SchedulerError(f"--scheduler {text!r} is not an address (tcp://HOST:PORT)")
    if port is None:
        return host, DASK_SCHEDULER_PORT
    if not (port.isascii() and port.isdigit() and 0 < int(port) < 65536):
        raise SchedulerError(f"--scheduler {text!r}: the port must be a number in [1, 65535]")
    return host, int(port)


def check_scheduler(text: str, timeout: float = SCHEDULER_TIMEOUT_S) -> str:
    """The tcp:// address of the dask scheduler `text` names, once it has answered as one: its host
    resolved and connected within `timeout` [s], and its first message a dask handshake (a length
    of at most _HANDSHAKE_LIMIT bytes, then that many bytes naming a pickle protocol) within
    `timeout` more. SchedulerError (one line) otherwise: nothing larger is read from a server that
    speaks another protocol."""
    host, port = scheduler_address(text)
    found = {}

    def resolve():
        try:
            found["addresses"] = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
        except OSError as exc:
            found["error"] = exc

    resolving = threading.Thread(target=resolve, daemon=True)  # getaddrinfo has no timeout of its own
    resolving.start()
    resolving.join(timeout)
    if "addresses" not in found:
        reason = found["error"].strerror if "error" in found else f"no answer in {timeout:g} s"
        raise SchedulerError(f"--scheduler {text!r}: cannot resolve {host} ({reason})")
    family, kind, proto, _, where = found["addresses"][0]
    try:
        with socket.socket(family, kind, proto) as connection:
            connection.settimeout(timeout)
            connection.connect(where)
            length = _receive(connection, 8)
            (size,) = struct.unpack("Q", length)  # dask's frame header: the message's length, native order
            if not 0 < size <= _HANDSHAKE_LIMIT or b"pickle-protocol" not in _receive(connection, size):
                raise SchedulerError(f"--scheduler {text!r}: the server at {host}:{port} is not a dask scheduler")
    except socket.timeout:
        raise SchedulerError(f"--scheduler {text!r}: no dask scheduler answered at {host}:{port} within "
                             f"{timeout:g} s") from None
    except OSError as exc:
        raise SchedulerError(f"--scheduler {text!r}: cannot reach {host}:{port} "
                             f"({exc.strerror or type(exc).__name__})") from None
    return f"tcp://[{host}]:{port}" if ":" in host else f"tcp://{host}:{port}"


def _receive(connection, size: int) -> bytes:
    """`size` bytes from `connection`; ConnectionError where it closes before."""
    data = b""
    while len(data) < size:
        chunk = connection.recv(size - len(data))
        if not chunk:
            raise ConnectionError(0, "closed by the server")
        data += chunk
    return data


def travelling(tasks) -> tuple:
    """(tasks, blobs): the tasks with every file they name (their FMUs, the case file and dyr of an
    ANDES case converted from one) replaced by its Content, and blobs {sha256: bytes} of each
    distinct file, each read once."""
    blobs, contents, cases = {}, {}, {}

    def content(path):
        if path is None:
            return None
        path = Path(path)
        if path not in contents:
            data = path.read_bytes()
            digest = hashlib.sha256(data).hexdigest()
            blobs.setdefault(digest, data)
            contents[path] = Content(digest, path.name)
        return contents[path]

    out = []
    for task in tasks:
        files = tuple(replace(f, paths=tuple(content(p) for p in f.paths)) for f in task.files)
        case = task.case
        if getattr(case, "source", None) is not None:
            if id(case) not in cases:
                cases[id(case)] = replace(case, source=tuple(content(p) for p in case.source))
            case = cases[id(case)]
        out.append(replace(task, files=files, case=case))
    return out, blobs


_RUNNERS = {}
_FOLDER = {}  # this process's folder for the files that travelled ("path")
_LOCK = threading.Lock()


def _folder(scratch) -> Path:
    """This process's folder for the files that travelled: made once, under its dask worker's local
    directory (a remote worker's own temporary folder), else under `scratch`."""
    with _LOCK:
        if "path" not in _FOLDER:
            from distributed import get_worker

            try:
                base = get_worker().local_directory
            except ValueError:  # not in a dask worker
                base = scratch
            _FOLDER["path"] = Path(tempfile.mkdtemp(prefix="opfmu_screen_", dir=base))
        return _FOLDER["path"]


def _arrived(item, blobs: dict, folder: Path):
    """The local path of `item` (a Content: written from `blobs` into `folder`/<sha256>/<name> the
    first time, checked against its sha256; anything else as it is)."""
    if not isinstance(item, Content):
        return item
    path = folder / item.sha256 / item.name
    with _LOCK:
        if not path.is_file():
            data = blobs[item.sha256]
            if hashlib.sha256(data).hexdigest() != item.sha256:
                raise RuntimeError(f"{item.name} arrived damaged (its sha256 differs)")
            with atomic_path(path) as tmp:
                tmp.write_bytes(data)
    return path


def screen_travelled(task: ScreeningTask, blobs: dict) -> dict:
    """screen_one of a task from `travelling`, with blobs {sha256: bytes} of its files, in a worker."""
    folder = _folder(task.scratch)
    files = tuple(replace(f, paths=tuple(_arrived(p, blobs, folder) for p in f.paths)) for f in task.files)
    case = task.case
    if getattr(case, "source", None) is not None and any(isinstance(p, Content) for p in case.source):
        case = replace(case, source=tuple(_arrived(p, blobs, folder) for p in case.source))
    return screen_one(replace(task, files=files, case=case, scratch=str(folder)))


def _runner(task: ScreeningTask):
    """A runner per (kind, files, settings, scratch) and thread, opened once per worker thread."""
    from .runners import MasterRunner, MonolithicRunner

    key = (task.kind, task.files, task.settings, task.scratch, threading.get_ident())
    if key not in _RUNNERS:
        if task.kind == "monolithic":
            _RUNNERS[key] = MonolithicRunner(task.case, task.settings.step, 1e-9)
        elif task.kind == "andes":
            from .andes_runner import AndesRunner

            _RUNNERS[key] = AndesRunner(task.case, task.settings.step)
        else:
            _RUNNERS[key] = MasterRunner(task.files, task.case, task.settings, task.scratch)
    return _RUNNERS[key]


def close_runners() -> None:
    """Closes the runners this process opened (their FMUs and extracted files) and removes its folder
    of the files that travelled."""
    while _RUNNERS:
        _, runner = _RUNNERS.popitem()
        runner.close()
    with _LOCK:
        folder = _FOLDER.pop("path", None)
    if folder is not None:
        shutil.rmtree(folder, ignore_errors=True)


def screen_one(task: ScreeningTask) -> dict:
    """The row of one contingency: label, bus, trip, clear_s, stable, first_swing_peak_deg, cct_s,
    bounded, runs (cct_s and bounded None where the task asks for no CCT)."""
    runner = _runner(task)
    c = task.contingency
    stable, _, result = run_verdict(runner, c, task.stop if task.stop is not None else default_stop(c))
    peak = math.degrees(first_swing_peak(result, c.clear_s))
    row = {"label": c.label, "bus": c.fault_bus, "trip": c.trip or "", "clear_s": c.clear_s,
           "stable": stable, "first_swing_peak_deg": peak if stable else None, "cct_s": None, "bounded": None,
           "runs": 1}
    if task.cct:
        cct = critical_clearing_time(runner_stable(runner, task.stop), c, task.resolution)
        row.update(cct_s=cct.cct_s, bounded=cct.bounded, runs=len(cct.runs) + 1)
    return row


WORKER_START_TIMEOUT_S = 120.0  # s: the local workers not all up by then is an error (a start that failed)
CLOSE_TIMEOUT_S = 15.0  # s: a client's or local cluster's close, before it is tried again


# the longest path of a Unix socket (sun_path: 108 bytes on Linux, 104 on the BSDs and macOS), less
# multiprocessing's own "/pymp-<8 characters>/listener-<8 characters>" under its folder
_SOCKET_FOLDER_LIMIT = 104 - 34


def _short_socket_folder() -> None:
    """Where this process's temporary folder (TMPDIR) is too long a path for the fork server's Unix
    socket, multiprocessing's own folder of this process (its sockets) goes under /tmp instead; it
    is removed at exit as it always is (multiprocessing.util.get_temp_dir)."""
    from multiprocessing import process, util

    if "tempdir" in process.current_process()._config:  # already made (and used) by this process
        return
    if len(os.fsencode(tempfile.gettempdir())) > _SOCKET_FOLDER_LIMIT and os.path.isdir("/tmp"):
        folder = tempfile.mkdtemp(prefix="pymp-", dir="/tmp")
        util.Finalize(None, shutil.rmtree, args=(folder,), kwargs={"ignore_errors": True}, exitpriority=-100)
        process.current_process()._config["tempdir"] = folder


def _local_cluster(workers: int, scratch: str):
    """(cluster, client): a LocalCluster of `workers` single-threaded processes with `scratch` as their
    folder, and its client. The workers are forked from multiprocessing's fork server, started with
    SIGINT blocked (reference_models.interrupts): they inherit that, so a Ctrl-C reaches this process
    alone. A Ctrl-C while the fork server, the scheduler and the workers start (a second or two) is
    held until they are up (closing a half-started cluster waits on workers still starting); then the
    cluster is closed, its workers with it, and KeyboardInterrupt raised. RuntimeError where the
    workers are not all up within WORKER_START_TIMEOUT_S."""
    import multiprocessing.forkserver

    import dask
    from dask.distributed import Client, LocalCluster
    from distributed.utils import get_mp_context

    with dask.config.set({"temporary-directory": scratch, "distributed.worker.multiprocessing-method": "forkserver"}):
        get_mp_context()  # the fork server's preloaded modules (distributed's)
        cluster = client = None
        try:
            with interrupts_held():
                _short_socket_folder()
                multiprocessing.forkserver.ensure_running()
                # no dashboard; the scheduler's HTTP server on a free local port (its default 8787 may be taken)
                cluster = LocalCluster(n_workers=0, threads_per_worker=1, processes=True, dashboard_address=None,
                                       scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                                       silence_logs=logging.CRITICAL, local_directory=scratch)
                cluster.scale(workers)
                client = Client(cluster)
                try:
                    client.wait_for_workers(workers, timeout=WORKER_START_TIMEOUT_S)
                except TimeoutError:
                    raise RuntimeError(f"the {workers} local dask workers did not start within "
                                       f"{WORKER_START_TIMEOUT_S:g} s") from None
        except BaseException:
            _close_quietly(client, cluster)
            raise
    return cluster, client


def close_workers(client, cluster, close=close_runners) -> None:
    """Runs `close` (by default close_runners: the runners' FMUs and the travelled files) on every
    worker of `client`, then closes `client` and `cluster` (None: a remote scheduler's, left running)
    as _close_quietly does. A worker already gone took its runners with it. A Ctrl-C while `close`
    runs ends it there; the client and the cluster are closed all the same, and KeyboardInterrupt
    then raised."""
    try:
        client.run(close)
    except Exception:  # a worker gone: its runners ended with it
        pass
    finally:
        _close_quietly(client, cluster)


def _close_quietly(client, cluster) -> None:
    """Closes `client` and `cluster` (None: not made yet, or a remote scheduler's) with Ctrl-C held off,
    at the end of a screening or on the way out of an interrupted or failed start. A close that dask's
    shutdown breaks half-way (its coroutine cancelled by the interrupt it follows: distributed's sync
    then raises UnboundLocalError) or that waits past CLOSE_TIMEOUT_S (its event loop left waiting for a
    worker the interrupt stopped half-started) is tried once more; where one still fails, this process's
    child processes (the fork server and the workers it started) are ended, so that nothing outlives the
    command."""
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        closed = True
        for close in [part.close for part in (client, cluster) if part is not None]:
            for _ in range(2):
                try:
                    close(timeout=CLOSE_TIMEOUT_S)
                    break
                except Exception:  # dask's own shutdown failed or hung: once more
                    continue
            else:
                closed = False
        if not closed:
            _end_children()
    finally:
        signal.signal(signal.SIGINT, previous)


def _end_children() -> None:
    """Terminates this process's descendants, and kills those still there a few seconds later; not
    multiprocessing's resource tracker, which ends with this process (ended, it is started again by
    the next clean-up and reports every semaphore it never saw: tracebacks after the one line)."""
    import psutil

    children = [c for c in psutil.Process().children(recursive=True) if not _resource_tracker(c)]
    for child in children:
        try:
            child.terminate()
        except psutil.NoSuchProcess:
            pass
    _, alive = psutil.wait_procs(children, timeout=5.0)
    for child in alive:
        try:
            child.kill()
        except psutil.NoSuchProcess:
            pass


def _resource_tracker(process) -> bool:
    """Whether the psutil Process is multiprocessing's resource tracker (False where it is gone)."""
    import psutil

    try:
        return any("resource_tracker" in part for part in process.cmdline())
    except psutil.Error:
        return False


def screen(tasks, workers: int = 2, scheduler: str | None = None, progress: bool = True) -> list:
    """The rows of every task (in the tasks' order), run on dask: `scheduler` (an address, see
    check_scheduler) or a LocalCluster of `workers` processes (0: in this process, no dask); the
    files of the tasks travel to the workers by content (`travelling`); progress: a bar on a
    terminal, a line every few seconds elsewhere (reference_models.progress). SchedulerError where
    the scheduler cannot be used."""
    from reference_models.progress import progress_bar

    scratch = None if scheduler else tempfile.mkdtemp(prefix="opfmu_screen_")  # remote workers: their own
    report = None
    try:
        tasks = [replace(t, scratch=scratch) for t in tasks]
        report = progress_bar(len(tasks), "contingencies", "runs", enabled=progress)
        rows = [None] * len(tasks)
        if not scheduler and workers == 0:
            try:
                for i, task in enumerate(tasks):
                    rows[i] = screen_one(task)
                    report.update()
            finally:
                close_runners()
            return rows
        from dask.distributed import Client, as_completed

        tasks, blobs = travelling(tasks)
        cluster = None
        if scheduler:
            try:
                client = Client(check_scheduler(scheduler), timeout=f"{SCHEDULER_TIMEOUT_S:g}s")
            except (OSError, TimeoutError) as exc:
                raise SchedulerError(f"--scheduler {scheduler!r}: {' '.join(str(exc).split())}") from None
        else:
            cluster, client = _local_cluster(workers, scratch)
        try:
            sent = client.scatter({f"opfmu-file-{d}": data for d, data in blobs.items()}, broadcast=True,
                                  hash=False) if blobs else {}
            arrived = {key[len("opfmu-file-"):]: future for key, future in sent.items()}
            futures = {client.submit(screen_travelled, task, arrived, pure=False): i for i, task in enumerate(tasks)}
            for future in as_completed(futures):
                rows[futures[future]] = future.result()
                report.update()
        finally:
            close_workers(client, cluster)
        return rows
    finally:
        if report is not None:
            report.close()
        if scratch is not None:
            shutil.rmtree(scratch, ignore_errors=True)
