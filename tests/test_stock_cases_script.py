"""benchmarks/stock_cases.py, the coverage table of ANDES' stock cases (issue 33): the stock files it
lists, the record of one file (ANDES' and opfmu's steps, each in a subprocess), its status and the
table written from records."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _script():
    spec = importlib.util.spec_from_file_location("stock_cases", REPO / "benchmarks" / "stock_cases.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _record(andes_ok=True, read_ok=True, runs_ok=True, models=("Bus", "GENROU")):
    fail = {"ok": False, "error": "x"}
    return {"key": "k", "checked": "2026-01-01 00:00:00", "commit": "abc", "s": 1.0,
            "andes": {"ok": andes_ok, "reason": None if andes_ok else "tds: diverged", "models": list(models),
                      "s": 1.0, "stages": {"tds": {"ok": andes_ok}}},
            "opfmu": {"ok": read_ok and runs_ok, "refused": not read_ok,
                      "reason": None if read_ok and runs_ok else ("the case uses the model X" if not read_ok
                                                                  else "reference: run: ended at 1 s"),
                      "read": {"ok": True} if read_ok else {**fail, "refused": True},
                      "runs": {} if not read_ok else {"reference": {"ok": runs_ok, "s": 1.0, "stable": True}}}}


@pytest.mark.andes
def test_the_stock_files_are_the_xlsx_and_json_files_and_the_raw_dyr_pairs():
    script = _script()
    files = script.stock_files()
    keys = {k for k, _, _ in files}
    assert {"kundur/kundur_full.xlsx", "ieee14/ieee14_full.xlsx", "kundur/kundur.raw+kundur_full.dyr",
            "nordic44/N44_BC.raw+N44_BC.dyr"} <= keys
    assert len(files) == len(keys)
    assert all(f.suffix in (".xlsx", ".json") for k, f, dyr in files if dyr is None)
    assert all(f.suffix == ".raw" and dyr.suffix == ".dyr" for k, f, dyr in files if dyr is not None)


@pytest.mark.andes
def test_one_stock_file_gives_a_record_with_andes_and_opfmu_steps(tmp_path, fmu_cache):
    pytest.importorskip("andes")
    script = _script()
    root = script.andes_cases_dir()
    r = script.check_file("kundur/kundur_full.xlsx", root / "kundur" / "kundur_full.xlsx", None, tmp_path,
                          timeout=240, build_timeout=600)
    assert r["key"] == "kundur/kundur_full.xlsx" and r["dyr"] is None and r["stop_s"] == 2.0
    a = r["andes"]
    assert a["ok"] and a["reason"] is None and set(a["stages"]) == {"load", "pflow", "tds"}
    assert a["stages"]["tds"]["t_end"] >= 2.0
    assert {"Bus", "Line", "GENROU", "EXDC2", "TGOV1", "Toggle"} <= set(a["models"])
    o = r["opfmu"]
    assert o["read"]["ok"] and o["read"]["units"] == 4 and o["read"]["buses"] == 10
    assert set(o["runs"]) == {"reference", "monolithic"}
    for kind, run in o["runs"].items():
        assert run["ok"], (kind, run)
        assert run["stages"]["run"]["t_end"] == pytest.approx(2.0) and run["stable"]
    assert (r["status"], r["reason"]) == ("runs", "") and r["missing_models"] == []
    assert {"GENROU", "EXDC2", "TGOV1"} <= set(o["read"]["known"])
    assert (tmp_path / "cases" / "kundur__kundur_full.xlsx").is_dir()  # converted afresh into the work folder


def test_the_status_and_the_table_of_records(tmp_path):
    script = _script()
    runs, refused = _record(), _record(read_ok=False, models=("Bus", "GENROU", "HYGOV"))
    fails, andes_fails = _record(runs_ok=False), _record(andes_ok=False, models=("Bus", "HYGOV", "REGCA1"))
    assert script.classify(runs) == ("runs", "")
    assert script.classify(refused) == ("refused", "the case uses the model X")
    assert script.classify(fails) == ("fails", "reference: run: ended at 1 s")
    assert script.classify(andes_fails) == ("ANDES fails", "tds: diverged")
    records = []
    for key, r in zip("abcd", (runs, refused, fails, andes_fails)):
        r["key"] = key
        r["status"], r["reason"] = script.classify(r)
        records.append(r)
    c = script.coverage(records)
    assert (c["files"], c["andes_runs"], c["runs"], c["read"], c["refused"], c["fails"], c["andes_fails"]) == \
        (4, 3, 1, 2, 1, 1, 1)
    known = script.known_models() - {"HYGOV", "REGCA1"}
    assert script.missing_models(records, known) == [("HYGOV", 1, 1)]  # files ANDES fails on are not counted
    named = _record(read_ok=False, models=("Bus", "GENROU", "ST2CUT", "PVD1"))
    named["opfmu"]["read"]["error"] = "the case uses the models ST2CUT, PVD1, which opfmu does not have (it has ...)"
    assert script.record_missing(named, {"Bus", "GENROU", "ST2CUT"}) == ["ST2CUT", "PVD1"]  # as it was checked
    named["opfmu"]["read"]["known"] = ["Bus", "GENROU", "PVD1"]
    assert script.record_missing(named) == ["ST2CUT"]
    text = script.write_table(records, tmp_path / "table.md", 2.0, 300.0)
    assert text == (tmp_path / "table.md").read_text()
    assert "opfmu runs 1 of the 3 files ANDES runs (33 %)" in text
    assert "| b | runs (1.0 s) | refused | refused | the case uses the model X |" in text
