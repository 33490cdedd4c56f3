"""Freed tensor memory kept in the process's heap while a training runs, where the C library is glibc.

A full-batch epoch allocates and frees the same intermediate tensors at every step, hundreds of MB
for a sub-system's tens of thousands of windows. glibc serves a block above its mmap threshold
(128 kB at start, raised by itself to at most 32 MB) with a fresh mapping and unmaps it when it is
freed, so every epoch the kernel maps and zeroes that memory again: on a 2-core machine that was
about 60 % of a plant operator's training (perf: clear_page under the page faults of torch's add and
mul kernels; 0.25 epochs/s against 0.63 with the memory kept, docs/results.md).

`freed_memory_kept` raises glibc's mmap and trim thresholds for the duration (blocks up to 2 GB come
from the heap and stay there when freed) and, on the way out, sets them where glibc's own adjustment
leaves a process that has freed large blocks (32 MB and 64 MB) and returns the heap's free memory to
the kernel (malloc_trim). Elsewhere (Windows, macOS, musl) it does nothing.
"""
from __future__ import annotations

import contextlib
import ctypes
import platform

M_TRIM_THRESHOLD = -1  # glibc's mallopt parameters (malloc.h)
M_MMAP_THRESHOLD = -3
ADJUSTED_MMAP_THRESHOLD = 32 * 2**20  # the largest mmap threshold glibc sets itself [bytes]
KEPT_THRESHOLD = 2**31 - 1  # the largest value mallopt takes (an int) [bytes]


def _glibc():
    """The process's glibc (ctypes), or None where the C library is another."""
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return None
    try:
        libc = ctypes.CDLL(None)
        return libc if hasattr(libc, "mallopt") and hasattr(libc, "malloc_trim") else None
    except OSError:
        return None


def _set_thresholds(libc, mmap: int, trim: int) -> None:
    libc.mallopt(M_MMAP_THRESHOLD, mmap)
    libc.mallopt(M_TRIM_THRESHOLD, trim)


@contextlib.contextmanager
def freed_memory_kept():
    """Within: freed blocks up to 2 GB stay in the heap for the next allocation. After: glibc's
    thresholds where its own adjustment would have left them (fixed from then on) and the heap's
    free memory returned."""
    libc = _glibc()
    if libc is None:
        yield
        return
    _set_thresholds(libc, KEPT_THRESHOLD, KEPT_THRESHOLD)
    try:
        yield
    finally:
        _set_thresholds(libc, ADJUSTED_MMAP_THRESHOLD, 2 * ADJUSTED_MMAP_THRESHOLD)
        libc.malloc_trim(0)
