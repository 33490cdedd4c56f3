"""What the surrogate, the pythonfmu reference and the native reference FMU must all do as FMI 2.0
co-simulation units."""
import numpy as np
import pytest
from fmpy import extract, read_model_description

from fmu_export.native_reference import build_native_reference_fmu
from fmu_slave import Slave


@pytest.fixture(scope="module")
def native_reference_path(tmp_path_factory):
    """The native reference FMU (Dormand-Prince 5(4) in C), built once for this module."""
    path = tmp_path_factory.mktemp("native_reference") / "SM4Reference.fmu"
    build_native_reference_fmu(path)
    return path


@pytest.fixture(scope="module", params=["fmu_path", "reference_path", "native_reference_path"])
def unzipped(request):
    path = request.getfixturevalue(request.param)
    return extract(str(path)), read_model_description(str(path))


def test_many_instances_live_side_by_side_and_the_fmu_reloads(unzipped):
    slaves = [Slave(unzipped, f"i{k}") for k in range(4)]
    results = [s.step(0.01, 0.9 + 0.02 * k) for k, s in enumerate(slaves)]
    for s in slaves:
        s.close()
    again = Slave(unzipped, "again")
    np.testing.assert_array_equal(again.step(0.01, 0.9), results[0])
    again.close()


def test_the_two_references_agree_on_held_inputs(reference_path, native_reference_path):
    runs = []
    for path in (reference_path, native_reference_path):
        slave = Slave((extract(str(path)), read_model_description(str(path))), rtol=1e-10, atol=1e-12)
        runs.append([slave.step(h, *u) for h, *u in [(0.01, 0.9, 0.1)] * 20 + [(0.05, 1.05, -0.2)] * 10])
        slave.close()
    np.testing.assert_allclose(runs[0], runs[1], rtol=0, atol=1e-9)
