"""How a component connects to a network and to the other components of its unit: its ports.

A component declares
* a **bus port** (`BusPort`) when it sits on a network bus: the two inputs that take the bus voltage
  phasor in polar form (magnitude [pu], angle [rad], network frame) and the two outputs that give
  the current phasor it injects into the bus (real and imaginary part [pu], network frame);
* **control links** (`Link`): the signals it takes (`inputs`) and gives (`outputs`), each a signal
  name from `SIGNALS` bound to one of its variables (an input for `inputs`; a state or derived output
  for `outputs`).

Whatever wires components together (the grid master, `compare`, `init`, the input families, the
scenarios) reads these declarations, never a component's name. Within a unit (the devices at one
generator), an input link takes the output link of the same signal; the bus gives
`terminal_voltage` (the magnitude of the bus voltage) to a unit that has no component giving it;
an input link that nothing gives is a set point, held at the start value the unit's initialisation
gives it.

The ports travel in the model description of every FMU the project builds, so an importer (and the
grid master, for an FMU the project did not build) finds them without knowing the component:

    FMI 2.0: <VendorAnnotations><Tool name="opfmu"><Ports>...</Ports></Tool></VendorAnnotations>
    FMI 3.0: <Annotations><Annotation type="org.opfmu.ports"><Ports>...</Ports></Annotation></Annotations>

    <Ports>
      <Bus voltageMagnitude="Vs" voltageAngle="theta_vs" currentReal="I_re" currentImaginary="I_im"
           activePower="P_bus" reactivePower="Q_bus" systemBaseMVA="100.0">
        <Norton currentReal="I_N_re" currentImaginary="I_N_im" g11="Y_N_11" g12="Y_N_12" g21="Y_N_21" g22="Y_N_22"/>
      </Bus>
      <Input signal="field_voltage" variable="Efd"/>
      <Output signal="speed" variable="omega"/>
    </Ports>

The attributes activePower, reactivePower and systemBaseMVA and the <Norton> element are what an
FMU adds to its component's bus port (fmu_export.variables.fmu_ports: the native reference FMU's
outputs P and Q at the bus and its Norton equivalent, docs/design.md); a description without them
reads as a bus port without them.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass
from pathlib import Path

from .messages import explain

#: The control signals components exchange: name -> (symbol, unit, meaning).
SIGNALS = {
    "field_voltage": ("Efd", "pu", "field voltage: an exciter's output, a machine's input"),
    "mechanical_power": ("Pm", "pu", "mechanical power: a governor's output, a machine's input"),
    "second_mechanical_power": ("Pm2", "pu", "mechanical power a turbine gives a second machine, that machine's base "
                                "(IEEEG1's low-pressure stages): the case takes it to that machine's unit as its "
                                "mechanical_power (Unit.takes)"),
    "terminal_voltage": ("Vt", "pu", "terminal voltage magnitude: an exciter's input"),
    "speed": ("omega", "rad/s", "rotor speed deviation from synchronous: SM4's speed state, which a grid result reads "
              "(controls take rotor_speed)"),
    "electrical_power": ("Pe", "pu", "electrical power: a machine's output, a stabiliser's input"),
    "stabiliser_signal": ("Vss", "pu", "stabiliser output: a power system stabiliser's output, an exciter's input"),
    "voltage_reference": ("Vref", "pu", "voltage set point of an exciter"),
    "power_reference": ("Pref", "pu", "power set point of a governor"),
    "rotor_speed": ("omega", "pu", "rotor speed in pu of synchronous speed (1 at rest): every synchronous machine's "
                    "output (SM4's 1 + omega / Wb), a governor's, exciter's or stabiliser's input"),
    "field_current": ("XadIfd", "pu", "field current times the d-axis mutual reactance: a standard machine's output, "
                      "a static exciter's input"),
    "terminal_voltage_angle": ("theta_vs", "rad", "terminal voltage angle (network frame): an exciter's input"),
    "terminal_current_real": ("I_re", "pu", "machine current into the bus, real part, system base: an exciter's input"),
    "terminal_current_imaginary": ("I_im", "pu", "machine current into the bus, imaginary part, system base: "
                                   "an exciter's input"),
    "rotor_angle": ("delta", "rad", "rotor angle (network frame) of a synchronous machine: what the stability "
                    "judgement compares between machines"),
    "active_current_command": ("Ipcmd", "pu", "active current command, system base: an inverter's electrical "
                               "controller's output, its converter's input"),
    "reactive_current_command": ("Iqcmd", "pu", "reactive current command, system base, ANDES' sign (< 0 delivers "
                                 "reactive power): an electrical controller's output, its converter's input"),
    "active_power": ("Pe", "pu", "active power of an inverter into its bus, system base: a converter's output, "
                     "its electrical and plant controllers' input"),
    "reactive_power": ("Qe", "pu", "reactive power of an inverter into its bus, system base: a converter's output, "
                       "its electrical and plant controllers' input"),
    "active_power_reference": ("Pref", "pu", "active power set point of an inverter's electrical controller, "
                               "system base (a plant controller's output)"),
    "reactive_power_reference": ("Qref", "pu", "reactive power set point of an inverter's electrical controller, "
                                 "system base (a plant controller's output)"),
    "power_factor_angle_reference": ("pfaref", "rad", "power factor angle set point of an inverter's electrical "
                                     "controller (its power factor control)"),
    # measurements a device takes from the network beyond its own bus (a plant controller's): the
    # unit's dynamic data name the measured bus and branch (Measurement); the network gives them
    "measured_voltage": ("Vm", "pu", "voltage magnitude at the measured bus"),
    "measured_voltage_angle": ("theta_m", "rad", "voltage angle at the measured bus (network frame)"),
    "branch_active_power": ("Pbr", "pu", "active power flowing into the measured branch at its measured end, "
                            "system base"),
    "branch_reactive_power": ("Qbr", "pu", "reactive power flowing into the measured branch at its measured end, "
                              "system base"),
    "branch_current_real": ("Ibr_re", "pu", "current into the measured branch at its measured end, real part, "
                            "network frame, system base"),
    "branch_current_imaginary": ("Ibr_im", "pu", "current into the measured branch at its measured end, imaginary "
                                 "part, network frame, system base"),
    # a wind turbine's controls (WTDTA1, WTARA1, WTPTA1, WTTQA1) around its electrical controller
    "active_power_order": ("Pord", "pu", "active power order of an inverter's electrical controller, system base: "
                           "its state, a wind turbine pitch controller's input"),
    "generator_speed": ("wg", "pu", "generator speed of a wind turbine's drive train (1 = synchronous): its output, "
                        "the torque controller's input"),
    "turbine_speed": ("wt", "pu", "turbine (blade) speed of a wind turbine's drive train: its output, the pitch "
                      "controller's input"),
    "turbine_speed_reference": ("wref", "pu", "speed reference of a wind turbine's pitch controller: its drive "
                                "train's speed set point w0"),
    "pitch_angle": ("theta", "deg", "blade pitch angle: a wind turbine pitch controller's output, its aerodynamics' "
                    "input"),
    "generator_speed_reference": ("wr0", "pu", "speed reference of a wind turbine's single-mass drive train (WTDS): "
                                  "its torque controller's power-speed characteristic fPe"),
    "pll_angle": ("am", "rad", "voltage angle a phase-locked loop measures (network frame): the PLL's output, its "
                  "converter's input (the frame of its d/q voltages and currents)"),
}

TOOL_NAME = "opfmu"
# the attributes of <Norton>, in BusPort.norton's order
NORTON_ATTRIBUTES = ("currentReal", "currentImaginary", "g11", "g12", "g21", "g22")
FMI3_ANNOTATION_TYPE = "org.opfmu.ports"


class PortError(ValueError):
    """A port declaration that names an unknown signal or variable, or a malformed <Ports> element."""


@dataclass(frozen=True)
class BusPort:
    """The connection to a bus: `voltage` = (magnitude input [pu], angle input [rad]), `current` =
    (real part output [pu], imaginary part output [pu]) of the current injected into the bus, both
    phasors in the network frame. What an FMU adds to its component's port (empty in a component's
    declaration): `power` = (active, reactive) power outputs into the bus [pu, generator convention],
    `norton` = the outputs of its Norton equivalent for the step to come (I_N real and imaginary part
    [pu], then the admittance d(I_re, I_im)/d(V_re, V_im) row by row, g11 g12 g21 g22 [pu]: I = I_N +
    Y_N V), and `base_mva`, the system base [MVA] its per-unit powers, currents and admittances are on."""

    voltage: tuple = ("Vs", "theta_vs")
    current: tuple = ("I_re", "I_im")
    power: tuple = ()
    norton: tuple = ()
    base_mva: float | None = None


@dataclass(frozen=True)
class Link:
    """One control signal (a key of SIGNALS) bound to the component variable that carries it."""

    signal: str
    variable: str


@dataclass(frozen=True)
class Ports:
    """A component's bus port (None: not on a bus) and its control links in and out."""

    bus: BusPort | None = None
    inputs: tuple = ()
    outputs: tuple = ()

    def input(self, signal: str) -> str | None:
        """The variable taking `signal`, or None."""
        return next((link.variable for link in self.inputs if link.signal == signal), None)

    def output(self, signal: str) -> str | None:
        """The variable giving `signal`, or None."""
        return next((link.variable for link in self.outputs if link.signal == signal), None)

    def check(self, inputs, outputs, owner: str) -> None:
        """Raise PortError unless every port names a known signal and a variable of the right kind:
        `inputs` are the input names, `outputs` the names that may be read (states and outputs)."""
        def need(name, pool, what):
            if name not in pool:
                raise PortError(f"{owner}: port {what} names {name!r}, which is not one of {', '.join(pool)}")

        if self.bus is not None:
            if len(self.bus.voltage) != 2 or len(self.bus.current) != 2:
                raise PortError(f"{owner}: a bus port has two voltage inputs and two current outputs")
            if len(self.bus.power) not in (0, 2) or len(self.bus.norton) not in (0, 6):
                raise PortError(f"{owner}: a bus port has two power outputs and six Norton outputs, or none")
            for name in self.bus.voltage:
                need(name, inputs, "bus voltage")
            for name in self.bus.current + self.bus.power + self.bus.norton:
                need(name, outputs, "bus output")
        for links, pool, what in ((self.inputs, inputs, "input"), (self.outputs, outputs, "output")):
            signals = [link.signal for link in links]
            if len(set(signals)) != len(signals):
                raise PortError(f"{owner}: a signal appears twice among the {what} links")
            for link in links:
                if link.signal not in SIGNALS:
                    raise PortError(f"{owner}: unknown signal {link.signal!r} (known: {', '.join(SIGNALS)})")
                need(link.variable, pool, f"{what} {link.signal}")

    def element(self) -> ET.Element:
        """The <Ports> element of a model description."""
        root = ET.Element("Ports")
        if self.bus is not None:
            (vm, va), (ir, ii) = self.bus.voltage, self.bus.current
            bus = ET.SubElement(root, "Bus", voltageMagnitude=vm, voltageAngle=va, currentReal=ir, currentImaginary=ii)
            if self.bus.power:
                bus.set("activePower", self.bus.power[0])
                bus.set("reactivePower", self.bus.power[1])
            if self.bus.base_mva is not None:
                bus.set("systemBaseMVA", repr(float(self.bus.base_mva)))
            if self.bus.norton:
                ET.SubElement(bus, "Norton", dict(zip(NORTON_ATTRIBUTES, self.bus.norton)))
        for tag, links in (("Input", self.inputs), ("Output", self.outputs)):
            for link in links:
                ET.SubElement(root, tag, signal=link.signal, variable=link.variable)
        return root

    @classmethod
    def from_element(cls, root: ET.Element) -> "Ports":
        """Ports from a <Ports> element; PortError for a malformed one (unknown signal, missing attribute)."""
        bus, inputs, outputs = None, [], []
        try:
            for child in root:
                if child.tag == "Bus":
                    if bus is not None:
                        raise PortError("a <Ports> element has more than one <Bus>")
                    bus = _bus_port(child)
                elif child.tag in ("Input", "Output"):
                    link = Link(child.attrib["signal"], child.attrib["variable"])
                    if link.signal not in SIGNALS:
                        raise PortError(f"unknown signal {link.signal[:40]!r} in <Ports>")
                    (inputs if child.tag == "Input" else outputs).append(link)
        except KeyError as exc:
            raise PortError(f"a <{child.tag}> element of <Ports> has no attribute {exc.args[0]}") from None
        return cls(bus, tuple(inputs), tuple(outputs))


def _bus_port(element: ET.Element) -> BusPort:
    """The BusPort of a <Bus> element (KeyError for a missing attribute, PortError for a malformed one)."""
    a = element.attrib
    power = (a["activePower"], a["reactivePower"]) if "activePower" in a or "reactivePower" in a else ()
    base = None
    if "systemBaseMVA" in a:
        try:
            base = float(a["systemBaseMVA"])
        except ValueError:
            base = math.nan
        if not (math.isfinite(base) and base > 0.0):
            raise PortError(f"systemBaseMVA {a['systemBaseMVA'][:40]!r} of <Bus> is not a positive number")
    norton = element.find("Norton")
    return BusPort((a["voltageMagnitude"], a["voltageAngle"]), (a["currentReal"], a["currentImaginary"]), power,
                   () if norton is None else tuple(norton.attrib[k] for k in NORTON_ATTRIBUTES), base)


@dataclass(frozen=True)
class MachineInputs:
    """The inputs of a machine on a bus, by the names its ports give them: the bus voltage
    magnitude [pu] and angle [rad] (its bus port), the mechanical power and the field voltage [pu]
    (its `mechanical_power` and `field_voltage` input links)."""

    magnitude: str
    angle: str
    power: str
    field: str


def machine_inputs(component) -> MachineInputs:
    """The machine inputs of `component` from its ports; PortError where it does not declare them."""
    ports = component.ports
    power, field = ports.input("mechanical_power"), ports.input("field_voltage")
    if ports.bus is None or power is None or field is None:
        raise PortError(f"component {component.name!r} is no machine on a bus: it needs a bus port and the input "
                        "links mechanical_power and field_voltage")
    return MachineInputs(*ports.bus.voltage, power, field)


def ports_of_model_description(root: ET.Element) -> Ports | None:
    """The ports declared in a parsed model description (FMI 2.0 or 3.0), or None where it declares none."""
    found = root.find(f"VendorAnnotations/Tool[@name='{TOOL_NAME}']/Ports")
    if found is None:
        found = root.find(f"Annotations/Annotation[@type='{FMI3_ANNOTATION_TYPE}']/Ports")
    return None if found is None else Ports.from_element(found)


MAX_MODEL_DESCRIPTION_BYTES = 16 * 1024 * 1024


def ports_of_fmu(path) -> Ports | None:
    """The ports an FMU declares (an .fmu file or its extracted directory), or None where it declares
    none. PortError (one line) for an FMU without a readable modelDescription.xml or with a malformed
    <Ports> element."""
    path = Path(path)
    try:
        if path.is_dir():
            source = path / "modelDescription.xml"
            if source.stat().st_size > MAX_MODEL_DESCRIPTION_BYTES:
                raise PortError(f"{path}: modelDescription.xml is larger than {MAX_MODEL_DESCRIPTION_BYTES} bytes")
            text = source.read_bytes()
        else:
            with zipfile.ZipFile(path) as archive:
                if archive.getinfo("modelDescription.xml").file_size > MAX_MODEL_DESCRIPTION_BYTES:
                    raise PortError(f"{path}: modelDescription.xml is larger than {MAX_MODEL_DESCRIPTION_BYTES} bytes")
                text = archive.read("modelDescription.xml")
        root = ET.fromstring(text)
    except PortError:
        raise
    except KeyError:
        raise PortError(f"{path} has no modelDescription.xml") from None
    except (OSError, zipfile.BadZipFile, ET.ParseError) as exc:
        reason = explain(exc)
        raise PortError(f"cannot read the model description of {path}: {reason}") from None
    return ports_of_model_description(root)
