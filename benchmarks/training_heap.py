"""A full-batch training's epochs with freed tensor memory kept in the heap (surrogate.heap, as
`train` runs) against glibc's own thresholds and against thresholds of 16 GB set in the environment
(which mallopt cannot set), in one run, the tries interleaved, each in a fresh process.

    python benchmarks/training_heap.py --data DIR [--epochs 10] [--rounds 3] [--out benchmarks/training_heap]

DIR is a dataset of a sub-system (`opfmu operator --subsystem ... --out OUT` writes OUT/data); the
training settings are those `opfmu operator` trains it with. Prints and writes (OUT.json, OUT.md)
epochs per second, CPU seconds per epoch and pages mapped anew per epoch, medians over the rounds.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from surrogate.heap import ENVIRONMENT  # noqa: E402

MODES = {"glibc": "glibc's thresholds", "kept": "freed memory kept (2 GB, as train runs)",
         "environment": "16 GB thresholds from the environment"}
SIXTEEN_GB = str(16 * 2**30)


def one_try(data: str, epochs: int, mode: str) -> dict:
    """Trains `epochs` epochs in this process; its wall and CPU seconds and minor page faults. mode:
    a key of MODES (glibc: the training's heap setting taken out)."""
    import surrogate.training as training
    from cosim.subsystem_operator import training_config
    from surrogate.data import load_metadata

    if mode == "glibc":
        training.freed_memory_kept = contextlib.nullcontext
    meta = load_metadata(Path(data))
    config = training_config(meta["state_names"], 0, epochs)
    with tempfile.TemporaryDirectory() as run:
        usage, wall = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
        result = training.train(data, config, run, progress=False)
        wall = time.perf_counter() - wall
        after = resource.getrusage(resource.RUSAGE_SELF)
    return {"epochs": result.epochs, "epoch_wall_s": result.wall_s / result.epochs,
            "run_wall_s": wall, "cpu_s": after.ru_utime + after.ru_stime - usage.ru_utime - usage.ru_stime,
            "system_cpu_s": after.ru_stime - usage.ru_stime, "minor_faults": after.ru_minflt - usage.ru_minflt}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="a sub-system's dataset folder")
    parser.add_argument("--epochs", type=int, default=10, help="epochs per try (default 10)")
    parser.add_argument("--rounds", type=int, default=3, help="tries of each heap setting, interleaved (default 3)")
    parser.add_argument("--out", default="benchmarks/training_heap", help="OUT.json and OUT.md (default %(default)s)")
    parser.add_argument("--one", choices=list(MODES), help=argparse.SUPPRESS)  # a try, in its own process
    args = parser.parse_args()
    if args.one:
        print(json.dumps(one_try(args.data, args.epochs, args.one)))
        return
    rows = []
    for round_ in range(args.rounds):
        for mode in list(MODES)[::1 if round_ % 2 == 0 else -1]:
            env = {k: v for k, v in os.environ.items() if k not in ENVIRONMENT}
            if mode == "environment":
                env |= {"MALLOC_MMAP_THRESHOLD_": SIXTEEN_GB, "MALLOC_TRIM_THRESHOLD_": SIXTEEN_GB}
            out = subprocess.run([sys.executable, __file__, "--data", args.data, "--epochs", str(args.epochs),
                                  "--one", mode], check=True, capture_output=True, text=True, env=env).stdout
            row = {"round": round_, "mode": MODES[mode], **json.loads(out.splitlines()[-1])}
            rows.append(row)
            print(f"round {round_}: {row['mode']}: {1 / row['epoch_wall_s']:.3f} epochs/s", flush=True)
    table = {}
    for mode in MODES.values():
        mine = [r for r in rows if r["mode"] == mode]
        table[mode] = {
            "epochs_per_s": statistics.median(1 / r["epoch_wall_s"] for r in mine),
            "cpu_s_per_epoch": statistics.median(r["cpu_s"] / r["epochs"] for r in mine),
            "system_share": statistics.median(r["system_cpu_s"] / r["cpu_s"] for r in mine),
            "pages_per_epoch": statistics.median(r["minor_faults"] / r["epochs"] for r in mine)}
    base = table[MODES["glibc"]]["epochs_per_s"]
    ratios = {m: v["epochs_per_s"] / base for m, v in table.items()}
    lines = [f"Training epochs on {args.data} ({args.epochs} epochs a try, median of {args.rounds} interleaved tries, "
             "each in a fresh process)", "",
             "| heap | epochs/s | against glibc's | CPU s/epoch | system share of CPU | pages mapped anew/epoch |",
             "| --- | ---: | ---: | ---: | ---: | ---: |"]
    lines += [f"| {m} | {v['epochs_per_s']:.3f} | {ratios[m]:.2f}x | {v['cpu_s_per_epoch']:.2f} | "
              f"{v['system_share']:.0%} | {v['pages_per_epoch']:.0f} |" for m, v in table.items()]
    Path(args.out + ".json").write_text(json.dumps({"args": vars(args), "rows": rows, "table": table,
                                                    "ratios": ratios}, indent=1))
    Path(args.out + ".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
