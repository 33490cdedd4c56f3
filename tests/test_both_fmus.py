"""What the surrogate and the reference FMU must both do as FMI 2.0 co-simulation units."""
import numpy as np
import pytest
from fmpy import extract, read_model_description

from fmu_slave import Slave


@pytest.fixture(scope="module", params=["fmu_path", "reference_path"])
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
