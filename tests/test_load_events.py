"""A case's own load switching (ANDES' Toggle of a PQ): the load's constant-impedance admittance leaves
the network at its time and comes back at the next toggle, in the master and the monolithic DAE alike,
and as ANDES simulates it."""
from __future__ import annotations

import json

import numpy as np
import pytest

from reference_models.grid.contingency import Contingency


def _kundur_with_toggles(tmp_path, times):
    import andes

    data = json.loads(open(andes.get_case("kundur/kundur_full.json")).read())
    data["Toggle"] = [{"idx": f"T{k}", "u": 1.0, "name": f"T{k}", "model": "PQ", "dev": "PQ_0", "t": t}
                      for k, t in enumerate(times)]
    path = tmp_path / "kundur_load_toggle.json"
    path.write_text(json.dumps(data))
    return path


@pytest.mark.andes
def test_a_toggled_load_leaves_the_network_and_comes_back_as_in_andes(tmp_path):
    pytest.importorskip("andes")
    from cosim.andes_runner import AndesRunner
    from cosim.outputs import errors
    from reference_models.grid.andes_case import case_from_file
    from reference_models.grid.monolithic import System, simulate

    case = case_from_file(_kundur_with_toggles(tmp_path, (1.0, 1.5)), cache_dir=tmp_path / "cache")
    loads = [e for e in case.events if e.kind == "load"]
    assert [(e.time, e.bus, e.status) for e in loads] == [(1.0, 7, 0), (1.5, 7, 1)]
    assert loads[0].power == pytest.approx(complex(11.59, -0.735))
    contingency = Contingency(network=case.network, events=case.events)
    topologies = contingency.topologies(3.0)
    assert [tp.loads_off for tp in topologies[:3]] == [(), ((7, loads[0].power),), ()]
    mono = simulate(System(case), contingency, 3.0, step=0.01)
    speed = mono.states["omega"]
    assert np.all(speed[(mono.time > 1.05) & (mono.time <= 1.5)] > 1.0)  # 11.6 pu of load lost: the machines speed up
    andes = AndesRunner(case, 0.001, rows=0.01).run(contingency, 3.0)[0]
    assert errors(mono, andes, None, case)["angle_deg"] < 0.1
