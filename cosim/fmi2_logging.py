"""FMI 2.0 callback functions whose logger outlives every FMU it serves.

An FMI 2.0 FMU logs through a variadic C function; fmpy formats those messages with one native proxy
per process (`fmpy.logging.addLoggerProxy`), which remembers the Python logger registered last and
calls it for every FMU in the process, including those instantiated with fmpy's default callbacks.
A logger freed with its FMU (fmpy's `instantiate_fmu(logger=...)` makes one per call) leaves that
proxy calling freed memory, and the next FMU that logs anything crashes its importer.

Here the proxy only ever holds one logger, created once and kept for the life of the process. Each
instance gets callbacks whose componentEnvironment is a key of its own; the logger hands the
instance's messages (status, category, formatted text) to the sink registered under that key, and
prints the others as fmpy's default logger does. `callbacks(sink)` registers a sink and returns
(callbacks, key); `release(key)` forgets it once its instance is freed. A bound method is held by a
weak reference, so the sink never keeps its owner alive.
"""
from __future__ import annotations

import itertools
import weakref
from ctypes import byref
from typing import Callable

from fmpy import calloc, free
from fmpy.fmi1 import printLogMessage
from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                       fmi2CallbackLoggerTYPE)

from reference_models.interrupts import called_from_c

Sink = Callable[[int, bytes, bytes], None]  # (fmi2Status, category, message)

_SINKS: dict[int, Callable[[], Sink | None]] = {}
_KEYS = itertools.count(1)


@called_from_c
def _dispatch(env, instance, status, category, message) -> None:
    """The one fmi2CallbackLogger: the message to its instance's sink, or printed."""
    found = _SINKS.get(env or 0)
    sink = found() if found is not None else None
    if sink is None:
        printLogMessage(env, instance, status, category, message)
    else:
        sink(int(status), category or b"", message or b"")


_LOGGER = fmi2CallbackLoggerTYPE(_dispatch)
_ALLOCATE = fmi2CallbackAllocateMemoryTYPE(calloc)
_FREE = fmi2CallbackFreeMemoryTYPE(free)


def callbacks(sink: Sink) -> tuple[fmi2CallbackFunctions, int]:
    """fmi2CallbackFunctions for one instance whose messages go to `sink`, and the key to release."""
    key = next(_KEYS)
    _SINKS[key] = weakref.WeakMethod(sink) if hasattr(sink, "__self__") else (lambda: sink)
    functions = fmi2CallbackFunctions()
    functions.logger = _LOGGER
    functions.allocateMemory = _ALLOCATE
    functions.freeMemory = _FREE
    functions.componentEnvironment = key
    try:
        from fmpy.logging import addLoggerProxy
    except Exception:  # no proxy library for this platform: the FMU's format string arrives unformatted
        return functions, key
    addLoggerProxy(byref(functions))  # the proxy now calls _LOGGER (for every FMU); functions.logger is the proxy
    return functions, key


def release(key: int) -> None:
    """Forgets the sink of a freed instance (idempotent)."""
    _SINKS.pop(key, None)
