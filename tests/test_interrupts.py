"""reference_models.interrupts: a Ctrl-C while worker processes start is held for this process and
never reaches the processes started meanwhile; one that comes inside an import or a ctypes callback
is raised after it, not dropped there."""
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Ctrl-C to the whole group (as a terminal sends it) inside the block, after a child and a thread
# that starts a grandchild are up; what happened is printed, line by line
_SCRIPT = textwrap.dedent("""
    import os, signal, subprocess, sys, threading, time
    from reference_models.interrupts import interrupts_held

    sleeper = [sys.executable, "-c", "import time; time.sleep(60)"]
    started = []
    try:
        with interrupts_held():
            started.append(subprocess.Popen(sleeper))
            thread = threading.Thread(target=lambda: started.append(subprocess.Popen(sleeper)))
            thread.start()
            thread.join()
            os.killpg(0, signal.SIGINT)
            time.sleep(0.5)
            print("the block ran on", flush=True)
    except KeyboardInterrupt:
        print("KeyboardInterrupt where the block ended", flush=True)
    time.sleep(0.5)
    for child in started:
        print("child", "running" if child.poll() is None else f"ended {child.returncode}", flush=True)
        child.kill()
    os.kill(os.getpid(), signal.SIGINT)  # after the block: Ctrl-C as before it
    print("not reached", flush=True)
""")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="process groups and signal masks as on Linux")
def test_a_ctrl_c_inside_the_block_is_raised_where_it_ends_and_the_processes_it_started_never_take_it():
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, "-c", _SCRIPT], capture_output=True, text=True, timeout=60, env=env,
                          start_new_session=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert done.stdout.splitlines() == ["the block ran on", "KeyboardInterrupt where the block ended",
                                        "child running", "child running"], done.stdout + done.stderr
    assert "KeyboardInterrupt" in done.stderr and done.returncode != 0  # the default handler is back


# Ctrl-C inside an import whose module drops every exception (as lxml.etree's initialisation drops
# one raised in the Python it calls) and inside a ctypes callback (libc's qsort calling a comparison)
_DROPPED = textwrap.dedent("""
    import ctypes, ctypes.util, os, signal, sys, time
    from reference_models.interrupts import called_from_c, ctrl_c_taken

    def ctrl_c_then_work():
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(50):
            time.sleep(0.001)

    for name in ("dropping", "dropping_last"):
        with open(os.path.join(sys.argv[1], name + ".py"), "w") as f:
            f.write("from __main__ import ctrl_c_then_work\\n"
                    "try:\\n    ctrl_c_then_work()\\nexcept BaseException:\\n    pass\\n")
    sys.path.insert(0, sys.argv[1])

    @called_from_c
    def compare(a, b):
        ctrl_c_then_work()
        return 0

    def import_then_more():
        import dropping
        print("the import ended", flush=True)
        time.sleep(30)  # woken by the Ctrl-C
        print("slept through", flush=True)

    def callback_then_more():
        values = (ctypes.c_int * 2)(2, 1)
        kind = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_int))
        ctypes.CDLL(ctypes.util.find_library("c")).qsort(values, 2, ctypes.sizeof(ctypes.c_int), kind(compare))
        print("the callback returned", flush=True)
        time.sleep(30)
        print("slept through", flush=True)

    def import_last():  # the block ends right after the import: the Ctrl-C is raised there
        import dropping_last

    for work in (import_then_more, callback_then_more, import_last):
        try:
            with ctrl_c_taken():
                work()
            print("not interrupted", flush=True)
        except KeyboardInterrupt:
            print("KeyboardInterrupt", flush=True)
    print("handler back:", signal.getsignal(signal.SIGINT) is signal.default_int_handler, flush=True)

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # as in a process started in the background
    with ctrl_c_taken():
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.1)
    print("ignored:", signal.getsignal(signal.SIGINT) is signal.SIG_IGN, flush=True)
""")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="libc's qsort found by ctypes.util as on Linux")
def test_a_ctrl_c_inside_an_import_or_a_ctypes_callback_is_raised_after_it_not_dropped_and_an_ignored_one_stays_so(
        tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, "-c", _DROPPED, str(tmp_path)], capture_output=True, text=True, timeout=120,
                          env=env, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert done.stdout.splitlines() == ["the import ended", "KeyboardInterrupt", "the callback returned",
                                        "KeyboardInterrupt", "KeyboardInterrupt", "handler back: True",
                                        "ignored: True"], \
        done.stdout + done.stderr
    assert done.stderr == ""  # nothing printed and dropped by ctypes
