"""ANDES' switched shunt (ShuntSw, reference_models.models.shuntsw): its steps switched by the bus
voltage after a delay, and its conversion from ieee14_shuntsw."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from reference_models.models import STANDARD_MODELS

SHUNTSW = STANDARD_MODELS["ShuntSw"]
P = SHUNTSW.params({"B0": 0.0, "B1": 0.05, "B2": 0.1, "B3": 0.15, "n": 3.0, "vref": 1.0, "dv": 0.05, "dt": 0.1})


def _reset(sel, tau, V):
    return tuple(float(v) for v in SHUNTSW.reset([sel, tau], [V, 0.0], P, math))


def test_a_step_goes_in_below_the_band_and_out_above_it_once_the_delay_has_run():
    assert _reset(1.0, 0.1, 0.94) == (2.0, 0.0)
    assert _reset(1.0, 0.1, 1.06) == (0.0, 0.0)
    assert _reset(1.0, 0.05, 0.94) == (1.0, 0.05)  # the delay not run out
    assert _reset(1.0, 0.1, 1.0) == (1.0, 0.1)  # inside the band
    assert _reset(3.0, 0.1, 0.9) == (3.0, 0.1) and _reset(0.0, 0.1, 1.1) == (0.0, 0.1)  # no step left


def test_the_shunt_draws_its_steps_admittance_and_its_timer_stops_at_the_delay():
    I_re, I_im, Pout, Q = SHUNTSW.output_values(np.array([2.0, 0.0]), np.array([1.02, 0.0]), P)
    assert (I_re, I_im) == pytest.approx((0.0, -0.1 * 1.02), rel=1e-14) and Q == pytest.approx(0.1 * 1.02 ** 2)
    assert SHUNTSW.rhs(np.array([2.0, 0.05]), np.array([1.0, 0.0]), P)[1] == 1.0
    assert SHUNTSW.rhs(np.array([2.0, 0.1]), np.array([1.0, 0.0]), P)[1] == 0.0


def test_the_start_finds_the_steps_of_the_load_flow_and_refuses_an_admittance_between_steps():
    x, _ = SHUNTSW.start({"Vs": 1.02, "theta_vs": 0.0, "V0": 1.02, "theta0": 0.0, "P0": 0.0, "Q0": 0.1 * 1.02 ** 2}, P)
    assert list(x) == [2.0, 0.0]
    with pytest.raises(ValueError, match="no number of steps"):
        SHUNTSW.start({"Vs": 1.0, "theta_vs": 0.0, "V0": 1.0, "theta0": 0.0, "P0": 0.0, "Q0": 0.07}, P)


@pytest.mark.andes
def test_andes_switched_shunts_convert_into_units_with_their_steps_of_the_load_flow(tmp_path):
    andes = pytest.importorskip("andes")
    from reference_models.grid.andes_case import case_from_file

    case = case_from_file(Path(andes.get_case("ieee14/ieee14_shuntsw.xlsx")), cache_dir=tmp_path / "cache")
    data = json.loads(Path(case.dynamic_data).read_text())
    shunts = [u for u in data["loads"] if u["load_device"]["component"] == "shuntsw"]
    assert [u["bus"] for u in shunts] == [9, 14]
    starts = [s for u, s in zip(case.units, case.starts) if u.machine.component is SHUNTSW]
    assert [s[0].states[0] for s in starts] == [4.0, 2.0]  # ANDES' power flow left 0.1 pu in at both
