"""The conditional of the equations' math namespaces (reference_models.piecewise.where): the same
selection on the math module, numpy, torch, the generated C and its generated derivatives."""
import ctypes
import math
import subprocess

import numpy as np
import pytest
import torch

from fmu_export.c_derivatives import jacobians_c_source
from fmu_export.c_equations import equations_c_source, output_input_dependencies
from reference_models.component import Component, Parameters, Quantity
from reference_models.piecewise import where


class NoParams(Parameters):
    pass


def rates(x, u, p, m):
    """A dead zone on u (|u| <= 1 gives 0) times x, and a kink at x = 0.5."""
    zone = where(m, u[0] > 1.0, u[0] - 1.0, where(m, u[0] < -1.0, u[0] + 1.0, 0.0))
    return (zone * x[0], where(m, 0.5 <= x[0], 2.0 * x[0], m.sin(x[0])))


def outputs(x, u, p, m):
    return (where(m, x[0] >= 0.0, x[0], 0.0), where(m, x[0] >= 0.0, u[0], -u[0]))


PIECES = Component(name="pieces", description="piecewise test component",
                   states=(Quantity("a", "", "a"), Quantity("b", "", "b")), inputs=(Quantity("u", "", "u", start=0.0),),
                   outputs=(Quantity("ya", "", "ya"), Quantity("yu", "", "yu")), params_type=NoParams,
                   derivatives=rates, output_equations=outputs, equilibrium=lambda u, p: np.zeros(2),
                   state_scales=(1.0, 1.0))
POINTS = [(x, u) for x in (-0.3, 0.2, 0.5, 0.9) for u in (-2.0, -0.5, 1.0, 1.7)]


def compiled(tmp_path, source, name):
    path = tmp_path / f"{name}.c"
    path.write_text(source)
    subprocess.run(["gcc", "-O2", "-Wall", "-Werror", "-Wno-unused-function", "-shared", "-fPIC", str(path), "-o",
                    str(tmp_path / f"{name}.so"), "-lm"], check=True)
    return ctypes.CDLL(str(tmp_path / f"{name}.so"))


def call(fn, x, u, n):
    out, ptr = np.zeros(n), ctypes.POINTER(ctypes.c_double)
    fn(np.array(x, dtype=float).ctypes.data_as(ptr), np.array(u, dtype=float).ctypes.data_as(ptr), out.ctypes.data_as(ptr))
    return out


def test_where_selects_alike_on_math_numpy_torch_and_the_generated_c(tmp_path):
    lib = compiled(tmp_path, equations_c_source(PIECES, NoParams(), linkage="")
                   + "void f(const double *x, const double *u, double *o) { model_derivatives(x, u, o); }\n"
                   + "void g(const double *x, const double *u, double *o) { model_outputs(x, u, o); }\n", "eq")
    for x, u in POINTS:
        xs, us = [x, 0.0], [u]
        expected = rates(xs, us, None, math)
        np.testing.assert_array_equal(PIECES.rhs(np.array(xs), np.array(us), NoParams()), expected)
        np.testing.assert_array_equal(PIECES.rhs(torch.tensor(xs, dtype=torch.float64),
                                                 torch.tensor(us, dtype=torch.float64), NoParams()).numpy(), expected)
        np.testing.assert_array_equal(call(lib.f, xs, us, 2), expected)
        np.testing.assert_array_equal(call(lib.g, xs, us, 2), outputs(xs, us, None, math))
    assert rates([0.9, 0.0], [1.7], None, math) == pytest.approx((0.7 * 0.9, 1.8))


def test_the_generated_derivatives_are_those_of_the_branch_taken(tmp_path):
    lib = compiled(tmp_path, jacobians_c_source(PIECES, NoParams())
                   + "void j(const double *x, const double *u, double *J) { model_derivatives_jacobian(x, u, J); }\n"
                   + "void k(const double *x, const double *u, double *J) { model_outputs_jacobian(x, u, J); }\n", "jac")
    for x, u in POINTS:
        xu = torch.tensor([x, 0.0, u], dtype=torch.float64)
        for fn, traced in ((lib.j, PIECES.rhs), (lib.k, PIECES.output_values)):
            expected = torch.autograd.functional.jacobian(lambda v: traced(v[:2], v[2:], NoParams()), xu).numpy()
            np.testing.assert_allclose(call(fn, [x, 0.0], [u], 6).reshape(2, 3), expected, rtol=1e-15, atol=0)


def test_an_output_depends_on_the_inputs_of_its_condition_and_branches():
    def picks(x, u, p, m):
        return (where(m, u[0] > 0.0, x[0], 1.0), where(m, x[0] > 0.0, 1.0, 2.0))

    component = Component(name="picks", description="", states=PIECES.states, inputs=PIECES.inputs,
                          outputs=PIECES.outputs, params_type=NoParams, derivatives=rates, output_equations=picks,
                          equilibrium=lambda u, p: np.zeros(2), state_scales=(1.0, 1.0))
    assert output_input_dependencies(component, NoParams()) == [("u",), ()]
    assert output_input_dependencies(PIECES, NoParams()) == [(), ("u",)]


def test_an_equation_that_branches_with_python_if_on_a_traced_value_fails_loudly():
    def branching(x, u, p, m):
        return (x[0] if x[0] > 0.5 else -x[0], x[1])

    component = Component(name="branching", description="", states=PIECES.states, inputs=PIECES.inputs,
                          outputs=PIECES.outputs, params_type=NoParams, derivatives=branching,
                          output_equations=outputs, equilibrium=lambda u, p: np.zeros(2), state_scales=(1.0, 1.0))
    for generate in (equations_c_source, jacobians_c_source):
        with pytest.raises(TypeError, match="no Python truth value"):
            generate(component, NoParams())
