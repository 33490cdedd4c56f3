"""A native FMU's component parameters are FMU parameters: one FMU of a model serves every parameter
set of its structure, refuses a value that would change its equations' form or break the
component's checks, and a surrogate refuses any but its trained ones (fmu_export/c_parameters.py)."""
from __future__ import annotations

import xml.etree.ElementTree as ET
import zipfile

import fmpy
import numpy as np
import pytest
from fmpy.fmi1 import FMICallException

from cosim.fmu import FMU, CouplingError
from cosim.fmus import generator_files
from fmu_export.model_description import validation_problems
from fmu_export.native_reference_fmu import build_native_reference_fmu, structure_of
from reference_models.grid.case import shipped_case
from reference_models.models.genrou import GENROU
from reference_models.models.tgov1 import TGOV1

# a GENROU unlike the default in every parameter its coefficients and swing derive from
GENROU_OTHER = {"M": 9.0, "D": 2.0, "xd": 1.6, "xq": 1.5, "xd1": 0.35, "xq1": 0.5, "Td10": 6.0, "ra": 0.003,
                "Sn": 500.0}


@pytest.fixture(scope="module", params=[2, 3], ids=["fmi2", "fmi3"])
def genrou(request, tmp_path_factory):
    """(FMI version, the default GENROU's FMU, an FMU built for GENROU_OTHER) of that version."""
    folder = tmp_path_factory.mktemp(f"genrou{request.param}")
    default, other = folder / "GENROUReference.fmu", folder / "GENROUOther.fmu"
    build_native_reference_fmu(default, "GENROUReference", GENROU, fmi_version=request.param)
    build_native_reference_fmu(other, "GENROUOther", GENROU, GENROU_OTHER, fmi_version=request.param)
    return request.param, default, other


@pytest.fixture(scope="module")
def tgov1(tmp_path_factory):
    """{FMI version: the FMU of the default TGOV1 (T1 = 0.1 s, T3 = 10 s)}."""
    folder = tmp_path_factory.mktemp("tgov1")
    out = {}
    for version in (2, 3):
        out[version] = folder / f"TGOV1Reference{version}.fmu"
        build_native_reference_fmu(out[version], "TGOV1Reference", TGOV1, fmi_version=version)
    return out


def starts_of(path) -> dict:
    """The start values of an FMU's inputs and initial-state parameters, by name."""
    md = fmpy.read_model_description(str(path))
    return {v.name: float(v.start) for v in md.modelVariables if v.start is not None
            and (v.causality == "input" or (v.name.endswith("0") and v.causality == "parameter"))}


def trajectory(path, start_values: dict):
    kw = dict(stop_time=0.5, output_interval=0.005, output=list(GENROU.state_names + ("P", "Q")))
    return fmpy.simulate_fmu(str(path), start_values=start_values, **kw)


def test_parameters_set_at_instantiation_give_the_fmu_built_for_them(genrou):
    version, default, other = genrou
    start = {**starts_of(other), "Vs": 0.9}  # the other machine's rest, then a dip
    baked = trajectory(other, start)
    tuned = trajectory(default, {**start, **GENROU_OTHER})
    for name in GENROU.state_names + ("P", "Q"):
        scale = np.max(np.abs(baked[name]))
        assert np.max(np.abs(tuned[name] - baked[name])) <= 1e-10 * scale, name
    assert np.ptp(baked["delta"]) > 1e-3  # the dip moved the machine


def test_the_projects_fmu_wrapper_sets_a_devices_parameters(genrou):
    version, default, other = genrou
    params = GENROU.params(GENROU_OTHER)
    start = starts_of(other)
    with FMU(other, "baked") as baked, FMU(default, "tuned", init=False) as tuned:
        tuned.initialise({**start, **tuned.parameter_values(params)})
        assert tuned.parameter_values(params) == params.to_dict()
        for _ in range(20):
            a, b = baked.step(0.01, 0.95), tuned.step(0.01, 0.95)
            assert np.allclose(b, a, rtol=1e-10, atol=0.0)
        assert tuned.get("M")[0] == 9.0


def test_the_model_descriptions_declare_fixed_parameters_with_their_ranges_and_validate(genrou):
    version, default, _ = genrou
    assert validation_problems(default) == []
    root = ET.fromstring(zipfile.ZipFile(default).read("modelDescription.xml"))
    tag = "ScalarVariable" if version == 2 else "Float64"
    variables = {v.get("name"): v for v in root.iter(tag)}
    M = variables["M"]
    assert (M.get("causality"), M.get("variability")) == ("parameter", "fixed")
    bounds = M.find("Real").attrib if version == 2 else M.attrib
    assert (float(bounds["min"]), float(bounds["max"]), float(bounds["start"])) == (0.1, 2000.0, 13.0)
    assert "structural" in variables["S10"].get("description")  # saturation data: coefficients in Python


def refusal(path, version: int, values: dict) -> str:
    """The message an FMU logs refusing the start values `values` (pytest fails if it accepts them)."""
    said = []

    def logger(*args):
        said.append(args[-1].decode())

    with pytest.raises(FMICallException):
        fmpy.simulate_fmu(str(path), start_values=values, stop_time=0.1, logger=logger, debug_logging=False)
    return " ".join(said)


@pytest.mark.parametrize("version", [2, 3])
def test_a_structural_parameter_change_is_refused_with_its_name(tgov1, version):
    # T3 = 0 makes the lead-lag a gain: other equations
    said = refusal(tgov1[version], version, {"T3": 0.0})
    assert "structural parameter T3 = 0 refused" in said and "the FMU was built for T3 > 0" in said
    # a time constant's value within the structure is a parameter like any other
    result = fmpy.simulate_fmu(str(tgov1[version]), start_values={"T3": 5.0}, stop_time=0.1)
    assert np.all(np.isfinite(result["Pm"]))


@pytest.mark.parametrize("version", [2, 3])
def test_a_value_outside_the_components_range_is_refused(tgov1, version):
    said = refusal(tgov1[version], version, {"R": -0.05})
    assert "parameter R = -0.05 pu lies outside [0.001, 10] pu" in said


@pytest.mark.parametrize("version", [2, 3])
def test_limits_out_of_order_are_refused_when_initialisation_ends(tgov1, version):
    said = refusal(tgov1[version], version, {"VMIN": 1.5})  # above VMAX = 1.2
    assert "ExitInitializationMode" in said and "VMAX > VMIN must hold" in said
    # set in any order, limits that end in order are taken
    result = fmpy.simulate_fmu(str(tgov1[version]), start_values={"VMIN": 1.5, "VMAX": 2.0}, stop_time=0.1)
    assert np.all(np.isfinite(result["Pm"]))


def test_a_parameter_is_fixed_once_initialised(tgov1):
    with FMU(tgov1[2], "governor") as fmu:
        with pytest.raises(Exception):
            fmu.set(T1=0.2)
        assert "fixed after initialization" in fmu.last_message()


def test_the_structure_is_what_the_equations_decide_on_parameter_values():
    default = structure_of(TGOV1)
    assert structure_of(TGOV1, {"T1": 0.3, "T3": 2.0, "R": 0.04}) == default  # values only
    assert structure_of(TGOV1, {"T3": 0.0}) != default  # a lead-lag without lag
    assert structure_of(GENROU, {"S10": 0.1, "S12": 0.4}) != structure_of(GENROU)  # saturation


def test_the_guid_follows_the_structure_not_the_values(tmp_path):
    guids = [build_native_reference_fmu(tmp_path / f"{k}.fmu", "TGOV1Reference", TGOV1, params)["guid"]
             for k, params in enumerate(({}, {"T1": 0.3, "R": 0.04}, {"T3": 0.0}))]
    assert guids[0] == guids[1] != guids[2]


def test_a_surrogate_refuses_any_parameter_but_its_trained_ones(fmu_path):
    md = fmpy.read_model_description(str(fmu_path))
    H = next(v for v in md.modelVariables if v.name == "H")
    assert (H.causality, H.variability) == ("parameter", "fixed")
    assert "trained" in H.description
    said = refusal(fmu_path, 2, {"H": float(H.start) * 1.5})
    assert f"the operator was trained for H = {float(H.start)!r} only" in said
    fmpy.simulate_fmu(str(fmu_path), start_values={"H": float(H.start)}, stop_time=0.05)  # its own value: taken


def test_a_case_builds_one_fmu_per_model_and_runs_each_device_with_its_parameters(grid_fmu_cache):
    case = shipped_case("kundur")  # 4 machines, exciters and governors of 3 models, each device its data
    files = generator_files(case, "reference", grid_fmu_cache)
    paths = {p for f in files for p in f.paths}
    assert len(paths) == 3
    for unit, unit_files in zip(case.units, files):
        machine = unit.devices[0]
        with FMU(unit_files.paths[0], "machine", init=False) as fmu:
            fmu.initialise(fmu.parameter_values(machine.params))
            assert fmu.get(*machine.params.to_dict()).tolist() == list(machine.params.to_dict().values())


def test_a_refused_parameter_reaches_the_master_as_one_line(tgov1):
    with FMU(tgov1[2], "governor", init=False) as fmu:
        with pytest.raises(CouplingError, match="refused its start values: .*structural parameter T3 = 0 refused"):
            fmu.initialise({"T3": 0.0})
