"""What a host with explicit coupling needs from a bus device's native reference FMU (FMI 2.0 and
3.0): the Norton equivalent at its bus port (I = I_N + Y_N V: exact for a machine, whose stator
equations are linear in the voltage; the exact first-order linearisation for an inverter whose
current follows the voltage angle), P and Q at the bus (V conj(I), generator convention, on the
declared system base) with exact directional derivatives, a unit on every Real variable, a bus
voltage magnitude a round-off below zero taken as zero (a clearly negative one refused with a
logged reason), and value references unique across types in every FMU the project builds."""
import math
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException

from cosim.fmu import FMU as Slave
from fmu_export.build_cache import cached_native_reference_fmu
from fmu_export.model_description import validation_problems
from fmu_export.variables import NORTON_OUTPUTS, POWER_OUTPUTS, SYSTEM_BASE_MVA
from reference_models.models import STANDARD_MODELS
from reference_models.ports import BusPort, Ports, ports_of_fmu
from reference_models.sm4 import SM4

COMPONENTS = {"SM4": SM4, "GENROU": STANDARD_MODELS["GENROU"], "REGCA1": STANDARD_MODELS["REGCA1"]}
MACHINES = ("SM4", "GENROU")  # stator equations linear in the bus voltage: the Norton equivalent is exact
EPS = np.finfo(float).eps


@pytest.fixture(scope="session")
def bus_fmus(fmu_cache):
    """{(model, FMI version): path} of the three native reference FMUs (default parameters), from the
    run's build cache (the names and parameters test_standard_model_fmus builds them with)."""
    return {(name, v): cached_native_reference_fmu(f"{name}Reference", component, fmi_version=v, cache=fmu_cache)
            for name, component in COMPONENTS.items() for v in (2, 3)}


def moved(path):
    """An instance whose state has left its equilibrium: five 10 ms steps at 0.7 pu, 0.2 rad (a dip
    that keeps REGCA1 inside its low-voltage ramps' smooth part), the voltage then held there."""
    slave = Slave(path, logging_on=True)
    for _ in range(5):
        slave.step(0.01, Vs=0.7, theta_vs=0.2)
    return slave


def current_at(slave, vm, va):
    """The bus current (re, im) [pu] at the current state with the bus voltage set to vm [pu], va [rad]."""
    slave.set(Vs=vm, theta_vs=va)
    return slave.get("I_re", "I_im")


def cartesian(vm, va):
    return np.array([vm * math.cos(va), vm * math.sin(va)])


def norton_at(slave, vm, va):
    """(I_N [2], Y_N [2, 2]) read with the bus voltage at vm, va."""
    slave.set(Vs=vm, theta_vs=va)
    values = slave.get(*NORTON_OUTPUTS)
    return values[:2], values[2:].reshape(2, 2)


@pytest.mark.parametrize("version", (2, 3))
@pytest.mark.parametrize("name", MACHINES)
def test_a_machines_norton_equivalent_gives_its_bus_current_at_any_voltage_down_to_a_bolted_fault(bus_fmus, name,
                                                                                                 version):
    slave = moved(bus_fmus[name, version])
    i_n, y_n = norton_at(slave, 0.7, 0.2)
    assert np.abs(y_n).max() > 0.1  # a machine's subtransient admittance, not a bare current source
    for vm, va in ((0.7, 0.2), (1.3, -0.4), (0.3, 2.5), (0.05, 1.0), (1e-13, 0.2), (0.0, 0.0)):
        v = cartesian(vm, va)
        scale = np.abs(i_n).max() + np.abs(y_n).max() * vm
        np.testing.assert_allclose(current_at(slave, vm, va), i_n + y_n @ v, rtol=0, atol=64 * EPS * scale)
        # read at that voltage, the equivalent is the same: it depends on the state alone
        np.testing.assert_allclose(np.concatenate(norton_at(slave, vm, va), axis=None),
                                   np.concatenate((i_n, y_n), axis=None), rtol=0, atol=64 * EPS * scale)


@pytest.mark.parametrize("version", (2, 3))
def test_an_inverters_norton_equivalent_is_its_current_to_first_order_in_the_voltage(bus_fmus, version):
    slave = moved(bus_fmus["REGCA1", version])
    vm, va = 0.7, 0.2
    i_n, y_n = norton_at(slave, vm, va)
    v0 = cartesian(vm, va)
    i0 = current_at(slave, vm, va)
    np.testing.assert_allclose(i_n + y_n @ v0, i0, rtol=0, atol=16 * EPS * np.abs(i0).max())
    # the admittance is the current's derivative in the network frame: central differences agree to
    # the h^2 of their truncation
    h = 1e-5
    for column in range(2):
        step = np.zeros(2)
        step[column] = h
        up, down = v0 + step, v0 - step
        difference = (current_at(slave, np.hypot(*up), math.atan2(up[1], up[0]))
                      - current_at(slave, np.hypot(*down), math.atan2(down[1], down[0]))) / (2 * h)
        np.testing.assert_allclose(y_n[:, column], difference, rtol=0, atol=1e-8 * np.abs(y_n).max())
    # first order: the error of the equivalent falls as the square of the voltage change
    errors = []
    for dv in (1e-2, 1e-3):
        v = v0 + dv * np.array([0.6, -0.8])
        errors.append(np.abs(current_at(slave, np.hypot(*v), math.atan2(v[1], v[0])) - (i_n + y_n @ v)).max())
    assert errors[1] < errors[0] / 50
    # at 1 pu (LVG = 1, below Volim) REGCA1's current magnitudes are its states': the current follows
    # the voltage angle alone, I = (Ipout - j Iqout) V / |V|, so a radial change of V leaves it and a
    # tangential one, dV = j V, turns it: dI = j I
    _, y1 = norton_at(slave, 1.0, 0.2)
    i1, v1 = complex(*slave.get("I_re", "I_im")), complex(*cartesian(1.0, 0.2))
    for change, expected in ((v1, 0.0), (1j * v1, 1j * i1)):
        np.testing.assert_allclose(y1 @ [change.real, change.imag], [expected.real, expected.imag], rtol=0,
                                   atol=16 * EPS * abs(i1))


@pytest.mark.parametrize("version", (2, 3))
@pytest.mark.parametrize("name", COMPONENTS)
def test_p_and_q_at_the_bus_are_v_conj_i_in_generator_convention_with_exact_derivatives(bus_fmus, name, version):
    slave = moved(bus_fmus[name, version])
    for vm, va in ((0.7, 0.2), (1.1, -0.3), (0.0, 0.4)):
        i = complex(*current_at(slave, vm, va))
        s = complex(*cartesian(vm, va)) * i.conjugate()
        p, q = slave.get(*POWER_OUTPUTS)
        scale = max(abs(s), EPS)
        assert abs(p - s.real) <= 16 * EPS * scale and abs(q - s.imag) <= 16 * EPS * scale
        np.testing.assert_allclose(slave.get("P", "Q"), [p, q], rtol=0, atol=64 * EPS * max(abs(i), 1.0))
    # the derivatives with respect to the bus voltage, as a network master's Newton asks them
    slave.set(Vs=0.7, theta_vs=0.2)
    vrs = {v.name: v.valueReference for v in slave.md.modelVariables}
    unknowns, knowns = [vrs[n] for n in POWER_OUTPUTS], [vrs["Vs"], vrs["theta_vs"]]
    h = 1e-6
    for k, known in enumerate(("Vs", "theta_vs")):
        got = np.array(slave.fmu.getDirectionalDerivative(unknowns, knowns, [1.0 if j == k else 0.0 for j in range(2)]))
        slave.set(**{"Vs": 0.7, "theta_vs": 0.2, known: (0.7, 0.2)[k] + h})
        up = slave.get(*POWER_OUTPUTS)
        slave.set(**{"Vs": 0.7, "theta_vs": 0.2, known: (0.7, 0.2)[k] - h})
        down = slave.get(*POWER_OUTPUTS)
        slave.set(Vs=0.7, theta_vs=0.2)
        np.testing.assert_allclose(got, (up - down) / (2 * h), rtol=0, atol=1e-7 * max(1.0, np.abs(got).max()))


@pytest.mark.parametrize("version", (2, 3))
def test_the_norton_outputs_derivatives_are_refused_with_a_reason(bus_fmus, version):
    slave = moved(bus_fmus["SM4", version])
    vrs = {v.name: v.valueReference for v in slave.md.modelVariables}
    with pytest.raises(FMICallException):
        slave.fmu.getDirectionalDerivative([vrs["I_N_re"]], [vrs["Vs"]], [1.0])
    assert any("Norton equivalent" in m for _, m in slave.messages), slave.messages


@pytest.mark.parametrize("version", (2, 3))
@pytest.mark.parametrize("name", COMPONENTS)
def test_the_ports_declare_the_norton_equivalent_and_the_power_on_the_system_base(bus_fmus, name, version):
    ports = ports_of_fmu(bus_fmus[name, version])
    bus = ports.bus
    assert bus.norton == NORTON_OUTPUTS and bus.power == POWER_OUTPUTS and bus.base_mva == SYSTEM_BASE_MVA
    assert (bus.voltage, bus.current) == (COMPONENTS[name].ports.bus.voltage, COMPONENTS[name].ports.bus.current)
    md = read_model_description(str(bus_fmus[name, version]))
    described = {v.name: v for v in md.modelVariables}
    for output in NORTON_OUTPUTS + POWER_OUTPUTS:
        assert described[output].causality == "output" and described[output].unit == "pu"
        assert "system base Sb = 100 MVA" in described[output].description


def test_ports_without_the_fmu_additions_read_as_before_and_the_additions_round_trip():
    plain = ET.fromstring('<Ports><Bus voltageMagnitude="V" voltageAngle="a" currentReal="ir" '
                          'currentImaginary="ii"/></Ports>')
    bus = Ports.from_element(plain).bus
    assert bus == BusPort(("V", "a"), ("ir", "ii")) and bus.norton == () and bus.power == () and bus.base_mva is None
    full = Ports(BusPort(("V", "a"), ("ir", "ii"), ("p", "q"), tuple("abcdef"), 900.0))
    assert Ports.from_element(full.element()) == full


def undeclared_units(path) -> list:
    """The Real (Float64) variables of an FMU (it has some) whose unit is missing or not among its
    UnitDefinitions, (name, unit) each."""
    with zipfile.ZipFile(path) as archive:
        root = ET.fromstring(archive.read("modelDescription.xml"))
    defined = {u.get("name") for u in root.iter("Unit")}
    if root.get("fmiVersion") == "2.0":
        reals = [(sv.get("name"), sv.find("Real").get("unit")) for sv in root.iter("ScalarVariable")
                 if sv.find("Real") is not None]
    else:
        reals = [(v.get("name"), v.get("unit")) for v in root.find("ModelVariables").iter("Float64")]
    assert reals
    return [(name, unit) for name, unit in reals if unit not in defined]


@pytest.mark.parametrize("version", (2, 3))
@pytest.mark.parametrize("name", COMPONENTS)
def test_every_real_variable_declares_a_defined_unit_and_the_fmu_validates(bus_fmus, name, version):
    path = bus_fmus[name, version]
    assert validation_problems(path) == []
    assert undeclared_units(path) == []


def test_the_surrogate_and_pythonfmu_fmus_declare_a_unit_on_every_real_too(fmu_path, reference_path):
    for path in (fmu_path, reference_path):
        assert undeclared_units(path) == [] and validation_problems(path) == []


def test_every_fmu_the_project_builds_gives_each_variable_its_own_value_reference(bus_fmus, fmu_path, reference_path):
    for path in [*bus_fmus.values(), fmu_path, reference_path]:
        md = read_model_description(str(path), validate=False)
        refs = [v.valueReference for v in md.modelVariables]
        assert len(set(refs)) == len(refs), (path, sorted(refs))


def test_the_surrogates_in_envelope_no_longer_shares_the_value_reference_of_a_real(fmu_path):
    slave = Slave(fmu_path)
    vrs = {v.name: (v.valueReference, v.type) for v in slave.md.modelVariables}
    flag, kind = vrs["in_envelope"]
    assert kind == "Boolean" and flag not in {vr for vr, t in vrs.values() if t != "Boolean"}
    assert slave.fmu.getBoolean([flag]) == [True]
    with pytest.raises(FMICallException):
        slave.fmu.getReal([flag])  # no Real answers to it


@pytest.mark.parametrize("version", (2, 3))
def test_a_magnitude_a_round_off_below_zero_is_taken_as_zero_and_a_negative_one_refused(bus_fmus, version):
    slave = moved(bus_fmus["SM4", version])
    slave.set(Vs=-1e-12)
    assert slave.get("Vs")[0] == 0.0
    slave.step(0.01, Vs=-1e-12, theta_vs=0.2)
    assert np.all(np.isfinite(slave.get("I_re", "I_im", *NORTON_OUTPUTS, *POWER_OUTPUTS)))
    for bad, reason in ((-0.1, "Vs = -0.1 pu is below its lower bound 0 pu"), (float("nan"), "not a finite number"),
                        (-1e-5, "is below its lower bound")):
        with pytest.raises(FMICallException):
            slave.set(Vs=bad)
        assert reason in slave.messages[-1][1], slave.messages[-1]
        assert slave.messages[-1][0] == 3  # fmi2Error / fmi3Error
    assert slave.get("Vs")[0] == 0.0  # a refused value leaves the input as it was


def test_a_ramp_ending_a_round_off_below_zero_ends_at_zero_and_one_ending_below_is_refused(bus_fmus):
    slave = moved(bus_fmus["SM4", 2])
    vs = slave.md.modelVariables[0]
    assert vs.name == "Vs"
    slave.set(Vs=1e-3)
    slave.fmu.setRealInputDerivatives([vs.valueReference], [1], [-(1e-3 + 1e-12) / 0.01])
    slave.fmu.doStep(currentCommunicationPoint=slave.t, communicationStepSize=0.01)
    slave.t += 0.01
    assert slave.get("Vs")[0] == 0.0
    slave.set(Vs=1e-3)
    slave.fmu.setRealInputDerivatives([vs.valueReference], [1], [-0.2])
    with pytest.raises(FMICallException):
        slave.fmu.doStep(currentCommunicationPoint=slave.t, communicationStepSize=0.01)
    assert "below its lower bound" in slave.messages[-1][1]


def test_the_build_cross_check_asks_the_derivatives_of_p_and_q_at_the_bus_not_of_the_norton_outputs():
    from fmu_export.cross_check import Refs
    from fmu_export.native_reference_fmu import native_reference_variables

    variables = native_reference_variables(SM4)
    vr = {v.name: v.vr for v in variables}
    derived = Refs.of(variables, 2).derived
    assert {vr[n] for n in POWER_OUTPUTS} <= set(derived) and not {vr[n] for n in NORTON_OUTPUTS} & set(derived)
