"""Ctrl-C around the start of worker processes: the workers take none, this process loses none.

A terminal sends Ctrl-C (SIGINT) to the whole process group: every dask worker would end with its
own traceback while this process closes the cluster. Processes started inside `interrupts_held`
inherit SIGINT blocked (the signal mask survives fork and exec, and multiprocessing's fork server
never unblocks it), so a Ctrl-C reaches this process alone; one that comes while the block runs is
held and raised as KeyboardInterrupt where the block ends, never lost."""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager

_SIGINT = {signal.SIGINT}


@contextmanager
def interrupts_held():
    """Within the block SIGINT is blocked on this thread (and on every thread the block starts, so
    on every process those start); a Ctrl-C meanwhile is held and raised as KeyboardInterrupt on the
    way out (where the block raised nothing itself). Off the main thread it does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    from multiprocessing import resource_tracker

    # the tracker's own start unblocks SIGINT on this thread when it is done: it starts first
    resource_tracker.ensure_running()
    held = []
    previous = signal.signal(signal.SIGINT, lambda *_: held.append(True))  # also where another thread takes it
    signal.pthread_sigmask(signal.SIG_BLOCK, _SIGINT)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, _SIGINT)  # one that came meanwhile reaches the holder
        signal.signal(signal.SIGINT, signal.SIG_DFL if previous is None else previous)
    if held:
        raise KeyboardInterrupt
