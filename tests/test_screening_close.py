"""cosim.screening.close_workers at the end of a screening on a LocalCluster: a Ctrl-C while the
workers close their runners ends that close, the cluster and its workers are closed all the same,
and the Ctrl-C is raised afterwards, not swallowed."""
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# one worker whose close takes 60 s (it marks a file when it starts); Ctrl-C to this process alone
# once it has started; what happened is printed, line by line
_SCRIPT = textwrap.dedent("""
    import logging, os, signal, sys, threading, time
    import psutil
    from dask.distributed import Client, LocalCluster
    from cosim.screening import close_workers

    marker = sys.argv[1]

    def slow_close():
        open(marker, "w").close()
        time.sleep(60)

    def interrupt_once_closing():
        while not os.path.exists(marker):
            time.sleep(0.05)
        os.kill(os.getpid(), signal.SIGINT)

    if __name__ == "__main__":
        cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=logging.CRITICAL)
        client = Client(cluster)
        workers = [c for c in psutil.Process().children(recursive=True)
                   if "resource_tracker" not in " ".join(c.cmdline())]
        threading.Thread(target=interrupt_once_closing, daemon=True).start()
        try:
            close_workers(client, cluster, close=slow_close)
            print("returned", flush=True)
        except KeyboardInterrupt:
            print("KeyboardInterrupt after the close", flush=True)
        print("cluster", cluster.status.name, flush=True)
        print("client", client.status, flush=True)
        _, alive = psutil.wait_procs(workers, timeout=10)
        print("worker processes", "started" if workers else "none", "left", len(alive), flush=True)
""")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="finds the workers among this process's children")
def test_a_ctrl_c_while_the_workers_close_is_raised_after_the_cluster_and_its_workers_are_closed(tmp_path):
    script = tmp_path / "close.py"
    script.write_text(_SCRIPT)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(script), str(tmp_path / "closing")], capture_output=True, text=True,
                          timeout=120, env=env, cwd=tmp_path,
                          preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert done.stdout.splitlines() == ["KeyboardInterrupt after the close", "cluster closed", "client closed",
                                        "worker processes started left 0"], done.stdout + done.stderr[-3000:]
