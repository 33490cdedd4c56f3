"""A case's own events (reference_models.grid.case.Event) merged with the user's contingency into the
topologies every runner switches between (Contingency.topologies): branches opened and closed again,
a case fault with its own impedance, a generator trip as Topology.tripped, one fault at a time,
`--no-case-events`; the result columns of the ANDES cases (speeds in rad/s deviation, every unit's
field voltage, units sharing a bus) and run comparisons at the rows both runs have outside their
events. With ANDES (marker `andes`): its runs of the same events switch at the same times."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from cosim.outputs import common_rows, errors
from reference_models.grid.case import Event, shipped_case
from reference_models.grid.contingency import Contingency
from reference_models.grid.result import GridResult, field_voltage, speed_deviation, unit_labels

KUNDUR = shipped_case("kundur")


def kundur(*events, **user) -> Contingency:
    """A contingency of the kundur network with `events` as the case's own."""
    return Contingency(network=KUNDUR.network, events=events, **user)


def test_the_case_events_merge_with_the_users_fault_in_time_order():
    c = Contingency(8, 1.1, None, 1.0, 1e-4j, KUNDUR.network, KUNDUR.events)
    tops = c.topologies(5.0)
    assert [(tp.start, tp.fault_bus, tp.open) for tp in tops] == [
        (0.0, None, ()), (1.0, 8, ()), (1.1, None, ()), (2.0, None, ("8-9:2",))]
    assert tops[1].fault_impedance == 1e-4j and tops[2].fault_impedance is None
    assert tops[3].description == "8-9:2 opened"
    assert [tp.start for tp in c.topologies(2.0)] == [0.0, 1.0, 1.1]  # an event at the stop is not reached
    assert c.with_clearing(1.2).events == KUNDUR.events


def test_without_case_events_only_the_users_contingency_switches():
    c = Contingency(8, 1.1, None, 1.0, 1e-4j, KUNDUR.network, KUNDUR.events).without_case_events()
    assert [(tp.start, tp.open) for tp in c.topologies(5.0)] == [(0.0, ()), (1.0, ()), (1.1, ())]
    assert c.case_event_labels() == ()


def test_a_toggled_branch_closes_again():
    c = kundur(Event("branch", 0.5, branch="7-8", status=0), Event("branch", 0.8, branch="7-8", status=1),
               fault_bus=9, clear_s=0.6, trip="8-9", fault_start=0.55, fault_impedance=1e-3j)
    tops = c.topologies(3.0)
    assert [(tp.start, tp.fault_bus, tp.open) for tp in tops] == [
        (0.0, None, ()), (0.5, None, ("7-8",)), (0.55, 9, ("7-8",)), (0.6, None, ("7-8", "8-9")),
        (0.8, None, ("8-9",))]
    assert tops[4].description == "7-8 closed"
    assert c.case_event_labels() == ("7-8 opened at 0.5 s", "7-8 closed at 0.8 s")


def test_a_case_fault_keeps_its_own_impedance():
    c = kundur(Event("fault", 1.0, bus=7, clear=1.08, impedance=0.02j), fault_bus=9, clear_s=0.2,
               fault_impedance=1e-4j)
    tops = c.topologies(3.0)
    assert [(tp.start, tp.fault_bus, tp.fault_impedance) for tp in tops] == [
        (0.0, 9, 1e-4j), (0.2, None, None), (1.0, 7, 0.02j), (1.08, None, None)]
    assert c.fault_intervals(3.0) == ((0.0, 0.2), (1.0, 1.08))


def test_two_faults_at_once_are_refused():
    with pytest.raises(ValueError, match="one fault at a time"):
        kundur(Event("fault", 1.0, bus=7, clear=1.1, impedance=1e-4j), fault_bus=9, clear_s=1.05, fault_start=0.9)
    # a fault starting where the other clears follows it
    kundur(Event("fault", 1.0, bus=7, clear=1.1, impedance=1e-4j), fault_bus=9, clear_s=1.2, fault_start=1.1)


def test_a_generator_trip_is_the_tripped_unit_in_case_order():
    c = kundur(Event("generator", 1.5, bus=3, generator="3", status=0), fault_bus=8, clear_s=1.1, fault_start=1.0)
    tops = c.topologies(3.0)
    assert [tp.tripped for tp in tops] == [(), (), (), (2,)]
    assert KUNDUR.units[2].bus == 3
    assert tops[-1].description == "generator 3 at bus 3 tripped"


@pytest.mark.parametrize("events, message", [
    ((Event("generator", 1.5, bus=3, generator="3", status=0), Event("generator", 2.0, bus=3, generator="3", status=1)),
     "a unit coming into service is not modelled"),
    ((Event("generator", 1.5, bus=3, generator="9", status=0),), "no generator 9 at bus 3"),
    ((Event("branch", 1.0, branch="1-9", status=0),), "no branch 1-9"),
    ((Event("fault", 1.0, bus=7, clear=0.9, impedance=1e-4j),), "never cleared"),
    ((Event("fault", 1.0, bus=7, clear=1.1, impedance=0j),), "nonzero"),
])
def test_case_events_that_cannot_happen_are_refused(events, message):
    with pytest.raises(ValueError, match=message):
        kundur(*events)


def test_an_island_with_loads_runs_on_and_one_without_trips_its_generators():
    tops = kundur(Event("branch", 1.0, branch="7-8", status=0), Event("branch", 1.0, branch="7-8:2", status=0),
                  Event("branch", 1.0, branch="7-8:3", status=0)).topologies(3.0)
    assert tops[-1].open == ("7-8", "7-8:2", "7-8:3") and not tops[-1].tripped  # load 7 west, load 8 east
    tops = kundur(Event("branch", 1.0, branch="8-9", status=0), Event("branch", 1.2, branch="8-9:2", status=0)).topologies(3.0)
    assert [tp.tripped for tp in tops] == [(), (), (2, 3)]  # generators 3, 4 left with no load
    tops = kundur(Event("branch", 1.0, branch="5-6", status=0), Event("branch", 1.0, branch="5-6:2", status=0),
                  Event("branch", 1.2, branch="6-7", status=0), Event("branch", 1.2, branch="6-7:2", status=0)).topologies(3)
    assert [tp.tripped for tp in tops] == [(), (0,), (0, 1)]  # the dead island 1-5 stays dead


def test_a_dead_island_is_grounded_so_the_network_still_solves():
    reduced = KUNDUR.reduced(out_of_service=("5-6", "5-6:2", "1-5"))
    assert np.all(np.isfinite(reduced.Y_real)) and np.linalg.matrix_rank(reduced.Y) == len(KUNDUR.buses)


def test_a_generator_left_open_circuited_trips_as_andes_holds_it():
    tops = kundur(Event("branch", 1.0, branch="1-5", status=0)).topologies(3.0)
    assert tops[-1].tripped == (0,) and "generator 1 open-circuited: tripped" in tops[-1].description


def test_units_sharing_a_bus_are_numbered_in_case_order():
    assert unit_labels((78, 21, 23, 23, 54, 54, 54)) == ("78", "21", "23_1", "23_2", "54_1", "54_2", "54_3")


def _result(time, omega, events=(), Vs=None, machine_inputs=None, states=None):
    n, g = len(time), len(KUNDUR.units)
    delta = np.zeros((n, g))
    Vs = np.ones((n, g)) if Vs is None else Vs
    return GridResult(time=np.asarray(time, float), states={"delta": delta, "omega": omega, **(states or {})},
                      rotor_angle=delta,
                      Vs=Vs, theta_vs=delta, P=delta, Q=delta, V_bus=np.ones((n, len(KUNDUR.buses))),
                      theta_bus=np.zeros((n, len(KUNDUR.buses))), stable=True, loss_of_synchronism_s=None,
                      events=tuple(events), gen_buses=KUNDUR.generator_buses, buses=KUNDUR.buses,
                      machine_inputs=machine_inputs or {})


def test_a_per_unit_speed_is_written_as_a_deviation_in_rad_per_s_and_every_unit_has_its_field_voltage():
    omega = np.full((2, 4), 1.001)
    Efd = np.array([[1.5, 1.6, 1.7, 1.8]] * 2)
    r = _result([0.0, 0.01], omega, machine_inputs={"Efd": Efd})
    fn = KUNDUR.units[0].machine.params.fn
    np.testing.assert_allclose(speed_deviation(r, KUNDUR), 0.001 * 2 * math.pi * fn)
    np.testing.assert_array_equal(field_voltage(r, KUNDUR), Efd)
    columns = r.columns(KUNDUR)
    assert list(columns)[:13] == (["time"] + [f"{q}_{b}" for q in ("delta", "omega", "Efd") for b in (1, 2, 3, 4)])
    assert {f"V_{b}" for b in KUNDUR.buses} <= set(columns)
    np.testing.assert_allclose(columns["omega_3"], 0.001 * 2 * math.pi * fn)


def test_a_speed_in_rad_per_s_is_taken_as_it_is():
    wscc9 = shipped_case("wscc9")
    n, g = 2, 3
    zeros = np.zeros((n, g))
    r = GridResult(time=np.array([0.0, 0.01]), states={"delta": zeros, "omega": zeros + 0.3},
                   machine_inputs={"Efd": zeros + 2.0}, rotor_angle=zeros,
                   Vs=zeros + 1, theta_vs=zeros, P=zeros, Q=zeros, V_bus=np.ones((n, 9)), theta_bus=np.zeros((n, 9)),
                   stable=True, loss_of_synchronism_s=None, events=(), gen_buses=(1, 2, 3), buses=wscc9.buses)
    np.testing.assert_array_equal(speed_deviation(r, wscc9), zeros + 0.3)
    np.testing.assert_array_equal(field_voltage(r, wscc9), zeros + 2.0)


def test_runs_are_compared_at_their_common_rows_outside_event_times():
    # one run holds the state before the switch at t = 0.02, the other after it; one has an extra row
    a = _result([0.0, 0.01, 0.02, 0.03, 0.035, 0.04], np.ones((6, 4)), [(0.02, "fault at bus 8")],
                Vs=np.array([[1.0], [1.0], [1.0], [0.2], [0.7], [0.2]]) * np.ones((1, 4)))
    b = _result([0.0, 0.01, 0.02, 0.03, 0.04], np.ones((5, 4)), [(0.02, "fault at bus 8")],
                Vs=np.array([[1.0], [1.0], [0.2], [0.201], [0.2]]) * np.ones((1, 4)))
    mine, theirs = common_rows(a, b)
    assert list(a.time[mine]) == [0.0, 0.01, 0.03, 0.04] and list(b.time[theirs]) == [0.0, 0.01, 0.03, 0.04]
    assert errors(a, b)["V"] == pytest.approx(0.001)
    assert errors(a, b, (0.02, 0.1))["V"] == 0.0  # the fault's own steps left out


@pytest.mark.parametrize("tripped", [0, 2])
def test_a_tripped_unit_is_left_out_of_the_errors_from_its_trip_and_is_no_angle_reference(tripped):
    # one run keeps the tripped machine standing still, the other (as ANDES) lets its voltage fall to 0
    # and its angle run; the machines in service agree, each moving by its own angle
    t = np.arange(0.0, 2.0, 0.1)
    trip = 1.0
    delta = np.outer(t, [0.1, 0.2, 0.3, 0.4])
    kept, dropped = _result(t, np.zeros((len(t), 4))), _result(t, np.zeros((len(t), 4)))
    kept.rotor_angle[:], dropped.rotor_angle[:] = delta, delta
    after = t >= trip
    kept.rotor_angle[after, tripped] = delta[np.argmax(after), tripped]
    dropped.rotor_angle[after, tripped] += 5.0
    dropped.Vs[after, tripped] = 0.0
    c = kundur(Event("generator", trip, bus=KUNDUR.units[tripped].bus, generator=KUNDUR.units[tripped].generator, status=0))
    trips = c.trip_times(2.0)
    assert trips == {tripped: trip}
    assert errors(kept, dropped, trips=trips)["angle_deg"] == 0.0 and errors(kept, dropped, trips=trips)["V"] == 0.0
    assert errors(kept, dropped)["angle_deg"] > 100 and errors(kept, dropped)["V"] == 1.0


def test_grid_run_applies_the_case_events_unless_told_not_to(tmp_path, capsys):
    from opfmu.cli import main

    common = ["grid", "run", "--case", "kundur", "--fmus", "monolithic", "--fault", "7", "--fault-start", "1.9",
              "--clear", "1.95", "--stop", "2.05", "--compare", "none"]
    assert main(common + ["--out", str(tmp_path / "with")]) == 0
    assert main(common + ["--no-case-events", "--out", str(tmp_path / "without")]) == 0
    capsys.readouterr()
    with_events = json.loads((tmp_path / "with" / "summary.json").read_text())
    without = json.loads((tmp_path / "without" / "summary.json").read_text())
    assert with_events["case_events"] == ["8-9:2 opened at 2 s"] and without["case_events"] == []
    assert "The case's own events: 8-9:2 opened at 2 s." in (tmp_path / "with" / "report.md").read_text()
    assert "own events" not in (tmp_path / "without" / "report.md").read_text()
    v_with = np.genfromtxt(tmp_path / "with" / "result.csv", delimiter=",", names=True)
    v_without = np.genfromtxt(tmp_path / "without" / "result.csv", delimiter=",", names=True)
    after = v_with["time"] > 2.0 + 1e-9
    assert np.max(np.abs(v_with["V_9"][after] - v_without["V_9"][after])) > 1e-3  # the line opened


@pytest.mark.andes
@pytest.mark.parametrize("name, events", [("kundur", [2.0]), ("npcc", [1.0, 1.1])])
def test_andes_switches_the_case_events_at_the_same_times_as_the_topologies(name, events):
    pytest.importorskip("andes")
    from cosim.andes_runner import AndesRunner

    case = shipped_case(name)
    c = Contingency(network=case.network, events=case.events)
    stop = events[-1] + 0.05
    result, _ = AndesRunner(case, 0.01).run(c, stop)
    assert [t for t, _ in result.events] == [tp.start for tp in c.topologies(stop)[1:]] == events
    grid = np.round(np.arange(0, stop + 1e-9, 0.01), 9)
    # a row at every multiple of the step but the event times, plus ANDES' first row after each event
    expected = sorted(set(grid) - set(events)) + [t + 1e-4 for t in events]
    np.testing.assert_allclose(result.time, sorted(expected), atol=1e-9)
    left_out, _ = AndesRunner(case, 0.01).run(c.without_case_events(), stop)
    assert left_out.events == () and len(left_out.time) == len(grid)
    before = result.time < events[0] - 1e-9
    np.testing.assert_allclose(result.V_bus[before], left_out.V_bus[:before.sum()], atol=1e-12)
    assert np.max(np.abs(result.V_bus[-1] - left_out.V_bus[-1])) > 1e-4  # the events moved the network


@pytest.mark.andes
def test_andes_trips_the_generator_of_a_case_toggle(tmp_path):
    pytest.importorskip("andes")
    from reference_models.grid.andes_case import convert
    from reference_models.grid.case import load_case

    trip = load_case(*convert("ieee14/ieee14_gentrip.xlsx", tmp_path, "trip"))
    c = Contingency(network=trip.network, events=trip.events)
    tops = c.topologies(2.0)
    k = [u.generator for u in trip.units].index("2")
    assert [(tp.start, tp.tripped) for tp in tops] == [(0.0, ()), (1.0, (k,))]


@pytest.mark.andes
def test_kundur_through_its_line_toggle_follows_andes_with_the_monolithic_dae_and_native_fmus():
    """Kundur, fault at bus 8 (1e-4j pu) 1.0-1.1 s, then the case's own opening of 8-9:2 at 2 s, 2.5 s:
    against ANDES at h = 1 ms, compared at the common rows outside the events, the monolithic DAE
    within 0.1 deg and the native reference FMUs at 10 ms within 0.5 deg and 0.01 pu (measured 0.09
    and 0.07 deg over 3 s); without the toggle the angles are more than 5 deg off."""
    pytest.importorskip("andes")
    from cosim.andes_runner import AndesRunner
    from cosim.master import MasterSettings
    from cosim.runners import MonolithicRunner, open_runner

    c = Contingency(8, 1.1, None, 1.0, 1e-4j, KUNDUR.network, KUNDUR.events)
    stop, faults = 2.5, c.fault_intervals(2.5)
    andes, _ = AndesRunner(KUNDUR, 0.001).run(c, stop)
    mono, _ = MonolithicRunner(KUNDUR, 0.001, 1e-9).run(c, stop)
    assert errors(mono, andes, faults, KUNDUR)["angle_deg"] < 0.1
    runner = open_runner("reference", KUNDUR, MasterSettings(step=0.01))
    try:
        fmus, _ = runner.run(c, stop)
    finally:
        runner.close()
    e = errors(fmus, andes, faults, KUNDUR)
    assert e["angle_deg"] < 0.5 and e["V"] < 0.01
    untoggled, _ = MonolithicRunner(KUNDUR, 0.001, 1e-9).run(c.without_case_events(), stop)
    assert errors(untoggled, andes, faults, KUNDUR)["angle_deg"] > 5.0


@pytest.mark.andes
def test_andes_trips_a_generator_its_case_file_does_not_toggle_as_the_native_fmus_do():
    """ieee14, whose file trips no generator, with generator 2's unit tripped at 1 s as an event of
    the contingency: ANDES adds the Toggle of that unit's machine and follows the native reference
    FMUs within 0.05 deg and 1e-3 of the speeds' fall (measured 0.004 deg at h = 10 ms over 2 s)."""
    pytest.importorskip("andes")
    from cosim.andes_runner import AndesRunner
    from cosim.master import MasterSettings
    from cosim.runners import open_runner

    case = shipped_case("ieee14")
    trip = Event(kind="generator", time=1.0, bus=2, generator="2", status=0)
    c = Contingency(network=case.network, events=(trip,))
    stop = 2.0
    andes, _ = AndesRunner(case, 0.01).run(c, stop)
    assert [t for t, _ in andes.events] == [1.0]
    runner = open_runner("reference", case, MasterSettings(step=0.01))
    try:
        fmus, _ = runner.run(c, stop)
    finally:
        runner.close()
    found = errors(fmus, andes, None, case, c.trip_times(stop))
    fall = np.nanmax(np.abs(speed_deviation(andes, case)[-1]))  # rad/s: the system slows without the unit
    assert fall > 0.5
    assert found["angle_deg"] < 0.05 and found["omega"] < 1e-3 * fall
