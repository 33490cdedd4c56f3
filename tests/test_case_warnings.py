"""Nothing silently wrong (issue 33): what ANDES drops, replaces or warns about while it reads a case
file is read back (reference_models.grid.andes_case.read_back): refused in one line (a dyr model
ANDES does not know, a model or field it drops, an impossible value it would replace, an empty
value), or stated as the case's notes, which `opfmu grid run` prints on stderr and writes into its
report. The power-flow tolerance scales with the case (GBnetwork, 2224 buses, converts). `--fmus
surrogate` says which devices are surrogates and refuses a case without operators; a case's own
events run without --fault."""
from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from opfmu.cli import main
from reference_models.grid.case import CaseError


def stock(name: str) -> Path:
    andes = pytest.importorskip("andes")
    return Path(andes.get_case(name))


def edited_xlsx(tmp_path, edits, source="kundur/kundur_full.xlsx", name="kundur_edited.xlsx") -> Path:
    """A copy of the stock case `source` with `edits`: (sheet, device row 1-based, column, value),
    value None empties the cell."""
    openpyxl = pytest.importorskip("openpyxl")
    book = openpyxl.load_workbook(stock(source))
    for sheet, row, column, value in edits:
        ws = book[sheet]
        header = [c.value for c in ws[1]]
        ws.cell(row=row + 1, column=header.index(column) + 1).value = value
    out = tmp_path / name
    book.save(out)
    return out


def edited_dyr(tmp_path, replace: dict, name="kundur_edited.dyr") -> Path:
    """kundur_full.dyr with each (bus, model) record's model renamed: {(bus, "EXDC2"): "IEEET2"}."""
    lines = stock("kundur/kundur_full.dyr").read_text().splitlines(keepends=True)
    for (bus, model), new in replace.items():
        pattern = re.compile(rf"^(\s*{bus}\s+)'{model}\s*'")
        hits = [k for k, line in enumerate(lines) if pattern.match(line)]
        assert len(hits) == 1, (bus, model)
        lines[hits[0]] = pattern.sub(rf"\1'{new}'", lines[hits[0]])
    out = tmp_path / name
    out.write_text("".join(lines))
    return out


def convert_refused(tmp_path, case, dyr=None) -> str:
    from reference_models.grid.andes_case import case_from_file

    cache = tmp_path / "cache"
    with pytest.raises(CaseError) as error:
        case_from_file(case, dyr, cache)
    message = str(error.value)
    assert "\n" not in message
    assert not cache.exists() or list(cache.iterdir()) == []  # nothing cached
    return message


@pytest.mark.andes
def test_a_dyr_model_andes_does_not_know_is_refused_naming_it_the_file_and_the_generator(tmp_path):
    dyr = edited_dyr(tmp_path, {(1, "EXDC2"): "IEEET2"})  # generator 1 would be left without its exciter
    message = convert_refused(tmp_path, stock("kundur/kundur.raw"), dyr)
    assert message.startswith(f"{dyr}: ANDES does not know and drops the dyr model IEEET2 (bus 1 ID 1) with its records")
    assert message.endswith("a generator left without a model it had in the file is an error")


@pytest.mark.andes
def test_every_unknown_dyr_model_is_named_in_one_line_a_misspelt_machine_too(tmp_path, capsys):
    dyr = edited_dyr(tmp_path, {(1, "EXDC2"): "IEEET2", (3, "GENROU"): "GENROUX"})
    message = convert_refused(tmp_path, stock("kundur/kundur.raw"), dyr)
    assert "the dyr models IEEET2 (bus 1 ID 1), GENROUX (bus 3 ID 1) with their records" in message
    assert main(["grid", "run", "--case", str(stock("kundur/kundur.raw")), "--dyr", str(dyr), "--fmus", "monolithic",
                 "--fault", "7", "--clear", "1.1", "--out", str(tmp_path / "out")]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and "IEEET2" in err and "GENROUX" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.andes
def test_impossible_values_andes_would_replace_are_refused_naming_model_device_parameter_value(tmp_path):
    case = edited_xlsx(tmp_path, [("GENROU", 1, "M", -13), ("EXDC2", 2, "TF1", 0), ("Line", 1, "x", 0)])
    message = convert_refused(tmp_path, case)
    assert message.startswith(f"{case}: data ANDES would replace: ")
    for part in ("GENROU 1 M = -13 (negative, which the model cannot take; ANDES would use 6)",
                 "EXDC2 2 TF1 = 0 (zero, which the model cannot take; ANDES would use 1)",
                 "Line Line_0 x = 0 (zero, which the model cannot take; ANDES would use 1e-08)"):
        assert part in message


@pytest.mark.andes
def test_an_empty_value_takes_andes_default_and_is_stated(tmp_path):
    """A null or NaN (an empty cell) of a parameter the conversion uses takes ANDES' documented
    default, as the stock files rely on (ieee14_ieeet1 leaves its exciter's cells empty), and the
    case says so in its notes."""
    from reference_models.grid.andes_case import case_from_file, case_notes

    data = json.loads(stock("kundur/kundur_full.json").read_text())
    data["GENROU"][1]["xd1"] = None
    data["GENROU"][2]["M"] = float("nan")  # json writes NaN
    case = tmp_path / "kundur_edited.json"
    case.write_text(json.dumps(data))
    notes = case_notes(case_from_file(case, cache_dir=tmp_path / "cache"))
    assert "GENROU 2: xd1 empty or NaN in the file, ANDES' default 0.302 used" in notes
    assert "GENROU 3: M empty or NaN in the file, ANDES' default 6 used" in notes


@pytest.mark.andes
def test_a_model_or_a_field_andes_does_not_know_is_refused_not_dropped(tmp_path):
    openpyxl = pytest.importorskip("openpyxl")
    book = openpyxl.load_workbook(stock("kundur/kundur_full.xlsx"))
    book["TGOV1"].title = "TGOV2"  # a misspelt sheet: ANDES would drop the governors
    genrou = book["GENROU"]
    header = [c.value for c in genrou[1]]
    genrou.cell(row=1, column=header.index("xd1") + 1).value = "xd_1"  # a misspelt column
    case = tmp_path / "kundur_sheets.xlsx"
    book.save(case)
    message = convert_refused(tmp_path, case)
    assert message.startswith(f"{case}: ANDES does not know and drops ")
    assert "the model TGOV2 with its devices" in message and "the field xd_1 of GENROU with its values" in message


@pytest.mark.andes
def test_adjustments_that_change_nothing_converted_are_notes_of_the_case(tmp_path):
    from reference_models.grid.andes_case import case_from_file, case_notes

    case = case_from_file(edited_xlsx(tmp_path, [("Bus", 1, "v0", 0)]), cache_dir=tmp_path / "cache")
    assert case_notes(case) == ("Bus 1: v0 = 0 in the file, ANDES uses 1 (a start guess of the power flow)",)
    again = case_from_file(case.source[0], cache_dir=tmp_path / "cache")  # from the cache, without ANDES
    assert case_notes(again) == case_notes(case)
    ieee39 = case_from_file(stock("ieee39/ieee39_full.xlsx"), cache_dir=tmp_path / "cache")
    assert case_notes(ieee39) == (
        "ACEc 1: bias = 300 in the file, ANDES uses -1 (ACEc is not converted)",
        "ACEc (1 device: a measurement that acts on no converted device) is left out: its outputs are not in the result",
        "BusFreq (10 devices: a measurement that acts on no converted device) is left out: its outputs are not in the "
        "result")
    shipped = case_from_file(stock("kundur/kundur_full.xlsx"), cache_dir=tmp_path / "cache")
    assert case_notes(shipped) == ()


@pytest.mark.andes
def test_grid_run_states_the_case_notes_on_stderr_and_in_its_report(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("OPFMU_CASE_CACHE", str(tmp_path / "cache"))
    case = edited_xlsx(tmp_path, [("Bus", 1, "v0", 0)])
    out = tmp_path / "run"
    assert main(["grid", "run", "--case", str(case), "--fmus", "monolithic", "--compare", "none", "--fault", "8",
                 "--clear", "1.05", "--stop", "1.2", "--no-case-events", "--out", str(out)]) == 0
    note = "Bus 1: v0 = 0 in the file, ANDES uses 1 (a start guess of the power flow)"
    assert f"note: {note}" in capsys.readouterr().err
    assert f"Note: {note}" in (out / "report.md").read_text()
    assert json.loads((out / "summary.json").read_text())["notes"] == [note]


@pytest.mark.andes
def test_every_model_opfmu_lacks_is_named_in_one_line(tmp_path):
    from reference_models.grid import andes_case
    from reference_models.models import STANDARD_MODELS

    source = stock("kundur/kundur_vsc.xlsx")  # a DC network: Node, Ground, R, VSCShunt
    ss = andes_case.load_andes(source)
    known = set(andes_case.NETWORK_MODELS) | set(andes_case.IGNORED_MODELS) | set(STANDARD_MODELS)
    missing = [name for name, model in ss.models.items() if model.n > 0 and name not in known]
    if len(missing) < 2:
        pytest.skip(f"opfmu lacks fewer than two of its models now ({missing})")
    message = convert_refused(tmp_path, source)
    assert message.startswith(f"the case uses the models {', '.join(missing)}, which opfmu does not have")


@pytest.mark.andes
def test_the_power_flow_tolerance_scales_with_the_case_and_gbnetwork_converts(tmp_path):
    from reference_models.grid import andes_case

    kundur = andes_case.load_andes("kundur/kundur_full.xlsx")
    assert andes_case.pflow_tolerance(kundur) == andes_case.PFLOW_TOLERANCE
    notes = []
    gb = andes_case.load_andes("GBnetwork/GBnetwork.xlsx", notes=notes)  # ANDES' Newton stalls at 2e-11 pu
    tolerance = gb.PFlow.config.tol
    assert 1e-10 < tolerance < 1e-8 and gb.PFlow.converged and notes == []
    assert andes_case.mismatch_limit(tolerance) == andes_case.MISMATCH_MARGIN * tolerance
    network, dynamic = andes_case.convert("GBnetwork/GBnetwork.xlsx", tmp_path, "gb")
    data = json.loads(network.read_text())
    assert len(data["buses"]) == 2224
    assert andes_case.mismatch(data) < andes_case.mismatch_limit(tolerance)
    assert len(json.loads(dynamic.read_text())["generators"]) == 394


@pytest.mark.andes
def test_a_case_s_own_events_run_without_a_fault(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("OPFMU_CASE_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "linetrip"
    assert main(["grid", "run", "--case", str(stock("ieee14/ieee14_linetrip.xlsx")), "--fmus", "monolithic",
                 "--compare", "none", "--stop", "1.5", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["contingency"] == "no contingency" and summary["case_events"]
    assert "opened at 1 s" in summary["case_events"][0]


@pytest.mark.parametrize("argv, words", [
    (["--case", "wscc9"], "nothing happens in this run"),
    (["--case", "kundur", "--no-case-events"], "nothing happens in this run"),
    (["--case", "wscc9", "--fault", "7"], "--fault needs --clear SECONDS"),
    (["--case", "wscc9", "--trip", "5-7"], "--trip without --fault opens the branch at --clear SECONDS"),
    (["--case", "wscc9", "--clear", "0.1"], "--clear goes with --fault BUS or --trip FROM-TO"),
    (["--case", "ieee14", "--fmus", "surrogate", "--fault", "4", "--clear", "1.1"],
     "--fmus surrogate: no machine of ieee14 has a surrogate operator"),
    (["--case", "ieee14", "--fmus", "monolithic", "--compare", "surrogate", "--fault", "4", "--clear", "1.1"],
     "--fmus surrogate: no machine of ieee14 has a surrogate operator"),
])
def test_run_events_and_surrogates_that_cannot_be_are_one_line_before_any_work(argv, words, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["grid", "run", *argv, "--out", str(out)]) == 2
    stdout, err = capsys.readouterr()
    assert stdout == "" and err.count("\n") == 1 and words in err
    assert not out.exists()


def test_surrogate_runs_say_which_devices_are_surrogates():
    from opfmu.grid_command import _surrogates
    from reference_models.grid import wscc9

    case = wscc9.case()
    text = _surrogates(case, "surrogate")
    assert text.startswith("surrogate FMUs for 3 bus devices: SM4 at bus 1 (operator wscc9_gen1.onnx), SM4 at bus 2")
    assert text.endswith("native reference FMUs for the other 3 devices")
    assert _surrogates(case, "reference") is None and _surrogates(case, "monolithic") is None


@pytest.mark.andes
def test_an_alter_of_a_load_andes_ignores_is_a_note_and_one_of_a_set_point_is_refused(tmp_path):
    """ANDES' constant-impedance loads keep the impedance of the start, so its Alter of a PQ's Ppf
    (ieee14_hygov4's load ramp) changes nothing in its simulation: stated and left out. An Alter of
    a governor's auxiliary power (ieee14_alter) changes the run: refused, naming every one."""
    from reference_models.grid.andes_case import case_from_file, case_notes

    case = case_from_file(stock("ieee14/ieee14_hygov4.xlsx"), cache_dir=tmp_path / "cache")
    assert any("Alter LoadRamp_1 (PQ PQ_7 Ppf + 0.1 at 1 s) changes nothing" in n for n in case_notes(case))
    assert not [e for e in case.events if e.kind not in ("fault", "branch", "generator")]
    with pytest.raises(CaseError, match=r"Alter 1 \(TGOV1 TGOV1_1 paux0 \+ 0.001 at 1 s\), Alter 2 .*not converted"):
        case_from_file(stock("ieee14/ieee14_alter.xlsx"), cache_dir=tmp_path / "cache")
