"""The monolithic DAE of the cases converted from ANDES against ANDES' own simulation of the same
fault (issue 26's goal: rotor-angle differences within 0.1 deg of ANDES at h = 1 ms).

    python benchmarks/cases_vs_andes.py [--cases kundur ieee14 ieee39 npcc] [--stop 10] [--step 0.001]
        [--fault-impedance 1e-4] [--defaults] [--no-resets] [--half-step]

Per case, the scenarios of SCENARIOS (--defaults: only the first, the case's default fault): a
fault at a bus (mid-network buses and generator buses, whose faults drive the exciters to their
ceilings) from 1.0 s, cleared after 50-150 ms, with or without the first branch at the bus that may
open (Network.trips_at) opened at clearing, the reactance --fault-impedance [pu] (ANDES' Fault
default 1e-4; its Newton stalls at a bolted 1e-6), until --stop. ANDES (cosim.andes_runner: its
case file, implicit trapezoid at the fixed step --step) and the monolithic DAE (scipy DOP853 with
its limiters' branches locked and their switchings located, rtol 1e-9, rows every --step;
--no-resets: without the components' limit resets) are run; printed: the largest error over
ANDES' rows of any rotor-angle difference to the first machine [deg], of the bus-voltage
magnitudes at the generators outside the fault [pu], the swing, both wall times [s], the
monolithic solve's right-hand-side evaluations and its verdict. --half-step: ANDES also at half
the step, printing the largest rotor-angle difference error of ANDES at --step against ANDES at
half of it (ANDES' own integration error), of the monolithic DAE against ANDES at half the step,
and of the monolithic DAE against ANDES' h -> 0 limit estimated as 2 A(h/2) - A(h): while an
exciter's regulator is pegged at its non-windup limit ANDES' error is first order in h (its Newton
iterates feed the regulator's value beyond the limit to the next equation before its limiter resets
it: docs/standard-models.md), so it halves per halving instead of quartering. Needs ANDES (pip
install andes==2.0.0).
"""
from __future__ import annotations

import argparse
import math
import time

import numpy as np

FAULT_START = 1.0  # s
# case: (fault bus, clearing after [s], a branch opened at clearing), the case's default fault first
SCENARIOS = {
    "kundur": [(8, 0.10, False), (8, 0.10, True), (7, 0.15, True), (1, 0.05, False)],
    "ieee14": [(4, 0.10, False), (4, 0.15, True), (1, 0.05, False), (2, 0.10, True)],
    "ieee39": [(16, 0.10, False), (16, 0.10, True), (39, 0.05, True), (34, 0.10, False)],
    "npcc": [(30, 0.10, False), (30, 0.10, True), (78, 0.05, True)],
}


def _differences(result, times) -> np.ndarray:
    """Every rotor-angle difference to the first machine [rad] at `times` [n, g]."""
    from cosim.outputs import on_times

    d = on_times(result, times, result.angles)
    return d - d[:, :1]


def _angle_error(result, reference, times) -> np.ndarray:
    """|error| [rad] of every rotor-angle difference to the first machine at `times` [n, g]."""
    return np.abs(_differences(result, times) - _differences(reference, times))


def _limit_error(result, coarse, fine) -> np.ndarray:
    """|error| [rad] of every rotor-angle difference against ANDES' h -> 0 limit estimated from its
    runs at h (`coarse`) and h/2 (`fine`) on coarse's rows, as 2 fine - coarse: ANDES' error while a
    non-windup limit is pegged is first order in h (docs/standard-models.md), so its step error
    halves, rather than quarters, per halving."""
    t = coarse.time
    return np.abs(_differences(result, t) - (2.0 * _differences(fine, t) - _differences(coarse, t)))


def compare(name: str, bus: int, clear: float, trip: bool, stop: float, step: float, reactance: float,
            resets: bool = True, half_step: bool = False) -> dict:
    """The errors and wall times of one scenario (see the module docstring)."""
    from cosim.andes_runner import AndesRunner
    from cosim.outputs import on_times
    from reference_models.grid.case import shipped_case
    from reference_models.grid.contingency import Contingency
    from reference_models.grid.monolithic import System, simulate

    case = shipped_case(name)
    branch = case.network.trips_at(bus)[0] if trip else None
    contingency = Contingency(bus, FAULT_START + clear, branch, FAULT_START, complex(0.0, reactance), case.network)
    started = time.perf_counter()
    andes, _ = AndesRunner(case, step).run(contingency, stop)
    andes_s = time.perf_counter() - started
    started = time.perf_counter()
    mono = simulate(System(case), contingency, stop, step=step, rtol=1e-9, atol=1e-11, resets=resets)
    mono_s = time.perf_counter() - started
    a = andes.angles
    angle_error = _angle_error(mono, andes, andes.time)
    half = {}
    if half_step:
        fine, _ = AndesRunner(case, step / 2).run(contingency, stop)
        half = {"andes_vs_half_deg": math.degrees(float(np.max(_angle_error(andes, fine, andes.time)))),
                "mono_vs_half_deg": math.degrees(float(np.max(_angle_error(mono, fine, andes.time)))),
                "mono_vs_limit_deg": math.degrees(float(np.max(_limit_error(mono, andes, fine))))}
    worst = np.unravel_index(np.argmax(angle_error), angle_error.shape)
    outside = (andes.time < FAULT_START) | (andes.time > FAULT_START + clear)
    V = np.max(np.abs(on_times(mono, andes.time, mono.Vs) - andes.Vs)[outside])
    return {"case": name, "fault_bus": bus, "clear_ms": clear * 1e3, "trip": branch or "-",
            "angle_deg": math.degrees(float(angle_error[worst])), "at_s": float(andes.time[worst[0]]),
            "machine_bus": case.generator_buses[worst[1]], "V_pu": float(V),
            "swing_deg": math.degrees(float(np.max(np.ptp(a - a[:, :1], axis=0)))), "andes_s": andes_s,
            "monolithic_s": mono_s, "n_rhs": mono.n_rhs, "stable": mono.stable, **half}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", nargs="+", default=list(SCENARIOS), choices=list(SCENARIOS))
    parser.add_argument("--stop", type=float, default=10.0)
    parser.add_argument("--step", type=float, default=0.001)
    parser.add_argument("--fault-impedance", type=float, default=1e-4)
    parser.add_argument("--defaults", action="store_true", help="only each case's default fault")
    parser.add_argument("--no-resets", action="store_true", help="the monolithic solve without the limit resets")
    parser.add_argument("--half-step", action="store_true", help="ANDES at half the step too (its own error)")
    args = parser.parse_args(argv)
    print(f"faults from {FAULT_START:g} s (x = {args.fault_impedance:g} pu), {args.stop:g} s, ANDES at "
          f"h = {args.step * 1e3:g} ms, monolithic {'without' if args.no_resets else 'with'} limit resets")
    print(f"{'case':8} {'bus':>4} {'clear':>6} {'trip':>8} {'angle err [deg]':>16} {'(at s, gen bus)':>16} "
          f"{'V err [pu]':>11} {'swing [deg]':>12} {'ANDES [s]':>10} {'monolithic [s]':>15} {'rhs':>7} stable"
          + (f" {'ANDES h vs h/2 [deg]':>21} {'monolithic vs h/2 [deg]':>24} {'vs limit [deg]':>18}"
             if args.half_step else ""))
    for name in args.cases:
        for bus, clear, trip in SCENARIOS[name][:1] if args.defaults else SCENARIOS[name]:
            r = compare(name, bus, clear, trip, args.stop, args.step, args.fault_impedance, not args.no_resets,
                        args.half_step)
            where = f"({r['at_s']:.2f}, {r['machine_bus']})"
            print(f"{r['case']:8} {r['fault_bus']:>4} {r['clear_ms']:>4.0f}ms {r['trip']:>8} {r['angle_deg']:>16.4f} "
                  f"{where:>16} {r['V_pu']:>11.2e} {r['swing_deg']:>12.1f} {r['andes_s']:>10.1f} "
                  f"{r['monolithic_s']:>15.1f} {r['n_rhs']:>7} {r['stable']}"
                  + (f" {r['andes_vs_half_deg']:>21.4f} {r['mono_vs_half_deg']:>24.4f} {r['mono_vs_limit_deg']:>18.4f}"
                     if args.half_step else ""),
                  flush=True)


if __name__ == "__main__":
    main()
