"""A turbine driving two machines (IEEEG1 with ANDES' syn2): its high-pressure stages' power goes to
the first machine and its low-pressure stages' to the second, each on its own machine's base; the
second machine's unit takes its mechanical power from the first unit's governor (Unit.takes), in
the start (the turbine's valve gives both machines their load-flow powers), in the co-simulation
master and in the monolithic DAE. With ANDES (marker `andes`): kundur_ieeeg1, whose IEEEG1 3
drives generators 3 and 4, converts so and follows ANDES through a fault."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from cosim.master import MasterSettings
from cosim.runners import open_runner
from reference_models.grid.case import DATA_DIR, CaseError, load_case
from reference_models.grid.contingency import Contingency
from reference_models.grid.monolithic import System, simulate
from reference_models.models.ieeeg1 import IEEEG1

STAGES = {"K1": 0.2, "K2": 0.1, "K3": 0.2, "K4": 0.0, "K5": 0.1, "K6": 0.3, "K7": 0.0, "K8": 0.1}


def test_a_turbine_gives_each_machine_its_stages_power_on_that_machines_base():
    p = IEEEG1.params({**STAGES, "Sn": 1500.0, "Sg": 600.0, "Sg2": 900.0, "T7": 0.2})
    x = np.array([0.0, 0.6, 0.5, 0.4, 0.3, 0.2])  # lead-lag, valve, the four stages [pu on 1500 MVA]
    Pm, Pm2 = IEEEG1.output_values(x, np.array([1.0, 0.6]), p)
    stages = x[2:]
    assert math.isclose(Pm * 600.0, 1500.0 * (0.2 * stages[0] + 0.2 * stages[1] + 0.1 * stages[2]), rel_tol=1e-12)
    assert math.isclose(Pm2 * 900.0, 1500.0 * (0.1 * stages[0] + 0.3 * stages[2] + 0.1 * stages[3]), rel_tol=1e-12)


def test_a_turbine_of_another_rating_than_its_one_machine_gives_it_power_on_the_machines_base():
    p = IEEEG1.params({"Sn": 1000.0, "Sg": 800.0})
    x0, solved = IEEEG1.start({"omega": 1.0, "Pm": 0.75}, p)
    assert math.isclose(IEEEG1.output_values(x0, np.array([1.0, solved["Pref"]]), p)[0], 0.75, rel_tol=1e-12)
    assert math.isclose(x0[1], 0.75 * 800.0 / 1000.0 / (0.3 + 0.3 + 0.4), rel_tol=1e-12)  # valve on the turbine base


def test_a_turbine_starts_giving_both_machines_their_load_flow_power():
    p = IEEEG1.params({**STAGES, "Sn": 1500.0, "Sg": 600.0, "Sg2": 900.0})
    # the high-pressure fractions sum to 0.5, the low-pressure ones to 0.5: equal powers in MW
    x0, solved = IEEEG1.start({"omega": 1.0, "Pm": 0.9, "Pm2": 0.6}, p)
    Pm, Pm2 = IEEEG1.output_values(x0, np.array([1.0, solved["Pref"]]), p)
    assert math.isclose(Pm, 0.9, rel_tol=1e-12) and math.isclose(Pm2, 0.6, rel_tol=1e-12)
    assert np.max(np.abs(IEEEG1.rhs(x0, np.array([1.0, solved["Pref"]]), p))) < 1e-12


def test_a_turbine_whose_machines_powers_do_not_stand_as_its_stages_is_refused():
    p = IEEEG1.params({**STAGES, "Sn": 1500.0, "Sg": 600.0, "Sg2": 900.0})
    with pytest.raises(ValueError, match="do not stand as its high- and low-pressure stage fractions"):
        IEEEG1.start({"omega": 1.0, "Pm": 0.9, "Pm2": 0.7}, p)


def _kundur_on_one_turbine(tmp_path, shares=None):
    """The shipped kundur case with generators 3 and 4 on one IEEEG1 (at generator 3): its stage
    fractions split as the load flow's powers of the two (or as `shares`), generator 4 taking its
    mechanical power from it. Returns the Case (CaseError propagates)."""
    network = DATA_DIR / "kundur_network.json"
    flow = json.loads(network.read_text())
    names = [g.get("name") or str(g["bus"]) for g in flow["generators"]]
    P3, P4 = (flow["load_flow"]["P"][names.index(n)] for n in ("3", "4"))
    high, low = shares or (P3 / (P3 + P4), P4 / (P3 + P4))
    data = json.loads((DATA_DIR / "kundur.json").read_text())
    units = {str(u["generator"]): u for u in data["generators"]}
    units["3"]["governor"] = {"component": "ieeeg1", "params": {
        "K": 20.0, "T1": 0.5, "T2": 1.0, "T3": 0.1, "T4": 0.3, "T5": 7.0, "T6": 0.6, "K1": 0.6 * high, "K2": 0.6 * low,
        "K3": 0.4 * high, "K4": 0.4 * low, "K5": 0.0, "K7": 0.0, "PMAX": 1.2, "Sn": 1800.0, "Sg": 900.0,
        "Sg2": 900.0}}
    del units["4"]["governor"]
    units["4"]["takes"] = {"mechanical_power": {"generator": "3", "signal": "second_mechanical_power"}}
    path = tmp_path / "kundur_one_turbine.json"
    path.write_text(json.dumps(data))
    return load_case(network, path, "kundur_one_turbine")


def test_a_machine_driven_by_another_units_turbine_starts_and_stays_at_rest(tmp_path):
    case = _kundur_on_one_turbine(tmp_path)
    k3, k4 = (next(k for k, u in enumerate(case.units) if u.generator == g) for g in ("3", "4"))
    governor = case.starts[k3][[d.name for d in case.units[k3].devices].index("governor")]
    assert math.isclose(governor.states[1] * 1800.0, 100.0 * (case.flow.P_gen[k3] + case.flow.P_gen[k4]),
                        rel_tol=1e-9)  # the valve carries both machines' power
    system = System(case)
    assert np.max(np.abs(system.rhs(0.0, system.x0, system.network()))) < 1e-9
    result = simulate(system, Contingency(), 1.0)
    assert np.max(np.abs(result.angles - result.angles[0])) < 1e-6
    runner = open_runner("reference", case, MasterSettings(step=0.01))
    try:
        fmu = runner.run(Contingency(), 1.0)[0]
    finally:
        runner.close()
    delta = fmu.states["delta"]
    assert np.max(np.abs(delta - delta[0])) < 1e-6


def test_a_machine_driven_by_another_units_turbine_follows_the_monolithic_run_through_a_fault(tmp_path):
    case = _kundur_on_one_turbine(tmp_path)
    fault = Contingency(8, 1.1, None, 1.0, 1e-4j, case.network)
    mono = open_runner("monolithic", case, MasterSettings(step=0.01)).run(fault, 3.0)[0]
    runner = open_runner("reference", case, MasterSettings(step=0.01))
    try:
        fmu = runner.run(fault, 3.0)[0]
    finally:
        runner.close()
    spread = lambda r: r.states["delta"] - r.states["delta"].mean(axis=1, keepdims=True)  # noqa: E731
    assert np.degrees(np.max(np.abs(spread(fmu) - spread(mono)))) < 0.3
    # the turbine's second machine feels its governor: its mechanical power moves with generator 3's speed
    k4 = next(k for k, u in enumerate(case.units) if u.generator == "4")
    Pm4 = fmu.machine_inputs["Pm"][:, k4]
    assert np.ptp(Pm4) > 1e-3 * abs(Pm4[0])


def test_machines_whose_load_flow_powers_do_not_stand_as_their_turbines_stages_are_refused(tmp_path):
    with pytest.raises(CaseError, match="do not stand as its high- and low-pressure"):
        _kundur_on_one_turbine(tmp_path, shares=(0.6, 0.4))  # the load flow gives both 700 MW


def test_a_unit_taking_a_signal_from_a_generator_the_case_does_not_have_is_refused(tmp_path):
    data = json.loads((DATA_DIR / "kundur.json").read_text())
    del data["generators"][3]["governor"]
    data["generators"][3]["takes"] = {"mechanical_power": {"generator": "9", "signal": "second_mechanical_power"}}
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(CaseError, match="from generator 9, which the case does not have"):
        load_case(DATA_DIR / "kundur_network.json", path)


@pytest.mark.andes
def test_kundur_ieeeg1_drives_generator_4_from_generator_3s_turbine_as_andes_does():
    andes = pytest.importorskip("andes")
    from reference_models.grid.andes_case import case_from_file, configure_andes_logging

    configure_andes_logging(andes)
    case = case_from_file(andes.get_case("kundur/kundur_ieeeg1.xlsx"))
    by_name = {u.generator: (k, u) for k, u in enumerate(case.units)}
    k3, unit3 = by_name["3"]
    k4, unit4 = by_name["4"]
    assert [(r.signal, r.generator, r.gives) for r in unit4.takes] == [
        ("mechanical_power", "3", "second_mechanical_power")]
    assert "governor" not in [d.name for d in unit4.devices]
    ss = andes.run(andes.get_case("kundur/kundur_ieeeg1.xlsx"), no_output=True, default_config=True)
    ss.TDS.init()
    g = ss.IEEEG1
    i = list(g.idx.v).index(3)
    governor = case.starts[k3][[d.name for d in unit3.devices].index("governor")]
    # ANDES' valve on the system base, ours on the turbine's (Sg + Sg2 = 1800 MVA)
    assert math.isclose(governor.states[1] * float(g.Sn.v[i]) / 100.0, float(g.IAW_y.v[i]), rel_tol=1e-9)
    machine4 = case.starts[k4][0]
    j = list(ss.GENROU.idx.v).index(4)
    assert math.isclose(machine4.inputs["Pm"] * 900.0 / 100.0, float(ss.GENROU.tm.v[j]), rel_tol=1e-9)
