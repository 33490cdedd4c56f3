"""A sub-system operator's windows chained as its FMU chains them, against single windows, on the
test split of its dataset (runs that training never saw): how much of its error comes from the
rollover (issue 35, docs/subsystems.md, `--rollover-share`).

    python benchmarks/subsystem_window_chain.py DATA_DIR OPERATOR.onnx [OPERATOR.onnx ...]

Every test run is cut into chains of windows eight 20 ms strides apart (each starts at the last
one's rollover, 0.16 s; surrogate.training.rollovers finds them; windows at rest alike in two runs
may join their chains). A chain starts from the recorded state; each next window takes its learned states (Ip, Iq, ...) from the operator's answer at the
last one's rollover and its known states as recorded (the FMU steps those by their equations), and
its input as recorded. Prints, per operator, the RMSE and largest error [pu, system base] of each
learned state over window times 10 ms to the rollover, chained and for single windows from the
recorded state, and the ratio of the two RMSEs (1: nothing added at a rollover). Needs the dataset
(`opfmu operator --subsystem ... --out DIR` leaves it in DIR/data), onnxruntime; no ANDES.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from surrogate.data import load_split  # noqa: E402
from surrogate.training import rollovers  # noqa: E402


def levels(found, n_windows: int) -> list:
    """The windows by their place in their chain: level 0 starts at no other's rollover, level k at
    the rollover of a window of level k - 1 (found.earlier[i] < found.later[i], so one pass in order)."""
    before = dict(zip(found.later.tolist(), found.earlier.tolist()))
    level = np.zeros(n_windows, dtype=int)
    for j in range(n_windows):
        if j in before:
            level[j] = level[before[j]] + 1
    return [np.nonzero(level == k)[0] for k in range(level.max() + 1)], before


def errors(session, raw: dict, found, learned) -> tuple:
    """(chained, single) errors [K, n_learned] of the learned states at window times 1..rollover."""
    names = [i.name for i in session.get_inputs()]
    index = found.index
    t = raw["t"][:index + 1].astype(np.float32)
    by_level, before = levels(found, len(raw["x0"]))
    at_rollover = {}
    chained, single = [], []
    for idx in by_level:
        x0 = raw["x0"][idx].copy()
        for row, j in enumerate(idx):
            if j in before:
                x0[row, learned] = at_rollover[before[j]]
        answer = lambda start: session.run(None, dict(zip(names, (start.astype(np.float32),  # noqa: E731
                                                                    raw["u"][idx].astype(np.float32), t))))[0]
        got, alone = answer(x0), answer(raw["x0"][idx])
        truth = raw["x"][idx][:, 1:index + 1][..., learned]
        chained.append((got[:, 1:][..., learned] - truth).reshape(-1, len(learned)))
        single.append((alone[:, 1:][..., learned] - truth).reshape(-1, len(learned)))
        at_rollover.update(zip(idx.tolist(), got[:, index][:, learned].astype(float)))
    return np.concatenate(chained), np.concatenate(single)


def main(argv=None) -> int:
    import onnxruntime as ort

    args = sys.argv[1:] if argv is None else argv
    if len(args) < 2:
        print(__doc__.split("\n\n")[1].strip(), file=sys.stderr)
        return 2
    raw = load_split(args[0], "test", frame=False)
    component = raw["component"]
    found = rollovers(raw, component, causal=True)
    learned = found.learned.numpy()
    by_level, _ = levels(found, len(raw["x0"]))
    print(f"{args[0]}: {len(raw['x0'])} test windows, {len(by_level[0])} chains of up to {len(by_level)} windows; "
          f"learned states {', '.join(component.state_names[i] for i in learned)}")
    for path in args[1:]:
        chained, single = errors(ort.InferenceSession(path), raw, found, learned)
        rms = lambda e: np.sqrt((e ** 2).mean(0))  # noqa: E731
        for k, i in enumerate(learned):
            print(f"{Path(path).name} {component.state_names[i]}: RMSE chained {rms(chained)[k]:.5f}, single "
                  f"{rms(single)[k]:.5f} (x{rms(chained)[k] / rms(single)[k]:.2f}); largest chained "
                  f"{np.abs(chained).max(0)[k]:.4f}, single {np.abs(single).max(0)[k]:.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
