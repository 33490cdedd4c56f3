"""Freed tensor memory kept in the process's heap while a training runs, where the C library is glibc.

A full-batch epoch allocates and frees the same intermediate tensors at every step, hundreds of MB
for a sub-system's tens of thousands of windows. glibc serves a block above its mmap threshold
(128 kB at start, raised by itself to at most 32 MB) with a fresh mapping and unmaps it when it is
freed, so every epoch the kernel maps and zeroes that memory again. On the 2-core machine of
benchmarks/training_heap.md, a plant operator's epoch (83613 windows) spent 43 % of its CPU in the
kernel and mapped 900 000 pages anew: 0.36 epochs/s, against 0.54 with the memory kept.

`freed_memory_kept` raises glibc's mmap and trim thresholds for the duration (blocks up to 2 GB come
from the heap and stay there when freed; in a thread that glibc moved to an arena of its own, whose
heaps grow by at most 64 MB, blocks above that are still mapped afresh) and, on the way out, sets
them where glibc's own adjustment leaves a process that has freed large blocks (32 MB and 64 MB) and
returns the heap's free memory to the kernel (malloc_trim). Elsewhere (Windows, macOS, musl), and
where the process started with an environment that sets glibc's heap (MALLOC_MMAP_THRESHOLD_,
MALLOC_TRIM_THRESHOLD_, GLIBC_TUNABLES), it does nothing. What glibc read is the environment at the
start (/proc/self/environ), not os.environ: dask's nanny puts MALLOC_TRIM_THRESHOLD_ into the
os.environ of the process that starts its workers, as `opfmu operator` does for a machine before it
trains, and glibc never reads it there. mallopt takes an int, so blocks above 2 GB are still mapped
afresh; thresholds set in the environment before the process starts have no such bound (16 GB took
the plant's epochs to 0.63 epochs/s):

    MALLOC_MMAP_THRESHOLD_=17179869184 MALLOC_TRIM_THRESHOLD_=17179869184 opfmu operator ...
"""
from __future__ import annotations

import contextlib
import ctypes
import os
import platform

M_TRIM_THRESHOLD = -1  # glibc's mallopt parameters (malloc.h)
M_MMAP_THRESHOLD = -3
ADJUSTED_MMAP_THRESHOLD = 32 * 2**20  # the largest mmap threshold glibc sets itself [bytes]
KEPT_THRESHOLD = 2**31 - 1  # the largest value mallopt takes (an int) [bytes]
ENVIRONMENT = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "GLIBC_TUNABLES")  # the user's own settings


def _glibc():
    """The process's glibc (ctypes), or None where the C library is another."""
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return None
    try:
        libc = ctypes.CDLL(None)
        return libc if hasattr(libc, "mallopt") and hasattr(libc, "malloc_trim") else None
    except OSError:
        return None


def started_with_heap_settings() -> bool:
    """Whether the environment this process started with (what glibc read) sets glibc's heap."""
    try:
        with open("/proc/self/environ", "rb") as f:
            names = {entry.split(b"=", 1)[0].decode("utf-8", "replace") for entry in f.read().split(b"\0")}
    except OSError:
        names = set(os.environ)
    return any(name in names for name in ENVIRONMENT)


def _set_thresholds(libc, mmap: int, trim: int) -> None:
    libc.mallopt(M_MMAP_THRESHOLD, mmap)
    libc.mallopt(M_TRIM_THRESHOLD, trim)


@contextlib.contextmanager
def freed_memory_kept():
    """Within: freed blocks up to 2 GB stay in the heap for the next allocation. After: glibc's
    thresholds where its own adjustment would have left them (fixed from then on) and the heap's
    free memory returned."""
    libc = _glibc()
    if libc is None or started_with_heap_settings():
        yield
        return
    _set_thresholds(libc, KEPT_THRESHOLD, KEPT_THRESHOLD)
    try:
        yield
    finally:
        _set_thresholds(libc, ADJUSTED_MMAP_THRESHOLD, 2 * ADJUSTED_MMAP_THRESHOLD)
        libc.malloc_trim(0)
