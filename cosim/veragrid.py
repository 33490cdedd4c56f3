"""VeraGrid as a host of opfmu's FMUs: a case (reference_models.grid.case.Case) run in VeraGrid's RMS
simulation (VeraGridEngine, MPL-2.0, optional like ANDES: `veragrid_available()`), each unit's bus
device an FMU that VeraGrid's own FMI importer runs (`attach_opfmu_device`), through the Norton port
the FMU declares.

How VeraGrid couples a co-simulation FMU (measured on VeraGridEngine 6.7.1): explicitly. Over each
step [t, t + h] the FMU steps with the bus voltage of t held (VeraGrid binds only the bus voltage
magnitude `Vm` and angle `Va` to FMU inputs), then VeraGrid solves its network at t + h with the
FMU's outputs frozen (each becomes a parameter of the device's block). Bound to P and Q, the FMU's
power answers the voltage of t, not the one VeraGrid solves for: a deep fault diverges. Bound
to its Norton port (reference_models.ports.BusPort.norton: I = I_N + Y_N V, for the step to come,
system base, network frame), the device's block gets two more equations,

    P + jQ = V conj(I_N + Y_N V),   V = Vm exp(j Va),

so that VeraGrid solves the network at t + h with the machine's admittance in it and its internal
source at the state of t + h: what a machine's stator does (its current is affine in V at a given
state), with no iteration and no derivatives. The six Norton outputs ride on VeraGrid references
the injection balance does not read (`NORTON_CARRIERS`).

A unit's control devices (exciter, governor, stabiliser) are FMUs too. VeraGrid's importer takes
only Vm and Va as inputs, so it cannot link one FMU to another: the adapter steps them itself,
around VeraGrid's step of the machine (`_UnitAdapter`, in VeraGrid's list of co-simulation
adapters): each control device in the unit's step order (reference_models.grid.case.step_order)
with its inputs at t (the bus voltage VeraGrid accepted at t, the terminal voltage behind the
machine's external impedance, the machine's outputs at t), a control stepped before it giving its
new output; then the machine's link inputs (field voltage, mechanical power) are set and VeraGrid
steps the machine. A control input nothing gives is held at its start value.

Held inputs, as VeraGrid's importer has them, are first order in h: on Kundur the machines drift 66
deg from opfmu's own master in 5 s. The adapter therefore gives every FMU its inputs as lines over
the step (the FMUs take first input derivatives: canInterpolateInputs; on the machine through the
FMI instance VeraGrid's importer opened): a control's new output is reached at the step's end, and
the bus and terminal voltage and the machine's outputs run to the end value predicted through their
values at the last three step starts (EXTRAPOLATION_POINTS), fewer after an event. And VeraGrid is
told each event one step early (`VeraGridRunner._event_time`): its backward Euler applies an event
to the network at the end of the step it falls in, while the FMUs step explicitly from the voltage
at the step's start. The first step after an event has nothing to predict from: the unit takes it
with its inputs held, and again at the next step's start, from its saved FMU states, with each input
on the line to the end value VeraGrid has by then accepted (`_UnitAdapter._redo`). Kundur then keeps
within 0.16 deg of the own master, 0.062 deg between the machines (benchmarks/veragrid_host.py;
held over that step, the four drifted 0.71 deg together).

Initialisation: VeraGrid's power flow of the grid built from the case (branches as pi sections
with their taps and phase shifts, loads as constant impedances at the case's load-flow voltages,
shunts, generators as PV buses and the slack) gives each unit's V, angle, P and Q; opfmu's
initialisation (case.unit_start) gives every device's start, set as the FMU's `<state>0`
parameters and its inputs. VeraGrid's slack bus has angle 0; results are turned back into the case's
frame (its slack angle).

Events (reference_models.grid.contingency): a fault is a shunt of admittance 1/z switched at the
fault bus, a branch opens or closes through its status, a load switches off and on; VeraGrid
applies them as events of its RMS simulation. A unit trip and a device that measures the network
beyond its bus or takes a signal from another unit are refused (CouplingError).
"""
from __future__ import annotations

import cmath
import importlib.util
import math
import time
from dataclasses import dataclass

import numpy as np

from reference_models.grid.case import external_impedance, step_order, unit_start, unit_wiring
from reference_models.grid.result import GridResult, device_labels
from reference_models.ports import ports_of_fmu

from .fmu import FMU, CouplingError

VERAGRID_VERSION = "6.7.1"
VERAGRID_MISSING = f"--host veragrid needs VeraGridEngine: pip install VeraGridEngine=={VERAGRID_VERSION}"
INTERFACES = ("norton", "power")
#: Why the grid built here gives every device's power into its bus divided by the bus voltage
#: magnitude (P / Vm, Q / Vm: the current in the frame of the bus voltage): VeraGrid's RMS problem
#: balances the powers at each bus, and a bus whose every device is linear in its current (a Norton
#: device, a branch, a shunt) then has a spurious root at Vm = 0 with the whole balance quadratic in
#: Vm. Newton started from a deep fault's voltage (below half the voltage after clearing) goes to it
#: (measured: SMIB, B = -10 pu, Vm 0.44 -> 0 at clearing). Divided by Vm the balance is the bus's
#: current balance (for Vm > 0 the same solution) and is linear in V for those devices: no spurious
#: root, one Newton step. A device of VeraGrid's own that gives P and Q cannot share a bus with them.
CURRENT_FORM = "P / Vm, Q / Vm"
POWER_FLOW_TOLERANCE = 1e-10  # pu: VeraGrid's power-flow mismatch
#: the values an input's end of step is predicted through (_UnitAdapter._inputs): 3, a quadratic. On
#: Kundur (fault at bus 8, 5 s, h = 10 ms) against opfmu's own iterated master: held (VeraGrid's own
#: coupling) 66 deg; 2 points 1.5 deg; 3 points 0.71 deg (0.063 deg between machines); 4 points 0.89 deg
EXTRAPOLATION_POINTS = 3


def veragrid_available() -> bool:
    """Whether VeraGridEngine can be imported here."""
    return importlib.util.find_spec("VeraGridEngine") is not None


def _vg():
    """(api, Devices, VarPowerFlowReferenceType, symbolic module, Block): what the adapter uses."""
    import VeraGridEngine.api as api
    import VeraGridEngine.Devices as devices
    import VeraGridEngine.Utils.Symbolic.symbolic as sym
    from VeraGridEngine.enumerations import VarPowerFlowReferenceType
    from VeraGridEngine.Utils.Symbolic.block import Block

    return api, devices, VarPowerFlowReferenceType, sym, Block


def norton_carriers():
    """The VeraGrid references the six Norton outputs ride on (I_N real, imaginary, then Y_N row by
    row): flows and currents of branch ends, which the injection balance of a bus does not read and
    VeraGrid does not seed from its power flow (it seeds an injection's Ir, Ii with the load-flow
    current, which would overwrite I_N before the first step)."""
    R = _vg()[2]
    return (R.Pf, R.Qf, R.Irf, R.Iif, R.Irt, R.Iit)


# ---------------------------------------------------------------------------------------------
# the network


def _current_form(i_re, i_im, angle):
    """(P / Vm, Q / Vm) of the current i_re + j i_im [pu] into a bus of voltage angle `angle` (symbolic):
    S / |V| = exp(j angle) conj(I)."""
    sym = _vg()[3]
    c, s = sym.cos(angle), sym.sin(angle)
    return c * i_re + s * i_im, s * i_re - c * i_im


def _admittance_block(vf, name: str, y: complex, bus):
    """(block, g, b): a shunt of admittance y = g + jb [pu] at the VeraGrid bus `bus`, its power into
    the bus in the current form (P / Vm = -g Vm, Q / Vm = b Vm: CURRENT_FORM), g and b event parameters (a fault, a load switched off). Its equations
    take the bus's own voltage variables: VeraGrid 6.7.1 links a block's input variables to the bus
    by name only, so the Jacobian has no column for them."""
    _, _, R, _, Block = _vg()
    vm = bus.rms_model.E(R.Vm)
    p, q = vf.add_var(f"P_{name}", reference=R.P), vf.add_var(f"Q_{name}", reference=R.Q)
    g, b = vf.add_var(f"g_{name}"), vf.add_var(f"b_{name}")
    block = Block(algebraic_eqs=[p + g * vm, q - b * vm], algebraic_vars=[p, q],
                  event_dict={g: vf.add_const(float(y.real)), b: vf.add_const(float(y.imag))},
                  external_mapping={R.P: p, R.Q: q}, name=name)
    return block, g, b


def _branch_block(vf, name: str, br, bus_from, bus_to):
    """(block, u): a pi branch (case.Branch: series r + jx, total shunt b, an ideal transformer
    tap e^{j phi} : 1 at the from side) between the VeraGrid buses `bus_from` and `bus_to` as the
    power flowing into it at each end (in the current form, CURRENT_FORM), times its status u. Its equations take the buses' own voltage
    variables (as VeraGrid's legacy transformer does: its branch inputs Vmf ... are not linked to
    the buses in 6.7.1)."""
    _, _, R, sym, Block = _vg()
    vmf, vaf = bus_from.rms_model.E(R.Vm), bus_from.rms_model.E(R.Va)
    vmt, vat = bus_to.rms_model.E(R.Vm), bus_to.rms_model.E(R.Va)
    pf, qf = vf.add_var(f"Pf_{name}", reference=R.Pf), vf.add_var(f"Qf_{name}", reference=R.Qf)
    pt, qt = vf.add_var(f"Pt_{name}", reference=R.Pt), vf.add_var(f"Qt_{name}", reference=R.Qt)
    u = vf.add_var(f"u_{name}")
    y = 1.0 / complex(br.r, br.x)
    m = br.tap * cmath.exp(1j * br.phi)
    Yff, Ytt = (y + 0.5j * br.b) / br.tap ** 2, y + 0.5j * br.b
    Yft, Ytf = -y / m.conjugate(), -y / m
    vrf, vif = vmf * sym.cos(vaf), vmf * sym.sin(vaf)
    vrt, vit = vmt * sym.cos(vat), vmt * sym.sin(vat)

    def flow(Ya, Yb, vra, via, vrb, vib, angle):  # S / |Va|, S = Va conj(Ya Va + Yb Vb) into the branch at end a
        ir = Ya.real * vra - Ya.imag * via + Yb.real * vrb - Yb.imag * vib
        ii = Ya.imag * vra + Ya.real * via + Yb.imag * vrb + Yb.real * vib
        return _current_form(ir, ii, angle)

    (pf_e, qf_e) = flow(Yff, Yft, vrf, vif, vrt, vit, vaf)
    (pt_e, qt_e) = flow(Ytt, Ytf, vrt, vit, vrf, vif, vat)
    block = Block(algebraic_eqs=[pf - u * pf_e, qf - u * qf_e, pt - u * pt_e, qt - u * qt_e],
                  algebraic_vars=[pf, qf, pt, qt], event_dict={u: vf.add_const(1.0)},
                  external_mapping={R.Pf: pf, R.Qf: qf, R.Pt: pt, R.Qt: qt}, name=name)
    return block, u


@dataclass
class VeraGridNetwork:
    """The VeraGrid grid of a case: `grid` (MultiCircuit), `buses` {bus number: Bus}, `generators` [one
    Generator per unit, unit order], `branches` {branch name: its Line, or its Transformer2W where it
    has a tap or a phase shift}, and the event parameters: `status` {branch: its u}, `loads`
    {bus: (shunt, g, b, y)}, `faults` {bus: (shunt, g, b)}."""

    grid: object
    buses: dict
    generators: list
    branches: dict
    status: dict
    loads: dict
    faults: dict


def build_network(case, fault_buses=()) -> VeraGridNetwork:
    """The VeraGrid grid of `case`'s network: its buses; its branches (case.Branch, taps and phase
    shifts as the case has them); its loads as constant admittances conj(S)/V^2 at the load-flow
    voltages and its shunts (a VeraGrid Shunt each, for the power flow and the RMS simulation); a
    Generator per unit (a PV bus at the case's generator voltage and power, or the slack); a fault
    shunt (admittance 0 until an event) at each of `fault_buses`. CouplingError for a unit that is a
    load (not a generator)."""
    api, dev, R, _, _ = _vg()
    from VeraGridEngine.Devices.multi_circuit import MultiCircuit
    from VeraGridEngine.Utils.Symbolic.bus_rms_template import initialize_bus_rms

    net, flow = case.network, case.flow
    base = net.base_mva
    grid = MultiCircuit(Sbase=base, fbase=net.f_hz)
    vf = grid.var_factory
    buses = {}
    for b in net.buses:
        # one nominal voltage for all: VeraGrid makes a Line between buses of different nominal voltages a
        # Transformer2W of its own (without the branch block below); the case is in pu throughout
        bus = dev.Bus(name=f"bus {b}", Vnom=1.0)
        grid.add_bus(bus)
        initialize_bus_rms(bus, vf)
        buses[b] = bus
    status, branches = {}, {}
    for br in net.branches:
        ends = dict(bus_from=buses[br.from_bus], bus_to=buses[br.to_bus], name=br.name, r=br.r, x=br.x, b=br.b)
        if br.tap != 1.0 or br.phi != 0.0:  # VeraGrid's Line has no tap: its power flow would miss it
            device = dev.Transformer2W(**ends, tap_module=br.tap, tap_phase=br.phi)
            grid.add_transformer2w(device)
        else:
            device = dev.Line(**ends)
            grid.add_line(device)
        device.rms_model, status[br.name] = _branch_block(vf, f"branch_{br.name}", br, buses[br.from_bus],
                                                           buses[br.to_bus])
        branches[br.name] = device

    def shunt(bus: int, name: str, y: complex):
        device = dev.Shunt(name=name, G=float(y.real) * base, B=float(y.imag) * base)
        grid.add_shunt(buses[bus], device)
        device.rms_model, g, b = _admittance_block(vf, name.replace(" ", "_"), y, buses[bus])
        return device, g, b

    loads = {}
    for bus, s in net.loads.items():
        y = complex(s).conjugate() / float(flow.V[net.bus_index(bus)]) ** 2
        loads[bus] = (*shunt(bus, f"load {bus}", y), y)
    for bus, y in net.shunts.items():
        shunt(bus, f"shunt {bus}", complex(y))
    faults = {bus: shunt(bus, f"fault {bus}", 0j) for bus in dict.fromkeys(fault_buses)}
    data = {g.bus if g.name is None else (g.bus, g.name): g for g in net.generators}
    generators = []
    for unit in case.units:
        if unit.load is not None:  # a unit that draws (a sub-system's equivalent, a dynamic load): its
            # injection -load at the load flow's voltage, which VeraGrid's power flow then holds
            gen = dev.Generator(name=f"unit {unit.bus} {len(generators)}", P=-float(unit.load.real) * base,
                                vset=float(flow.V[net.bus_index(unit.bus)]))
            grid.add_generator(buses[unit.bus], gen)
            generators.append(gen)
            continue
        g = data.get((unit.bus, unit.generator), data.get(unit.bus))
        gen = dev.Generator(name=f"gen {unit.bus}" + (f" {unit.generator}" if unit.generator else ""),
                            P=float(g.P or 0.0) * base, vset=float(g.V))
        grid.add_generator(buses[unit.bus], gen)
        if g.kind == "slack":
            buses[unit.bus].is_slack = True
        generators.append(gen)
    return VeraGridNetwork(grid, buses, generators, branches, status, loads, faults)


def power_flow(network: VeraGridNetwork):
    """VeraGrid's Newton power flow of the grid (PowerFlowResults); CouplingError where it does not converge."""
    api = _vg()[0]
    options = api.PowerFlowOptions(tolerance=POWER_FLOW_TOLERANCE)
    driver = api.PowerFlowDriver(network.grid, options)
    driver.run()
    if not bool(np.all(driver.results.converged)):
        raise CouplingError("VeraGrid's power flow of the case does not converge")
    return driver.results


# ---------------------------------------------------------------------------------------------
# an FMU on a VeraGrid device


def attach_opfmu_device(grid, device, fmu_path, start: dict | None = None, name: str | None = None,
                        interface: str = "norton", inputs: dict | None = None, current_form: bool = False):
    """Attach the opfmu FMU `fmu_path` (a bus device: a machine, an inverter's converter) to the VeraGrid
    injection device `device` of `grid` (MultiCircuit) for its RMS simulation, through VeraGrid's FMU
    importer (co-simulation). The FMU's bus port (its model description's <Ports>) names the
    variables: the bus voltage inputs take VeraGrid's Vm [pu] and Va [rad]; `interface` "norton"
    binds its Norton outputs and adds P + jQ = V conj(I_N + Y_N V) to the device's block (VeraGrid
    solves the network with the device's admittance in it: deep faults run), "power" binds its P and Q
    at the bus (what VeraGrid's importer does by itself: P and Q of the voltage of the step before).
    `start`: the FMU's parameter start values by name (its initial states `<state>0`); `inputs`:
    its input values at the start by name (the bus voltage of the load flow among them): the FMU's
    outputs there are the block's values before VeraGrid's first step (VeraGrid projects its network
    onto them before it initialises the FMU; with none, no machine holds the network's angle and its
    Jacobian is singular). VeraGrid sets only the bound inputs: the unit sets the others
    (`_UnitAdapter`). `current_form`: the block's P and Q are P / Vm and Q / Vm (CURRENT_FORM; only in
    a grid whose every device gives its power so). Returns the device's block. CouplingError for
    an FMU without a bus port, its powers on a base other than the grid's, or without the interface."""
    _, _, R, sym, _ = _vg()
    from VeraGridEngine.IO.fmu.importer.bindings import FmuFloat64ParameterValue, FmuRefBinding
    from VeraGridEngine.IO.fmu.importer.model_description import FmuInterfaceMode
    from VeraGridEngine.IO.fmu.importer.user_api import (FmuDeviceAttachmentRequest, FmuDeviceDomain,
                                                        FmuReferenceValue, attach_fmu_to_device)

    if interface not in INTERFACES:
        raise ValueError(f"interface must be one of {', '.join(INTERFACES)}, got {interface!r}")
    ports = ports_of_fmu(fmu_path)
    port = ports.bus if ports is not None else None
    if port is None:
        raise CouplingError(f"{fmu_path}: the FMU declares no bus port")
    if port.base_mva is not None and not math.isclose(port.base_mva, grid.Sbase, rel_tol=1e-12):
        raise CouplingError(f"{fmu_path}: its bus port is on {port.base_mva:g} MVA, the grid on {grid.Sbase:g} MVA")
    wanted = port.norton if interface == "norton" else port.power
    if not wanted:
        raise CouplingError(f"{fmu_path}: its bus port declares no {'Norton equivalent' if interface == 'norton' else 'P, Q'}")
    carriers = norton_carriers() if interface == "norton" else (R.P, R.Q)
    defaults = _outputs_at_start(fmu_path, {**(start or {}), **(inputs or {})}, wanted)
    request = FmuDeviceAttachmentRequest(
        fmu_path, FmuDeviceDomain.RMS, FmuInterfaceMode.CO_SIMULATION,
        input_bindings=(FmuRefBinding(R.Vm, port.voltage[0]), FmuRefBinding(R.Va, port.voltage[1])),
        output_bindings=tuple(FmuRefBinding(r, n) for r, n in zip(carriers, wanted)), name=name,
        output_defaults=tuple(FmuReferenceValue(r, v) for r, v in zip(carriers, defaults)),
        parameter_values=tuple(FmuFloat64ParameterValue(n, float(v)) for n, v in (start or {}).items()))
    block = attach_fmu_to_device(device, grid, request)
    if interface == "power":
        return block
    vf = grid.var_factory
    label = name or device.name.replace(" ", "_")
    i_re, i_im, g11, g12, g21, g22 = (block.external_mapping[r] for r in carriers)
    # the bus's own voltage variables (VeraGrid links a block's inputs to its bus by name only: no
    # Jacobian column, and a network of Norton devices with no angle reference)
    vm, va = device.bus.rms_model.E(R.Vm), device.bus.rms_model.E(R.Va)
    p, q = vf.add_var(f"P_{label}", reference=R.P), vf.add_var(f"Q_{label}", reference=R.Q)
    v_re, v_im = vm * sym.cos(va), vm * sym.sin(va)
    current_re, current_im = i_re + g11 * v_re + g12 * v_im, i_im + g21 * v_re + g22 * v_im
    block.algebraic_vars = list(block.algebraic_vars) + [p, q]
    if current_form:
        p_e, q_e = _current_form(current_re, current_im, va)
    else:
        p_e, q_e = v_re * current_re + v_im * current_im, v_im * current_re - v_re * current_im
    block.algebraic_eqs = list(block.algebraic_eqs) + [p_e - p, q_e - q]
    block.external_mapping.update({R.P: p, R.Q: q})
    return block


def _device_parameters(fmu_path, params) -> dict:
    """{name: value} of the device's parameters `params` that the FMU declares (FMU.parameter_values)."""
    with FMU(fmu_path, "parameters", init=False) as fmu:
        return fmu.parameter_values(params)


def _outputs_at_start(fmu_path, start: dict, names) -> list:
    """The FMU's outputs `names` after its initialisation with the start values `start` (by name)."""
    with FMU(fmu_path, "start values", init=False) as fmu:
        fmu.initialise(start)
        return [float(v) for v in fmu.get(*names)]


# ---------------------------------------------------------------------------------------------
# a unit: the machine VeraGrid steps, its controls stepped around it


class _UnitAdapter:
    """One unit in VeraGrid's RMS problem, in the place of VeraGrid's adapter of its machine FMU
    (`inner`, a VeraGridEngine FmuCsDeviceAdapter, which it delegates the machine to): it sets the
    machine's inputs VeraGrid does not bind (held or from the unit's controls), steps the control
    FMUs (`controls`: cosim.fmu.FMU, device order after the machine) and records each device's states
    at every step's end (`rows`: (time, {device index: states}, machine link inputs))."""

    def __init__(self, inner, unit, start, controls, order, events=(), step: float = 0.01):
        self.inner, self.unit, self.start, self.controls = inner, unit, start, controls
        self.device, self.problem = inner.device, inner.problem
        ports = [d.component.ports for d in unit.devices]
        self.wiring = unit_wiring(ports, f"generator at bus {unit.bus}")
        for j, wires in enumerate(self.wiring):
            for name, source in wires.items():
                if source.kind == "measured" or source.unit is not None:
                    raise CouplingError(f"generator at bus {unit.bus}: {unit.devices[j].name} takes {name} from "
                                        "beyond its unit, which the VeraGrid host does not wire")
        self.order = order
        machine = unit.machine.component
        self.bus_port = machine.ports.bus
        self.z_ext = external_impedance(unit.machine)
        # the machine's inputs the unit sets (not the bus voltage VeraGrid binds)
        self.machine_inputs = [n for n in machine.input_names if n not in self.bus_port.voltage]
        needed = {s.variable for wires in self.wiring for s in wires.values() if s.kind == "device" and s.device == 0}
        self.machine_reads = list(dict.fromkeys([*machine.state_names, *self.bus_port.current, *needed]))
        self.values = [dict() for _ in unit.devices]  # {variable: value} of each device now
        self.rows = []
        self.events, self.step = tuple(float(e) for e in events), float(step)
        self.history = []  # [(time, {(device, input): value at that step's start})] of the last steps, latest first
        self.interpolates, self.input_refs = False, []  # the machine FMU's, once VeraGrid opened it
        self.redo = None  # the first step after an event, to be taken again once its end is known (_redo)

    # VeraGrid's adapter interface (FmuCsDeviceAdapter: what its RMS problem calls)

    def initialize_outputs(self, time_value, x_snapshot):
        outputs = self.inner.initialize_outputs(time_value, x_snapshot)
        host = self.inner.runtime_host
        if not self.rows:
            self.interpolates = bool(getattr(host.model_description.coSimulation, "canInterpolateInputs", False))
            self.input_refs = host._get_value_references([*self.bus_port.voltage, *self.machine_inputs])
            host.set_real({n: float(self.start[0].inputs[n]) for n in self.machine_inputs})
            self._read_machine()
            for j, fmu in enumerate(self.controls, start=1):
                self.values[j] = dict(zip(fmu.output_names, fmu.outputs()))
            self._record(time_value)
        return outputs

    def advance(self, current_time, step_size, x_snapshot):
        from VeraGridEngine.IO.fmu.importer.co_simulation import _get_rms_input_value

        R = _vg()[2]
        V = (_get_rms_input_value(self.problem, self.device, R.Vm, x_snapshot),
             _get_rms_input_value(self.problem, self.device, R.Va, x_snapshot))
        if self.redo is not None:
            self._redo(V)
        terminal = self._terminal(V)
        before = [dict(v) for v in self.values]  # every device's outputs at the step's start
        saved = self._save() if self._after_event(current_time, step_size) else None
        now = {}
        inputs, rates = self._step_controls(current_time, step_size, V, terminal, before, now)
        host = self.inner.runtime_host
        set_now = dict(zip(self.machine_inputs, inputs[2:]))
        host.set_real(set_now)
        if self.interpolates:
            host.runtime.setRealInputDerivatives(self.input_refs, [1] * len(rates), rates)
        outputs = self.inner.advance(current_time, step_size, x_snapshot)
        self._read_machine()
        self._record(current_time + step_size, set_now)
        self.history = [(current_time, now)] + self.history[:EXTRAPOLATION_POINTS - 2]
        if saved is not None:
            self.redo = (current_time, step_size, saved, V, now, before)
        return outputs

    def apply_outputs(self, target, outputs):
        self.inner.apply_outputs(target, outputs)

    def close(self):
        self.inner.close()

    # the unit

    def _terminal(self, V) -> tuple:
        """(magnitude, angle) of the machine's terminal voltage: the bus voltage V (magnitude, angle)
        plus the drop over its external impedance at its current now."""
        current = complex(*(self.values[0][n] for n in self.bus_port.current))
        Vt = V[0] * cmath.exp(1j * V[1]) + self.z_ext * current
        return abs(Vt), cmath.phase(Vt)

    def _step_controls(self, t: float, h: float, V, terminal, before, now: dict, ends: dict | None = None) -> tuple:
        """Steps the control FMUs over [t, t + h] in step order; (values, rates) of the machine's
        inputs (its bus voltage, then machine_inputs) for the same step (_inputs)."""
        stepped = set()
        for j in self.order[:-1]:  # the controls, then the machine
            fmu = self.controls[j - 1]
            inputs, rates = self._inputs(j, fmu.input_names, V, terminal, before, stepped, now, t, h, ends)
            self.values[j] = dict(zip(fmu.output_names, fmu.advance(t, h, inputs, rates if fmu.interpolates else None)))
            stepped.add(j)
        return self._inputs(0, tuple(self.bus_port.voltage) + tuple(self.machine_inputs), V, terminal, before,
                            stepped, now, t, h, ends)

    def _after_event(self, t: float, h: float) -> bool:
        """Whether the step from t is the first after an event (its inputs held: no history runs up to it)."""
        return any(t - h - 1e-9 * max(1.0, t) <= e < t - 1e-9 * max(1.0, t) for e in self.events)

    def _save(self) -> list:
        """The FMU states of the unit's devices (machine first)."""
        return [self.inner.runtime_host.runtime.getFMUstate()] + [fmu.save() for fmu in self.controls]

    def _redo(self, V_end) -> None:
        """Steps the unit again over the first step after an event, [t, t + h], from its saved states,
        with each input on the line from its value at t to its value at t + h (known now: the bus
        voltage `V_end` VeraGrid accepted at t + h, the terminal voltage and the outputs after the held
        step) instead of held, which lost energy at the event (Kundur: 0.7 deg over 4 s). VeraGrid's
        network at t + h keeps the Norton outputs of the held step; the states go on from the redone
        one."""
        t, h, saved, V, now_before, before = self.redo
        self.redo = None
        runtime = self.inner.runtime_host.runtime
        terminal_end = self._terminal(V_end)
        ends = {(j, name): self._source(j, name, V_end, terminal_end) for j, name in now_before}
        runtime.setFMUstate(saved[0])
        runtime.freeFMUstate(saved[0])
        for fmu, state in zip(self.controls, saved[1:]):
            fmu.restore(state)
            fmu.free(state)
        self.values = [dict(v) for v in before]
        inputs, rates = self._step_controls(t, h, V, self._terminal(V), before, dict(now_before), ends)
        host = self.inner.runtime_host
        host.set_real(dict(zip([*self.bus_port.voltage, *self.machine_inputs], inputs)))
        if self.interpolates:
            runtime.setRealInputDerivatives(self.input_refs, [1] * len(rates), rates)
        host.do_step(current_time=t, step_size=h)
        self._read_machine()
        self.rows.pop()
        self._record(t + h, dict(zip(self.machine_inputs, inputs[2:])))

    def _inputs(self, j: int, names, V, terminal, before, stepped, now: dict, t: float, h: float,
                ends: dict | None = None) -> tuple:
        """(values at the step's start t, rates over [t, t + h]) of device j's inputs `names`. An input
        from a device stepped before it in this step runs linearly from that device's output at the
        step's start to its new one. Any other (the bus and terminal voltage, the machine's outputs)
        runs linearly to the end of the step predicted through its values at the last steps' starts
        (EXTRAPOLATION_POINTS - 1 of them, fewer after an event or at the start; held with none):
        VeraGrid's coupling would hold it, first order in h. `ends` {(device, input): value at t + h}:
        the step taken again (_redo), each such input on the line to its known end. Records each
        value in `now` for the next steps."""
        values, rates = [], []
        # the last steps over which the inputs ran smoothly: each at t - k h, no event from it to t.
        # VeraGrid applies an event it is told at e to the network at e + h (VeraGridRunner._event_time):
        # the voltage of e is the one before it, of e + h the one after
        history = []
        for k, (time_k, values_k) in enumerate(self.history, start=1):
            if abs(time_k + k * h - t) > 1e-9 * max(1.0, t) or any(time_k - 1e-9 <= e < t - 1e-9 for e in self.events):
                break
            history.append(values_k)
        for name in names:
            source = self.wiring[j].get(name)
            if source is not None and source.kind == "device" and source.device in stepped:
                start = float(before[source.device][source.variable])
                values.append(start)
                rates.append((float(self.values[source.device][source.variable]) - start) / h)
                continue
            value = self._source(j, name, V, terminal)
            now[(j, name)] = value
            values.append(value)
            held = source is None or source.kind == "held"
            angle = source is not None and source.kind in ("bus", "terminal") and source.index == 1
            if ends is not None:  # the step again, its end known
                change = 0.0 if held else ends[(j, name)] - value
                rates.append((math.remainder(change, 2.0 * math.pi) if angle else change) / h)
                continue
            points = [value] + ([] if held else [v[(j, name)] for v in history if (j, name) in v])
            steps = [a - b for a, b in zip(points, points[1:])]  # the changes over the last steps, latest first
            if angle:
                steps = [math.remainder(d, 2.0 * math.pi) for d in steps]  # an angle: the short way round
            rates.append(_predicted_change(steps) / h)
        return values, rates

    def _source(self, j: int, name: str, V, terminal) -> float:
        """Device j's input `name` now: the bus voltage at the step's start, the terminal voltage, a
        device's output (a control stepped before: its new one), or its start value (held)."""
        source = self.wiring[j].get(name)
        if source is None or source.kind == "held":
            return float(self.start[j].inputs[name])
        if source.kind == "bus":
            return float(V[source.index])
        if source.kind == "terminal":
            return float(terminal[source.index])
        return float(self.values[source.device][source.variable])

    def _read_machine(self) -> None:
        self.values[0] = self.inner.runtime_host.get_real(self.machine_reads)

    def _record(self, t: float, machine_inputs: dict | None = None) -> None:
        states = [[self.values[j][n] for n in d.component.state_names] for j, d in enumerate(self.unit.devices)]
        inputs = machine_inputs or {n: float(self.start[0].inputs[n]) for n in self.machine_inputs}
        self.rows.append((t, states, dict(inputs)))


def _predicted_change(steps) -> float:
    """The change over the next step of a value whose changes over the last steps were `steps`
    (latest first): through the last len(steps) + 1 values (at most EXTRAPOLATION_POINTS), a
    polynomial of degree len(steps) extrapolated one step; 0 with none."""
    steps = list(steps)[:EXTRAPOLATION_POINTS - 1]
    if len(steps) == 0:
        return 0.0
    if len(steps) == 1:
        return steps[0]  # linear
    return 2.0 * steps[0] - steps[1]  # quadratic: v(t + h) = 3 v(t) - 3 v(t - h) + v(t - 2 h)


def _control_fmu(path, device, start, name: str) -> FMU:
    """A control device's FMU (cosim.fmu.FMU) initialised at its start (states `<state>0`, inputs),
    bound to all its inputs and its states and outputs."""
    fmu = FMU(path, name, init=False)
    try:
        values = fmu.parameter_values(device.params)  # one FMU per model: the device's own parameters
        values.update({f"{n}0": v for n, v in zip(device.component.state_names, start.states)})
        values.update({n: v for n, v in start.inputs.items() if n in fmu.vr})
        fmu.initialise(values)
        outputs = list(dict.fromkeys([*device.component.state_names, *device.component.output_names]))
        fmu.bind(list(device.component.input_names), [n for n in outputs if n in fmu.vr])
    except BaseException:
        fmu.close()
        raise
    return fmu


# ---------------------------------------------------------------------------------------------
# a run


class VeraGridRunner:
    """A grid runner (cosim.runners) that runs a case in VeraGrid's RMS simulation at the fixed step
    `step` [s]: the FMUs `files` (cosim.fmus.UnitFiles per unit, as generator_files gives them; the
    first of each unit a bus device with a bus port), `interface` "norton" or "power"
    (attach_opfmu_device). CouplingError (ValueError) where VeraGridEngine is missing."""

    def __init__(self, case, files, step: float = 0.01, interface: str = "norton", tolerance: float = 1e-8):
        if not veragrid_available():
            raise ValueError(VERAGRID_MISSING)
        if interface not in INTERFACES:
            raise ValueError(f"interface must be one of {', '.join(INTERFACES)}, got {interface!r}")
        self.case, self.files, self.step, self.interface, self.tolerance = case, files, step, interface, tolerance

    def run(self, contingency, stop: float, stop_at_loss: bool = False):
        """(GridResult, timing dict) of the case through `contingency` until `stop` [s]: rows at the
        multiples of the step (and at events off them), angles in the case's frame. RuntimeError
        where VeraGrid's Newton iteration does not converge (the time it stopped at named)."""
        started = time.perf_counter()
        topologies = contingency.topologies(stop)
        if any(tp.tripped for tp in topologies):
            raise CouplingError("the VeraGrid host does not trip units")
        faulted = [tp.fault_bus for tp in topologies if tp.fault_bus is not None]
        network = build_network(self.case, faulted)
        flow = power_flow(network)
        offset = self._frame_offset(flow)
        starts = self._starts(network, flow)
        adapters, controls = [], []
        try:
            for k, (unit, start, files, gen) in enumerate(zip(self.case.units, starts, self.files, network.generators)):
                machine_start = _device_parameters(files.paths[0], unit.machine.params)  # one FMU per model
                machine_start.update({f"{n}0": v for n, v in zip(unit.machine.component.state_names, start[0].states)})
                attach_opfmu_device(network.grid, gen, files.paths[0], machine_start, f"unit_{k}", self.interface,
                                    start[0].inputs, current_form=True)
                unit_controls = [_control_fmu(path, device, s, f"{device.name} at bus {unit.bus}")
                                 for device, s, path in zip(unit.controls, start[1:], files.paths[1:])]
                controls.extend(unit_controls)
                adapters.append((unit, start, unit_controls))
            self._events(network, topologies)
            problem, solver = self._solver(network, flow, stop)
            by_device = {a.device.idtag: a for a in problem._fmu_cs_adapters}
            units = []
            for gen, (unit, start, unit_controls) in zip(network.generators, adapters):
                wiring = unit_wiring([d.component.ports for d in unit.devices], f"generator at bus {unit.bus}")
                units.append(_UnitAdapter(by_device[gen.idtag], unit, start, unit_controls, step_order(wiring),
                                          [self._event_time(tp.start) for tp in topologies[1:]], self.step))
            problem._fmu_cs_adapters = units
            t, y, well_initialised, converged = solver.simulate()
        finally:
            for fmu in controls:
                fmu.close()
        if not well_initialised:
            raise RuntimeError(f"VeraGrid's RMS simulation of {self.case.name} does not start at rest")
        if not converged:
            raise RuntimeError(f"VeraGrid's Newton iteration in its RMS simulation of {self.case.name} did not "
                               f"converge after t = {units[0].rows[-1][0] - self.step:.4f} s")
        result = self._result(network, problem, units, t, y, offset, topologies, stop_at_loss)
        return result, {"total_s": time.perf_counter() - started, "steps": len(t) - 1}

    def close(self):
        pass

    def _frame_offset(self, flow) -> float:
        """The case's slack angle minus VeraGrid's [rad]: what turns VeraGrid's angles into the case's frame."""
        k = next(i for i, g in enumerate(self.case.network.generators) if g.kind == "slack")
        i = self.case.network.bus_index(self.case.network.generators[k].bus)
        return float(self.case.flow.theta[i] - np.angle(flow.voltage[i]))

    def _starts(self, network, flow) -> tuple:
        """Each unit's DeviceStarts from VeraGrid's power flow: V, angle at its bus, its generator's P, Q."""
        base = network.grid.Sbase
        out = []
        for k, unit in enumerate(self.case.units):
            i = self.case.network.bus_index(unit.bus)
            V = complex(flow.voltage[i])
            op = {"V": abs(V), "theta": cmath.phase(V), "P": float(flow.gen_p[k]) / base,
                  "Q": float(flow.gen_q[k]) / base}
            out.append(unit_start(unit, op))
        return tuple(out)

    def _event_time(self, start: float) -> float:
        """When VeraGrid is told a topology change at `start` [s] happens: one step before. VeraGrid's
        backward Euler applies an event at e to the network it solves at the end of the step from e,
        and the FMUs step explicitly from the voltage at a step's start; told at start - h, VeraGrid's
        network at `start` is the one after the change, the FMUs step on from it, and the states
        before it come from the voltage before it: the change at `start`, as opfmu's master has it."""
        return max(0.0, start - self.step)

    def _events(self, network, topologies) -> None:
        """VeraGrid RMS events for each topology after the first (at _event_time): fault shunts,
        branch status, loads."""
        api = _vg()[0]
        group = api.RmsEventsGroup(name="contingency")
        network.grid.add_rms_events_group(group)
        opened, off, fault = set(), set(), None
        for tp in topologies[1:]:
            changes = []
            now_fault = (tp.fault_bus, complex(tp.fault_impedance)) if tp.fault_bus is not None else None
            if now_fault != fault:
                if fault is not None:
                    shunt, g, b = network.faults[fault[0]]
                    changes += [(shunt, g, 0.0), (shunt, b, 0.0)]
                if now_fault is not None:
                    shunt, g, b = network.faults[now_fault[0]]
                    y = 1.0 / now_fault[1]
                    changes += [(shunt, g, y.real), (shunt, b, y.imag)]
                fault = now_fault
            now_open = set(tp.open)
            for name in now_open ^ opened:
                changes.append((network.branches[name], network.status[name], 0.0 if name in now_open else 1.0))
            opened = now_open
            now_off = {bus for bus, _ in tp.loads_off}
            for bus in now_off ^ off:
                shunt, g, b, y = network.loads[bus]
                on = bus not in now_off
                changes += [(shunt, g, y.real if on else 0.0), (shunt, b, y.imag if on else 0.0)]
            off = now_off
            for device, parameter, value in changes:
                network.grid.add_rms_event(api.RmsEvent(device=device, parameter=parameter,
                                                        time=self._event_time(tp.start),
                                                        value=float(value), group=group))

    def _solver(self, network, flow, stop: float):
        """VeraGrid's RMS problem of the grid with its events and its backward-Euler integrator at the step."""
        api = _vg()[0]
        from VeraGridEngine.Simulations.Rms.numerical.back_euler_fx import BackEulerImplicitIntegration
        from VeraGridEngine.Simulations.Rms.rms_problem_factory import build_rms_problem

        options = api.RmsOptions(time_step=self.step, simulation_time=stop, tolerance=self.tolerance)
        driver = api.RmsSimulationDriver(network.grid, options, flow)
        problem = build_rms_problem(grid=network.grid, options=options, pf_results=flow,
                                    progress_signal=driver.progress_signal, logger=driver.logger)
        problem.set_events_group(rms_events_group=network.grid.rms_events_groups[0])
        problem.reset_boundary_update_state(0.0)
        solver = BackEulerImplicitIntegration(problem=problem, t0=0, t_end=stop, h=self.step,
                                              max_iter=options.max_iter, tolerance=self.tolerance)
        return problem, solver

    def _result(self, network, problem, units, t, y, offset, topologies, stop_at_loss) -> GridResult:
        """The GridResult of VeraGrid's rows `t`, `y` and the units' recorded states."""
        R = _vg()[2]
        case = self.case
        column = problem.uid2idx_vars
        buses = [network.buses[b] for b in case.buses]
        V_bus = np.stack([y[:, column[b.rms_model.external_mapping[R.Vm].uid]] for b in buses], axis=1)
        theta_bus = np.stack([y[:, column[b.rms_model.external_mapping[R.Va].uid]] for b in buses], axis=1) + offset
        n, g = len(t), len(units)
        gen_cols = [case.network.bus_index(u.bus) for u in case.units]
        # the units' P / Vm, Q / Vm (CURRENT_FORM) times their bus voltage
        P = np.stack([y[:, column[d.rms_model.external_mapping[R.P].uid]] for d in network.generators], axis=1)
        Q = np.stack([y[:, column[d.rms_model.external_mapping[R.Q].uid]] for d in network.generators], axis=1)
        P, Q = P * V_bus[:, gen_cols], Q * V_bus[:, gen_cols]
        labels = device_labels(case.units)
        names = list(dict.fromkeys(n_ for u in case.units for n_ in u.machine.component.state_names))
        states = {name: np.full((n, g), np.nan) for name in names}
        device_states, machine_inputs = {}, {}
        rotor = np.full((n, g), np.nan)
        for k, (unit, adapter) in enumerate(zip(case.units, units)):
            times = np.array([row[0] for row in adapter.rows])
            rows = [adapter.rows[int(np.argmin(np.abs(times - ti)))] for ti in t]
            angle_states = unit.machine.component.drift.angle_states if unit.machine.component.drift else ()
            for j, (device, label) in enumerate(zip(unit.devices, labels[k])):
                for s, name in enumerate(device.component.state_names):
                    values = np.array([row[1][j][s] for row in rows])
                    if j == 0 and s in angle_states:
                        values = values + offset
                    device_states[f"{label}_{name}"] = values
                    if j == 0:
                        states[name][:, k] = values
            angle = unit.machine.component.ports.output("rotor_angle")
            if angle in states:
                rotor[:, k] = states[angle][:, k]
            field = unit.machine.component.ports.input("field_voltage")
            if field is not None:
                machine_inputs.setdefault(field, np.full((n, g), np.nan))[:, k] = [row[2][field] for row in rows]
        lost = None
        for i in range(n):
            angles = rotor[i][np.isfinite(rotor[i])]
            if len(angles) and np.ptp(angles) >= math.pi:
                lost = float(t[i])
                break
        return GridResult(time=np.asarray(t, dtype=float), states=states, Vs=V_bus[:, gen_cols],
                          theta_vs=theta_bus[:, gen_cols], P=P, Q=Q, V_bus=V_bus, theta_bus=theta_bus,
                          stable=lost is None, loss_of_synchronism_s=lost,
                          events=tuple((tp.start, tp.description) for tp in topologies[1:]),
                          gen_buses=case.generator_buses, buses=case.buses, machine_inputs=machine_inputs,
                          rotor_angle=rotor, device_states=device_states)


def run_in_veragrid(case, contingency, stop: float, step: float = 0.01, cache=None, interface: str = "norton",
                    progress=None) -> GridResult:
    """Run `case` (reference_models.grid.case.Case) through `contingency`
    (reference_models.grid.contingency.Contingency) until `stop` [s] in VeraGrid's RMS simulation at
    the step `step` [s], every unit's devices as opfmu's native reference FMUs (built into `cache`
    as needed, cosim.fmus.generator_files; progress(text) before each build). The GridResult the
    own master gives (rows every step, angles [rad] in the case's frame, speeds as the machines hold
    them)."""
    from .fmus import generator_files

    files = generator_files(case, "reference", cache, progress)
    result, _ = VeraGridRunner(case, files, step, interface).run(contingency, stop)
    return result


def smib_case(folder, machine: str = "sm4", params: dict | None = None, P: float = 0.7, x: float = 0.2):
    """A single machine against an infinite bus as an opfmu Case (written as its two files into
    `folder`): bus 1 the machine (`machine`, a component of reference_models.components, with
    `params`), a PV bus at V = 1 pu and P [pu, 100 MVA]; bus 2 the infinite bus, the slack at
    V = 1 pu, angle 0: a GENCLS of 1e5 MVA (M = 2000 s, xd1 = 0.3 pu on its base: 3e-4 pu on the
    system's); a lossless line of reactance `x` [pu] between them. The load flow is the line's own
    (theta = asin(P x))."""
    import json
    from pathlib import Path

    from reference_models.grid.case import load_case

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    theta = math.asin(P * x)
    Q = (1.0 - math.cos(theta)) / x
    network = {"name": "smib", "base_mva": 100.0, "f_hz": 60.0,
               "buses": [{"number": 1, "kv": 20.0}, {"number": 2, "kv": 20.0}],
               "branches": [{"from": 1, "to": 2, "r": 0.0, "x": x, "b": 0.0, "kind": "line"}],
               "loads": [], "shunts": [],
               "generators": [{"bus": 1, "kind": "pv", "V": 1.0, "P": P}, {"bus": 2, "kind": "slack", "V": 1.0}],
               "load_flow": {"V": [1.0, 1.0], "theta": [theta, 0.0], "P": [P, -P], "Q": [Q, Q]}}
    dynamic = {"case": "smib", "generators": [
        {"bus": 1, "machine": {"component": machine, "params": dict(params or {})}},
        {"bus": 2, "machine": {"component": "gencls", "params": {"Sn": 1e5, "M": 2000.0, "xd1": 0.3}}}]}
    (folder / "smib_network.json").write_text(json.dumps(network))
    (folder / "smib.json").write_text(json.dumps(dynamic))
    return load_case(folder / "smib_network.json", folder / "smib.json", "smib")
