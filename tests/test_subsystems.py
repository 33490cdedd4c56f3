"""Generated sub-systems (reference_models.grid.subsystems: radial feeders of PVD1 units) and their
attachment to a host case at a bus (reference_models.grid.attach, `opfmu grid run --attach`)."""
from __future__ import annotations

import json
from collections import defaultdict

import numpy as np
import pytest

from reference_models.grid.subsystems import FeederSpec, feeder, write_case


def test_a_feeder_is_the_same_for_a_seed_and_spreads_its_units_settings():
    a, b, c = feeder(FeederSpec(units=40, seed=3)), feeder(FeederSpec(units=40, seed=3)), feeder(FeederSpec(units=40, seed=4))
    assert a == b and a != c
    units = a["PVD1"]
    assert len(units) == 40 and len(a["Slack"]) == 1 and a["Slack"][0]["bus"] == 1
    for u in units:  # trip curves in order around the nominal voltage and frequency
        assert u["vt0"] < u["vt1"] < 1.0 < u["vt2"] < u["vt3"]
        assert u["ft0"] < u["ft1"] < 60.0 < u["ft2"] < u["ft3"]
        assert u["v0"] < 0.93 and u["v1"] > 1.05  # the Q-V dead band holds the feeder's voltages
    assert np.std([u["vt1"] for u in units]) > 0.01 and np.std([u["Sn"] for u in units]) > 0.05
    shares = defaultdict(float)
    for u in units:
        shares[u["gen"]] += u["gammap"]
    assert set(shares) == {g["idx"] for g in a["PV"]}
    assert np.allclose(list(shares.values()), 1.0, rtol=1e-12)
    power = {g["idx"]: g["p0"] for g in a["PV"]}
    assert sum(power.values()) == pytest.approx(sum(u["Sn"] / 100.0 * 0.5 for u in units), rel=0.5)


def _through_a_fault_at_bus_4(case, folder):
    """The case's run with native FMUs at 10 ms through a 1e-4j pu fault at bus 4 from 1.0 to 1.1 s
    (its own events with it), to 2 s."""
    from cosim.fmus import generator_files
    from cosim.master import MasterSettings
    from cosim.runners import MasterRunner
    from reference_models.grid.contingency import ANDES_FAULT_IMPEDANCE, Contingency

    fault = Contingency(fault_bus=4, fault_start=1.0, clear_s=1.1, fault_impedance=ANDES_FAULT_IMPEDANCE,
                        network=case.network, events=case.events)
    runner = MasterRunner(generator_files(case, "reference", folder / "cache"), case, MasterSettings(step=0.01))
    try:
        return runner.run(fault, 2.0)[0]
    finally:
        runner.close()


@pytest.mark.parametrize("units, sections", [(10, 3), (100, 10), (300, 30)])
def test_the_feeder_grows_with_its_units_and_keeps_its_voltage_drop(units, sections):
    records = feeder(FeederSpec(units=units))
    assert len(records["PVD1"]) == units and len(records["Line"]) == sections + 1
    voltages = [b["v0"] for b in records["Bus"][2:]]
    assert 0.9 < min(voltages) < 1.0  # the sweep's voltages, a drop of a few per cent
    assert records["Line"][0]["trans"] == 1 and records["Line"][0]["Vn1"] != records["Line"][0]["Vn2"]


def test_a_bad_feeder_size_is_refused():
    with pytest.raises(ValueError, match="at least one unit"):
        FeederSpec(units=0)


def test_the_case_file_is_written_whole(tmp_path):
    path = write_case(feeder(FeederSpec(units=5)), tmp_path / "f.json")
    assert json.loads(path.read_text())["PVD1"][0]["idx"] == "unit 1"
    assert [p.name for p in tmp_path.iterdir()] == ["f.json"]  # no temporary file left


@pytest.mark.parametrize("attach, message", [
    ("9", "--attach takes BUS=NAME|FILE"),
    ("x=f.json", "--attach takes BUS=NAME|FILE"),
    ("9=missing.json", "no file missing.json"),
    ("9=missing.json:aggregate", "no file missing.json"),
])
def test_a_malformed_attachment_is_one_line_and_exit_code_2(attach, message, tmp_path, capsys, monkeypatch):
    from opfmu.cli import main

    monkeypatch.chdir(tmp_path)
    (tmp_path / "f.json").write_text("{}")
    assert main(["grid", "run", "--case", "ieee14", "--attach", attach, "--out", "out"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and message in err
    assert not (tmp_path / "out").exists()


@pytest.mark.andes
@pytest.mark.parametrize("spoil, message", [
    (lambda r: r["Slack"][0].update(bus=77), "ANDES cannot set it up: KeyError"),  # a Slack on no bus
    (lambda r: r.update(Line=r["Line"][:1]), "are not connected to its boundary"),
    (lambda r: r["Bus"][1].update(Vn="abc"), "ANDES cannot set it up: ValueError"),
])
def test_a_subsystem_andes_cannot_run_is_one_line_and_exit_code_2(spoil, message, tmp_path, capsys, monkeypatch):
    from opfmu.cli import main

    monkeypatch.chdir(tmp_path)
    records = feeder(FeederSpec(units=10))
    spoil(records)
    write_case(records, tmp_path / "spoilt.json")
    assert main(["grid", "run", "--case", "ieee14", "--attach", "9=spoilt.json", "--trip", "4-5", "--clear", "0.02",
                 "--stop", "0.05", "--compare", "none", "--out", "out"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and message in err, err
    assert not (tmp_path / "out").exists()


@pytest.mark.andes
def test_a_feeder_attached_to_ieee14_solves_jointly_beside_another_probe_and_runs_through_a_host_fault(tmp_path):
    import andes

    from reference_models.grid.andes_case import case_from_file
    from reference_models.grid.attach import attached_file

    sub = write_case(feeder(FeederSpec(units=12, seed=1)), tmp_path / "feeder.json")
    # another process' joint power flow probe in flight in the same cache folder is left alone
    other = write_case({"Bus": []}, tmp_path / "attached" / ".joint_power_flow_probe.json")
    path = attached_file(andes.get_case("ieee14/ieee14_full.xlsx"), [(9, sub)], tmp_path / "attached")
    assert json.loads(other.read_text()) == {"Bus": []}
    assert sorted(p.name for p in path.parent.iterdir()) == sorted([path.name, other.name])  # no probe left behind
    assert attached_file(andes.get_case("ieee14/ieee14_full.xlsx"), [(9, sub)], tmp_path / "attached") == path
    merged = json.loads(path.read_text())
    assert not any(r["idx"] == "9:grid" for r in merged["Slack"])  # the sub-system's grid is the host now
    assert [r["bus1"] for r in merged["Line"] if r["idx"] == "9:transformer"] == [9]
    ss = andes.run(str(path), no_output=True, default_config=True)
    assert ss.PFlow.converged
    pv = [i for i, idx in enumerate(ss.PV.idx.v) if str(idx).startswith("9:")]
    assert np.max(np.abs(ss.PV.q.v[pv])) < 1e-6  # the units start at unity power factor
    case = case_from_file(path)
    assert sum(1 for u in case.units if u.bus >= 1000) == 12
    result = _through_a_fault_at_bus_4(case, tmp_path)
    assert result.stable and np.all(np.isfinite(result.V_bus))
    # the feeder's head follows the host: its voltage dips with the fault at bus 4 and recovers
    head = case.network.bus_index(min(b for b in case.buses if b >= 1000))
    assert result.V_bus[np.round(result.time, 9) == 1.05, head] < result.V_bus[0, head] - 0.05
    assert abs(result.V_bus[-1, head] - result.V_bus[0, head]) < 0.02


@pytest.mark.andes
def test_a_deep_fault_at_the_feeders_boundary_is_continued_from_the_network_before_it(tmp_path, capsys):
    """ieee14 with the shipped feeder at bus 9, a fault at bus 9 itself: each PVD1's current turns
    with its bus voltage's angle, and from the voltages before the fault Newton finds no solution
    of the faulted network (through 0.009 pu: the run failed, as ANDES' does). Continued from the
    network before the fault it runs (bus 9 at 0.04-0.05 pu); through 0.005 pu no solution
    is near the path, and the refusal says how far it got."""
    from opfmu.cli import main

    def run(z, out):
        return main(["grid", "run", "--case", "ieee14", "--attach", "9=feeder", "--fmus", "reference", "--fault", "9",
                     "--fault-impedance", z, "--fault-start", "0.5", "--clear", "0.6", "--stop", "0.8",
                     "--compare", "none", "--out", str(out)])

    assert run("0.009", tmp_path / "deep") == 0, capsys.readouterr().err
    lines = (tmp_path / "deep" / "result.csv").read_text().splitlines()
    names = lines[0].split(",")
    rows = np.array([[float(v) for v in line.split(",")] for line in lines[2:]])
    during = rows[(rows[:, 0] >= 0.5) & (rows[:, 0] < 0.6), names.index("V_9")]
    assert np.all((0.03 < during) & (during < 0.06)) and rows[-1, names.index("V_9")] > 0.95
    capsys.readouterr()
    assert run("0.005", tmp_path / "deeper") == 1
    said = capsys.readouterr()
    assert "nor along a continuation from the network before it (solved up to 99." in said.out + said.err


@pytest.mark.andes
def test_on_a_low_voltage_host_bus_the_substation_tap_keeps_the_feeders_own_voltages(tmp_path):
    """Kundur's bus 7 (a load bus at 0.96 pu): the feeder built for 1 pu at its boundary would sag into
    its units' Q-V droop (no rest); its substation transformer's tap settles instead, as an on-load
    tap changer does, and ANDES starts the whole at rest."""
    import andes

    from reference_models.grid.attach import attached_file

    sub = write_case(feeder(FeederSpec(units=10, seed=0)), tmp_path / "feeder.json")
    own = andes.run(str(sub), no_output=True, default_config=True)
    path = attached_file(andes.get_case("kundur/kundur_full.xlsx"), [(7, sub)], tmp_path / "attached")
    merged = json.loads(path.read_text())
    tap = next(r["tap"] for r in merged["Line"] if r["idx"] == "7:transformer")
    ss = andes.run(str(path), no_output=True, default_config=True)
    assert ss.Bus.v.v[ss.Bus.idx2uid(7)] < 0.98 and tap < 0.99
    heads = [b for b in ss.Bus.idx.v if b >= 1000]
    assert np.allclose([ss.Bus.v.v[ss.Bus.idx2uid(b)] for b in heads], own.Bus.v.v[1:], atol=1e-4)
    ss.TDS.config.tf = 0.2
    ss.TDS.run()
    assert ss.exit_code == 0


@pytest.mark.andes
def test_the_monolithic_dae_continues_a_current_headroom_past_its_switching(tmp_path):
    """A PVD1's reactive-current limit sqrt(ialim^2 - Ip^2) on a branch locked where the headroom was
    positive, evaluated past the switching that ends it: its continuation (0), not a math domain error."""
    from cosim.runners import MonolithicRunner
    from reference_models.grid.andes_case import case_from_file
    from reference_models.grid.contingency import Contingency

    case = case_from_file(write_case(feeder(FeederSpec(units=30, seed=0)), tmp_path / "feeder.json"))
    fault = Contingency(fault_bus=5, fault_start=1.0, clear_s=1.1, fault_impedance=1e-4j, network=case.network)
    result, _ = MonolithicRunner(case, 0.01, 1e-9).run(fault, 1.5)
    assert result.time[-1] == pytest.approx(1.5) and np.all(np.isfinite(result.V_bus))


def test_a_plant_is_the_same_for_a_seed_and_spreads_its_units_settings():
    from reference_models.grid.subsystems import PlantSpec, plant

    a, b, c = plant(PlantSpec(seed=3)), plant(PlantSpec(seed=3)), plant(PlantSpec(seed=4))
    assert a == b and a != c
    assert len(a["REGCA1"]) == len(a["REECA1"]) == len(a["REPCA1"]) == len(a["PV"]) == 20
    assert len(a["Slack"]) == 1 and a["Slack"][0]["bus"] == 1
    main = a["Line"][0]
    assert main["bus1"] == 1 and main["trans"] == 1 and (main["Vn1"], main["Vn2"]) == (230.0, 34.5)
    pads = [r for r in a["Line"] if r["idx"].startswith("pad-mount")]
    assert len(pads) == 20 and all((r["Vn1"], r["Vn2"]) == (34.5, 0.69) for r in pads)
    gens = {g["idx"]: g for g in a["PV"]}
    for gen, ree in zip(a["REGCA1"], a["REECA1"]):
        pv = gens[gen["gen"]]
        assert pv["bus"] == gen["bus"] and pv["Sn"] == gen["Sn"] and pv["q0"] == 0.0
        assert pv["p0"] * 100.0 / gen["Sn"] < 0.95 * ree["Imax"]  # inside the current limit
        assert 0.8 < ree["Vdip"] < 0.95 < 1.05 < ree["Vup"] and ree["Iq4"] < ree["Imax"] and ree["Ip4"] < ree["Imax"]
    # the flags are the plant's, the settings the unit's
    for flag in ("PFFLAG", "VFLAG", "QFLAG", "PQFLAG"):
        assert len({r[flag] for r in a["REECA1"]}) == 1
    for key in ("Vdip", "Vup", "Imax", "Trv", "Tpord"):
        assert np.std([r[key] for r in a["REECA1"]]) > 0.003
    assert np.std([g["Sn"] for g in a["REGCA1"]]) > 0.3 and np.std([g["Tg"] for g in a["REGCA1"]]) > 0.003
    # one plant controller: the same measurement and reference, gains split by rating
    rep = a["REPCA1"]
    assert {(r["busr"], r["line"], r["RefFlag"], r["Ddn"], r["Tfltr"]) for r in rep} == {
        (1, None, 1, rep[0]["Ddn"], rep[0]["Tfltr"])}
    ratings = np.array([g["Sn"] for g in a["REGCA1"]])
    for key in ("Kp", "Ki", "Kpg", "Kig", "Qmax", "Pmax"):
        values = np.array([r[key] for r in rep])
        assert np.allclose(values / values.sum(), ratings / ratings.sum(), rtol=1e-12)
    assert plant(PlantSpec(units=100, seed=1))["REPCA1"][99]["ree"] == "unit 100"


def test_a_bad_plant_size_is_refused():
    from reference_models.grid.subsystems import PlantSpec

    with pytest.raises(ValueError, match="at least one unit"):
        PlantSpec(units=0)
    with pytest.raises(ValueError, match="feeders"):
        PlantSpec(units=4, feeders=5)


def test_the_plant_command_writes_its_case(tmp_path, capsys):
    from reference_models.grid.subsystems import main

    assert main(["plant", str(tmp_path / "p.json"), "--units", "24", "--seed", "5"]) == 0
    records = json.loads((tmp_path / "p.json").read_text())
    assert len(records["REPCA1"]) == 24 and "24 units" in capsys.readouterr().out


@pytest.mark.andes
def test_andes_starts_a_plant_at_rest(tmp_path, caplog):
    import andes

    from reference_models.grid.subsystems import PlantSpec, plant

    path = write_case(plant(PlantSpec(units=20, seed=1)), tmp_path / "plant.json")
    ss = andes.run(str(path), no_output=True, default_config=True)
    assert ss.PFlow.converged
    assert np.max(np.abs(ss.PV.q.v)) < 1e-6  # the units start at unity power factor
    ss.TDS.config.tf = 1.0
    ss.TDS.config.no_tqdm = 1
    ss.TDS.run()
    assert ss.exit_code == 0 and "Initialization FAILED" not in caplog.text
    ts = ss.dae.ts
    assert np.max(np.abs(ts.x[-1] - ts.x[0])) < 1e-6 and np.max(np.abs(ts.y[-1] - ts.y[0])) < 1e-6


@pytest.mark.andes
def test_a_plant_attached_to_ieee14_runs_through_a_host_fault(tmp_path):
    import andes

    from reference_models.grid.andes_case import case_from_file
    from reference_models.grid.attach import attached_file
    from reference_models.grid.subsystems import PlantSpec, plant

    sub = write_case(plant(PlantSpec(units=20, seed=2)), tmp_path / "plant.json")
    path = attached_file(andes.get_case("ieee14/ieee14_full.xlsx"), [(9, sub)], tmp_path / "attached")
    merged = json.loads(path.read_text())
    assert {r["busr"] for r in merged["REPCA1"] if r["idx"].startswith("9:")} == {9}  # the POI is the host's bus
    case = case_from_file(path)
    assert sum(1 for u in case.units if u.bus >= 1000) == 20
    result = _through_a_fault_at_bus_4(case, tmp_path)
    assert result.stable and np.all(np.isfinite(result.V_bus))
    collector = case.network.bus_index(min(b for b in case.buses if b >= 1000))
    assert np.max(np.abs(result.V_bus[result.time < 0.99, collector] - result.V_bus[0, collector])) < 1e-4  # at rest
    assert result.V_bus[np.round(result.time, 9) == 1.05, collector] < result.V_bus[0, collector] - 0.05
    assert abs(result.V_bus[-1, collector] - result.V_bus[0, collector]) < 0.02


@pytest.mark.andes
def test_the_aggregate_is_one_unit_with_the_summed_rating_drawing_what_the_detail_draws(tmp_path):
    import andes

    from reference_models.grid.aggregate import aggregate_file

    records = feeder(FeederSpec(units=20, seed=2))
    sub = write_case(records, tmp_path / "feeder.json")
    path = aggregate_file(sub, tmp_path / "aggregates")
    assert aggregate_file(sub, tmp_path / "aggregates") == path  # cached by the file's bytes
    agg = json.loads(path.read_text())
    assert [len(agg[m]) for m in ("Bus", "Line", "PQ", "PV", "PVD1", "Slack")] == [2, 1, 1, 1, 1, 1]
    unit = agg["PVD1"][0]
    ratings = np.array([u["Sn"] for u in records["PVD1"]]) * np.array([u["gammap"] for u in records["PVD1"]])
    assert unit["Sn"] == pytest.approx(sum(u["Sn"] for u in records["PVD1"]))
    assert unit["vt1"] == pytest.approx(np.sum(ratings * [u["vt1"] for u in records["PVD1"]]) / ratings.sum())
    assert agg["PV"][0]["p0"] == pytest.approx(sum(g["p0"] for g in records["PV"]))
    line = agg["Line"][0]
    assert line["r"] > 0 and line["x"] > 0
    # the equivalent draws at its boundary what the detail draws there, and ANDES starts it at rest
    detail, equivalent = (andes.run(str(p), no_output=True, default_config=True) for p in (sub, path))
    assert complex(equivalent.Slack.p.v[0], equivalent.Slack.q.v[0]) == pytest.approx(
        complex(detail.Slack.p.v[0], detail.Slack.q.v[0]), abs=1e-3 * unit["Sn"] / 100.0)
    equivalent.TDS.config.tf = 0.5
    equivalent.TDS.run()
    assert equivalent.exit_code == 0


@pytest.mark.andes
def test_grid_run_attaches_the_aggregate_of_a_feeder(tmp_path, capsys, monkeypatch):
    from opfmu.cli import main

    monkeypatch.setenv("OPFMU_CASE_CACHE", str(tmp_path / "cases"))
    sub = write_case(feeder(FeederSpec(units=10, seed=0)), tmp_path / "feeder.json")
    code = main(["grid", "run", "--case", "ieee14", "--attach", f"9={sub}:aggregate", "--fmus", "reference",
                 "--fault", "4", "--clear", "1.1", "--stop", "1.5", "--compare", "none",
                 "--fmu-cache", str(tmp_path / "fmus"), "--out", str(tmp_path / "out")])
    assert code == 0, capsys.readouterr().err
    header = (tmp_path / "out" / "result.csv").read_text().splitlines()[0].split(",")
    # one unit in the feeder's place: the aggregate's, at its bus behind the equivalent (from 1000)
    units = [c for c in header if c.startswith("P_") and c.split("_")[1].isdigit() and int(c.split("_")[1]) >= 1000]
    assert units == ["P_1000"] and "P_attach_9" in header


@pytest.mark.andes
def test_the_aggregate_of_a_plant_follows_its_control_chain_and_sums_the_gains_split_among_its_units(tmp_path):
    from reference_models.grid.aggregate import aggregate_file
    from reference_models.grid.subsystems import PlantSpec, plant

    records = plant(PlantSpec(units=20, seed=3))
    path = aggregate_file(write_case(records, tmp_path / "plant.json"), tmp_path / "aggregates")
    agg = json.loads(path.read_text())
    assert [len(agg[m]) for m in ("REGCA1", "REECA1", "REPCA1", "PV")] == [1, 1, 1, 1]
    # the chain: static generator <- converter <- electrical control <- plant controller
    assert agg["REGCA1"][0]["gen"] == agg["PV"][0]["idx"]
    assert agg["REECA1"][0]["reg"] == agg["REGCA1"][0]["idx"]
    assert agg["REPCA1"][0]["ree"] == agg["REECA1"][0]["idx"]
    # the plant controller's gains and limits, split by rating among the units, add up; a time constant
    # (each unit's own) is the rating-weighted mean
    for field in ("Kp", "Ki", "Qmax", "Pmax"):
        assert agg["REPCA1"][0][field] == pytest.approx(sum(r[field] for r in records["REPCA1"]), rel=1e-12)
    ratings = np.array([r["Sn"] for r in records["REGCA1"]])
    assert agg["REGCA1"][0]["Sn"] == pytest.approx(ratings.sum())
    assert agg["REGCA1"][0]["Tg"] == pytest.approx(np.sum(ratings * [r["Tg"] for r in records["REGCA1"]]) / ratings.sum())
