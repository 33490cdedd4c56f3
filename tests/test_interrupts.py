"""reference_models.interrupts: a Ctrl-C while worker processes start is held for this process and
never reaches the processes started meanwhile."""
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
