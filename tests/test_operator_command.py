"""`opfmu operator`: a machine file in, a dataset, a trained operator, both FMUs and a report out."""
import json

import pytest
from fmpy.validation import validate_fmu

from opfmu.cli import main

from machines import wscc9_machine

MACHINE = wscc9_machine(3)  # WSCC generator 3 as shipped
QUICK = ["--windows", "16", "--epochs", "10", "--horizon", "0.2", "--report-stop", "0.5", "--workers", "0", "--quiet",
         "--pm", "0.7", "1.0", "--efd", "1.2", "1.8", "--operating-point", "0.85", "1.403", "--name", "Gen3"]


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("operator")
    machine = root / "gen3.json"
    machine.write_text(json.dumps(MACHINE))
    out = root / "run"
    assert main(["operator", "--machine", str(machine), "--out", str(out), *QUICK]) == 0
    return machine, out


@pytest.mark.slow
def test_operator_writes_the_dataset_run_operator_both_fmus_and_a_report(quick_run):
    _, out = quick_run
    for name in ("data/metadata.json", "run/result.json", "operator.onnx", "Gen3Surrogate.fmu", "Gen3Reference.fmu",
                 "report.md"):
        assert (out / name).exists(), name
    for fmu in ("Gen3Surrogate.fmu", "Gen3Reference.fmu"):
        assert validate_fmu(str(out / fmu)) == []
    report = (out / "report.md").read_text()
    assert "Single window" in report and "co-simulation against the native reference" in report
    assert "| mix |" in report and "| governor |" in report


@pytest.mark.slow
def test_operator_trains_for_the_machine_in_the_file_with_the_levels_given(quick_run):
    import onnx

    _, out = quick_run
    meta = {p.key: p.value for p in onnx.load(str(out / "operator.onnx")).metadata_props}
    params = json.loads(meta["params"])
    assert all(params[k] == pytest.approx(v) for k, v in MACHINE.items())
    data = json.loads((out / "data" / "metadata.json").read_text())
    assert data["preset"]["levels"] == {"Pm": [0.7, 1.0], "Efd": [1.2, 1.8]}
    assert data["horizon_s"] == pytest.approx(0.2)
    assert "network" in {name for name, _ in data["preset"]["families"]}


@pytest.mark.slow
def test_rerunning_the_same_command_resumes_from_the_finished_stages(quick_run):
    machine, out = quick_run
    before = (out / "run" / "result.json").read_text()
    assert main(["operator", "--machine", str(machine), "--out", str(out), *QUICK]) == 0
    assert (out / "run" / "result.json").read_text() == before  # no epoch trained again


@pytest.mark.parametrize("extra, message", [
    (["--pm", "1.0", "0.5"], "LOW <= HIGH"),
    (["--horizon", "0"], "--horizon"),
    (["--name", "1bad"], "C identifier"),
])
def test_bad_requests_end_in_one_line_and_exit_code_2(tmp_path, capsys, extra, message):
    machine = tmp_path / "m.json"
    machine.write_text(json.dumps(MACHINE))
    assert main(["operator", "--machine", str(machine), "--out", str(tmp_path / "o"), *QUICK, *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_a_machine_file_with_pm_is_refused_since_pm_is_an_input(tmp_path, capsys):
    machine = tmp_path / "m.json"
    machine.write_text(json.dumps({**MACHINE, "Pm": 0.8}))
    assert main(["operator", "--machine", str(machine), "--out", str(tmp_path / "o"), *QUICK]) == 2
    assert "unknown sm4 parameter" in capsys.readouterr().err
