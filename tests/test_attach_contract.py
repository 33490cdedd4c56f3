"""The contract of `opfmu grid run --attach` (DESIGN section 11, docs/grid.md "Sub-systems behind a
bus"): the kinds and how they agree with --fmus, the shipped names `feeder` and `plant`, the
`opfmu grid feeder|plant` commands, the result columns P_attach_<bus>, Q_attach_<bus> and the
rating S_attach_<bus> in summary.json."""
from __future__ import annotations

import json

import numpy as np
import pytest

from reference_models.grid.subsystems import FeederSpec, feeder, write_case

HOST, BUS = "ieee14", 9  # the host case and its bus the sub-systems attach at
EVENT = ["--trip", "4-5", "--clear", "0.02", "--stop", "0.05", "--compare", "none"]  # a short run


def _one_line_exit_2(capsys, argv) -> str:
    """The one line on stderr of `opfmu argv`, asserted to end in exit code 2 with nothing on stdout."""
    from opfmu.cli import main

    assert main(argv) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert captured.out == "" and err and "\n" not in err
    return err


@pytest.fixture(scope="module")
def case_cache(tmp_path_factory):
    """$OPFMU_CASE_CACHE of this module's tests: one folder, so that the attached case is joined and
    converted once."""
    path = tmp_path_factory.mktemp("cases")
    environment = pytest.MonkeyPatch()
    environment.setenv("OPFMU_CASE_CACHE", str(path))
    yield path
    environment.undo()


@pytest.fixture(scope="module")
def small_feeder(tmp_path_factory):
    """(the case file of a 10-unit feeder, its records)."""
    records = feeder(FeederSpec(units=10, seed=1))
    return write_case(records, tmp_path_factory.mktemp("feeder") / "feeder.json"), records


@pytest.mark.parametrize("attach, fmus, message", [
    (["9=F:monolithic"], ["--fmus", "reference"], "conflicts with --fmus reference"),
    (["9=F:monolithic"], ["--fmus", "andes"], "conflicts with --fmus andes"),
    (["9=F:reference"], ["--fmus", "monolithic"], "conflicts with --fmus monolithic"),
    (["9=F:reference"], ["--fmus", "andes"], "conflicts with --fmus andes"),
    (["9=F:reference", "5=F:monolithic"], [], "conflicts with another --attach's :monolithic"),
    (["9=F:detail"], [], "unknown kind 'detail'"),
    (["9=./feeder"], [], "no file ./feeder"),
    (["9=feeder.json"], [], "no file feeder.json"),
    (["9=plant:"], [], "unknown kind ''"),
])
def test_a_kind_that_disagrees_with_the_runner_or_a_bad_source_is_one_line_and_exit_code_2(
        attach, fmus, message, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "F").write_text("{}")
    argv = ["grid", "run", "--case", HOST, *[a for text in attach for a in ("--attach", text)], *fmus,
            "--fault", "4", "--clear", "1.1", "--out", "out"]
    assert message in _one_line_exit_2(capsys, argv)
    assert not (tmp_path / "out").exists()


@pytest.mark.andes
def test_a_surrogate_without_an_operator_is_refused_in_one_line(tmp_path, capsys, case_cache):
    unlearned = write_case(feeder(FeederSpec(units=10, seed=7)), tmp_path / "unlearned.json")
    err = _one_line_exit_2(capsys, ["grid", "run", "--case", HOST, "--attach", f"{BUS}={unlearned}:surrogate", *EVENT,
                                    "--out", str(tmp_path / "out")])
    assert "no operator is registered for the sub-system unlearned.json" in err
    assert "opfmu operator --subsystem" in err
    assert not (tmp_path / "out").exists()


def test_a_shipped_name_is_written_once_into_the_cache_and_reused(tmp_path, monkeypatch):
    from reference_models.grid import subsystems

    path = subsystems.shipped_file("feeder", tmp_path)
    assert json.loads(path.read_text()) == json.loads(json.dumps(feeder(FeederSpec(units=30, seed=0))))
    written = path.stat().st_mtime_ns

    def must_not_generate(spec):
        raise AssertionError("the shipped sub-system was generated again")

    monkeypatch.setattr(subsystems, "records", must_not_generate)
    assert subsystems.shipped_file("feeder", tmp_path) == path and path.stat().st_mtime_ns == written
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temporary file left


@pytest.mark.andes
def test_a_shipped_name_attaches_its_generated_file_and_summary_gives_its_rating(tmp_path, capsys, case_cache):
    """`--attach 9=feeder:aggregate` under ANDES: the shipped 30-unit feeder (seed 0) is generated into
    the case cache, and S_attach_9 is its units' summed rating (the aggregate's one unit carries it)."""
    from opfmu.cli import main

    code = main(["grid", "run", "--case", HOST, "--attach", f"{BUS}=feeder:aggregate", "--fmus", "andes", *EVENT,
                 "--out", str(tmp_path / "out")])
    assert code == 0, capsys.readouterr().err
    files = list((case_cache / "subsystems").glob("feeder_*.json"))
    assert len(files) == 1 and len(json.loads(files[0].read_text())["PVD1"]) == 30
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    rating = sum(u["Sn"] for u in feeder(FeederSpec(units=30, seed=0))["PVD1"])
    assert summary[f"S_attach_{BUS}"] == pytest.approx(rating, rel=1e-12)


@pytest.mark.andes
@pytest.mark.parametrize("kind, fmus, runner", [
    (":monolithic", [], "monolithic"),  # :monolithic with --fmus left out makes the run monolithic
    ("", ["--fmus", "andes"], "andes"),  # no kind: the detail runs where the case does
    (":reference", ["--fmus", "reference"], "reference"),
])
def test_p_and_q_attach_start_at_the_subsystems_load_flow_injection_and_s_attach_is_its_rating(
        kind, fmus, runner, small_feeder, tmp_path, capsys, case_cache):
    import andes

    from opfmu.cli import main
    from reference_models.grid.andes_case import case_from_file
    from reference_models.grid.attach import attached_file

    path, records = small_feeder
    code = main(["grid", "run", "--case", HOST, "--attach", f"{BUS}={path}{kind}", *fmus, *EVENT,
                 "--out", str(tmp_path / "out")])
    assert code == 0, capsys.readouterr().err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["fmus"] == runner
    assert summary[f"S_attach_{BUS}"] == pytest.approx(sum(u["Sn"] for u in records["PVD1"]), rel=1e-12)
    lines = (tmp_path / "out" / "result.csv").read_text().splitlines()
    names, units = lines[0].split(","), lines[1].removeprefix("# ").split(",")
    p, q = names.index(f"P_attach_{BUS}"), names.index(f"Q_attach_{BUS}")
    assert units[p] == units[q] == "pu"
    first = [float(v) for v in lines[2].split(",")]
    # the joint load flow's injection from the sub-system into bus 9, from the network's admittance
    # matrix: the current bus 9 sends into the branches to the sub-system's buses (numbered from 1000)
    case = case_from_file(attached_file(andes.get_case("ieee14/ieee14_full.xlsx"), [(BUS, path)],
                                        case_cache / "attached"))
    net, V = case.network, case.flow.V_complex
    boundary = [br.name for br in net.branches if br.connects(BUS) and max(br.from_bus, br.to_bus) >= 1000]
    i = net.bus_index(BUS)
    injected = -V[i] * np.conj(((net.ybus() - net.ybus(boundary)) @ V)[i])
    assert injected.real < 0  # the feeder's loads draw 1.5 times its units' power: it takes power from the host
    assert first[p] == pytest.approx(injected.real, abs=1e-6)
    assert first[q] == pytest.approx(injected.imag, abs=1e-6)


def test_grid_feeder_writes_a_case_andes_reads(tmp_path, capsys):
    from opfmu.cli import main

    out = tmp_path / "f.json"
    assert main(["grid", "feeder", "--units", "10", "--seed", "3", "--out", str(out)]) == 0
    assert "feeder of 10 PVD1 units" in capsys.readouterr().out
    assert json.loads(out.read_text()) == json.loads(json.dumps(feeder(FeederSpec(units=10, seed=3))))
    andes = pytest.importorskip("andes")
    ss = andes.run(str(out), no_output=True, default_config=True)
    assert ss.PFlow.converged and ss.PVD1.n == 10


def test_grid_plant_writes_the_generators_plant_and_defaults_to_its_units(tmp_path, capsys):
    from opfmu.cli import main
    from reference_models.grid.subsystems import PlantSpec, plant

    out = tmp_path / "p.json"
    assert main(["grid", "plant", "--out", str(out)]) == 0
    assert json.loads(out.read_text()) == json.loads(json.dumps(plant(PlantSpec())))
    assert main(["grid", "feeder", "--out", str(out)]) == 0
    assert len(json.loads(out.read_text())["PVD1"]) == FeederSpec().units


@pytest.mark.parametrize("argv, message", [
    (["feeder", "--units", "0"], "at least one unit"),
    (["plant", "--units", "1001"], "at most 1000"),
    (["feeder", "--seed", "-1"], "seed must be an integer >= 0"),
    (["feeder", "--units", "many"], "invalid int value"),
    (["feeder", "--out", "f.txt"], "--out must name a .json file"),
    (["plant", "--out", "missing/p.json"], "no folder missing"),
    (["plant", "--out", "folder.json"], "is a folder"),
])
def test_grid_feeder_and_plant_refuse_bad_arguments_in_one_line(argv, message, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "folder.json").mkdir()
    if "--out" not in argv:
        argv = argv + ["--out", "out.json"]
    assert message in _one_line_exit_2(capsys, ["grid", *argv])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder.json"]
