"""FMI 2.0 log messages: each reaches the instance that logged it, and no freed logger is ever called.

fmpy formats FMI 2.0 messages through one native proxy per process that calls the Python logger
registered last; these tests pin that opfmu's importers (the grid master's FMU, compare) never leave
it pointing at a logger they free, which used to crash the next FMU that logged in that process.
"""
import gc

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from cosim.fmu import FMU, CouplingError
from opfmu.compare import compare, scenario_inputs


def refused_step_printed(directory, capfd) -> str:
    """Steps an FMU instantiated with fmpy's default callbacks with a negative step size (which it
    refuses with a logged reason) and returns what fmpy's default logger printed."""
    md = read_model_description(directory)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=directory, modelIdentifier=md.coSimulation.modelIdentifier)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    capfd.readouterr()
    with pytest.raises(Exception, match="fmi2DoStep"):
        fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=-1.0)
    fmu.freeInstance()
    return capfd.readouterr().out


@pytest.fixture(scope="module")
def surrogate_dir(fmu_path, tmp_path_factory):
    return extract(str(fmu_path), unzipdir=str(tmp_path_factory.mktemp("logging") / "s"))


def test_fmpys_default_logger_still_prints_after_a_comparison_freed_its_fmus(surrogate_dir, reference_path, capfd):
    reference_dir = extract(str(reference_path))
    compare(surrogate_dir, reference_dir, scenario_inputs("slow", 0, 0.2, 0.01), 0.2, 0.01)
    gc.collect()
    assert "must be positive and finite" in refused_step_printed(surrogate_dir, capfd)


def test_fmpys_default_logger_still_prints_after_a_grid_fmu_closed(surrogate_dir, capfd):
    with FMU(surrogate_dir, name="closed") as fmu:
        fmu.step(0.01)
    del fmu
    gc.collect()
    assert "must be positive and finite" in refused_step_printed(surrogate_dir, capfd)


def test_each_fmus_messages_reach_that_fmu_alone_formatted(surrogate_dir):
    with FMU(surrogate_dir, name="first") as first, FMU(surrogate_dir, name="second") as second:
        with pytest.raises(CouplingError):
            first.do_step(first.t, -1.0)
        assert any("-1 must be positive and finite" in text for _, text in first.messages)
        assert second.messages == []
