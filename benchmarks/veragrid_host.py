"""opfmu's native FMUs hosted by VeraGrid's RMS simulation (cosim.veragrid) against opfmu's own
master, on the same case and fault, and ANDES where it is installed (issue 34's goal: rotor angles
within 0.5 deg and voltages within 0.01 pu of the own master at h = 10 ms, outside the fault's own
steps).

    python benchmarks/veragrid_host.py [--step 0.01] [--stop 2] [--kundur-stop 5]

Scenarios: an SM4 on a SMIB (cosim.veragrid.smib_case: a 0.2 pu line to a GENCLS of 1e5 MVA)
through a fault shunt of B = -10 and -50 pu at its bus from 0.1 to 0.2 s; Kundur (shipped, GENROU +
EXDC2 + TGOV1 per unit, the case's own events left out) through a fault of 1e-4j pu at bus 8 from
1.0 to 1.1 s; where ANDES is installed (it reads the file), ANDES' ieee14_pvd1 (five GENROU units
with their controls, ten PVD1 inverters at bus 4, tapped transformers, its own line toggle) through
a fault of 1e-4j pu at bus 4 from 1.0 to 1.1 s. Runs: VeraGrid with the Norton interface; VeraGrid with the FMUs' P, Q alone (what
VeraGrid's importer does by itself; a failure is printed as such); the own master iterated (its
default) and with held inputs (the explicit coupling VeraGrid does); ANDES for Kundur. Printed per
run against the iterated master: the largest rotor-angle error [deg] (absolute, and of the angles
relative to the first machine), the largest bus-voltage error [pu] outside the fault's own steps,
the largest P, Q error of the units without a rotor angle (inverters) [pu, system base], the wall
time [s] (VeraGrid's first run includes its numba compilation of the equations).
Needs VeraGridEngine (pip install VeraGridEngine==6.7.1).
"""
from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from cosim.andes_runner import AndesRunner, andes_available
from cosim.fmus import generator_files
from cosim.master import MasterSettings
from cosim.runners import MasterRunner
from cosim.veragrid import VeraGridRunner, smib_case
from reference_models.grid.case import shipped_case
from reference_models.grid.contingency import ANDES_FAULT_IMPEDANCE, Contingency


def errors(run, reference, events) -> tuple:
    """(abs angle [deg], relative angle [deg], voltage [pu], inverter P and Q [pu]) errors of `run`
    against `reference` on their common rows, the rows at `events` left out (NaN: no inverter)."""
    t = np.round(run.time, 9)
    common = np.intersect1d(t, np.round(reference.time, 9))
    common = common[~np.isin(common, np.round(events, 9))]
    a, b = (np.searchsorted(np.round(r.time, 9), common) for r in (run, reference))
    da = run.rotor_angle[a] - reference.rotor_angle[b]
    rel = da - da[:, :1]
    dv = run.V_bus[a] - reference.V_bus[b]
    inverters = ~np.isfinite(reference.rotor_angle[0])
    power = max((float(np.max(np.abs(getattr(run, x)[a][:, inverters] - getattr(reference, x)[b][:, inverters])))
                 for x in ("P", "Q")), default=float("nan")) if inverters.any() else float("nan")
    return (float(np.degrees(np.nanmax(np.abs(da)))), float(np.degrees(np.nanmax(np.abs(rel)))),
            float(np.nanmax(np.abs(dv))), power)


def timed(runner, contingency, stop):
    started = time.perf_counter()
    try:
        result, _ = runner.run(contingency, stop)
        return result, time.perf_counter() - started, None
    except RuntimeError as exc:
        return None, time.perf_counter() - started, str(exc)
    finally:
        runner.close()


def scenario(name, case, files, contingency, stop, step, andes: bool) -> None:
    events = [contingency.fault_start, contingency.clear_s]
    settings = MasterSettings(step=step)
    own, own_s, _ = timed(MasterRunner(files, case, settings), contingency, stop)
    runs = {"veragrid norton": VeraGridRunner(case, files, step, "norton"),
            "veragrid P, Q": VeraGridRunner(case, files, step, "power"),
            "master held": MasterRunner(files, case, replace(settings, coupling="held", event_refinement=()))}
    if andes:
        runs["andes (1 ms)"] = AndesRunner(case, 0.001, rows=step)
    print(f"\n{name}: own master (iterated) {own_s:.2f} s")
    print(f"{'run':18s} {'angle deg':>10s} {'rel. deg':>10s} {'V pu':>8s} {'inv. P,Q':>9s} {'wall s':>8s}")
    for label, runner in runs.items():
        result, wall, failed = timed(runner, contingency, stop)
        if failed:
            print(f"{label:18s} failed: {failed[:90]}")
            continue
        da, dr, dv, dp = errors(result, own, events)
        print(f"{label:18s} {da:10.4f} {dr:10.4f} {dv:8.5f} {dp:9.5f} {wall:8.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--step", type=float, default=0.01)
    parser.add_argument("--stop", type=float, default=2.0)
    parser.add_argument("--kundur-stop", type=float, default=5.0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        case = smib_case(Path(tmp) / "smib", "sm4", {"D": 2.0})
        files = generator_files(case, "reference", Path(tmp) / "fmus")
        for B in (-10.0, -50.0):
            fault = Contingency(fault_bus=1, fault_start=0.1, clear_s=0.2, fault_impedance=1.0 / (1j * B),
                                network=case.network)
            scenario(f"SMIB, SM4, B = {B:g} pu", case, files, fault, args.stop, args.step, False)
        case = shipped_case("kundur")
        files = generator_files(case, "reference", Path(tmp) / "fmus")
        fault = Contingency(fault_bus=8, fault_start=1.0, clear_s=1.1, fault_impedance=ANDES_FAULT_IMPEDANCE,
                            network=case.network)
        scenario("Kundur, fault at bus 8", case, files, fault, args.kundur_stop, args.step, andes_available())
        if andes_available():
            import andes

            from reference_models.grid.andes_case import case_from_file

            case = case_from_file(andes.get_case("ieee14/ieee14_pvd1.xlsx"))
            files = generator_files(case, "reference", Path(tmp) / "fmus")
            fault = Contingency(fault_bus=4, fault_start=1.0, clear_s=1.1, fault_impedance=ANDES_FAULT_IMPEDANCE,
                                network=case.network, events=case.events)
            scenario("ieee14_pvd1, fault at bus 4", case, files, fault, args.kundur_stop, args.step, True)


if __name__ == "__main__":
    main()
