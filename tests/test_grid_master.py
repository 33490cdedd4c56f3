"""The grid co-simulation master on the WSCC 9-bus system: with native reference FMUs it reproduces
the monolithic DAE to the coupling error of linear inputs over an iterated step (second order in
the communication step), solves the network exactly at every communication point, puts events at
their exact times, mixes FMU kinds, differentiates FMUs without directional derivatives by finite
differences, rewinds its FMUs between runs, and refuses what it cannot couple."""
import json
import math
import shutil
from dataclasses import replace

import numpy as np
import pytest

from cosim.fmus import generator_files
from cosim.master import GridMaster, MasterSettings
from cosim.outputs import errors
from cosim.fmu import CouplingError, Slave
from reference_models.grid import wscc9
from reference_models.grid.contingency import Contingency
from reference_models.grid.monolithic import WSCC9, simulate_contingency


@pytest.fixture(scope="session")
def fmu_cache(grid_fmu_cache):
    return grid_fmu_cache


@pytest.fixture(scope="module")
def reference_master(fmu_cache):
    with GridMaster(generator_files(wscc9.dynamic_data(), "reference", fmu_cache)) as master:
        yield master


def monolithic_on(run, contingency, stop):
    return simulate_contingency(contingency, stop, t_eval=run.time)


def angle_error_deg(run, reference) -> float:
    return errors(run, reference)["angle_deg"]


@pytest.mark.parametrize("contingency", [Contingency(6, 0.09, "6-9"), Contingency(8, 0.065), Contingency(5, 0.0725, "5-7"),
                                         Contingency(9, 0.21, fault_start=0.04, fault_impedance=0.02j)])
def test_native_reference_fmus_follow_the_monolithic_solve_within_the_coupling_error(reference_master, contingency):
    run = reference_master.run(contingency, 2.0).result
    mono = monolithic_on(run, contingency, 2.0)
    assert run.stable and mono.stable
    assert angle_error_deg(run, mono) < 0.6
    fault = (contingency.fault_start, contingency.clear_s)
    assert errors(run, mono, fault)["V"] < 0.01


def test_the_iterated_linear_coupling_is_second_order_in_the_step(fmu_cache):
    contingency = Contingency(9, 0.08)
    files = generator_files(wscc9.dynamic_data(), "reference", fmu_cache)
    error = {}
    for h in (0.02, 0.01):
        with GridMaster(files, settings=MasterSettings(step=h, passes=8, tolerance=1e-9)) as master:
            run = master.run(contingency, 1.5).result
        error[h] = angle_error_deg(run, monolithic_on(run, contingency, 1.5))
    assert error[0.02] / error[0.01] > 3.0  # 4 for second order; 2 for first


def test_held_voltages_err_most_and_one_extrapolated_pass_more_than_an_iterated_step(fmu_cache):
    contingency = Contingency(7, 0.07, "7-8")
    files = generator_files(wscc9.dynamic_data(), "reference", fmu_cache)
    error = {}
    for coupling in ("held", "extrapolated", "iterated"):
        with GridMaster(files, settings=MasterSettings(coupling=coupling)) as master:
            run = master.run(contingency, 1.5).result
        error[coupling] = angle_error_deg(run, monolithic_on(run, contingency, 1.5))
    assert error["iterated"] < 0.5 * error["extrapolated"] and error["extrapolated"] < 0.5 * error["held"]


def test_the_network_solve_reproduces_the_load_flow_at_rest(reference_master):
    run = reference_master.run(Contingency(), 0.2).result
    flow = wscc9.load_flow()
    assert np.max(np.abs(run.V_bus - flow.V)) < 1e-9
    assert np.max(np.abs(run.theta_bus - flow.theta)) < 1e-9
    assert np.max(np.abs(run.omega)) < 1e-9


def test_events_land_on_communication_points_at_their_exact_times(reference_master):
    contingency = Contingency(7, 5 / 60, "5-7", fault_start=0.0133)
    run = reference_master.run(contingency, 0.3).result
    for t_event in (0.0133, 5 / 60):
        assert np.any(np.abs(run.time - t_event) < 1e-12)
    during = (run.time >= 0.0133) & (run.time < 5 / 60)  # the rows at an event: after it
    assert np.max(run.V_bus[during, wscc9.bus_index(7)]) < 1e-4  # bolted
    before = run.time < 0.0133
    assert np.max(np.abs(run.V_bus[before] - wscc9.load_flow().V)) < 1e-9
    assert [e[1] for e in run.events] == ["fault at bus 7", "fault at bus 7 cleared, 5-7 opened"]


def test_a_run_on_the_same_master_again_gives_the_same_result(reference_master):
    contingency = Contingency(4, 0.06, "4-6")
    first = reference_master.run(contingency, 0.5).result
    reference_master.run(Contingency(9, 0.2), 0.4)
    again = reference_master.run(contingency, 0.5).result
    assert np.array_equal(first.delta, again.delta) and np.array_equal(first.V_bus, again.V_bus)


def test_an_unstable_run_is_found_unstable_and_stops_early_when_asked(reference_master):
    contingency = Contingency(7, 0.12, "5-7")
    reference_master.settings = replace(reference_master.settings, stop_at_loss=True)
    try:
        run = reference_master.run(contingency, 3.0).result
    finally:
        reference_master.settings = replace(reference_master.settings, stop_at_loss=False)
    mono = simulate_contingency(contingency, 3.0, stop_at_loss=True, rtol=1e-9)
    assert not run.stable and not mono.stable
    assert run.time[-1] < 2.0
    assert abs(run.loss_of_synchronism_s - mono.loss_of_synchronism_s) < 0.02


def test_fmus_without_directional_derivatives_are_differentiated_numerically(fmu_cache):
    """pythonfmu reference FMUs: no directional derivatives, no input interpolation (midpoint hold)."""
    files = generator_files(wscc9.dynamic_data(), "python", fmu_cache)
    contingency = Contingency(5, 0.05)
    with GridMaster(files) as master:
        assert not any(m.directional or m.interpolates for m in master.machines)
        run = master.run(contingency, 0.6).result
    assert angle_error_deg(run, monolithic_on(run, contingency, 0.6)) < 0.3


def dynamic_data_with(tmp_path, fmus):
    """The shipped dynamic data with each generator's `fmu` entry replaced, written beside copies of
    its machine files; the path."""
    data = json.loads(wscc9.DYNAMIC_DATA_FILE.read_text())
    for bus, generator in zip(wscc9.GENERATOR_BUSES, data["generators"]):
        shutil.copy(wscc9.DATA_DIR / f"wscc9_gen{bus}.json", tmp_path / f"wscc9_gen{bus}.json")
        generator["fmu"] = fmus.get(bus, generator["fmu"])
    path = tmp_path / "dynamic.json"
    path.write_text(json.dumps(data))
    return path


def test_a_dynamic_data_file_mixes_fmu_kinds_per_generator(fmu_cache, tmp_path):
    path = dynamic_data_with(tmp_path, {1: {"kind": "surrogate", "operator": "wscc9_gen1.onnx"}, 2: "reference",
                                        3: {"kind": "python"}})
    dynamics = wscc9.dynamic_data(path)
    files = generator_files(dynamics, None, fmu_cache)
    assert [f.kind for f in files] == ["surrogate", "reference", "python"]
    contingency = Contingency(6, 0.07)
    with GridMaster(files, WSCC9(dynamics)) as master:
        run = master.run(contingency, 0.5).result
    assert angle_error_deg(run, monolithic_on(run, contingency, 0.5)) < 1.0


def test_a_surrogate_for_another_machine_is_refused(fmu_cache, tmp_path):
    path = dynamic_data_with(tmp_path, {2: {"kind": "surrogate", "operator": "wscc9_gen3.onnx"}})
    with pytest.raises(CouplingError, match="bus 2.*trained for another machine"):
        generator_files(wscc9.dynamic_data(path), None, fmu_cache)


def test_an_fmu_without_the_variables_of_its_role_is_refused(fmu_cache):
    files = generator_files(wscc9.dynamic_data(), "reference", fmu_cache)
    with pytest.raises(CouplingError, match="has no variable Vs"):
        Slave(files[0].exciter, "machine", ("Vs", "theta_vs"), ("I_re",), {})


def test_settings_and_contingencies_refuse_what_makes_no_sense():
    with pytest.raises(ValueError, match="communication step"):
        MasterSettings(step=0.0)
    with pytest.raises(ValueError, match="passes"):
        MasterSettings(passes=0)
    with pytest.raises(ValueError, match="disconnects a generator"):
        Contingency(7, 0.1, "2-7")
    with pytest.raises(ValueError, match="after the fault start"):
        Contingency(7, 0.1, fault_start=0.2)
    with pytest.raises(ValueError, match="no bus"):
        Contingency(12, 0.1)
    with pytest.raises(ValueError, match="no branch"):
        Contingency(7, 0.1, "4-9")
