"""Machine (SM4) and exciter (IEEE1) start values from a load-flow result: exact equilibria of the
components, the WSCC 9-bus numbers of Anderson & Fouad / Sauer & Pai, and refusals."""
import math

import numpy as np
import pytest

from reference_models.ieee1 import IEEE1
from reference_models.initialisation import ExciterStart, MachineStart, exciter_start, machine_start
from reference_models.sm4 import SM4

from machines import wscc9_machine

# WSCC 9-bus machines as shipped (Rs = D = Xep = Re = 0, 60 Hz); the expected start values below are
# the textbook's, so the tests also check the data files against Anderson & Fouad / Sauer & Pai
WSCC = [wscc9_machine(k) for k in (1, 2, 3)]
# load flow: V [pu], theta [deg], P, Q [pu] injected by the generator
FLOW = [(1.04, 0.0, 0.7164, 0.2705), (1.025, 9.280, 1.63, 0.0665), (1.025, 4.665, 0.85, -0.1086)]
EXCITER = IEEE1.params()  # the WSCC exciters


def wscc(k):
    V, theta_deg, P, Q = FLOW[k]
    return machine_start(V, math.radians(theta_deg), P, Q, SM4.params(WSCC[k]))


# (machine parameters, V, theta [rad], P, Q): the WSCC ones and others with resistance, external
# reactance, damping, a leading power factor and a motoring machine
CASES = [(SM4.params(WSCC[k]), FLOW[k][0], math.radians(FLOW[k][1]), *FLOW[k][2:]) for k in range(3)]
CASES += [(SM4.params(), 1.0, 0.0, 0.7048, 0.1), (SM4.params({"Re": 0.02, "Rs": 0.003, "Xep": 0.15}), 0.95, -0.4, 0.9, 0.3),
          (SM4.params({"Rs": 0.01}), 1.05, 1.2, 0.5, -0.25), (SM4.params(), 1.0, 0.3, -0.4, 0.05)]


def test_the_wscc_machines_start_at_the_textbook_field_voltages_and_rotor_angles():
    starts = [wscc(k) for k in range(3)]
    np.testing.assert_allclose([s.Efd for s in starts], [1.0821, 1.7893, 1.4030], atol=1e-4)
    delta = np.degrees([s.x0[0] for s in starts])
    np.testing.assert_allclose(delta, [3.58, 61.10, 54.14], atol=0.01)  # Sauer & Pai: 3.58, 61.1, 54.2
    assert delta[1] - delta[0] == pytest.approx(57.51, abs=0.01)
    assert delta[2] - delta[0] == pytest.approx(50.55, abs=0.01)
    np.testing.assert_allclose([s.Pm for s in starts], [0.7164, 1.63, 0.85], rtol=1e-12)  # lossless: Pm = P
    np.testing.assert_allclose([s.Vt for s in starts], [1.04, 1.025, 1.025], rtol=1e-15)  # Re = Xep = 0
    assert all(s.x0[1] == 0.0 for s in starts)
    assert starts[0].x0[2] == pytest.approx(0.0, abs=1e-15)  # Xq = Xq_p: no d-axis transient voltage


def test_the_wscc_exciters_start_at_the_textbook_set_points():
    starts = [exciter_start(s.Efd, s.Vt, EXCITER) for s in (wscc(k) for k in range(3))]
    np.testing.assert_allclose([e.x0[2] for e in starts], [1.1049, 1.9021, 1.4515], atol=1e-4)  # VR
    np.testing.assert_allclose([e.x0[1] for e in starts], [0.1948, 0.3221, 0.2525], atol=1e-4)  # RF
    np.testing.assert_allclose([e.Vref for e in starts], [1.0952, 1.1201, 1.0976], atol=1e-4)


@pytest.mark.parametrize("params, V, theta, P, Q", CASES)
def test_the_machine_start_is_an_exact_equilibrium_of_sm4_that_injects_the_given_power(params, V, theta, P, Q):
    s = machine_start(V, theta, P, Q, params)
    assert isinstance(s, MachineStart) and s.x0.shape == (4,)
    u = np.array([V, theta, s.Pm, s.Efd])
    np.testing.assert_allclose(SM4.rhs(s.x0, u, params), 0.0, atol=1e-12)
    Id, Iq, I_re, I_im, P_out, Q_out, speed = SM4.output_values(s.x0, u, params)
    np.testing.assert_allclose([P_out, Q_out], [P, Q], atol=1e-13)
    np.testing.assert_allclose([Id, Iq, I_re, I_im], [s.Id, s.Iq, s.I_re, s.I_im], atol=1e-13)
    assert speed == 1.0  # at rest: synchronous speed in pu, as a standard machine's omega
    assert s.Pm == pytest.approx(P + (params.Rs + params.Re) * (s.I_re ** 2 + s.I_im ** 2), abs=1e-13)  # + losses
    terminal = V * np.exp(1j * theta) + complex(params.Re, params.Xep) * complex(s.I_re, s.I_im)
    assert s.Vt == pytest.approx(abs(terminal), abs=1e-15)


@pytest.mark.parametrize("params, V, theta, P, Q", CASES)
def test_it_is_the_stable_equilibrium_sm4_itself_finds_at_the_inputs_it_returns(params, V, theta, P, Q):
    s = machine_start(V, theta, P, Q, params)
    np.testing.assert_allclose(SM4.steady_state((V, theta, s.Pm, s.Efd), params), s.x0, atol=1e-9)


def test_the_start_arrays_cannot_be_changed():
    s, e = wscc(1), exciter_start(1.5, 1.0, EXCITER)
    for array in (s.x0, e.x0):
        with pytest.raises(ValueError):
            array[0] = 0.0


@pytest.mark.parametrize("Efd, Vt", [(1.0821, 1.04), (1.7893, 1.025), (0.5, 0.9), (3.0, 1.1), (-0.3, 1.0)])
def test_the_exciter_start_is_ieee1s_own_steady_state_at_its_set_point(Efd, Vt):
    e = exciter_start(Efd, Vt, EXCITER)
    assert isinstance(e, ExciterStart) and e.x0[0] == Efd
    np.testing.assert_allclose(IEEE1.rhs(e.x0, np.array([Vt, e.Vref]), EXCITER), 0.0, atol=1e-12)
    np.testing.assert_allclose(IEEE1.steady_state((Vt, e.Vref), EXCITER), e.x0, atol=1e-12)


def test_an_exciter_start_within_its_regulator_limits_is_one_of_the_limited_equations():
    limited = IEEE1.params({"VRmin": -1.0, "VRmax": 2.0})
    e = exciter_start(1.7893, 1.025, limited)
    np.testing.assert_allclose(IEEE1.rhs(e.x0, np.array([1.025, e.Vref]), limited), 0.0, atol=1e-12)
    assert e.Vref == exciter_start(1.7893, 1.025, EXCITER).Vref


@pytest.mark.parametrize("args, says", [
    ((float("nan"), 0.0, 1.0, 0.0), "V must be a finite number"),
    ((1.0, float("inf"), 1.0, 0.0), "theta must be a finite number"),
    ((1.0, 0.0, "lots", 0.0), "P must be a number"),
    ((1.0, 0.0, 1.0, True), "Q must be a number"),
    ((1.0, 0.0, 1.0, None), "Q must be a number"),
    ((0.0, 0.0, 1.0, 0.0), r"bus voltage V = 0 pu lies outside its physical range \[0.5, 1.5\] pu"),
    ((-1.0, 0.0, 1.0, 0.0), r"bus voltage V = -1 pu lies outside"),
    ((1e-300, 0.0, 1.0, 0.0), r"bus voltage V = 1e-300 pu lies outside its physical range \[0.5, 1.5\] pu"),
    ((1.0, 7.0, 1.0, 0.0), r"angle theta = 7 rad lies outside its physical range \[-6.28319, 6.28319\] rad"),
    ((1.0, 0.0, 1e300, 0.0), r"active power P = 1e\+300 pu lies outside its physical range \[-10, 10\] pu"),
    ((1.0, 0.0, 100.0, 0.0), r"active power P = 100 pu lies outside"),
    ((1.0, 0.0, 1.0, -11.0), r"reactive power Q = -11 pu lies outside its physical range \[-10, 10\] pu"),
    # within the ranges, but the machine would need a field voltage of 38.5 pu
    ((0.5, 0.0, 10.0, 10.0), r"field voltage Efd = 38.5389 pu the machine needs there lies outside its physical "
                             r"range \[-10, 10\] pu"),
])
def test_impossible_load_flow_numbers_are_refused_naming_them(args, says):
    with pytest.raises(ValueError, match=says):
        machine_start(*args, SM4.params())


def test_a_machine_absorbing_exactly_the_reactive_power_that_cancels_its_internal_voltage_is_refused():
    p = SM4.params({"Xep": 0.0})
    # E = V + j Xq I = 0 for I = j V / Xq: P + jQ = V conj(I) = -j V^2 / Xq
    with pytest.raises(ValueError, match="no rotor angle"):
        machine_start(1.0, 0.0, 0.0, -1.0 / p.Xq, p)


@pytest.mark.parametrize("Efd, Vt, params, says", [
    (float("nan"), 1.0, EXCITER, "Efd must be a finite number"),
    (1.0, 0.0, EXCITER, "terminal voltage Vt must be > 0"),
    (1.0, "1", EXCITER, "Vt must be a number"),
    (-1.0, 1.0, EXCITER, "no unique steady state"),
    (1.7893, 1.025, IEEE1.params({"VRmax": 1.5}), "needs VR = 1.90205 pu, beyond the regulator limit VRmax = 1.5"),
    (-0.2, 1.025, IEEE1.params({"VRmin": 0.0}), "beyond the regulator limit VRmin = 0.0"),
    (1e300, 1.0, EXCITER, r"field voltage Efd = 1e\+300 pu lies outside its physical range \[-10, 10\] pu"),
    # the WSCC exciter's saturation asks for VR = 4748 pu to hold 7.7 pu
    (7.69754, 1.0, EXCITER, r"regulator output VR = 4747.\d+ pu the exciter needs to hold Efd = 7.69754 pu lies "
                            r"outside its physical range \[-100, 100\] pu"),
    (1.5833, 1.0, IEEE1.params({"KA": 0.01}), r"voltage set point Vref = 166.\d+ pu the exciter needs lies outside "
                                               r"its physical range \[0, 10\] pu"),
])
def test_an_exciter_start_that_cannot_be_is_refused(Efd, Vt, params, says):
    with pytest.raises(ValueError, match=says):
        exciter_start(Efd, Vt, params)


def test_parameters_of_the_wrong_component_are_a_type_error():
    with pytest.raises(TypeError, match="SM4Params"):
        machine_start(1.0, 0.0, 0.5, 0.1, EXCITER)
    with pytest.raises(TypeError, match="IEEE1Params"):
        exciter_start(1.0, 1.0, SM4.params())
