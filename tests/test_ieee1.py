"""The IEEE Type I exciter, the second component: its definition, its generated C and its native
reference FMU against an independent solve."""
import ctypes
import subprocess

import numpy as np
import pytest
import torch
from fmpy import extract, read_model_description
from scipy.integrate import solve_ivp

from fmu_export.c_equations import equations_c_source
from fmu_export.native_reference import build_native_reference_fmu
from fmu_slave import Slave
from reference_models.component import ParameterError
from reference_models.components import component
from reference_models.ieee1 import IEEE1

DEFAULT = IEEE1.params()


def jacobian(x, u, p):
    return torch.autograd.functional.jacobian(lambda v: IEEE1.rhs(v, torch.tensor(u), p),
                                              torch.tensor(x, dtype=torch.float64)).numpy()


@pytest.mark.parametrize("u", [(1.0, 1.05), (0.9, 1.05), (1.02, 1.1)])
def test_the_steady_state_is_a_stable_root_of_the_right_hand_side(u):
    x = IEEE1.steady_state(u, DEFAULT)
    np.testing.assert_allclose(IEEE1.rhs(x, np.array(u), DEFAULT), 0.0, atol=1e-12)
    assert np.all(np.linalg.eigvals(jacobian(x, u, DEFAULT)).real < 0)


def test_the_registry_knows_it_and_numpy_and_torch_agree():
    assert component("ieee1") is IEEE1
    rng = np.random.default_rng(0)
    x, u = rng.uniform([0.5, 0.0, 0.5], [3.0, 0.5, 3.0], (20, 3)), rng.uniform([0.5, 0.9], [1.2, 1.2], (20, 2))
    np.testing.assert_allclose(IEEE1.rhs(torch.tensor(x), torch.tensor(u), DEFAULT).numpy(), IEEE1.rhs(x, u, DEFAULT),
                               rtol=1e-13)


def test_the_generated_c_computes_what_numpy_computes(tmp_path):
    source = tmp_path / "ieee1.c"
    source.write_text(equations_c_source(IEEE1, DEFAULT, linkage="")
                      + "void f(const double *x, const double *u, double *out) { model_derivatives(x, u, out); }\n")
    subprocess.run(["gcc", "-O2", "-Wall", "-shared", "-fPIC", str(source), "-o", str(tmp_path / "l.so"), "-lm"],
                   check=True)
    lib, p = ctypes.CDLL(str(tmp_path / "l.so")), ctypes.POINTER(ctypes.c_double)
    x, u, out = np.array([2.0, 0.3, 2.5]), np.array([0.8, 1.1]), np.zeros(3)
    lib.f(x.ctypes.data_as(p), u.ctypes.data_as(p), out.ctypes.data_as(p))
    np.testing.assert_allclose(out, IEEE1.rhs(x, u, DEFAULT), rtol=1e-14)


@pytest.mark.parametrize("values, says", [({"KA": 0}, "parameter KA"), ({"KE": -0.05}, "self-excited"),
                                          ({"TF": -1}, "parameter TF"), ({"Kx": 1}, "unknown ieee1 parameter")])
def test_bad_parameters_are_refused_naming_the_field(values, says):
    with pytest.raises(ParameterError, match=says):
        IEEE1.params(values)


def test_its_native_reference_fmu_follows_an_independent_solve_through_a_voltage_dip(tmp_path):
    path = tmp_path / "IEEE1Reference.fmu"
    build_native_reference_fmu(path, "IEEE1Reference", IEEE1)
    directory, md = extract(str(path)), read_model_description(str(path))
    assert [u.dependencies for u in md.outputs if u.variable.name == "SE"] == [[]]  # SE reads no input
    slave = Slave((directory, md), component=IEEE1)
    inputs = [(0.01, 1.0, 1.05)] * 20 + [(0.01, 0.4, 1.05)] * 10 + [(0.01, 1.0, 1.05)] * 170
    got = np.array([slave.step(h, vt, vref) for h, vt, vref in inputs])
    slave.close()
    x, expected = IEEE1.steady_state(None, DEFAULT), []
    for h, vt, vref in inputs:
        x = solve_ivp(lambda _t, s: IEEE1.rhs(s, np.array([vt, vref]), DEFAULT), (0, h), x, method="DOP853",
                      rtol=1e-12, atol=1e-12).y[:, -1]
        expected.append(x)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-8)
    assert got[:, 0].max() > IEEE1.steady_state(None, DEFAULT)[0] + 0.5  # the field forced up by the dip
