"""A state held on a limit that moves with an input while its rate keeps pushing on it slides along
the limit in the native reference FMU (no Zeno chattering of located switchings): ESDC2A's regulator
on its ceiling VRMAX Vt while Vt recovers, as after a cleared fault (the stock kundur_esdc2a case)."""
import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from fmu_export.native_reference_fmu import build_native_reference_fmu
from reference_models.components import COMPONENTS

ESDC2A = COMPONENTS["esdc2a"]


@pytest.fixture(scope="module")
def esdc2a(tmp_path_factory):
    path = tmp_path_factory.mktemp("esdc2a") / "ESDC2AReference.fmu"
    build_native_reference_fmu(path, "ESDC2AReference", ESDC2A)
    return path


def test_a_regulator_on_a_rising_ceiling_follows_it_through_the_step(esdc2a):
    p = ESDC2A.params()
    md = read_model_description(str(esdc2a))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(esdc2a)), modelIdentifier="ESDC2AReference",
                    instanceName="exciter")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    Vt = 0.6  # the terminal voltage just after clearing: the regulator on its ceiling VRMAX Vt, pushed up
    x0 = {"LG_y0": Vt, "LL_x0": 0.5, "LA_y0": p.VRMAX * Vt, "INT_y0": 2.0, "WF_x0": 2.0}
    fmu.setReal([vr[n] for n in x0], list(x0.values()))
    fmu.setReal([vr["Vt"], vr["Vref"], vr["Vss"]], [Vt, 1.05, 0.0])
    fmu.exitInitializationMode()
    rate = 20.0  # pu/s: Vt recovering, the ceiling rising at VRMAX * 20 = 146 pu/s
    fmu.setRealInputDerivatives([vr["Vt"]], [1], [rate])
    for k in range(10):  # 10 steps of 1 ms, as the master takes them after a clearing
        fmu.doStep(currentCommunicationPoint=0.001 * k, communicationStepSize=0.001)
        (regulator,) = fmu.getReal([vr["LA_y"]])
        ceiling = p.VRMAX * (Vt + rate * 0.001 * (k + 1))
        # on the ceiling, or below it by at most its rise over ZENO_DWELL (1 ms), never above
        assert ceiling - p.VRMAX * rate * 1e-3 - 1e-9 <= regulator <= ceiling + 1e-9, (k, regulator, ceiling)
    fmu.terminate()
    fmu.freeInstance()
