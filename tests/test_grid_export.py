"""`opfmu grid export`: a case's FMUs and case.json for another master. Every exported FMU passes
fmpy's validator; case.json names every device's FMU, bus, parameters, load-flow point, start
values and the source of each input, all resolvable; fmpy's own simulate_fmu of a device, with
the exported start values and its inputs held at them, stays at its load-flow point; a refused
request writes nothing."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from cosim.export import export_case
from reference_models.grid.case import shipped_case


@pytest.fixture(scope="module")
def kundur_export(tmp_path_factory):
    out = tmp_path_factory.mktemp("export") / "kundur"
    path = export_case(shipped_case("kundur"), out)
    return out, json.loads(path.read_text())


def test_every_exported_fmu_passes_fmpys_validator(kundur_export):
    from fmpy.validation import validate_fmu

    out, description = kundur_export
    files = sorted({d["fmu"] for d in description["devices"]})
    assert sorted(p.name for p in out.glob("*.fmu")) == files == ["EXDC2Reference.fmu", "GENROUReference.fmu",
                                                                  "TGOV1Reference.fmu"]  # one FMU per model
    for name in files:
        assert validate_fmu(str(out / name)) == [], name


def test_case_json_names_every_device_with_resolvable_inputs(kundur_export):
    from fmpy import read_model_description

    out, description = kundur_export
    case = shipped_case("kundur")
    devices = {d["id"]: d for d in description["devices"]}
    assert len(devices) == sum(len(u.devices) for u in case.units) == len(description["devices"])
    outputs = {i: {v.name for v in read_model_description(str(out / d["fmu"])).modelVariables
                   if v.causality == "output"} for i, d in devices.items()}
    for d in devices.values():
        assert set(d["inputs"]) == set(d["start"]["inputs"])  # every input has a source
        for name, source in d["inputs"].items():
            (kind,) = set(source) - {"output", "quantity"}
            assert kind in ("bus", "terminal", "device", "measured", "held")
            if kind == "device":
                assert source["output"] in outputs[source["device"]], (d["id"], name)
            if kind == "held":
                assert source["held"] == d["start"]["inputs"][name]
    assert description["base_mva"] == case.network.base_mva
    assert len(description["network"]["load_flow"]["V"]) == len(case.network.buses)
    machine = devices["1/machine"]
    assert machine["load_flow"]["P"] == pytest.approx(float(case.flow.P_gen[0]), rel=1e-12)
    assert machine["inputs"]["Vs"] == {"bus": "magnitude"}


@pytest.mark.parametrize("device", ["1/machine", "3/machine", "2/exciter", "3/governor"])
def test_fmpys_own_simulation_of_an_exported_device_stays_at_its_load_flow_point(kundur_export, device):
    from fmpy import simulate_fmu

    out, description = kundur_export
    d = next(e for e in description["devices"] if e["id"] == device)
    start = dict(d["parameters"])  # one FMU per model: the device's own parameters set at instantiation
    start.update({f"{name}0": value for name, value in d["start"]["states"].items()})
    start.update(d["start"]["inputs"])  # every input held at its start (the bus voltage, the links, the set points)
    result = simulate_fmu(str(out / d["fmu"]), start_values=start, stop_time=2.0, output_interval=0.1,
                          output=list(d["start"]["states"]))
    for name, value in d["start"]["states"].items():
        assert np.max(np.abs(result[name] - value)) <= 1e-9 * max(1.0, abs(value)), (device, name)


def test_export_into_a_file_is_refused_in_one_line_and_writes_nothing(tmp_path):
    target = tmp_path / "taken"
    target.write_text("x")
    done = subprocess.run([sys.executable, "-m", "opfmu", "grid", "export", "--case", "kundur", "--out", str(target)],
                          capture_output=True, text=True)
    assert done.returncode == 2 and done.stdout == "" and done.stderr.count("\n") == 1
    assert "is a file" in done.stderr and target.read_text() == "x"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken"]


def test_a_case_on_another_system_base_gets_fmus_that_declare_it(tmp_path):
    from dataclasses import replace

    from cosim.fmus import generator_files
    from reference_models.ports import ports_of_fmu

    case = shipped_case("kundur")
    other = replace(case, network=replace(case.network, base_mva=250.0))
    machine = generator_files(other, "reference", tmp_path / "cache")[0].paths[0]
    assert ports_of_fmu(machine).bus.base_mva == 250.0
    assert ports_of_fmu(generator_files(case, "reference", tmp_path / "cache")[0].paths[0]).bus.base_mva == 100.0
