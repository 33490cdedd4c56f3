"""The Kundur two-area case in VeraGrid's RMS simulation, each unit's GENROU, EXDC2 and TGOV1 as
opfmu's native FMUs, beside opfmu's own master on the same fault.

    pip install VeraGridEngine==6.7.1       # MPL-2.0, optional
    python examples/veragrid_kundur.py [--fault 8] [--clear 1.1] [--stop 5] [--out kundur_veragrid.png]

1. The case (shipped_case("kundur")) and its native reference FMUs (generator_files, built once into
   ~/.cache/opfmu/fmus).
2. cosim.veragrid.VeraGridRunner builds the VeraGrid grid from the case's network, runs VeraGrid's
   power flow, starts every FMU from it, attaches each machine FMU to its VeraGrid generator through
   VeraGrid's FMU importer and its Norton port, steps the exciters and governors around VeraGrid's
   step, and runs VeraGrid's RMS simulation (backward Euler at 10 ms) through the fault.
3. The own master (iterated coupling) on the same case and fault; the figure puts both on one axis.
The same from the command line: opfmu grid run --case kundur --fault 8 --clear 1.1 --host veragrid --out DIR
"""
import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from cosim.fmus import generator_files
from cosim.master import MasterSettings
from cosim.runners import MasterRunner
from cosim.veragrid import VeraGridRunner
from reference_models.grid.case import shipped_case
from reference_models.grid.contingency import ANDES_FAULT_IMPEDANCE, Contingency


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--fault", type=int, default=8)
    parser.add_argument("--clear", type=float, default=1.1)
    parser.add_argument("--stop", type=float, default=5.0)
    parser.add_argument("--out", default="kundur_veragrid.png")
    args = parser.parse_args()
    case = shipped_case("kundur")
    files = generator_files(case, "reference")
    fault = Contingency(fault_bus=args.fault, fault_start=1.0, clear_s=args.clear,
                        fault_impedance=ANDES_FAULT_IMPEDANCE, network=case.network)
    hosted, _ = VeraGridRunner(case, files, step=0.01).run(fault, args.stop)
    master = MasterRunner(files, case, MasterSettings(step=0.01))
    try:
        own, _ = master.run(fault, args.stop)
    finally:
        master.close()
    fig, ax = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for k, bus in enumerate(case.generator_buses[1:], start=1):
        for result, style, label in ((hosted, "-", "VeraGrid"), (own, "--", "opfmu master")):
            ax[0].plot(result.time, np.degrees(result.rotor_angle[:, k] - result.rotor_angle[:, 0]), style,
                       label=f"{label}, gen {bus}")
    for result, style, label in ((hosted, "-", "VeraGrid"), (own, "--", "opfmu master")):
        ax[1].plot(result.time, result.V_bus[:, case.network.bus_index(args.fault)], style, label=label)
    ax[0].set_ylabel("rotor angle - gen 1 [deg]")
    ax[1].set_ylabel(f"V bus {args.fault} [pu]")
    ax[1].set_xlabel("time [s]")
    ax[0].legend(fontsize=7)
    ax[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"stable: {hosted.stable}; figure: {args.out}")


if __name__ == "__main__":
    main()
