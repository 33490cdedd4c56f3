"""The co-simulation master runs the cases converted from ANDES with one native reference FMU per
device, wired by their ports: kundur follows the monolithic run of the same case; two units at one
bus inject into it together (a unit split into two halves at its bus runs as the whole one); a
tripped unit injects nothing, stands still and leaves the loss-of-synchronism spread. With ANDES
(marker `andes`): kundur follows ANDES' own simulation at h = 1 ms."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from cosim.master import MasterSettings
from cosim.runners import open_runner
from reference_models.grid.case import Event, shipped_case
from reference_models.grid.contingency import Contingency

KUNDUR = shipped_case("kundur")
STOP = 3.0
FAULT = Contingency(8, 1.1, None, 1.0, 1e-4j, KUNDUR.network)  # 100 ms at bus 8, the case's own event not in it


@pytest.fixture(scope="module")
def kundur_fmu_run():
    runner = open_runner("reference", KUNDUR, MasterSettings(step=0.01))
    try:
        yield runner.run(FAULT, STOP)[0]
    finally:
        runner.close()


def away_from_events(result, h=0.01):
    """Rows more than one step from every event (the fault's own steps left out)."""
    keep = np.ones(len(result.time), bool)
    for t, _ in result.events:
        keep &= np.abs(result.time - t) > 1.01 * h
    return keep


def angle_spread_deg(a, b):
    """The largest difference [deg] of the rotor angles relative to their mean, rows of both runs."""
    da = a.states["delta"] - a.states["delta"].mean(axis=1, keepdims=True)
    db = b.states["delta"] - b.states["delta"].mean(axis=1, keepdims=True)
    return float(np.degrees(np.max(np.abs(da - db))))


def test_kundur_with_reference_fmus_follows_the_monolithic_run(kundur_fmu_run):
    mono, _ = open_runner("monolithic", KUNDUR, MasterSettings(step=0.01)).run(FAULT, STOP)
    fmu = kundur_fmu_run
    assert np.allclose(fmu.time, mono.time)
    assert fmu.stable and mono.stable
    assert angle_spread_deg(fmu, mono) < 0.3  # measured 0.11 deg at h = 10 ms
    keep = away_from_events(fmu)
    assert np.max(np.abs(fmu.V_bus[keep] - mono.V_bus[keep])) < 0.002  # measured 2e-4 pu


def split_unit(case, k):
    """The case with unit k replaced by two halves at its bus (machine base Sn halved each: the same
    per-unit states, half the current)."""
    unit = case.units[k]
    machine = replace(unit.machine, params=replace(unit.machine.params, Sn=unit.machine.params.Sn / 2))
    half = replace(unit, devices=(machine,) + unit.devices[1:])
    units = case.units[:k] + (half, half) + case.units[k + 1:]
    starts = case.starts[:k] + (case.starts[k], case.starts[k]) + case.starts[k + 1:]
    return replace(case, units=units, starts=starts)


def test_two_units_at_one_bus_inject_into_it_together(kundur_fmu_run):
    split = split_unit(KUNDUR, 0)
    assert split.generator_buses[:2] == (KUNDUR.units[0].bus,) * 2
    runner = open_runner("reference", split, MasterSettings(step=0.01))
    try:
        halves, _ = runner.run(FAULT, STOP)
    finally:
        runner.close()
    whole = kundur_fmu_run
    delta_h, delta_w = halves.states["delta"], whole.states["delta"]
    assert np.max(np.abs(delta_h[:, 0] - delta_h[:, 1])) < 1e-9
    assert np.max(np.abs(delta_h[:, 1:] - delta_w)) < 1e-6
    assert np.max(np.abs(halves.V_bus - whole.V_bus)) < 1e-7
    assert np.max(np.abs(halves.P[:, 0] + halves.P[:, 1] - whole.P[:, 0])) < 1e-6


def test_a_tripped_unit_injects_nothing_stands_still_and_leaves_the_stability_check():
    trip_s, stop = 0.5, 5.0
    tripped = [u.bus for u in KUNDUR.units].index(3)
    contingency = Contingency(network=KUNDUR.network,
                              events=(Event("generator", trip_s, bus=3, generator="3", status=0),))
    runner = open_runner("reference", KUNDUR, MasterSettings(step=0.01))
    try:
        result, _ = runner.run(contingency, stop)
    finally:
        runner.close()
    after = result.time >= trip_s
    at = int(np.argmax(after))
    assert 0 < at < len(result.time) - 1
    assert np.all(result.P[after, tripped] == 0.0) and np.all(result.Q[after, tripped] == 0.0)
    assert abs(result.P[at - 1, tripped]) > 1.0  # it was generating until the trip
    for name, values in result.states.items():
        assert np.all(values[after, tripped] == values[at, tripped]), name
    others = [k for k in range(len(KUNDUR.units)) if k != tripped]
    omega = result.states["omega"][:, others]
    assert np.all(omega[-1] < omega[at] - 1e-3)  # the rest slows down: generation lost
    assert np.ptp(result.states["delta"][-1]) > math.pi  # the standing angle falls behind ...
    assert result.stable and result.loss_of_synchronism_s is None  # ... but is no longer compared
    mono, _ = open_runner("monolithic", KUNDUR, MasterSettings(step=0.01)).run(contingency, stop)
    rel_f = result.states["delta"][:, others] - result.states["delta"][:, others[:1]]
    rel_m = mono.states["delta"][:, others] - mono.states["delta"][:, others[:1]]
    assert np.degrees(np.max(np.abs(rel_f - rel_m))) < 0.3  # measured 0.12 deg


@pytest.mark.andes
def test_kundur_with_reference_fmus_follows_andes(kundur_fmu_run):
    pytest.importorskip("andes")
    from cosim.andes_runner import AndesRunner
    from cosim.outputs import errors

    andes, _ = AndesRunner(KUNDUR, 0.001).run(FAULT, STOP)
    found = errors(kundur_fmu_run, andes, fault=(FAULT.fault_start, FAULT.clear_s))
    assert found["angle_deg"] < 0.5
    assert found["V"] < 0.01


def test_steps_right_after_a_topology_change_are_cut_and_only_the_grid_is_recorded():
    from cosim.master import refined_points

    points = [(0.01, None), (0.02, "fault"), (0.03, None), (0.04, None), (0.05, None)]
    out = list(refined_points(points, ((0.02, 4),)))
    recorded = [(t, tp) for t, tp, keep in out if keep]
    assert recorded == points
    added = [t for t, _, keep in out if not keep]
    # the two steps starting within 0.02 s of the change at 0.02 s are quartered, no other
    assert np.allclose(added, [0.0225, 0.025, 0.0275, 0.0325, 0.035, 0.0375])
    assert [t for t, _, _ in refined_points(points, ((0.02, 1),))] == [t for t, _ in points]
    # the first window that holds a step's start decides: quartered, then halved up to 0.03 s after
    tiers = [t for t, _, keep in refined_points(points, ((0.01, 4), (0.03, 2))) if not keep]
    assert np.allclose(tiers, [0.0225, 0.025, 0.0275, 0.035, 0.045])


@pytest.mark.parametrize("refinement", [((0.05, 0),), ((-1.0, 2),), ((0.05, 2.5),), ((float("nan"), 2),), (0.05, 10)])
def test_a_refinement_that_is_not_window_and_substeps_pairs_is_refused(refinement):
    from cosim.master import MasterSettings

    with pytest.raises(ValueError, match="event_refinement"):
        MasterSettings(event_refinement=refinement)


def test_surrogate_runs_the_machines_with_an_operator_and_native_fmus_for_the_rest():
    from cosim.fmus import unit_fmus

    assert {f.kind for f in unit_fmus(shipped_case("kundur"), "surrogate")} == {"surrogate"}  # operators named
    assert {f.kind for f in unit_fmus(shipped_case("ieee14"), "surrogate")} == {"reference"}  # none named


def test_pythonfmu_fmus_of_the_standard_models_are_refused_in_one_line_before_any_build(tmp_path, capsys):
    from opfmu.cli import main

    out = tmp_path / "out"
    assert main(["grid", "run", "--case", "kundur", "--fmus", "python", "--fault", "7", "--clear", "1.1",
                 "--fmu-cache", str(tmp_path / "cache"), "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1 and "--fmus reference" in captured.err
    assert not out.exists() and not list((tmp_path / "cache").glob("*.fmu"))
