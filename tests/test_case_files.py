"""A user's case file (anything ANDES reads: xlsx, json, a PSS/E raw with its dyr) becomes an opfmu
Case in one call (reference_models.grid.andes_case.case_from_file): converted once into a cache
keyed by the files' bytes, at rest at its start, the source recorded for ANDES; a file that cannot
be used is one CaseError line."""
from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from reference_models.grid.andes_case import case_from_file, compare_starts, load_andes
from reference_models.grid.case import CaseError
from reference_models.grid.monolithic import System

REPO = Path(__file__).resolve().parents[1]
REST_TOLERANCE = 1e-9  # largest |dy/dt| of the monolithic DAE at the start state
ANDES_START_TOLERANCE = 1e-9  # largest start-value difference from ANDES' TDS.init (states, set points)


def andes_case(name: str) -> Path:
    import andes

    return Path(andes.get_case(name))


def files_in(folder: Path) -> dict:
    """{path relative to folder: (inode, mtime_ns)} of every file under folder."""
    return {str(p.relative_to(folder)): (p.stat().st_ino, p.stat().st_mtime_ns) for p in folder.rglob("*")
            if p.is_file()}


@pytest.mark.andes
def test_a_pss_e_raw_with_its_dyr_becomes_a_case_at_rest_with_andes_start_values(tmp_path):
    raw, dyr = andes_case("kundur/kundur.raw"), andes_case("kundur/kundur_full.dyr")
    case = case_from_file(raw, dyr, tmp_path)
    assert case.name == "kundur"
    assert case.source == (str(raw.resolve()), str(dyr.resolve()))
    assert len(case.units) == 4 and len(case.network.buses) == 10
    system = System(case)
    assert np.max(np.abs(system.rhs(0.0, system.x0, system.network()))) < REST_TOLERANCE
    ss = load_andes(raw, dyr)
    ss.TDS.init()
    differences = compare_starts(case, ss)
    assert set(differences) == {"GENROU", "EXDC2", "TGOV1"}
    for model, d in differences.items():
        assert d["state"] < ANDES_START_TOLERANCE and d["set_point"] < ANDES_START_TOLERANCE, (model, d)


@pytest.mark.andes
def test_an_xlsx_variant_that_opfmu_does_not_ship_converts_at_rest(tmp_path):
    case = case_from_file(andes_case("kundur/kundur_ieeest.xlsx"), cache_dir=tmp_path)
    assert case.source[1] is None
    assert {d.component.name for u in case.units for d in u.devices} >= {"ieeest"}
    system = System(case)
    assert np.max(np.abs(system.rhs(0.0, system.x0, system.network()))) < REST_TOLERANCE


@pytest.mark.andes
def test_a_second_call_loads_the_cached_conversion_without_andes_or_rewriting_it(tmp_path):
    source = andes_case("kundur/kundur_full.xlsx")
    first = case_from_file(source, cache_dir=tmp_path)
    written = files_in(tmp_path)
    assert len(written) == 2
    script = ("import sys; from reference_models.grid.andes_case import case_from_file; "
              f"case = case_from_file({str(source)!r}, cache_dir={str(tmp_path)!r}); "
              "print(len(case.units), 'andes' in sys.modules)")
    run = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == [str(len(first.units)), "False"]
    assert files_in(tmp_path) == written


@pytest.mark.andes
def test_a_damaged_cache_entry_is_converted_again(tmp_path):
    source = andes_case("kundur/kundur_full.xlsx")
    first = case_from_file(source, cache_dir=tmp_path)
    network = next(tmp_path.rglob("*_network.json"))
    network.write_text('{"buses": [')
    again = case_from_file(source, cache_dir=tmp_path)
    assert again.network == first.network
    assert network.read_text().startswith("{")
    assert len(list(tmp_path.iterdir())) == 1  # the entry, nothing left aside


@pytest.mark.andes
def test_a_copy_of_a_case_file_elsewhere_shares_its_cache_entry_and_records_its_own_path(tmp_path):
    source = andes_case("kundur/kundur_full.xlsx")
    copy = tmp_path / "files" / "kundur_full.xlsx"
    copy.parent.mkdir()
    copy.write_bytes(source.read_bytes())
    cache = tmp_path / "cache"
    case_from_file(source, cache_dir=cache)
    case = case_from_file(copy, cache_dir=cache)
    assert len(list(cache.iterdir())) == 1  # same name and bytes, same entry
    assert case.source == (str(copy.resolve()), None)


@pytest.mark.andes
def test_the_same_raw_with_another_dyr_is_another_conversion(tmp_path):
    raw = andes_case("kundur/kundur.raw")
    full = case_from_file(raw, andes_case("kundur/kundur_full.dyr"), tmp_path)
    classical = case_from_file(raw, andes_case("kundur/kundur_gencls.dyr"), tmp_path)
    assert len(list(tmp_path.iterdir())) == 2
    assert {u.machine.component.name for u in full.units} == {"genrou"}
    assert {u.machine.component.name for u in classical.units} == {"gencls"}


def test_a_missing_case_file_is_one_line(tmp_path):
    with pytest.raises(CaseError, match=r"^no case file .*nothing\.xlsx$"):
        case_from_file(tmp_path / "nothing.xlsx", cache_dir=tmp_path)


def test_a_missing_dyr_file_is_one_line(tmp_path):
    raw = tmp_path / "grid.raw"
    raw.write_text("0, 100.0\n")
    with pytest.raises(CaseError, match=r"^no dyr file .*grid\.dyr$"):
        case_from_file(raw, tmp_path / "grid.dyr", cache_dir=tmp_path)


def test_a_raw_file_without_its_dyr_asks_for_it(tmp_path):
    raw = tmp_path / "grid.raw"
    raw.write_text("0, 100.0\n")
    with pytest.raises(CaseError, match=r"PSS/E raw file: its machines come from its dyr file \(--dyr FILE\)"):
        case_from_file(raw, cache_dir=tmp_path)


@pytest.mark.andes
def test_a_text_file_that_is_not_a_case_is_one_line_and_caches_nothing(tmp_path, capfd):
    text = tmp_path / "notes.txt"
    text.write_text("these are not the buses you are looking for\n")
    with pytest.raises(CaseError) as error:
        case_from_file(text, cache_dir=tmp_path / "cache")
    message = str(error.value)
    assert "\n" not in message and message.startswith(f"ANDES cannot read {text}")
    assert list((tmp_path / "cache").iterdir()) == []
    out, err = capfd.readouterr()
    assert out == "" and err == ""  # ANDES' own log output silenced


@pytest.mark.andes
def test_a_case_with_a_model_opfmu_does_not_have_names_it(tmp_path):
    with pytest.raises(CaseError, match=r"^the case uses the model Fortescue, which opfmu does not have"):
        case_from_file(andes_case("5bus_fortescue.xlsx"), cache_dir=tmp_path)


@pytest.mark.andes
def test_a_case_whose_data_opfmu_refuses_names_the_users_file(tmp_path):
    source = andes_case("smib/SMIB.xlsx")  # its infinite bus: a GENCLS of Sn = 1e9 MVA
    with pytest.raises(CaseError) as error:
        case_from_file(source, cache_dir=tmp_path)
    assert str(error.value).startswith(f"{source}: generator at bus 2 (Slack_1): machine: parameter Sn")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(importlib.util.find_spec("andes") is not None, reason="ANDES is installed")
def test_without_andes_a_case_file_asks_for_it(tmp_path):
    case = tmp_path / "grid.xlsx"
    case.write_bytes(b"PK")
    with pytest.raises(CaseError, match=r"^reading case files needs ANDES: pip install -e '\.\[andes\]'$"):
        case_from_file(case, cache_dir=tmp_path / "cache")
