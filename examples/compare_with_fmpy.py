"""Check a surrogate FMU against the reference FMU with fmpy alone (no opfmu needed); FMI 2.0 or 3.0.

    python examples/compare_with_fmpy.py SM4Surrogate.fmu SM4Reference.fmu [--plot compare.png]

Both FMUs see the same inputs, sampled at the communication points and held over each step: a fault
of the bus voltage to 0.5 pu at t = 1 s, cleared after 150 ms, with a 0.1 rad jump of the voltage
angle, and the mechanical power Pm lowered by 10 % at t = 3 s, the field voltage Efd held. Both
start from their default state (the machine at rest at its inputs' start values: Vs = 1 pu,
theta_vs = 0, Pm = 0.7048 pu, Efd = 1.08 pu). Every output the two model descriptions share is
compared; the states (the outputs with an initial-state parameter <name>0) are plotted.
"""
import argparse
import time

import numpy as np
from fmpy import read_model_description, simulate_fmu

STOP_TIME, STEP = 5.0, 0.01
PM_START, EFD_START = 0.7048, 1.08  # pu, the start values of the FMUs' inputs Pm and Efd (paper Table I)


def shared_outputs(*fmus) -> tuple[list, list]:
    """(outputs, states): the Real outputs every FMU has, in the first one's order, and those of them
    that are states (an initial-state parameter <name>0 exists)."""
    descriptions = [read_model_description(f).modelVariables for f in fmus]
    names = [{v.name for v in d if v.causality == "output" and v.type in ("Real", "Float64")} for d in descriptions]
    outputs = [v.name for v in descriptions[0] if all(v.name in n for n in names)]
    parameters = {v.name for v in descriptions[0] if v.causality == "parameter"}
    return outputs, [n for n in outputs if f"{n}0" in parameters]


def fault() -> np.ndarray:
    t = np.arange(0.0, STOP_TIME + STEP / 2, STEP)
    names = ("time", "Vs", "theta_vs", "Pm", "Efd")
    signal = np.zeros(len(t), dtype=[(name, float) for name in names])
    signal["time"] = t
    signal["Vs"] = np.where((t >= 1.0) & (t < 1.15), 0.5, 1.0)
    signal["theta_vs"] = np.where(t >= 1.0, 0.1, 0.0)
    signal["Pm"] = np.where(t >= 3.0, 0.9 * PM_START, PM_START)
    signal["Efd"] = EFD_START
    return signal


def run(fmu: str, signal: np.ndarray, outputs: list):
    start = time.perf_counter()
    result = simulate_fmu(fmu, stop_time=STOP_TIME, output_interval=STEP, input=signal, output=outputs)
    return result, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("surrogate")
    parser.add_argument("reference")
    parser.add_argument("--plot", help="write a PNG of both runs")
    args = parser.parse_args()

    signal = fault()
    outputs, states = shared_outputs(args.surrogate, args.reference)
    surrogate, t_surrogate = run(args.surrogate, signal, outputs)
    reference, t_reference = run(args.reference, signal, outputs)
    print(f"{'output':<8}{'max abs error':>15}")
    for name in outputs:
        print(f"{name:<8}{np.max(np.abs(surrogate[name] - reference[name])):>15.3e}")
    print(f"wall time: surrogate {t_surrogate:.3f} s, reference {t_reference:.3f} s "
          f"({t_reference / t_surrogate:.1f}x)")

    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(len(states), 1, figsize=(8, 2 * len(states)), sharex=True, squeeze=False)
        axes = axes[:, 0]
        for ax, name in zip(axes, states):
            ax.plot(reference["time"], reference[name], "k", label="reference")
            ax.plot(surrogate["time"], surrogate[name], "r--", label="surrogate")
            ax.set_ylabel(name)
        axes[0].legend()
        axes[-1].set_xlabel("time [s]")
        fig.savefig(args.plot, dpi=100)
        print(f"plot: {args.plot}")


if __name__ == "__main__":
    main()
