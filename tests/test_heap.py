"""The heap a training runs on (surrogate.heap): glibc's, where freed blocks of a full-batch step stay
for the next step (the effect on a training's speed is measured in docs/results.md, not here).

The check runs in a fresh process, started as a command is: its main thread allocates from glibc's
main arena (a thread's own arena grows in heaps of 64 MB, where larger blocks are mapped afresh
regardless), and without the MALLOC_TRIM_THRESHOLD_ that a test's dask nanny put into os.environ."""
import ctypes
import json
import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from surrogate.heap import ENVIRONMENT, _glibc, freed_memory_kept, started_with_heap_settings

ROOT = Path(__file__).resolve().parents[1]
PAGE = resource.getpagesize()
BLOCK = 64 * 2**20  # above glibc's largest self-set mmap threshold (32 MB)

pytestmark = pytest.mark.skipif(_glibc() is None or started_with_heap_settings(),
                                reason="the heap settings are glibc's, where the environment leaves them to it")


def _minor_faults() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt


def _resident_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * PAGE


def _pages_mapped_to_fill_a_block(libc) -> int:
    """Minor page faults of allocating BLOCK bytes and writing them; the block is freed after."""
    pointer = libc.malloc(BLOCK)
    assert pointer, "malloc failed"
    before = _minor_faults()
    libc.memset(pointer, 1, BLOCK)
    faults = _minor_faults() - before
    libc.free(pointer)
    return faults


def measure() -> dict:
    """Pages mapped anew for a block freed just before, within; bytes returned on the way out; pages
    mapped for a block after; in a process whose os.environ gained a heap setting after its start."""
    os.environ["MALLOC_TRIM_THRESHOLD_"] = "65536"  # as dask's nanny leaves it, too late for glibc to read
    libc = _glibc()
    libc.malloc.restype = ctypes.c_void_p
    libc.malloc.argtypes = [ctypes.c_size_t]
    libc.free.argtypes = [ctypes.c_void_p]
    libc.memset.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_size_t]
    with freed_memory_kept():
        _pages_mapped_to_fill_a_block(libc)
        again = _pages_mapped_to_fill_a_block(libc)
        kept = _resident_bytes()
    returned = kept - _resident_bytes()
    return {"again": again, "returned": returned, "after": _pages_mapped_to_fill_a_block(libc)}


def test_a_freed_block_is_given_again_without_new_pages_within_and_goes_back_to_the_kernel_after():
    # a command's environment: without the heap setting that a test's dask nanny put into os.environ here
    env = {k: v for k, v in os.environ.items() if k not in ENVIRONMENT}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))
    done = subprocess.run([sys.executable, __file__], capture_output=True, text=True, env=env, cwd=ROOT, timeout=120)
    assert done.returncode == 0, done.stderr
    got = json.loads(done.stdout)
    pages = BLOCK // PAGE
    assert got["again"] < pages // 100, f"{got['again']} of {pages} pages mapped anew for a block freed just before"
    assert got["returned"] > BLOCK // 2, \
        f"{got['returned']} of the {BLOCK} bytes freed returned to the kernel on the way out"
    assert got["after"] > pages // 2, \
        f"after it, a block above 32 MB is mapped afresh ({got['after']} of {pages} pages), as glibc does"


if __name__ == "__main__":
    print(json.dumps(measure()))
