"""`opfmu grid run|cct|screen`: the grid contract of docs/grid.md (result.csv columns, one row per
communication point, cct --json with cct_s), the surrogate FMUs against the monolithic run and its
critical clearing time, one-line errors with exit code 2 for what cannot run, decided before any
work, a result set written whole or not at all, and no extracted FMU folder left behind."""
import csv
import json
import os
import tempfile

import numpy as np
import pytest

from conftest import interrupt_and_wait, opfmu_process
from opfmu.cli import main
from reference_models.grid import wscc9


def read_csv(path):
    """(column names, rows) of a result.csv; its second line, `# ` and the columns' units, is skipped."""
    with open(path) as f:
        rows = list(csv.reader(f))
    assert rows[1][0].startswith("# ") and len(rows[1]) == len(rows[0])
    return rows[0], np.array(rows[2:], dtype=float)


def test_grid_run_writes_the_contracted_columns_plots_and_a_report(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["grid", "run", "--case", "wscc9", "--fault", "8", "--clear", "0.0717", "--trip", "8-9",
                 "--stop", "1.2", "--fmus", "reference", "--out", str(out)]) == 0
    names, data = read_csv(out / "result.csv")
    expected = (["time"] + [f"{q}_{b}" for q in ("delta", "omega", "Efd") for b in wscc9.GENERATOR_BUSES]
                + [f"V_{b}" for b in wscc9.BUSES])
    assert names[:len(expected)] == expected
    time = data[:, 0]
    assert np.all(np.diff(time) > 0) and time[0] == 0.0 and abs(time[-1] - 1.2) < 1e-12
    assert np.any(np.abs(time - 0.0717) < 1e-12)  # the clearing is a communication point
    assert (out / "result.png").stat().st_size > 10_000
    report = (out / "report.md").read_text()
    assert "monolithic DAE" in report and "Largest differences from the monolithic run" in report
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stable"] and summary["difference_from_monolithic"]["reference"]["angle_deg"] < 0.6
    assert "stable" in capsys.readouterr().out


def test_surrogate_fmus_follow_the_monolithic_run_of_a_fault_with_a_trip(tmp_path):
    out = tmp_path / "surrogate"
    assert main(["grid", "run", "--fault", "4", "--clear", "0.095", "--trip", "4-5", "--stop", "3", "--fmus",
                 "surrogate", "--compare", "reference,monolithic", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stable"]
    differences = summary["difference_from_monolithic"]
    assert differences["surrogate"]["angle_deg"] < 1.0
    assert differences["surrogate"]["V"] < 0.01
    assert differences["reference"]["angle_deg"] < 0.6


def test_grid_cct_of_the_surrogate_fmus_is_within_5_ms_of_the_monolithic_one(capsys):
    found = {}
    for kind in ("monolithic", "surrogate"):
        assert main(["grid", "cct", "--case", "wscc9", "--fault", "9", "--trip", "8-9", "--stop", "2",
                     "--fmus", kind, "--json"]) == 0
        found[kind] = json.loads(capsys.readouterr().out)
    assert found["monolithic"]["bounded"] and found["monolithic"]["cct_s"] > 0.05
    assert abs(found["surrogate"]["cct_s"] - found["monolithic"]["cct_s"]) <= 0.005


def test_grid_screen_tabulates_ccts_verdicts_and_first_swing_peaks_on_dask(tmp_path, capsys, monkeypatch):
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    out = tmp_path / "screen"
    assert main(["grid", "screen", "--faults", "5", "--trips", "each", "--fmus", "reference", "--clear", "0.1",
                 "--stop", "1.5", "--resolution", "0.004", "--workers", "1", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "\r" not in err and "contingencies: 3/3 runs" in err  # lines, not a bar, into a redirected stderr
    # every extracted FMU folder removed; multiprocessing's folder of this process (its fork server's
    # socket) goes when the process ends (tests/test_grid_cli_hostile.py checks a whole command's)
    assert not [p for p in scratch.iterdir() if not p.name.startswith("pymp-")]
    rows = json.loads((out / "screening.json").read_text())
    assert [(r["bus"], r["trip"]) for r in rows] == [(5, ""), (5, "4-5"), (5, "5-7")]
    for r in rows:
        assert r["bounded"] and r["cct_s"] is not None
        assert r["stable"] == (r["cct_s"] >= 0.1)  # the verdict at 0.1 s agrees with the CCT
        assert (r["first_swing_peak_deg"] is None) == (not r["stable"])
    assert (out / "screening.png").exists() and "CCT" in (out / "screening.md").read_text()


@pytest.mark.parametrize("argv, message", [
    (["grid", "run", "--case", "ieee118", "--fault", "7", "--clear", "0.1", "--out", "x"], "unknown case"),
    (["grid", "run", "--fault", "12", "--clear", "0.1", "--out", "x"], "no bus 12"),
    (["grid", "run", "--fault", "7", "--clear", "0.1", "--trip", "2-7", "--out", "x"], "disconnects a generator"),
    (["grid", "run", "--fault", "7", "--clear", "0.1", "--trip", "seven", "--out", "x"], "FROM-TO"),
    (["grid", "run", "--fault", "7", "--clear", "-1", "--out", "x"], "finite and >= 0"),
    (["grid", "run", "--fault", "7", "--clear", "0.1", "--step", "0", "--out", "x"], "communication step"),
    (["grid", "run", "--fault", "7", "--clear", "0.1", "--compare", "psse", "--out", "x"], "unknown run kind"),
    (["grid", "cct", "--fault", "7", "--resolution", "0", "--fmus", "monolithic"], "resolution"),
    (["grid", "screen", "--faults", "4,x", "--out", "x"], "bus numbers"),
    (["grid", "screen", "--faults", ",", "--out", "x"], "bus numbers"),
    (["grid", "screen", "--faults", "", "--out", "x"], "bus numbers"),
    (["grid", "run", "--fault", "7", "--clear", "0.1", "--stop", "1e9", "--out", "x"], "--stop must be a time in (0, 3600] s"),
    (["grid", "run", "--fault", "7", "--clear", "0.1", "--stop", "3000", "--step", "1e-5", "--out", "x"],
     "communication steps (at most 1e+06"),
    (["grid", "cct", "--fault", "7", "--stop", "1e9", "--fmus", "monolithic"], "--stop must be a time"),
    (["grid", "run", "--fault", "7", "--clear", "0.1", "--fault-impedance", "-0.01", "--out", "x"],
     "--fault-impedance must be a finite reactance > 0 pu"),
    (["grid", "run", "--fault", "7", "--clear", "1e300", "--out", "x"], "must come before the stop at 5 s"),
    (["grid", "run", "--fault", "7", "--clear", "0.1", "--stop", "0.05", "--out", "x"],
     "the clearing at 0.1 s must come before the stop at 0.05 s"),
    (["grid", "run", "--fault", "7", "--clear", "0.1", "--stop", "0.1", "--out", "x"], "must come before the stop"),
    (["grid", "screen", "--faults", "7", "--clear", "5", "--stop", "3", "--out", "x"], "must come before the stop"),
    (["grid", "screen", "--faults", "12", "--out", "x"], "no bus 12"),
])
def test_grid_mistakes_end_in_one_line_and_exit_code_2(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("OPFMU_FMU_CACHE", str(tmp_path / "cache"))
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "cache").exists() and not (tmp_path / "x").exists()  # refused before any work


def test_an_output_folder_that_cannot_take_the_results_is_refused_before_any_build(capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("OPFMU_FMU_CACHE", str(tmp_path / "cache"))
    (tmp_path / "a_file").write_text("")
    for out, message in ((tmp_path / "a_file", "is a file"), (tmp_path / "a_file" / "sub", "cannot write into")):
        assert main(["grid", "run", "--fault", "7", "--clear", "0.1", "--fmus", "reference", "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1
    assert not (tmp_path / "cache").exists()


def test_a_result_set_is_written_whole_or_not_at_all(capsys, tmp_path):
    out = tmp_path / "run"
    (out / "result.png").mkdir(parents=True)
    argv = ["grid", "run", "--fault", "7", "--clear", "0.1", "--stop", "0.3", "--fmus", "monolithic", "--compare",
            "none", "--out", str(out)]
    assert main(argv) == 2
    assert "result.png: it exists and is not a file" in capsys.readouterr().err
    assert [p.name for p in out.iterdir()] == ["result.png"]
    (out / "result.png").rmdir()
    assert main(argv) == 0
    assert sorted(p.name for p in out.iterdir()) == ["report.md", "result.csv", "result.png", "summary.json"]


def test_a_refused_fmu_file_leaves_no_extracted_folder(capsys, tmp_path, monkeypatch):
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    (tmp_path / "bad.fmu").write_bytes(b"not a zip")
    data = json.loads(wscc9.DYNAMIC_DATA_FILE.read_text())
    for g in data["generators"]:
        g["machine"]["file"] = str(wscc9.machine_file(g["bus"]))
        g["fmu"] = {"kind": "file", "machine_fmu": "bad.fmu", "exciter_fmu": "bad.fmu"}
    path = tmp_path / "dyn.json"
    path.write_text(json.dumps(data))
    assert main(["grid", "run", "--fault", "7", "--clear", "0.1", "--stop", "0.2", "--compare", "none",
                 "--dynamic-data", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "bad.fmu is not a readable FMU" in err and err.count("\n") == 1 and str(scratch) not in err
    assert not list(scratch.iterdir())


@pytest.mark.parametrize("content", ["{not json", '{"generators": 3}', '{"generators": [{"bus": 1}]}',
                                     "[]", '{"generators": [{"bus": 1, "machine": {"component": "sm4", "file": '
                                                             '"../../../../etc/passwd"}, "exciter": {}}]}',
                                     '{"generators": [[1]]}', '{"generators": [{"bus": 1, "machine": null}]}',
                                     '{"generators": [{"bus": 1, "machine": {"component": "sm4", "file": null}}]}',
                                     '{"generators": [{"bus": "x"}]}'])
def test_a_malformed_dynamic_data_file_is_one_line_without_python_internals_and_exit_code_2(content, capsys, tmp_path):
    path = tmp_path / "dyn.json"
    path.write_text(content)
    assert main(["grid", "run", "--fault", "7", "--clear", "0.1", "--dynamic-data", str(path),
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1
    for internal in ("NoneType", "list indices", "object has no attribute", "Error:"):
        assert internal not in err


def test_ctrl_c_during_a_screening_on_dask_workers_ends_in_one_interrupted_line(tmp_path):
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    screening = opfmu_process(["grid", "screen", "--fmus", "monolithic", "--faults", "4,5,6,7,8,9", "--workers", "2",
                               "--stop", "3", "--resolution", "0.0001", "--out", tmp_path / "out"],
                              env=dict(os.environ, TMPDIR=str(scratch)))
    first = screening.stderr.readline()  # the first progress line: the workers are busy
    assert first.startswith("contingencies: ") and not first.startswith("contingencies: 18/18")
    code, rest = interrupt_and_wait(screening, 120)
    assert code == 130
    lines = rest.splitlines()
    assert lines[-1] == "interrupted" and rest.count("interrupted") == 1  # no "rerun to resume": a rerun starts over
    assert all(line.startswith("contingencies: ") for line in lines[:-1]), rest  # no worker traceback
    assert not list(scratch.iterdir())


@pytest.mark.parametrize("argv, message", [
    (["grid", "run", "--case", "kundur", "--fault", "99", "--clear", "0.1", "--out", "x"], "kundur has no bus 99"),
    (["grid", "run", "--case", "kundur", "--fault", "7", "--clear", "0.1", "--trip", "1-5", "--out", "x"],
     "opening branch 1-5 disconnects a generator"),
    (["grid", "cct", "--case", "ieee14", "--fault", "4", "--trip", "4-7:2", "--fmus", "monolithic"], "no branch 4-7"),
    (["grid", "screen", "--fmus", "andes", "--faults", "7", "--out", "x"], "converted from ANDES"),
    (["grid", "cct", "--case", "kundur", "--dyr", "k.dyr", "--fault", "7"], "--dyr goes with a PSS/E raw"),
    (["grid", "run", "--case", "kundur", "--fault", "7", "--clear", "0.5", "--out", "x"],
     "after the fault start (1.0 s)"),  # the ANDES cases' faults start at 1 s by default
    (["grid", "cct", "--case", "ieee14", "--fault", "4", "--stop", "0.5", "--fmus", "monolithic"],
     "--stop (0.5 s) must come after the fault start at 1 s"),
    (["grid", "screen", "--case", "kundur", "--clear", "5.5", "--out", "x"],
     "the clearing at 5.5 s must come before the stop at 5 s"),  # default stop: fault start 1 s + 4 s
    (["grid", "screen", "--clear", "3.5", "--out", "x"], "before the stop at 3 s"),  # wscc9: DESIGN's 3 s
])
def test_mistakes_with_the_andes_cases_end_in_one_line_before_any_work(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("OPFMU_FMU_CACHE", str(tmp_path / "cache"))
    assert main(argv) == 2
    out, err = capsys.readouterr()
    assert out == "" and message in err and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "cache").exists() and not (tmp_path / "x").exists()


@pytest.mark.andes
def test_andes_is_refused_a_fault_from_t_0_before_any_work(capsys, tmp_path):
    pytest.importorskip("andes")
    out = tmp_path / "x"
    assert main(["grid", "run", "--case", "kundur", "--fmus", "andes", "--fault", "7", "--fault-start", "0",
                 "--clear", "0.1", "--out", str(out)]) == 2
    stdout, err = capsys.readouterr()
    assert stdout == "" and err.count("\n") == 1 and "--fault-start later than" in err and not out.exists()


def test_kundur_runs_with_native_fmus_beside_the_monolithic_dae(tmp_path, capsys):
    out = tmp_path / "kundur"
    assert main(["grid", "run", "--case", "kundur", "--fmus", "reference", "--fault", "8", "--fault-start", "0.1",
                 "--clear", "0.2", "--stop", "0.6", "--out", str(out)]) == 0
    names, data = read_csv(out / "result.csv")
    expected = (["time"] + [f"{q}_{b}" for q in ("delta", "omega", "Efd") for b in (1, 2, 3, 4)]
                + [f"V_{b}" for b in range(1, 11)])
    assert names[:len(expected)] == expected
    omega = data[:, names.index("omega_1")]
    assert omega[0] == 0.0 and 0.1 < np.max(np.abs(omega)) < 10  # a deviation in rad/s, not a speed in pu
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stable"] and summary["case_events"] == []  # its line toggle at 2 s is after the stop
    difference = summary["difference_from_monolithic"]["reference"]
    assert difference["angle_deg"] < 0.1 and difference["V"] < 0.01
    assert "Kundur two-area: fault at bus 8" in capsys.readouterr().out


@pytest.mark.andes
def test_grid_run_compares_with_andes_at_its_reference_step_on_the_runs_rows(tmp_path, capsys):
    pytest.importorskip("andes")
    out = tmp_path / "andes"
    assert main(["grid", "run", "--case", "kundur", "--fmus", "monolithic", "--compare", "andes", "--fault", "8",
                 "--fault-start", "1.0", "--clear", "1.1", "--stop", "1.3", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["difference_from_andes"]["monolithic"]["angle_deg"] < 0.1  # ANDES at 1 ms, not at --step
    assert summary["difference_from_andes"]["monolithic"]["V"] < 0.01
    assert "Largest differences from the ANDES run" in (out / "report.md").read_text()
    assert "monolithic DAE against the ANDES run" in capsys.readouterr().out


def test_a_screening_of_an_andes_case_faults_from_1_s_and_names_the_case(tmp_path, capsys):
    out = tmp_path / "screen"
    assert main(["grid", "screen", "--case", "kundur", "--faults", "5", "--trips", "none", "--fmus", "monolithic",
                 "--stop", "1.3", "--resolution", "0.1", "--workers", "0", "--quiet", "--out", str(out)]) == 0
    rows = json.loads((out / "screening.json").read_text())
    assert [(r["bus"], r["clear_s"]) for r in rows] == [(5, 1.1)]  # cleared 0.1 s after the fault at 1 s
    report = (out / "screening.md").read_text()
    assert report.startswith("# Kundur two-area contingency screening") and "WSCC" not in report


@pytest.mark.andes
def test_an_andes_screening_checks_every_fault_start_before_any_work(tmp_path, capsys):
    pytest.importorskip("andes")
    out = tmp_path / "x"
    assert main(["grid", "screen", "--case", "kundur", "--fmus", "andes", "--fault-start", "0", "--out", str(out)]) == 2
    stdout, err = capsys.readouterr()
    assert stdout == "" and err.count("\n") == 1 and "--fault-start later than" in err and not out.exists()


@pytest.mark.andes
def test_an_unstable_andes_run_with_stop_at_loss_ends_at_the_loss_of_synchronism():
    pytest.importorskip("andes")
    from cosim.andes_runner import AndesRunner
    from reference_models.grid.case import shipped_case
    from reference_models.grid.contingency import ANDES_FAULT_IMPEDANCE, Contingency

    case = shipped_case("kundur")
    c = Contingency(5, 1.5, "5-6", 1.0, ANDES_FAULT_IMPEDANCE, case.network, case.events)  # CCT 1.319 s
    result, _ = AndesRunner(case, 0.01).run(c, 4.0, stop_at_loss=True)
    assert not result.stable and 1.5 < result.loss_of_synchronism_s == result.time[-1] < 2.0
    spread = np.ptp(result.states["delta"][-1])
    assert spread >= np.pi and np.ptp(result.states["delta"][-2]) < np.pi


def test_a_case_file_that_is_not_there_or_a_dyr_with_a_shipped_case_is_refused_in_one_line(tmp_path, capsys):
    from opfmu.cli import main

    for argv, words in ((["--case", str(tmp_path / "mine.raw")], "no case file"),
                        (["--case", "kundur", "--dyr", "x.dyr"], "--dyr goes with a PSS/E raw"),
                        (["--case", str(tmp_path / "mine.xlsx"), "--dynamic-data", "d.json"], "--dynamic-data goes with")):
        out = tmp_path / "out"
        assert main(["grid", "run", *argv, "--fault", "7", "--clear", "1.1", "--out", str(out)]) == 2
        captured = capsys.readouterr()
        assert captured.out == "" and captured.err.count("\n") == 1 and words in captured.err, captured.err
        assert not out.exists()


@pytest.mark.andes
def test_a_pss_e_raw_with_its_dyr_runs_with_native_fmus_and_follows_the_monolithic_run(tmp_path, capsys):
    import andes

    from opfmu.cli import main

    raw, dyr = andes.get_case("kundur/kundur.raw"), andes.get_case("kundur/kundur_gencls.dyr")
    out = tmp_path / "raw"
    assert main(["grid", "run", "--case", raw, "--dyr", dyr, "--fault", "7", "--clear", "1.1", "--stop", "1.5",
                 "--fmus", "reference", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "stable" in text and (out / "result.csv").is_file()
    header = (out / "result.csv").read_text().splitlines()[0].split(",")
    assert {"delta_1", "omega_4", "V_10"} <= set(header)
    angle = float(text.split("rotor angles ")[1].split(" deg")[0])
    assert angle < 0.1  # native FMUs against the monolithic DAE of the same file (measured 0.008 deg over 2 s)
