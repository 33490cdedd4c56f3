"""A component other than SM4 gets a native reference FMU from its definition alone: a first-order
lag (one state, one input, one derived output) whose exact solution is known."""
import math
from dataclasses import dataclass, replace

import numpy as np
import pytest
from fmpy import extract, read_model_description

from fmu_export.c_derivatives import jacobians_c_source
from fmu_export.c_equations import parameter_space, switching_c_source
from fmu_export.native_reference_fmu import build_native_reference_fmu
from fmu_export.variables import REFERENCE_EXTRAS, REFERENCE_STARTS, exchange_variables, fmu_variables
from cosim.fmu import FMU as Slave
from reference_models.component import Component, Parameters, ParameterError, Quantity


@dataclass(frozen=True)
class LagParams(Parameters):
    """Time constant T [s] and gain K of y' = (K v - y) / T."""

    T: float = 0.5
    K: float = 2.0

    def check(self) -> None:
        self.require("T", self.T > 0, "be > 0")


def derivatives(x, u, p, m):
    return ((p.K * u[0] - x[0]) / p.T,)


def outputs(x, u, p, m):
    return (x[0] * m.exp(-u[0]),)  # depends directly on the input: a derivative to check


LAG = Component(
    name="lag", description="first-order lag",
    states=(Quantity("y", "pu", "lag output"),),
    inputs=(Quantity("v", "pu", "lag input", start=1.0, operating_range=(0.0, 2.0)),),
    outputs=(Quantity("w", "pu", "output times exp(-input)"),),
    params_type=LagParams, derivatives=derivatives, output_equations=outputs,
    equilibrium=lambda u, p: np.array([p.K * u[0]]), state_scales=(0.1,), affine_states=(0,))


@pytest.fixture(scope="module")
def lag_fmu(tmp_path_factory):
    path = tmp_path_factory.mktemp("lag") / "Lag.fmu"
    build_native_reference_fmu(path, "Lag", LAG, {"T": 0.25, "K": 3.0})
    return extract(str(path)), read_model_description(str(path))


def test_its_variables_follow_the_one_table_and_start_at_its_equilibrium(lag_fmu):
    params = LAG.params({"T": 0.25, "K": 3.0})
    table = exchange_variables(fmu_variables(LAG, params, [3.0], REFERENCE_EXTRAS, REFERENCE_STARTS,
                                             space=parameter_space(LAG, params)),  # T, K are FMU parameters
                               LAG, switching_c_source(LAG, parameter_space(LAG, params))[0])  # and Model Exchange's
    described = {v.name: (v.valueReference, v.start) for v in lag_fmu[1].modelVariables}
    assert {v.name: v.vr for v in table} == {n: vr for n, (vr, _) in described.items()}
    assert float(described["y0"][1]) == 3.0


def test_it_integrates_the_lag_exactly_enough_and_derives_its_output(lag_fmu):
    slave = Slave(lag_fmu, component=LAG)
    states = [slave.step(0.01, 0.5)[0] for _ in range(100)]
    w = slave.get("w")[0]
    slave.close()
    exact = 1.5 + (3.0 - 1.5) * math.exp(-1.0 / 0.25)
    assert states[-1] == pytest.approx(exact, abs=1e-9)
    assert w == pytest.approx(states[-1] * math.exp(-0.5), abs=1e-12)


def test_its_directional_derivative_is_the_traced_one(lag_fmu):
    slave = Slave(lag_fmu, component=LAG)
    slave.step(0.01, 0.5)
    y = slave.state()[0]
    vr = slave.vr
    got = slave.fmu.getDirectionalDerivative([vr["w"]], [vr["v"]], [1.0])[0]
    slave.close()
    assert got == pytest.approx(-y * math.exp(-0.5), rel=1e-12)
    assert "J[1] = " in jacobians_c_source(LAG, LAG.params())


def test_a_component_is_refused_without_outputs_or_with_bad_scales():
    with pytest.raises(ValueError, match="at least one input and one derived output"):
        replace(LAG, outputs=())
    with pytest.raises(ValueError, match="one positive state scale per state"):
        replace(LAG, state_scales=(0.1, 0.2))
    with pytest.raises(ParameterError, match="parameter T"):
        LAG.params({"T": 0.0})
