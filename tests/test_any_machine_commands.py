"""`compare`, `init`, `build-reference-fmu` and benchmarks/fmu_step.py on a machine other than SM4: a
GENROU native reference FMU and the shipped GENROU surrogate operator (surrogate/default/kundur_gen12.onnx).
The component comes from the operator's metadata or --component, the machine inputs from its ports,
the start values from its own initialisation."""
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description

from cosim.fmu import FMU
from opfmu.cli import main
from opfmu.compare import compare, csv_inputs, fmu_component, scenario_inputs
from reference_models.models import GENROU

from test_cli import assert_one_line_error, in_process

ROOT = Path(__file__).resolve().parents[1]
OPERATOR = ROOT / "surrogate" / "default" / "kundur_gen12.onnx"
POINT = ["--V", "1.03", "--theta-deg", "20.2", "--P", "7.0", "--Q", "1.85"]  # Kundur's G1 (system base 100 MVA)


@pytest.fixture(scope="module")
def genrou_surrogate(fmu_cache):
    from fmu_export.build_cache import cached_surrogate_fmu

    return cached_surrogate_fmu(OPERATOR, "GENROUSurrogate", n_check=4, cache=fmu_cache)


@pytest.fixture(scope="module")
def genrou_reference(tmp_path_factory):
    """GENROUReference.fmu built by `opfmu build-reference-fmu --operator kundur_gen12.onnx` (its name by default)."""
    out = tmp_path_factory.mktemp("genrou_reference")
    code = main(["build-reference-fmu", "--operator", str(OPERATOR), "-o", str(out / "GENROUReference.fmu")])
    assert code == 0
    return out / "GENROUReference.fmu"


@pytest.fixture(scope="module")
def extracted(genrou_surrogate, genrou_reference, tmp_path_factory):
    root = tmp_path_factory.mktemp("genrou_extracted")
    return (extract(str(genrou_surrogate), unzipdir=str(root / "s")),
            extract(str(genrou_reference), unzipdir=str(root / "r")))


def test_the_reference_of_an_operator_is_of_its_component_machine_and_operating_point(genrou_reference, extracted):
    md = read_model_description(str(genrou_reference))
    assert md.modelName == "GENROUReference" and md.coSimulation.modelIdentifier == "GENROUReference"
    starts = {v.name: v.start for v in md.modelVariables}
    assert {f"{s}0" for s in GENROU.state_names} <= set(starts)
    assert float(starts["Pm"]) == pytest.approx(0.78) and float(starts["Efd"]) == pytest.approx(1.9)
    component, params = fmu_component(extracted[0])
    assert component is GENROU and params.M == 13.0
    surrogate = {v.name: v.start for v in read_model_description(extracted[0]).modelVariables}
    np.testing.assert_allclose([float(starts[f"{s}0"]) for s in GENROU.state_names],
                               [float(surrogate[f"{s}0"]) for s in GENROU.state_names], rtol=1e-9, atol=1e-12)


def test_a_native_reference_of_a_named_component_and_machine_file(tmp_path, capsys):
    machine = tmp_path / "g.json"
    machine.write_text(json.dumps({"M": 12.0, "D": 1.0}))
    result = in_process(capsys, "build-reference-fmu", "--component", "genrou", "--machine", machine,
                        "-o", tmp_path / "G.fmu")
    assert result.returncode == 0, result.stderr
    assert "model GENROUReference" in result.stdout
    md = read_model_description(str(tmp_path / "G.fmu"))
    assert [v.name for v in md.modelVariables if v.causality == "input"] == list(GENROU.input_names)
    assert_one_line_error(in_process(capsys, "build-reference-fmu", "--component", "nope", "-o", tmp_path / "x.fmu"),
                          "unknown component 'nope'")
    assert_one_line_error(in_process(capsys, "build-reference-fmu", "--component", "genrou", "--machine", machine,
                                     "--operator", OPERATOR, "-o", tmp_path / "x.fmu"), "not allowed with")


def test_compare_runs_the_genrou_surrogate_against_its_reference_on_a_scenario(extracted):
    component, params = fmu_component(extracted[0])
    inputs = scenario_inputs("step", 1, 1.0, 0.01, params, (0.78, 1.9), component)
    assert inputs.names == GENROU.input_names and inputs.x0.shape == (6,)
    np.testing.assert_allclose(GENROU.rhs(inputs.x0, inputs.values[0], params), 0.0, atol=1e-9)
    result = compare(*extracted, inputs, 1.0, 0.01)
    assert set(result["metrics"]) == set(GENROU.state_names + GENROU.output_names)
    assert result["metrics"]["delta"]["maxae"] < 0.05  # rad, the shipped operator on a bus step
    assert isinstance(result["in_envelope"], bool) and result["wall_s"]["surrogate"] > 0


def test_the_compare_command_on_genrou_fmus_with_a_csv_and_a_scenario(genrou_surrogate, genrou_reference, tmp_path):
    csv = tmp_path / "dip.csv"
    csv.write_text("time,Vs,theta_vs\n0,1.0,0.3\n0.2,1.0,0.3\n0.2,0.8,0.35\n0.3,0.8,0.35\n0.3,1.0,0.32\n0.6,1.0,0.32\n")
    done = subprocess.run([sys.executable, "-m", "opfmu", "compare", "--surrogate", str(genrou_surrogate),
                           "--reference", str(genrou_reference), "--inputs", str(csv), "--out", str(tmp_path / "o")],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert "e2q" in done.stdout and "XadIfd" in done.stdout
    summary = json.loads((tmp_path / "o" / "dip.json").read_text())
    assert set(summary["metrics"]) == set(GENROU.state_names + GENROU.output_names)
    assert summary["metrics"]["delta"]["maxae"] < 0.05
    for name in ("dip_states.png", "dip_currents_powers.png"):
        assert (tmp_path / "o" / name).stat().st_size > 10_000
    # a column left out holds the surrogate FMU's start value (its operator's operating point)
    inputs = csv_inputs(csv, GENROU.params(), GENROU, {"Pm": 0.78, "Efd": 1.9})
    np.testing.assert_array_equal(inputs.values[:, 2:], [[0.78, 1.9]] * 6)


def test_compare_refuses_fmus_of_two_components_in_one_line(genrou_surrogate, native_reference_path, tmp_path):
    done = subprocess.run([sys.executable, "-m", "opfmu", "compare", "--surrogate", str(genrou_surrogate),
                           "--reference", str(native_reference_path), "--scenario", "step", "--stop-time", "0.1",
                           "--out", str(tmp_path / "o")], capture_output=True, text=True)
    assert_one_line_error(done, "is of sm4, the other of genrou")


def test_init_gives_genrou_start_values_its_fmu_stays_at_rest_with(capsys, genrou_reference, extracted, tmp_path):
    machine_file = tmp_path / "kundur_g1.json"  # the reference FMU's machine (its operator's)
    machine_file.write_text(json.dumps(fmu_component(extracted[0])[1].to_dict()))
    code = main(["init", "--component", "genrou", "--machine", str(machine_file), *POINT, "--no-exciter", "--json"])
    out, _ = capsys.readouterr()
    assert code == 0
    result = json.loads(out)
    machine = result["machine"]
    assert list(machine) == [f"{s}0" for s in GENROU.state_names] + list(GENROU.input_names)
    assert machine["Vs"] == 1.03 and machine["theta_vs"] == pytest.approx(math.radians(20.2), rel=1e-15)
    op = result["operating_point"]
    assert op["stable_at_constant_field"] is True and "Id" not in op
    assert complex(op["I_re"], op["I_im"]) == pytest.approx(complex(7.0, -1.85) / (1.03 * np.exp(-1j * math.radians(20.2))))
    with FMU(genrou_reference, name="rest", scratch=tmp_path, start=machine) as fmu:
        x0 = fmu.state()
        for _ in range(20):
            x = fmu.step(0.05, *[machine[n] for n in GENROU.input_names])
    np.testing.assert_allclose(x, x0, rtol=1e-8, atol=1e-8)
    code = main(["init", "--component", "genrou", *POINT])  # with the WSCC IEEE1 exciter: from Efd and Vt = V
    out, _ = capsys.readouterr()
    assert code == 0 and "exciter FMU (ieee1)" in out and "machine FMU (genrou)" in out and "Id =" not in out


def test_init_refuses_a_component_without_a_bus_port_or_field_voltage_in_one_line(capsys):
    code = main(["init", "--component", "ieee1", *POINT])
    assert code == 2 and "init takes a machine on a bus" in capsys.readouterr().err
    load = ["--V", "1", "--theta", "0", "--P", "-0.5", "--Q", "-0.1"]  # a ZIP load: on a bus, no field voltage
    code = main(["init", "--component", "zip", *load])
    err = capsys.readouterr().err
    assert code == 2 and "takes no field voltage" in err and len(err.strip().splitlines()) == 1
    assert main(["init", "--component", "zip", *load, "--no-exciter", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["machine"]["P0"] == -0.5


def test_the_step_benchmark_takes_a_genrou_surrogate(genrou_surrogate):
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "fmu_step.py"), str(genrou_surrogate),
                           "--steps", "60", "--sizes", "0.01"], capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "GENROUSurrogate" in done.stdout and "one operator evaluation" in done.stdout
    assert done.stdout.strip().splitlines()[-1].lstrip().startswith("0.01 |")
