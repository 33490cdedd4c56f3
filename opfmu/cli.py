"""The `opfmu` command line. User mistakes end in one line on stderr and exit code 2."""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path


class UserError(Exception):
    """A mistake in what the user asked for: reported as one line, exit code 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line instead of usage + message
        raise UserError(f"{self.prog}: {message}")


def _cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def cmd_data(args) -> None:
    from surrogate.data import generate
    from surrogate.data.plots import plot_preview
    from surrogate.data.presets import load_preset
    from surrogate.data.runner import SolveRunner

    if args.workers < 0:
        raise UserError("--workers must be >= 0")
    try:
        recipe = load_preset(args.preset)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    meta = generate(recipe, args.out, seed=args.seed, runner=SolveRunner(args.workers, args.scheduler),
                    progress=not args.quiet)
    preview = plot_preview(args.out)
    print(summary_table(meta))
    print(f"dataset written to {args.out} ({meta['wall_time_s']} s); preview: {preview}")


def summary_table(meta: dict) -> str:
    """The dataset's counts and envelope as a small text table."""
    lines = [f"preset {meta['preset']['name']}, seed {meta['seed']}: "
             + ", ".join(f"{k} {v}" for k, v in meta["counts"].items()),
             f"{'quantity':<10}{'min':>10}{'max':>10}   (training envelope: x0 and u)"]
    for group in ("x0", "u"):
        for name, (lo, hi) in meta["envelope"][group].items():
            lines.append(f"{name:<10}{lo:>10.4f}{hi:>10.4f}")
    if "reachable" in meta:
        lines.append(f"reachable states ({meta['reachable']['probes']} probe windows from equilibria):")
        for name, (lo, hi) in meta["reachable"]["all"].items():
            lines.append(f"{name:<10}{lo:>10.4f}{hi:>10.4f}")
    return "\n".join(lines)


def cmd_demo(args) -> None:
    """The main job on defaults, as far as the pipeline is built: a quick co-simulation dataset."""
    args.preset, args.seed, args.scheduler, args.quiet = "quick", 0, None, False
    out = Path(args.out)
    args.out = str(out / "data")
    cmd_data(args)
    print(f"demo run directory: {out}")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="opfmu", description=__doc__)
    parser.add_argument("--version", action="version", version=_version())
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    data = sub.add_parser("data", help="generate labeled and collocation datasets with RK45",
                          description="Generate train/collocation/val/test splits (resumes an interrupted run).")
    data.add_argument("--preset", default="paper",
                      help="paper | cosim | quick, or a JSON file of Preset fields (default: paper)")
    data.add_argument("--out", required=True, help="dataset directory")
    data.add_argument("--seed", type=int, default=0, help="base seed; same seed, same files (default 0)")
    data.add_argument("--workers", type=int, default=_cores(),
                      help="local dask worker processes; 0 solves in this process (default: all cores)")
    data.add_argument("--scheduler", default=None, help="address of a running dask scheduler to use instead")
    data.add_argument("--quiet", action="store_true", help="no progress bars")
    data.set_defaults(func=cmd_data)

    demo = sub.add_parser("demo", help="run the main job end to end on defaults")
    demo.add_argument("--out", default="runs/demo", help="run directory (default runs/demo)")
    demo.add_argument("--workers", type=int, default=_cores(), help="dask worker processes (default: all cores)")
    demo.set_defaults(func=cmd_demo)
    return parser


def _version() -> str:
    from opfmu import __version__

    return f"opfmu {__version__}"


def main(argv=None) -> int:
    from surrogate.data import DatasetError

    try:
        args = build_parser().parse_args(argv)
        args.func(args)
    except (UserError, DatasetError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except RuntimeError as exc:  # a failed reference solve: finished work is kept for the rerun
        print(f"failed: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted: rerun the same command to resume", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
