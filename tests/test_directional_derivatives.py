"""fmi2GetDirectionalDerivative of both native FMUs (surrogate and reference): outputs with respect to
inputs, exact, against finite differences of the outputs themselves; outputs that follow inputs set
without a step; refusals; a Newton iteration on an algebraic loop that uses them."""
import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException

from cosim.fmu import FMU as Slave
from reference_models.sm4 import SM4

DEFAULT = SM4.params()
RUN = [(0.01, 1.0, 0.0)] * 5 + [(0.01, 0.6, 0.2, 0.6, 1.4)] * 8 + [(0.02, 1.05, -0.1, 0.75, 1.2)] * 10


@pytest.fixture(scope="module", params=["fmu_path", "native_reference_path"])
def unzipped(request):
    path = request.getfixturevalue(request.param)
    return extract(str(path)), read_model_description(str(path))


def moving(unzipped, steps=RUN):
    """An instance after `steps` (h, Vs, theta_vs[, Pm, Efd]): away from rest, inputs off their starts."""
    slave = Slave(unzipped)
    for h, *u in steps:
        slave.step(h, *u)
    return slave


def derivative(slave, unknowns, knowns, seeds):
    return np.array(slave.fmu.getDirectionalDerivative([slave.vr[n] for n in unknowns],
                                                       [slave.vr[n] for n in knowns], list(seeds)))


def finite_difference(slave, outputs, name, eps=1e-6):
    """d outputs / d input `name` by a central difference of the outputs read after setting the input
    (no step)."""
    u0 = slave.get(name)[0]
    slave.set(**{name: u0 + eps})
    hi = slave.get(*outputs)
    slave.set(**{name: u0 - eps})
    lo = slave.get(*outputs)
    slave.set(**{name: u0})
    return (hi - lo) / (2 * eps)


def test_both_native_fmus_declare_them_and_interpolate_inputs(fmu_path, native_reference_path):
    surrogate, reference = read_model_description(str(fmu_path)), read_model_description(str(native_reference_path))
    assert surrogate.coSimulation.providesDirectionalDerivative and reference.coSimulation.providesDirectionalDerivative
    assert reference.coSimulation.canInterpolateInputs and surrogate.coSimulation.canInterpolateInputs


def test_derived_outputs_have_the_derivatives_of_their_finite_differences_and_states_none(unzipped):
    slave = moving(unzipped)
    outputs = list(SM4.output_names)
    for extra in ([], [(0.01, 0.85, 0.3)] * 3):  # at two points of the run
        for h, *u in extra:
            slave.step(h, *u)
        for name in SM4.input_names:
            exact = derivative(slave, outputs, [name], [1.0])
            np.testing.assert_allclose(exact, finite_difference(slave, outputs, name), rtol=1e-7, atol=1e-8)
            np.testing.assert_array_equal(derivative(slave, SM4.state_names, [name], [1.0]), 0.0)
        for name in ("Pm", "Efd"):  # no derived output depends on them within a step
            np.testing.assert_array_equal(derivative(slave, outputs, [name], [1.0]), 0.0)
        # a seed over several inputs is the combination of the columns; unknowns in any order, repeated
        columns = np.array([derivative(slave, outputs, [n], [1.0]) for n in SM4.input_names]).T
        combined = derivative(slave, outputs[::-1] + ["delta", "P"], ["theta_vs", "Pm", "Vs"], [-0.3, 5.0, 2.0])
        expected = columns @ np.array([2.0, -0.3, 5.0, 0.0])
        np.testing.assert_allclose(combined, np.concatenate([expected[::-1], [0.0, expected[4]]]), rtol=1e-14,
                                   atol=1e-15)
    slave.close()


def test_outputs_follow_inputs_set_without_a_step(unzipped):
    slave = moving(unzipped)
    x = slave.state()
    for u in [(0.7, 0.4, 0.7048, 1.08), (1.2, -0.3, 0.5, 1.6), (0.0, 0.0, 0.9, 0.9)]:
        slave.set(**dict(zip(SM4.input_names, u)))
        np.testing.assert_allclose(slave.get(*SM4.output_names), SM4.output_values(x, np.array(u), DEFAULT),
                                   rtol=0, atol=1e-13)
    np.testing.assert_array_equal(slave.state(), x)  # no step was taken
    slave.close()


def test_newton_on_an_algebraic_loop_converges_quadratically_with_them(unzipped):
    """Set the voltage, read the current, iterate: the machine's bus behind a reactance X from a source
    E, V = E - j X I(V), solved for (Vs, theta_vs) by Newton with the FMU's exact derivatives."""
    slave = moving(unzipped)
    x = slave.state()
    E, X = 1.05 * np.exp(0.05j), 0.3

    def residual(vs, theta):
        slave.set(Vs=vs, theta_vs=theta)
        i_re, i_im = slave.get("I_re", "I_im")
        r = vs * np.exp(1j * theta) - E + 1j * X * (i_re + 1j * i_im)
        return np.array([r.real, r.imag])

    vs, theta, norms = 1.0, 0.0, []
    for _ in range(8):
        r = residual(vs, theta)
        norms.append(np.abs(r).max())
        if norms[-1] < 1e-13:
            break
        dI = [complex(*derivative(slave, ["I_re", "I_im"], [n], [1.0])) for n in SM4.input_names]
        columns = [np.exp(1j * theta) + 1j * X * dI[0], 1j * vs * np.exp(1j * theta) + 1j * X * dI[1]]
        J = np.array([[c.real for c in columns], [c.imag for c in columns]])
        vs, theta = np.array([vs, theta]) - np.linalg.solve(J, r)
    assert norms[-1] < 1e-13 and len(norms) <= 6, norms
    assert norms[2] < norms[1] ** 1.5  # quadratic: exact derivatives
    np.testing.assert_array_equal(slave.state(), x)
    slave.close()


@pytest.mark.parametrize("unknowns, knowns, seeds, reason", [
    (["Vs"], ["Vs"], [1.0], "is not an output"),
    (["delta0"], ["Vs"], [1.0], "is not an output"),
    (["P"], ["delta"], [1.0], "is not an input"),
    (["P"], ["delta0"], [1.0], "is not an input"),
    (["P"], ["Vs"], [float("nan")], "not a finite number"),
])
def test_a_known_that_is_not_an_input_or_an_unknown_that_is_not_an_output_is_refused(unzipped, unknowns, knowns,
                                                                                     seeds, reason):
    slave = moving(unzipped, RUN[:3])
    with pytest.raises(FMICallException):
        derivative(slave, unknowns, knowns, seeds)
    assert any(reason in m for _, m in slave.messages), slave.messages
    slave.close()


def test_unknown_value_references_are_refused(unzipped):
    slave = moving(unzipped, RUN[:3])
    for unknowns, knowns in (([999], [0]), ([slave.vr["P"]], [999])):
        with pytest.raises(FMICallException):
            slave.fmu.getDirectionalDerivative(unknowns, knowns, [1.0])
    assert sum("value reference 999" in m for _, m in slave.messages) == 2
    slave.close()


def test_the_surrogates_residual_is_a_diagnostic_without_a_derivative(fmu_path):
    slave = moving((extract(str(fmu_path)), read_model_description(str(fmu_path))), RUN[:3])
    with pytest.raises(FMICallException):
        derivative(slave, ["P", "residual"], ["Vs"], [1.0])
    assert any("residual is a diagnostic" in m for _, m in slave.messages)
    slave.close()


def test_before_initialization_they_are_refused(unzipped):
    slave = Slave(unzipped, init=False)
    with pytest.raises(FMICallException):
        derivative(slave, ["P"], ["Vs"], [1.0])
    assert any("fmi2GetDirectionalDerivative is not allowed" in m for _, m in slave.messages)
    slave.fmu.freeInstance()
