"""The shipped grid cases (reference_models.grid.case.shipped_case): they load without ANDES, their
network holds the shipped load flow, every device starts at rest and wired to its unit, and (with
ANDES, marker `andes`) the converter reproduces the shipped files and the start values are ANDES'."""
from __future__ import annotations

import json
import math
from collections import Counter

import numpy as np
import pytest

from reference_models.grid import wscc9
from reference_models.grid.andes_case import ANDES_CASES, mismatch
from reference_models.grid.case import DATA_DIR, SHIPPED_CASES, CaseError, shipped_case, unit_wiring

CONVERTED = tuple(ANDES_CASES)
# the shipped cases: buses, units, devices by component
EXPECTED = {
    "kundur": (10, 4, {"genrou": 4, "exdc2": 4, "tgov1": 4}),
    "ieee14": (14, 5, {"genrou": 5, "tgov1": 5, "exst1": 1, "esst3a": 4}),
    "ieee39": (39, 10, {"genrou": 10, "ieeex1": 10, "tgov1n": 10, "ieeest": 10}),
    "npcc": (140, 48, {"gencls": 21, "genrou": 27, "tgov1": 29, "ieeex1": 24}),
}
REST_TOLERANCE = 1e-9  # largest |dx/dt| of any device at its start (in its states' units per s)
ANDES_TOLERANCE = 1e-11  # measured: at most 1.4e-14 (GENCLS' Pm, npcc) and 1e-13 (IEEEST, ieee39)


@pytest.mark.parametrize("name", CONVERTED)
def test_shipped_cases_load_with_their_buses_and_units(name):
    case = shipped_case(name)
    buses, units, devices = EXPECTED[name]
    assert len(case.buses) == buses and len(case.units) == units
    assert Counter(d.component.name for u in case.units for d in u.devices) == devices
    assert all(u.machine.name == "machine" for u in case.units)


def test_wscc9_loads_by_name_as_its_own_module_builds_it():
    named, built = shipped_case("wscc9"), wscc9.case()
    assert named.network == built.network and named.units == built.units and named.starts == built.starts
    assert np.array_equal(named.flow.V_complex, built.flow.V_complex) and named.events == ()
    with pytest.raises(CaseError, match="no shipped case 'ieee300'"):
        shipped_case("ieee300")


@pytest.mark.parametrize("name", SHIPPED_CASES)
def test_shipped_network_holds_its_load_flow(name):
    network = json.loads((DATA_DIR / f"{name}_network.json").read_text())
    assert mismatch(network) < 1e-8


def _values(device, start) -> np.ndarray:
    c = device.component
    u = np.array([start.inputs[n] for n in c.input_names])
    return np.asarray(start.states, dtype=float), u


@pytest.mark.parametrize("name", SHIPPED_CASES)
def test_every_device_starts_at_rest(name):
    case = shipped_case(name)
    worst = 0.0
    for unit, starts in zip(case.units, case.starts):
        for device, start in zip(unit.devices, starts):
            x, u = _values(device, start)
            worst = max(worst, float(np.abs(device.component.rhs(x, u, device.params)).max()))
    assert worst < REST_TOLERANCE


@pytest.mark.parametrize("name", SHIPPED_CASES)
def test_start_values_agree_along_every_wire_of_a_unit(name):
    case = shipped_case(name)
    for k, (unit, starts) in enumerate(zip(case.units, case.starts)):
        flow = case.flow.generator_at(k)
        wiring = unit_wiring([d.component.ports for d in unit.devices])
        given = []
        for device, start in zip(unit.devices, starts):
            x, u = _values(device, start)
            c = device.component
            y = dict(zip(c.output_names, c.output_values(x, u, device.params)))
            given.append({**dict(zip(c.state_names, x)), **y})
        for j, (device, start) in enumerate(zip(unit.devices, starts)):
            for variable, source in wiring[j].items():
                value = start.inputs[variable]
                if source.kind == "device":
                    assert value == pytest.approx(given[source.device][source.variable], abs=1e-12)
                elif source.kind == "bus":
                    assert value == pytest.approx((flow["V"], flow["theta"])[source.index], abs=0)
                elif source.kind == "terminal" and source.index == 0:
                    assert value == pytest.approx(flow["V"], abs=1e-12)  # no external impedance here


def test_units_are_keyed_by_generator_where_a_bus_has_two():
    case = shipped_case("npcc")
    buses = Counter(u.bus for u in case.units)
    shared = [bus for bus, n in buses.items() if n > 1]
    assert len(shared) == 2
    for bus in shared:
        units = [u for u in case.units if u.bus == bus]
        assert len({u.generator for u in units}) == len(units)
    assert case.reduced().Y_real.shape == (2 * len(buses), 2 * len(buses))


def test_case_events_name_branches_the_network_has():
    kundur, npcc = shipped_case("kundur"), shipped_case("npcc")
    assert [(e.kind, e.time, e.branch, e.status) for e in kundur.events] == [("branch", 2.0, "8-9:2", 0)]
    assert kundur.network.branch("8-9:2") != kundur.network.branch("8-9")
    assert [(e.time, e.status) for e in npcc.events] == [(1.0, 0), (1.1, 1)]
    for case in (kundur, npcc):
        for event in case.events:
            case.network.openable(event.branch)


def test_a_parallel_branch_opens_alone():
    net = shipped_case("kundur").network
    both = net.ybus()
    one = net.ybus(["8-9:2"])
    i, k = net.bus_index(8), net.bus_index(9)
    branch = net.branch("8-9:2")
    assert branch != net.branch("8-9")
    assert one[i, k] - both[i, k] == pytest.approx(1.0 / complex(branch.r, branch.x), rel=1e-12)


@pytest.mark.andes
@pytest.mark.parametrize("name", CONVERTED)
def test_converter_reproduces_the_shipped_files(name, tmp_path):
    pytest.importorskip("andes")
    from reference_models.grid.andes_case import convert

    for written, shipped in zip(convert(ANDES_CASES[name], tmp_path, name),
                                (DATA_DIR / f"{name}_network.json", DATA_DIR / f"{name}.json")):
        assert _close(_without_operators(json.loads(written.read_text())),
                      _without_operators(json.loads(shipped.read_text()))), written.name


def _without_operators(data: dict) -> dict:
    """A case file without the operator files its units' fmu entries name (the shipped kundur names
    the surrogates trained for it, which no converter can know)."""
    for unit in data.get("generators", []):
        if isinstance(unit.get("fmu"), dict):
            unit["fmu"] = {k: v for k, v in unit["fmu"].items() if k != "operator"}
    return data


def _close(a, b) -> bool:
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_close(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b))
    if isinstance(a, float) or isinstance(b, float):
        return math.isclose(a, b, rel_tol=1e-12, abs_tol=1e-14)
    return a == b


@pytest.mark.andes
@pytest.mark.parametrize("name", CONVERTED)
def test_start_values_are_andes_initial_states(name):
    pytest.importorskip("andes")
    from reference_models.grid.andes_case import compare_shipped

    results = compare_shipped(name)
    assert max(results.pop("load_flow").values()) < ANDES_TOLERANCE
    counts = Counter()
    for model, r in results.items():
        assert r["state"] < ANDES_TOLERANCE and r["set_point"] < ANDES_TOLERANCE, model
        counts[model.lower()] = r["devices"]
    assert counts == EXPECTED[name][2]


@pytest.mark.andes
def test_converted_events_are_the_case_files_own(tmp_path):
    pytest.importorskip("andes")
    from reference_models.grid.andes_case import convert
    from reference_models.grid.case import load_case

    fault = load_case(*convert("ieee14/ieee14_fault.xlsx", tmp_path, "fault"))
    trip = load_case(*convert("ieee14/ieee14_gentrip.xlsx", tmp_path, "trip"))
    assert [(e.kind, e.bus, e.time, e.clear, e.impedance) for e in fault.events] == [("fault", 9, 1.0, 1.1, 1e-4j)]
    assert [(e.kind, e.bus, e.generator, e.time, e.status) for e in trip.events] == [("generator", 2, "2", 1.0, 0)]
    assert any(u.generator == "2" for u in trip.units)


@pytest.mark.andes
@pytest.mark.parametrize("source, message", [
    ("kundur/kundur_vsc.xlsx", "the case uses the models Node, Ground, R, VSCShunt, which opfmu does not have"),
    ("no_such_case.xlsx", "no case file no_such_case.xlsx"),
])
def test_a_case_the_converter_cannot_take_is_refused_in_one_line(source, message, tmp_path, capsys):
    pytest.importorskip("andes")
    from reference_models.grid.andes_case import main

    assert main([source, str(tmp_path)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and message in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.andes
@pytest.mark.parametrize("model, dev", [("PV", 2), ("StaticGen", 2), ("GENROU", "GENROU_2"), ("SynGen", "GENROU_2")])
def test_a_toggle_of_a_machine_or_its_load_flow_generator_is_a_generator_event(model, dev):
    pytest.importorskip("andes")
    import andes

    from reference_models.grid.andes_case import configure_andes_logging, events

    configure_andes_logging(andes)
    ss = andes.load(andes.get_case("ieee14/ieee14_full.xlsx"), setup=False, no_output=True, default_config=True)
    ss.add("Toggle", {"model": model, "dev": dev, "t": 1.0})
    ss.add("Toggle", {"model": "Line", "dev": "Line_3", "t": 1.2})
    ss.add("Toggle", {"model": "Line", "dev": "Line_3", "t": 1.3})
    ss.setup()
    number = {idx: int(idx) for idx in ss.Bus.idx.v}
    found = events(ss, number)
    assert [(e["kind"], e["time"], e.get("generator"), e["status"]) for e in found] == [
        ("generator", 1.0, "2", 0), ("branch", 1.2, None, 0), ("branch", 1.3, None, 1)]
    assert found[0]["bus"] == 2
