"""Runs of the cases converted from ANDES (kundur, ieee14, ...): the monolithic DAE over their
standard-model units at rest stays at rest, the grid command runs them, and (with ANDES) the
monolithic run follows ANDES' own simulation of the same fault."""
from __future__ import annotations

import math

import numpy as np
import pytest

from reference_models.grid.case import shipped_case
from reference_models.grid.contingency import Contingency
from reference_models.grid.monolithic import System, simulate


@pytest.mark.parametrize("name", ["kundur", "ieee14"])
def test_a_converted_case_without_a_fault_stays_at_its_load_flow_rest(name):
    system = System(shipped_case(name))
    result = simulate(system, Contingency(), 1.0)
    delta = result.angles
    assert np.max(np.abs(delta - delta[0])) < 1e-6
    assert np.max(np.abs(system.rhs(0.0, system.x0, system.network()))) < 1e-9


def test_units_sharing_a_bus_inject_into_it_together_at_rest():
    case = shipped_case("npcc")
    assert len(set(case.generator_buses)) < len(case.units)  # npcc has two units at one bus
    system = System(case)
    V_re, V_im = system.generator_voltages(system.x0, system.network())
    V = np.array([case.flow.generator_at(k)["V"] for k in range(len(case.units))])
    assert np.max(np.abs(np.hypot(V_re, V_im) - V)) < 1e-9


def test_grid_run_of_kundur_writes_the_monolithic_result(tmp_path, capsys):
    from opfmu.cli import main

    out = tmp_path / "run"
    assert main(["grid", "run", "--case", "kundur", "--fmus", "monolithic", "--fault", "8", "--fault-start", "0.2",
                 "--clear", "0.3", "--stop", "1", "--out", str(out)]) == 0
    header = (out / "result.csv").read_text().splitlines()[0].split(",")
    assert header[:5] == ["time", "delta_1", "delta_2", "delta_3", "delta_4"]
    assert {"omega_1", "Efd_4", "V_10"} <= set(header)
    assert "Kundur two-area: fault at bus 8" in capsys.readouterr().out


@pytest.mark.andes
def test_kundur_monolithic_rotor_angles_follow_andes_through_a_fault(tmp_path, monkeypatch):
    """Kundur, fault at bus 8 (1e-4j pu) 1.0-1.1 s, 3 s, ANDES at h = 1 ms: every rotor-angle
    difference within 0.1 deg of ANDES' (measured 0.089 deg over 5 s); ANDES' run leaves nothing in
    the temporary folder (its logger makes a folder for a log file unless told where)."""
    import tempfile

    from cosim.andes_runner import AndesRunner
    from cosim.outputs import on_times

    case = shipped_case("kundur")
    contingency = Contingency(8, 1.1, None, 1.0, 1e-4j, case.network)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    andes, _ = AndesRunner(case, 0.001).run(contingency, 3.0)
    assert not list(tmp_path.iterdir())
    mono = simulate(System(case), contingency, 3.0, step=0.001, rtol=1e-9, atol=1e-11)
    a = andes.angles
    m = on_times(mono, andes.time, mono.angles)
    error = np.max(np.abs((m - m[:, :1]) - (a - a[:, :1])))
    assert math.degrees(error) < 0.1
    assert np.ptp(a[:, 2] - a[:, 0]) > math.radians(5)  # the fault moves the angles


def test_andes_runs_only_the_cases_converted_from_andes(capsys, tmp_path):
    from opfmu.cli import main

    out = tmp_path / "x"
    assert main(["grid", "run", "--fmus", "andes", "--fault", "7", "--clear", "0.1", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not wscc9" in err and not out.exists()
