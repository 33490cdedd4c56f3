"""Ctrl-C that this process never loses: not to the workers it starts, not to code that drops it.

A terminal sends Ctrl-C (SIGINT) to the whole process group: every dask worker would end with its
own traceback while this process closes the cluster. Processes started inside `interrupts_held`
inherit SIGINT blocked (the signal mask survives fork and exec, and multiprocessing's fork server
never unblocks it), so a Ctrl-C reaches this process alone; one that comes while the block runs is
held and raised as KeyboardInterrupt where the block ends, never lost.

Python raises a Ctrl-C as KeyboardInterrupt in whatever Python code runs when it comes, and some
code drops it: the initialisation of an extension module (lxml.etree's, imported by fmpy the first
time an FMU's model description is read) clears an exception raised in the Python it calls, and
ctypes prints and drops one raised in a callback (an FMU's logger). `ctrl_c_taken` raises it after
such code instead: an import or a function marked `called_from_c` finishes first, then the
KeyboardInterrupt comes."""
from __future__ import annotations

import _thread
import signal
import threading
from contextlib import contextmanager

_SIGINT = {signal.SIGINT}
RETRY_S = 0.02  # s: how often a Ctrl-C deferred past an import or a callback looks again
_CALLED_FROM_C: set = set()  # the code objects of functions marked called_from_c
_IMPORT_MACHINERY = ("importlib._bootstrap", "importlib._bootstrap_external")  # frozen or not


def called_from_c(function):
    """Marks `function` as a ctypes callback (decorator): a Ctrl-C that comes while it, or what it
    calls, runs is raised after it returns (ctypes would print and drop it)."""
    _CALLED_FROM_C.add(function.__code__)
    return function


def _deferred(frame) -> bool:
    """True where `frame` or a frame under it is an import or a function marked called_from_c."""
    while frame is not None:
        if frame.f_code in _CALLED_FROM_C or frame.f_globals.get("__name__") in _IMPORT_MACHINERY:
            return True
        frame = frame.f_back
    return False


_pending = [False]  # a Ctrl-C deferred and not yet raised
_pending_lock = threading.RLock()  # re-entered where the handler runs while the block ends


def _again() -> None:
    """SIGINT once more to the main thread (waking a blocking call there; where threads take no
    signals, as on Windows, the handler is called at its next Python step) while the deferred
    Ctrl-C is pending."""
    with _pending_lock:
        if _pending[0]:
            if hasattr(signal, "pthread_kill"):
                signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)
            else:
                _thread.interrupt_main()


def _on_ctrl_c(signum, frame) -> None:
    deferred = frame is not None and _deferred(frame)
    with _pending_lock:
        _pending[0] = deferred
    if not deferred:
        raise KeyboardInterrupt
    retry = threading.Timer(RETRY_S, _again)
    retry.daemon = True
    retry.start()


@contextmanager
def ctrl_c_taken():
    """Within the block a Ctrl-C is a KeyboardInterrupt raised where no import and no function
    marked called_from_c runs; one still deferred where the block ends is raised there. The
    handler before it is back after the block. It does nothing off the main thread, and where
    SIGINT has another handler than Python's own (ignored, as in a process started in the
    background; or the caller's)."""
    if threading.current_thread() is not threading.main_thread() or \
            signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return
    previous = signal.signal(signal.SIGINT, _on_ctrl_c)
    try:
        yield
    finally:
        with _pending_lock:
            pending, _pending[0] = _pending[0], False
        signal.signal(signal.SIGINT, previous)  # Python's own: the only one the block replaces
    if pending:
        raise KeyboardInterrupt


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
