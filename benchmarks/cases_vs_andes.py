"""The monolithic DAE of the cases converted from ANDES against ANDES' own simulation of the same
fault (issue 26's goal: rotor-angle differences within 0.1 deg of ANDES at h = 1 ms).

    python benchmarks/cases_vs_andes.py [--cases kundur ieee14] [--stop 5] [--step 0.001]
        [--fault-impedance 1e-4]

Per case: a fault at its bus (kundur 8, ieee14 4, ieee39 16, npcc 30) from 1.0 to 1.1 s with the
reactance --fault-impedance [pu] (ANDES' Fault default 1e-4; its Newton stalls at a bolted 1e-6),
no trip, until --stop. ANDES (cosim.andes_runner: its case file, implicit trapezoid at the fixed
step --step) and the monolithic DAE (scipy DOP853, rtol 1e-9, rows every --step) are run; printed:
the largest error over ANDES' rows of any rotor-angle difference to the first machine [deg], of
the bus-voltage magnitudes at the generators outside the fault [pu], and both wall times [s].
Needs ANDES (pip install andes==2.0.0). The monolithic solves of ieee39 (bus 16) and npcc do not
get through the fault yet (scipy's step size collapses where a limiter of a control device switches,
ieee39 at t = 1.1066 s with DOP853), so the default runs kundur and ieee14.
"""
from __future__ import annotations

import argparse
import math
import time

import numpy as np

FAULT_BUS = {"kundur": 8, "ieee14": 4, "ieee39": 16, "npcc": 30}


def compare(name: str, stop: float, step: float, reactance: float) -> dict:
    """The errors and wall times of one case (see the module docstring)."""
    from cosim.andes_runner import AndesRunner
    from cosim.outputs import on_times
    from reference_models.grid.case import shipped_case
    from reference_models.grid.contingency import Contingency
    from reference_models.grid.monolithic import System, simulate

    case = shipped_case(name)
    contingency = Contingency(FAULT_BUS[name], 1.1, None, 1.0, complex(0.0, reactance), case.network)
    started = time.perf_counter()
    andes, _ = AndesRunner(case, step).run(contingency, stop)
    andes_s = time.perf_counter() - started
    started = time.perf_counter()
    mono = simulate(System(case), contingency, stop, step=step, rtol=1e-9, atol=1e-11)
    mono_s = time.perf_counter() - started
    a = andes.states["delta"]
    m = on_times(mono, andes.time, mono.states["delta"])
    angle = np.max(np.abs((m - m[:, :1]) - (a - a[:, :1])))
    outside = (andes.time < 1.0) | (andes.time > 1.1)
    V = np.max(np.abs(on_times(mono, andes.time, mono.Vs) - andes.Vs)[outside])
    return {"case": name, "fault_bus": FAULT_BUS[name], "angle_deg": math.degrees(angle), "V_pu": float(V),
            "swing_deg": math.degrees(float(np.max(np.ptp(a - a[:, :1], axis=0)))), "andes_s": andes_s,
            "monolithic_s": mono_s, "stable": mono.stable}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", nargs="+", default=["kundur", "ieee14"], choices=list(FAULT_BUS))
    parser.add_argument("--stop", type=float, default=5.0)
    parser.add_argument("--step", type=float, default=0.001)
    parser.add_argument("--fault-impedance", type=float, default=1e-4)
    args = parser.parse_args(argv)
    print(f"fault 1.0-1.1 s (x = {args.fault_impedance:g} pu), {args.stop:g} s, ANDES at h = {args.step * 1e3:g} ms")
    print(f"{'case':8} {'bus':>4} {'angle err [deg]':>16} {'V err [pu]':>11} {'swing [deg]':>12} "
          f"{'ANDES [s]':>10} {'monolithic [s]':>15}")
    for name in args.cases:
        r = compare(name, args.stop, args.step, args.fault_impedance)
        print(f"{r['case']:8} {r['fault_bus']:>4} {r['angle_deg']:>16.4f} {r['V_pu']:>11.2e} {r['swing_deg']:>12.1f} "
              f"{r['andes_s']:>10.1f} {r['monolithic_s']:>15.1f}", flush=True)


if __name__ == "__main__":
    main()
