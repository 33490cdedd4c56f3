"""The IEEE Type I exciter, the second component: its definition, its generated C and its native
reference FMU against an independent solve, without and with regulator limits."""
import ctypes
import math
import subprocess

import numpy as np
import pytest
import torch
from fmpy import extract, read_model_description
from scipy.integrate import solve_ivp

from fmu_export.c_derivatives import jacobians_c_source
from fmu_export.c_equations import equations_c_source
from fmu_export.native_reference_fmu import build_native_reference_fmu
from cosim.fmu import FMU as Slave
from reference_models.component import ParameterError
from reference_models.components import component
from reference_models.ieee1 import IEEE1, NO_LIMIT

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
                                          ({"TF": -1}, "parameter TF"), ({"Kx": 1}, "unknown ieee1 parameter"),
                                          ({"TA": 1e-9}, r"parameter TA = 1e-09 must lie in \[0.005, 10\] s"),
                                          ({"KA": 1e9}, r"parameter KA = 1000000000.0 must lie in \[0, 1000\] pu"),
                                          ({"Bx": 100}, r"parameter Bx = 100.0 must lie in \[0, 5\] 1/pu"),
                                          ({"KF": 10}, r"parameter KF = 10.0 must lie in \[0, 1\] pu")])
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


# --- regulator limits (Sauer-Pai's non-windup limit on VR) ---------------------------------------

LIMITS = {"VRmin": 0.0, "VRmax": 3.0}
LIMITED = IEEE1.params(LIMITS)


def test_without_limits_the_traced_equations_have_no_conditional():
    assert DEFAULT.VRmin <= -NO_LIMIT and DEFAULT.VRmax >= NO_LIMIT
    assert "?" not in equations_c_source(IEEE1, DEFAULT) and "?" in equations_c_source(IEEE1, LIMITED)


def test_limits_that_do_not_bracket_anything_are_refused():
    with pytest.raises(ParameterError, match="parameter VRmax = 1.0 must exceed VRmin = 2.0"):
        IEEE1.params({"VRmin": 2.0, "VRmax": 1.0})


def regulator_rate(x, u, p):
    """The unlimited dVR/dt, written out."""
    Efd, RF, VR = x
    return (-VR + p.KA * RF - p.KA * p.KF / p.TF * Efd + p.KA * (u[1] - u[0])) / p.TA


# (state, inputs): VR at the upper limit pushed up / pulled down, at the lower limit pushed down /
# pulled up, and between the limits
POINTS = [((1.5, 0.2, 3.0), (0.5, 1.05)), ((1.5, 0.2, 3.0), (1.2, 1.05)), ((1.5, 0.3, 0.0), (1.2, 1.0)),
          ((0.5, 0.1, 0.0), (0.8, 1.05)), ((1.0, 0.2, 1.5), (0.95, 1.05))]
HELD = [True, False, True, False, False]


def test_vr_is_held_exactly_while_the_regulator_pushes_it_beyond_a_limit_on_every_namespace(tmp_path):
    source = tmp_path / "limited.c"
    source.write_text(equations_c_source(IEEE1, LIMITED, linkage="")
                      + "void f(const double *x, const double *u, double *out) { model_derivatives(x, u, out); }\n")
    subprocess.run(["gcc", "-O2", "-Wall", "-Werror", "-shared", "-fPIC", str(source), "-o", str(tmp_path / "l.so"),
                    "-lm"], check=True)
    lib, ptr = ctypes.CDLL(str(tmp_path / "l.so")), ctypes.POINTER(ctypes.c_double)
    for (x, u), held in zip(POINTS, HELD):
        unlimited = regulator_rate(x, u, LIMITED)
        assert held == ((x[2] == 3.0 and unlimited > 0) or (x[2] == 0.0 and unlimited < 0))
        want = 0.0 if held else unlimited
        x_a, u_a, out = np.array(x), np.array(u), np.zeros(3)
        lib.f(x_a.ctypes.data_as(ptr), u_a.ctypes.data_as(ptr), out.ctypes.data_as(ptr))
        rates = [IEEE1.rhs(x_a, u_a, LIMITED), out, np.array(IEEE1.derivatives(x, u, LIMITED, math)),
                 IEEE1.rhs(torch.tensor(x, dtype=torch.float64), torch.tensor(u, dtype=torch.float64), LIMITED).numpy()]
        for rate in rates:
            assert rate[2] == pytest.approx(want, abs=1e-12)
            np.testing.assert_allclose(rate[:2], IEEE1.rhs(x_a, u_a, DEFAULT)[:2], rtol=1e-14)


def test_the_generated_jacobian_of_the_limited_equations_is_that_of_the_branch_taken(tmp_path):
    source = tmp_path / "jacobian.c"
    source.write_text(jacobians_c_source(IEEE1, LIMITED)
                      + "void j(const double *x, const double *u, double *J) { model_derivatives_jacobian(x, u, J); }\n")
    subprocess.run(["gcc", "-O2", "-Wall", "-Werror", "-Wno-unused-function", "-shared", "-fPIC", str(source), "-o",
                    str(tmp_path / "j.so"), "-lm"], check=True)
    lib, ptr = ctypes.CDLL(str(tmp_path / "j.so")), ctypes.POINTER(ctypes.c_double)
    for (x, u), held in zip(POINTS, HELD):
        J = np.zeros(15)
        lib.j(np.array(x).ctypes.data_as(ptr), np.array(u).ctypes.data_as(ptr), J.ctypes.data_as(ptr))
        xu = torch.tensor(x + u, dtype=torch.float64)
        expected = torch.autograd.functional.jacobian(lambda v: IEEE1.rhs(v[:3], v[3:], LIMITED), xu).numpy()
        np.testing.assert_allclose(J.reshape(3, 5), expected, rtol=1e-13, atol=1e-13)
        assert np.all(J[10:] == 0.0) == held


def test_a_limited_steady_state_rests_at_the_limit_the_regulator_pushes_against():
    for u, vr in [((0.8, 1.05), 3.0), ((1.2, 1.05), 0.0), ((1.0, 1.05), 1.0)]:
        x = IEEE1.steady_state(u, LIMITED)
        assert x[2] == pytest.approx(vr, abs=1e-12)
        np.testing.assert_allclose(IEEE1.rhs(x, np.array(u), LIMITED), 0.0, atol=1e-12)


def hybrid_step(x, vt, vref, h, p):
    """The limited equations over [0, h] at held inputs, written out as a hybrid system: free, or VR
    held at a limit; the switches located by solve_ivp's events (DOP853)."""
    def rate(y):
        return regulator_rate(y, (vt, vref), p)

    def rhs(y, held):
        Efd, RF, VR = y
        return [(-(p.KE + p.Ax * np.exp(p.Bx * Efd)) * Efd + VR) / p.TE, (-RF + p.KF / p.TF * Efd) / p.TF,
                0.0 if held else rate(y)]

    t, x = 0.0, np.array(x, dtype=float)
    for _ in range(10):
        f = rate(x)
        held = (x[2] >= p.VRmax and f > 0) or (x[2] <= p.VRmin and f < 0)
        if held:  # until the regulator stops pushing
            release = lambda _t, y: rate(y)  # noqa: E731
            release.terminal, release.direction = True, -1 if x[2] >= p.VRmax else 1
            events = [release]
        else:  # until VR reaches a limit
            upper, lower = (lambda _t, y: y[2] - p.VRmax), (lambda _t, y: y[2] - p.VRmin)
            upper.terminal, upper.direction, lower.terminal, lower.direction = True, 1, True, -1
            events = [upper, lower]
        sol = solve_ivp(lambda _t, y: rhs(y, held), (t, h), x, method="DOP853", rtol=1e-12, atol=1e-13, events=events)
        t, x = sol.t[-1], sol.y[:, -1].copy()
        if sol.status == 0:
            return x
        if not held:
            x[2] = p.VRmax if sol.t_events[0].size else p.VRmin
    raise AssertionError("more switches in one step than expected")


def test_the_limited_native_reference_fmu_follows_a_hybrid_solve_through_a_dip_that_drives_vr_into_both_limits(
        tmp_path):
    path = tmp_path / "IEEE1Limited.fmu"
    build_native_reference_fmu(path, "IEEE1Limited", IEEE1, params=LIMITS)
    slave = Slave((extract(str(path)), read_model_description(str(path))), component=IEEE1)
    # a dip to 0.4 pu for 150 ms, an overvoltage of 1.15 pu for 300 ms, back to 1 pu
    inputs = [(0.01, 1.0, 1.05)] * 20 + [(0.01, 0.4, 1.05)] * 15 + [(0.01, 1.15, 1.05)] * 30 + [(0.01, 1.0, 1.05)] * 135
    got = np.array([slave.step(h, vt, vref) for h, vt, vref in inputs])
    slave.close()
    x, expected = IEEE1.steady_state(None, LIMITED), []
    for h, vt, vref in inputs:
        x = hybrid_step(x, vt, vref, h, LIMITED)
        expected.append(x)
    expected = np.array(expected)
    assert np.sum(expected[:, 2] == 3.0) >= 10 and np.sum(expected[:, 2] == 0.0) >= 10  # held at both limits
    # the integrator does not locate the switches: VR overshoots a limit by about the tolerance's effect
    np.testing.assert_allclose(got, expected, rtol=0, atol=2e-7)
    unlimited = [IEEE1.steady_state(None, DEFAULT)]
    for h, vt, vref in inputs:
        unlimited.append(solve_ivp(lambda _t, s: IEEE1.rhs(s, np.array([vt, vref]), DEFAULT), (0, h), unlimited[-1],
                                   method="DOP853", rtol=1e-10, atol=1e-12).y[:, -1])
    assert np.abs(np.array(unlimited[1:])[:, 2] - got[:, 2]).max() > 1.0  # the limits matter here
