"""Bus devices sharing one static generator (ANDES' gammap, gammaq), static generators without a
dynamic model (ANDES' PV and Slack in the time domain: reference_models.models.static_generator),
devices out of service through their bus, and a dropped field that is no misspelling: converted
as ANDES runs them."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from reference_models.models import STANDARD_MODELS

PV, SLACK = STANDARD_MODELS["PV"], STANDARD_MODELS["Slack"]
POINT = {"Vs": 1.02, "theta_vs": 0.1, "V0": 1.02, "theta0": 0.1, "P0": 0.5, "Q0": 0.2}


def _at(component, **change) -> tuple:
    x, u = component.start(POINT, component.params_type())
    u = {**u, **change}
    return component.output_values(x, np.array([u[n] for n in component.input_names]), component.params_type())


@pytest.mark.parametrize("component", [PV, SLACK], ids=["PV", "Slack"])
def test_a_static_generator_injects_its_load_flow_power_at_its_load_flow_voltage(component):
    I_re, I_im, P, Q = _at(component)
    assert (P, Q) == pytest.approx((0.5, 0.2), rel=1e-14)
    V = POINT["Vs"] * complex(math.cos(0.1), math.sin(0.1))
    assert V * complex(I_re, -I_im) == pytest.approx(complex(0.5, 0.2), rel=1e-14)


def test_a_pv_holds_its_active_power_and_answers_a_voltage_drop_with_reactive_power_kv_per_pu():
    _, _, P, Q = _at(PV, Vs=1.01)
    assert P == pytest.approx(0.5, rel=1e-14) and Q == pytest.approx(0.2 + 1e5 * 0.01, rel=1e-12)


def test_a_slack_is_a_stiff_source_whose_current_is_affine_in_its_bus_voltage():
    assert SLACK.affine_current and not PV.affine_current
    a, b, c = (np.array(_at(SLACK, Vs=v)[:2]) for v in (0.98, 1.0, 1.02))
    np.testing.assert_allclose(b - a, c - b, rtol=1e-9)
    assert abs(complex(*(b - a))) == pytest.approx(0.02 / 1e-5, rel=1e-9)  # 1 / xs per pu of voltage


def test_a_static_generator_started_off_its_load_flow_voltage_is_refused():
    with pytest.raises(ValueError, match="not at its load flow"):
        PV.start({**POINT, "Vs": 1.0}, PV.params_type())


def _convert(tmp_path, name: str):
    andes = pytest.importorskip("andes")
    from reference_models.grid.andes_case import case_from_file

    return case_from_file(Path(andes.get_case(name)), cache_dir=tmp_path / "cache")


@pytest.mark.andes
def test_devices_sharing_a_static_generator_are_one_generator_each_with_its_share(tmp_path):
    case = _convert(tmp_path, "ieee14/ieee14_pvd1.xlsx")
    shared = [k for k, g in enumerate(case.network.generators) if str(g.name).startswith("6/")]
    assert len(shared) == 10 and all(case.network.generators[k].bus == 4 for k in shared)
    P = case.flow.P_gen[shared]
    np.testing.assert_allclose(P, P.sum() / 10, rtol=1e-12)  # each gammap = 0.1 of PV 6
    assert P.sum() == pytest.approx(0.05, rel=1e-9)
    assert all(case.units[k].machine.component.name == "pvd1" for k in shared)


@pytest.mark.andes
def test_static_generators_without_a_dynamic_model_become_pv_and_slack_devices_stated(tmp_path):
    from reference_models.grid.andes_case import case_notes

    case = _convert(tmp_path, "wscc9/wscc9.xlsx")
    assert [u.machine.component.name for u in case.units] == ["slack", "pv", "pv"]
    assert any("Slack 1, PV 2, PV 3 have no machine or converter" in n for n in case_notes(case))


@pytest.mark.andes
def test_a_device_on_a_bus_out_of_service_is_out_of_service(tmp_path):
    case = _convert(tmp_path, "ieee14/ieee14_conn.xlsx")  # bus 15 off, with PV 6 and a shunt on it
    assert 15 not in case.buses and 15 not in {g.bus for g in case.network.generators}


@pytest.mark.andes
def test_a_dropped_field_of_another_model_version_is_stated_and_devices_of_two_groups_keep_their_idx(tmp_path):
    from reference_models.grid.andes_case import case_notes

    case = _convert(tmp_path, "kundur/kundur_reg.xlsx")  # REGCA1's Iqmax beside the Iqrmax it gives
    assert any("ANDES does not know the field Iqmax of REGCA1" in n for n in case_notes(case))
    assert case.units[-1].machine.component.name == "regca1"  # GENROU 1 and REGCA1 1 share idx 1: both kept
    assert [u.machine.component.name for u in case.units].count("genrou") == 3


@pytest.mark.andes
def test_a_limit_andes_widens_at_its_initialisation_is_widened_too_and_stated(tmp_path):
    import json

    from reference_models.grid.andes_case import case_notes

    case = _convert(tmp_path, "kundur/kundur_wtdta1.xlsx")  # 7 pu on a converter whose WTTQA1 allows 1.2
    assert any("WTTQA1 1: Temax = 1.2 in the file, which ANDES widens to 7" in n for n in case_notes(case))
    data = json.loads(Path(case.dynamic_data).read_text())
    torque = next(u["torque_control"] for u in data["generators"] if "torque_control" in u)
    assert torque["params"]["Temax"] == pytest.approx(7.0, rel=1e-12)


@pytest.mark.andes
def test_a_time_series_of_a_constant_impedance_loads_power_is_left_out_stated(tmp_path):
    from reference_models.grid.andes_case import case_notes

    case = _convert(tmp_path, "ieee14/ieee14_timeseries.xlsx")  # plays PQ_1's Ppf, Qpf, which ANDES never reads
    assert any(n.startswith("TimeSeries 1 (PQ PQ_1 Ppf, Qpf from pqts.xlsx) changes nothing") for n in case_notes(case))


@pytest.mark.andes
def test_a_jumper_joins_its_buses_into_one(tmp_path):
    case = _convert(tmp_path, "ieee14/ieee14_jumper.xlsx")  # J9-10: a zero impedance, ANDES holds one voltage
    assert 10 not in case.buses and 9 in case.buses
    assert not any({br.from_bus, br.to_bus} == {9, 10} for br in case.network.branches)
    assert any(9 in (br.from_bus, br.to_bus) and 11 in (br.from_bus, br.to_bus) for br in case.network.branches)


@pytest.mark.andes
@pytest.mark.parametrize("fmus", ["reference", "monolithic"])
def test_a_case_of_static_generators_runs_through_a_line_trip_holding_their_voltages(tmp_path, fmus):
    """The stiff PV devices bend their current along the angle: the master's Newton retries in polar
    coordinates where its step in (V_re, V_im) overshoots; ANDES holds the same voltages exactly."""
    from cosim.runners import open_runner
    from reference_models.grid.contingency import Contingency

    case = _convert(tmp_path, "ieee14/ieee14_jumper.xlsx")
    runner = open_runner(fmus, case, cache=tmp_path / "fmus")
    try:
        result = runner.run(Contingency(None, 1.0, "4-5", network=case.network, events=case.events), 1.3)[0]
    finally:
        runner.close()
    held = [k for k, u in enumerate(case.units)]
    V0 = np.array([case.flow.V[case.buses.index(u.bus)] for u in case.units])
    np.testing.assert_allclose(result.Vs[:, held], np.broadcast_to(V0, result.Vs.shape), atol=1e-4)
    assert np.ptp(result.V_bus[:, case.buses.index(5)]) > 1e-3  # the trip moved the network


@pytest.mark.andes
def test_buses_islanded_from_the_slack_are_held_where_andes_freezes_them(tmp_path):
    from reference_models.grid.andes_case import case_notes

    case = _convert(tmp_path, "ieee14/ieee14_island.xlsx")  # buses 8 (a machine) and 14 (a load) cut off
    holders = [u for u in case.units if str(u.generator).startswith("island ")]
    assert [(u.bus, u.machine.component.name) for u in holders] == [(8, "slack"), (14, "slack")]
    assert any("buses 8, 14 lie in islands without a slack" in n for n in case_notes(case))
