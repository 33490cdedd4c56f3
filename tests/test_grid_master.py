"""The grid co-simulation master on the WSCC 9-bus system: with native reference FMUs it reproduces
the monolithic DAE to the coupling error of quadratic inputs over an iterated step (third order in
the communication step), solves the network exactly at every communication point, puts events at
their exact times, mixes FMU kinds, differentiates FMUs without directional derivatives by finite
differences, rewinds its FMUs between runs, runs FMI 3.0 FMUs, wires any FMU by the ports its model
description declares, removes every extracted FMU folder, and refuses what it cannot couple."""
import json
import shutil
import zipfile
from dataclasses import replace

import numpy as np
import pytest

from cosim.fmu import FMU, CouplingError
from cosim.fmus import generator_files
from cosim.master import GridMaster, MasterSettings, communication_points
from cosim.outputs import errors
from cosim.stability import loss_of_synchronism
from reference_models.grid import wscc9
from reference_models.grid.contingency import Contingency
from reference_models.grid.monolithic import System, simulate

CASE = wscc9.case()
SYSTEM = System(CASE)


@pytest.fixture(scope="module")
def reference_master(fmu_cache):
    with GridMaster(CASE, generator_files(CASE, "reference", fmu_cache)) as master:
        yield master


def monolithic_on(run, contingency, stop, system=SYSTEM):
    return simulate(system, contingency, stop, t_eval=run.time)


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


def test_the_iterated_coupling_on_parabolas_is_third_order_in_the_step(fmu_cache):
    contingency = Contingency(9, 0.08)
    files = generator_files(CASE, "reference", fmu_cache)
    error = {}
    for h in (0.02, 0.01):
        with GridMaster(CASE, files, settings=MasterSettings(step=h, passes=8, tolerance=1e-9)) as master:
            run = master.run(contingency, 1.5).result
        error[h] = angle_error_deg(run, monolithic_on(run, contingency, 1.5))
    assert all(f.input_order == 2 for f in master.fmus)  # the native reference FMUs take second derivatives
    assert error[0.02] / error[0.01] > 6.0  # 8 for third order (measured 7.7); 4 for second (lines)


def test_held_voltages_err_most_and_one_extrapolated_pass_more_than_an_iterated_step(fmu_cache):
    contingency = Contingency(7, 0.07, "7-8")
    files = generator_files(CASE, "reference", fmu_cache)
    error = {}
    for coupling in ("held", "extrapolated", "iterated"):
        with GridMaster(CASE, files, settings=MasterSettings(coupling=coupling)) as master:
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
    mono = simulate(SYSTEM, contingency, 3.0, stop_at_loss=True, rtol=1e-9)
    assert not run.stable and not mono.stable
    assert run.time[-1] < 2.0
    assert abs(run.loss_of_synchronism_s - mono.loss_of_synchronism_s) < 0.02
    # the rows of both show the loss that the verdict reads, so run_verdict does not run them again to the stop
    for result in (run, mono):
        assert loss_of_synchronism(result, contingency, 3.0) == pytest.approx(result.loss_of_synchronism_s, abs=0.02)


def test_fmus_without_directional_derivatives_are_differentiated_numerically(fmu_cache):
    """pythonfmu reference FMUs: no directional derivatives, no input interpolation (midpoint hold)."""
    files = generator_files(CASE, "python", fmu_cache)
    contingency = Contingency(5, 0.05)
    with GridMaster(CASE, files) as master:
        assert not any(f.directional or f.interpolates for f in master.fmus)
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
    case = wscc9.case(path)
    files = generator_files(case, None, fmu_cache)
    assert [f.kind for f in files] == ["surrogate", "reference", "python"]
    contingency = Contingency(6, 0.07)
    with GridMaster(case, files) as master:
        run = master.run(contingency, 0.5).result
    assert angle_error_deg(run, monolithic_on(run, contingency, 0.5, System(case))) < 1.0


def test_a_surrogate_for_another_machine_is_refused(fmu_cache, tmp_path):
    path = dynamic_data_with(tmp_path, {2: {"kind": "surrogate", "operator": "wscc9_gen3.onnx"}})
    with pytest.raises(CouplingError, match="bus 2.*trained for another machine"):
        generator_files(wscc9.case(path), None, fmu_cache)


def test_an_fmu_without_the_variables_it_is_bound_to_is_refused(fmu_cache, tmp_path):
    files = generator_files(CASE, "reference", fmu_cache)
    with FMU(files[0].paths[1], "exciter", scratch=tmp_path) as exciter:
        with pytest.raises(CouplingError, match="has no variable Vs"):
            exciter.bind(("Vs", "theta_vs"), ("I_re",))
    assert not list(tmp_path.iterdir())


def test_an_fmu_without_a_bus_port_cannot_be_a_machine_and_leaves_no_folder(fmu_cache, tmp_path):
    files = generator_files(CASE, "reference", fmu_cache)
    exciter = files[0].paths[1]
    wrong = [replace(files[0], paths=(exciter, exciter)), *files[1:]]
    with pytest.raises(CouplingError, match="declares no bus port"):
        GridMaster(CASE, wrong, scratch=tmp_path)
    assert not list(tmp_path.iterdir())


def foreign(path, out, ports: bool):
    """The FMU at `path` as if another tool had built it: its generationTool and description changed,
    with (ports) or without the <Ports> element of its component."""
    import xml.etree.ElementTree as ET

    from reference_models.components import COMPONENTS

    with zipfile.ZipFile(path) as src, zipfile.ZipFile(out, "w") as dst:
        for item in src.infolist():
            data = src.read(item.filename)
            if item.filename == "modelDescription.xml":
                root = ET.fromstring(data)
                component = next(c for c in COMPONENTS.values() if root.get("description").startswith(c.description))
                root.set("generationTool", "another tool")
                root.set("description", "a machine")
                for annotations in root.findall("VendorAnnotations"):
                    root.remove(annotations)
                if ports:
                    annotations = ET.Element("VendorAnnotations")
                    ET.SubElement(annotations, "Tool", name="opfmu").append(component.ports.element())
                    root.insert(list(root).index(root.find("ModelVariables")), annotations)
                data = ET.tostring(root, encoding="UTF-8", xml_declaration=True)
            dst.writestr(item, data)
    return out


def test_an_fmu_another_tool_built_is_wired_by_the_ports_its_model_description_declares(fmu_cache, tmp_path):
    files = generator_files(CASE, "reference", fmu_cache)
    theirs = [replace(f, kind="file", paths=tuple(foreign(p, tmp_path / f"{f.bus}_{j}.fmu", ports=True)
                                                   for j, p in enumerate(f.paths))) for f in files]
    contingency = Contingency(8, 0.065)
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    with GridMaster(CASE, files) as ours, GridMaster(CASE, theirs, scratch=scratch) as master:
        assert np.array_equal(master.run(contingency, 0.4).result.delta, ours.run(contingency, 0.4).result.delta)
    assert not list(scratch.iterdir())


def test_an_fmu_that_declares_no_ports_and_is_not_the_projects_is_refused(fmu_cache, tmp_path):
    files = generator_files(CASE, "reference", fmu_cache)
    bare = [replace(files[0], kind="file", paths=(foreign(files[0].paths[0], tmp_path / "m.fmu", ports=False),
                                                 files[0].paths[1])), *files[1:]]
    with pytest.raises(CouplingError, match="declares no ports"):
        GridMaster(CASE, bare, scratch=tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == ["m.fmu"]


def test_fmi3_fmus_run_with_their_inputs_held_at_the_step_midpoint(fmu_cache):
    contingency = Contingency(7, 0.083)
    fmi2 = generator_files(CASE, "reference", fmu_cache)
    fmi3 = generator_files(CASE, "reference", fmu_cache, fmi_version=3)
    with GridMaster(CASE, fmi3) as master:
        assert all(f.version == 3 and not f.interpolates and f.rolls_back for f in master.fmus)
        run = master.run(contingency, 1.0).result
    with GridMaster(CASE, fmi2) as master:
        linear = master.run(contingency, 1.0).result
    mono = monolithic_on(run, contingency, 1.0)
    assert run.stable and angle_error_deg(run, mono) < 1.0
    assert not np.array_equal(run.delta, linear.delta)


def test_communication_points_are_the_step_multiples_and_the_event_times():
    changes = Contingency(7, 5 / 60, "5-7", fault_start=0.0133).topologies(0.05 + 1e-3)[1:]
    points = list(communication_points(0.01, 0.051, changes))
    assert [round(t, 12) for t, _ in points] == [0.01, 0.0133, 0.02, 0.03, 0.04, 0.05, 0.051]
    assert [t for t, c in points if c is not None] == [0.0133]
    assert len(list(communication_points(0.01, 3600.0, ()))) == 360000


def test_settings_and_contingencies_refuse_what_makes_no_sense():
    with pytest.raises(ValueError, match="negative part"):
        Contingency(7, 0.1, fault_impedance=-0.01j)
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
