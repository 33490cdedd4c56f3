"""A machine FMU with an exciter FMU in the loop, started from a load-flow point, through a voltage dip.

    python examples/machine_with_exciter.py [--out DIR] [--surrogate]

Builds the native reference FMU of the Table I machine (SM4Reference.fmu) and of the IEEE Type I
exciter with the WSCC gains (IEEE1Reference.fmu), and with --surrogate also the surrogate FMU of
the shipped operator (SM4Surrogate.fmu; skipped with a note where that operator does not build).
The start values come from a load-flow point with opfmu's initialisation API: the machine injects
P + jQ = 0.8 + j0.3 pu into a bus at 1.0 pu, 0.1 rad; `machine_start` gives its state, Pm and Efd,
`cosim.bus_driven.start_at_rest` the exciter's state and Vref that hold that Efd. Then 5 s at
h = 10 ms with the exciter in the loop (cosim.bus_driven.couple, wired by the FMUs' ports): the bus
voltage dips to 0.5 pu at t = 1 s for 150 ms. Every step the master sets the bus voltage, reads the
machine's bus current I, gives the exciter the terminal voltage Vt = |V + (Re + j Xep) I|, steps
it, gives its Efd to the machine and steps the machine. Writes DIR/machine_with_exciter.png (Efd and
the rotor angle).
"""
import argparse
from pathlib import Path

import numpy as np

from cosim.bus_driven import UnitFMU, couple, start_at_rest
from fmu_export.native_reference_fmu import build_native_reference_fmu
from reference_models.ieee1 import IEEE1
from reference_models.initialisation import machine_start
from reference_models.sm4 import SM4

STOP, STEP = 5.0, 0.01
BUS = dict(V=1.0, theta=0.1, P=0.8, Q=0.3)  # the load-flow point: bus voltage [pu, rad], power injected [pu]


def run(machine_fmu, exciter_fmu, machine, bus_voltage):
    """Co-simulate the machine with its exciter; bus_voltage(t) -> (Vs, theta_vs). Returns the
    times and the recorded delta, Efd."""
    units = (UnitFMU(machine_fmu), UnitFMU(exciter_fmu))
    times = np.arange(int(round(STOP / STEP)) + 1) * STEP
    bus = np.array([(*bus_voltage(t), machine.Pm) for t in times])  # Vs, theta_vs, and Pm held
    starts = start_at_rest(units, machine.x0, (BUS["V"], BUS["theta"], machine.Pm), {"Efd": machine.Efd})
    result = couple(units, times, bus, starts)
    return times, result.machine[:, 0], result.states[1][:, 0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("."))
    parser.add_argument("--surrogate", action="store_true", help="also run the shipped operator's surrogate FMU")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    fmus = {"reference": args.out / "SM4Reference.fmu"}
    build_native_reference_fmu(fmus["reference"])
    build_native_reference_fmu(args.out / "IEEE1Reference.fmu", "IEEE1Reference", IEEE1)
    if args.surrogate:
        from fmu_export.surrogate_fmu import BuildError, build_surrogate_fmu
        from surrogate.operator import DEFAULT_OPERATOR

        try:
            build_surrogate_fmu(DEFAULT_OPERATOR, args.out / "SM4Surrogate.fmu")
            fmus["surrogate"] = args.out / "SM4Surrogate.fmu"
        except BuildError as exc:
            print(f"no surrogate: {exc}")

    machine = machine_start(BUS["V"], BUS["theta"], BUS["P"], BUS["Q"], SM4.params())
    print(f"load flow V = {BUS['V']} pu at {BUS['theta']} rad, P = {BUS['P']}, Q = {BUS['Q']} pu: delta0 = "
          f"{machine.x0[0]:.4f} rad, Pm = {machine.Pm:.4f}, Efd = {machine.Efd:.4f}, Vt = {machine.Vt:.4f} pu")

    def dip(t):
        return (0.5 if 1.0 <= t + 1e-9 < 1.15 else BUS["V"]), BUS["theta"]

    results = {name: run(path, args.out / "IEEE1Reference.fmu", machine, dip) for name, path in fmus.items()}
    for name, (_, delta, efd) in results.items():
        print(f"{name}: Efd peak {efd.max():.3f} pu, delta swing {delta.min():.3f}..{delta.max():.3f} rad")
    if "surrogate" in results:
        (_, d_r, e_r), (_, d_s, e_s) = results["reference"], results["surrogate"]
        print(f"surrogate - reference: MaxAE delta {np.abs(d_s - d_r).max():.2e} rad, Efd {np.abs(e_s - e_r).max():.2e} pu")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for (name, (t, delta, efd)), style in zip(results.items(), ("k-", "C1--")):
        top.plot(t, efd, style, label=name)
        bottom.plot(t, delta, style, label=name)
    top.set_ylabel("Efd [pu] (exciter)")
    bottom.set_ylabel("delta [rad]")
    bottom.set_xlabel("t [s]")
    top.legend()
    fig.suptitle("SM4 with an IEEE Type I exciter in the loop: Vs dips to 0.5 pu at 1 s for 150 ms")
    fig.savefig(args.out / "machine_with_exciter.png", dpi=100)
    print(f"plot: {args.out / 'machine_with_exciter.png'}")


if __name__ == "__main__":
    main()
