"""Stability runs of the cases converted from ANDES: the CCT bisection brackets a stable and an
unstable run, a screening of such a case gives one row per contingency, and (with ANDES) the native
FMUs' CCT is that of ANDES' own bisection."""
from __future__ import annotations

import math

import numpy as np
import pytest

from reference_models.grid.case import shipped_case
from reference_models.grid.contingency import Contingency

FAULT = complex(0.0, 1e-4)  # pu: ANDES' Newton stalls at a bolted fault


def test_the_default_screening_faults_are_the_buses_without_a_generator():
    from cosim.screening import default_fault_buses

    assert default_fault_buses(shipped_case("wscc9").network) == [4, 5, 6, 7, 8, 9]
    assert default_fault_buses(shipped_case("kundur").network) == [5, 6, 7, 8, 9, 10]


def test_kundur_monolithic_cct_bisection_brackets_a_stable_and_an_unstable_run():
    from cosim.runners import MonolithicRunner
    from cosim.stability import angle_spread, critical_clearing_time, run_verdict

    case = shipped_case("kundur")
    runner = MonolithicRunner(case, 0.01, 1e-9)
    c = Contingency(5, 1.1, "5-6", 1.0, FAULT, case.network)  # CCT 1.319 s, a loss about 1 s after the fault
    stop, results = 2.5, {}

    def stable(contingency):
        ok, lost, result = run_verdict(runner, contingency, stop)
        results[contingency.clear_s] = (lost, result)
        return ok

    cct = critical_clearing_time(stable, c, resolution=0.05, guess=1.3)
    assert cct.bounded and cct.unstable_s - cct.cct_s == pytest.approx(0.05)
    assert (cct.cct_s, True) in cct.runs and (cct.unstable_s, False) in cct.runs
    lost, unstable = results[cct.unstable_s]
    assert cct.unstable_s < lost < stop and unstable.loss_of_synchronism_s == pytest.approx(lost, abs=0.01)
    _, stable_run = results[cct.cct_s]
    assert stable_run.time[-1] == pytest.approx(stop)
    assert np.max(angle_spread(stable_run, c, stop)) < math.pi < np.max(angle_spread(unstable, c, stop))


def test_screening_kundur_without_dask_gives_one_row_per_contingency(fmu_cache):
    from cosim.fmus import generator_files
    from cosim.master import MasterSettings
    from cosim.screening import ScreeningTask, contingencies, screen

    case = shipped_case("kundur")
    files = tuple(generator_files(case, "reference", fmu_cache))
    pairs = contingencies(case.network, [5], "each")[:2]
    tasks = [ScreeningTask(case, Contingency(bus, 1.1, trip, 1.0, FAULT, case.network), "reference", files,
                           MasterSettings(step=0.01), 2.5, 0.04) for bus, trip in pairs]
    rows = screen(tasks, workers=0, progress=False)
    assert [(r["bus"], r["trip"]) for r in rows] == [(5, ""), (5, "5-6")]
    for row in rows:
        assert row["stable"] and row["first_swing_peak_deg"] > 0
        assert row["bounded"] and 1.1 < row["cct_s"] < 1.6 and row["runs"] > 3


@pytest.mark.andes
def test_kundur_cct_by_native_fmus_is_within_5_ms_of_andes_bisection(fmu_cache):
    """Kundur, fault at bus 5 (1e-4j pu) from 1 s, 5-6 opened at clearing: the native FMUs (h = 10 ms)
    and ANDES (h = 1 ms, bisected from around the FMUs' CCT) to 1 ms, runs to 2.5 s (the loss comes
    within a second of the fault)."""
    from cosim.andes_runner import AndesRunner
    from cosim.master import MasterSettings
    from cosim.runners import open_runner
    from cosim.stability import critical_clearing_time, runner_stable

    case = shipped_case("kundur")
    c = Contingency(5, 1.1, "5-6", 1.0, FAULT, case.network)
    fmus = open_runner("reference", case, MasterSettings(step=0.01), fmu_cache)
    try:
        native = critical_clearing_time(runner_stable(fmus, 2.5), c)
    finally:
        fmus.close()
    andes = critical_clearing_time(runner_stable(AndesRunner(case, 0.001), 2.5), c, guess=native.cct_s)
    assert native.bounded and andes.bounded
    assert abs(native.cct_s - andes.cct_s) <= 0.005
