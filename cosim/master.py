"""The grid co-simulation master: the FMUs of every unit of a case (case.Case: a machine with a bus
port and its control devices per generator bus), coupled through the network, which is solved at
every communication point. The FMUs are wired by the ports their model descriptions declare
(case.unit_wiring); the master names no component and no variable.

Coupling, over each communication step [t0, t1] (h = t1 - t0):

1. The bus voltages V(t0) are known (the network solved at t0), and an end guess V(t1): extrapolated
   linearly from the last two communication points, or held after an event.
2. Each unit's control devices step first (each after those it takes a signal from), the machine
   last. Every input is linear over the step from its value at t0 to its value at t1: the bus
   voltage (magnitude, angle) to the guess V(t1); the terminal voltage |V + (Re + jXep) I| to its
   value at the guess; a link from a device stepped before in this pass to that device's new output
   (the exciter's field voltage for the machine); a link from a device stepped after it (the
   machine's speed for a governor) to that device's output at t1 from the pass before, or, on the
   first pass, extrapolated linearly from the last two communication points (held after an event);
   a set point held. "Linear" is fmi2SetRealInputDerivatives where the FMU can interpolate its inputs
   (FMI 2.0 canInterpolateInputs); an FMU that cannot, and every FMI 3.0 FMU (FMI 3.0
   co-simulation takes no input derivatives), gets the mean of the start and end values held over
   the step (the midpoint rule: the same second order in h for what the step integrates). An FMU
   that takes second input derivatives too (FMU.input_order 2: opfmu's native reference FMUs) gets
   each input on the parabola through its values at the step's start and end and at the start of the
   step before (where that one ran smoothly into this one: not across an event).
3. The network is solved at t1 with the machines' new states: each machine's bus current I(V)
   (its bus-port current outputs), and Y_red V = I(V) at the generator buses is solved by Newton
   with the FMUs' directional derivatives dI/d(voltage magnitude, angle) (central differences for
   an FMU without them). Units sharing a bus inject into it together: their currents are summed
   and their Jacobians accumulated at that bus; the results stay per unit. A machine whose current is affine in V for given states is solved by
   one Newton step; the next confirms.
4. If V(t1) moved by more than `tolerance` from the guess, the FMUs are set back to t0
   (fmi2SetFMUstate) and the step is done again from 2 with a new guess: V(t1) on the second
   pass, then each unit's guess moved along its change by an Aitken factor (from the last two
   changes, within RELAX_BOUNDS; a machine of small subtransient reactance pins its bus voltage to
   its subtransient flux, which follows the guessed voltage within the step, so the plain
   iteration contracts by only 0.85-0.97 a pass there: ieee39); at most `passes` passes; the last
   pass keeps the solved V(t1). Converged, every input over the step is linear between two
   consistent ends: the coupling error is second order in h (held inputs are first order: degrees of rotor angle at
   h = 10 ms after a fault; see docs/grid.md for the measured numbers); on the parabola, third order
   (pjm5bus at h = 10 ms: 0.83 deg from ANDES linear, 0.022 deg on the parabola).

Events (a fault, its clearing, a branch opening or closing, a unit tripped:
reference_models.grid.contingency) happen at communication points: the step before an event is shortened to end there. At an event time the
network is solved twice: in the old topology (the end of the step before) and in the new one (the
start of the step after; the inputs jump there). The row recorded at an event time is the one after.
The steps after an event are cut finer (`event_refinement`, rows stay on the step grid).
A tripped unit (Topology.tripped) injects nothing from its trip on; its FMUs are no longer stepped
(its row values stand at the trip) and its rotor angle leaves the loss-of-synchronism spread.

The master runs FMI 2.0 and 3.0 FMUs over fmpy (cosim.fmu.FMU). Every FMU is rewound to its initial
state between runs (set FMU state), so one master serves the many runs of a critical-clearing-time
bisection. A run refuses more than MAX_STEPS communication steps before it starts, and the
communication points are generated one at a time.
"""
from __future__ import annotations

import cmath
import math
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from reference_models.grid.case import Case, external_impedance, measured_values, remote_wiring, step_order, unit_wiring
from reference_models.grid.contingency import Contingency
from reference_models.grid.result import GridResult, device_labels, rotor_angle_state

from .fmu import FMU, CouplingError, extracted


COUPLINGS = ("iterated", "extrapolated", "held")


@dataclass(frozen=True)
class MasterSettings:
    """step [s]: the communication step; coupling: `iterated` (inputs linear to a consistent end,
    the step redone up to `passes` times), `extrapolated` (inputs linear to the end guess, one
    pass) or `held` (the inputs at the step's start held over it, one pass: what a plain master
    does); passes: the most passes of an iterated step; tolerance [pu]: the change of the end
    voltages below which a step is consistent; newton_tolerance [pu]: the network's current
    mismatch that ends Newton; stop_at_loss: end a run when two rotor angles are pi apart (a
    critical-clearing-time run needs no more); event_refinement: (window [s], substeps) pairs, a
    step starting within the first window after a topology change cut into its substeps (the
    first pair that holds: 10 within 50 ms, 2 within 1 s by default; refined_points)."""

    step: float = 0.01
    coupling: str = "iterated"
    passes: int = 3
    tolerance: float = 1e-6
    newton_tolerance: float = 1e-10
    newton_iterations: int = 20
    stop_at_loss: bool = False
    event_refinement: tuple = ((0.05, 10), (1.0, 2))

    def __post_init__(self):
        if not (isinstance(self.step, (int, float)) and math.isfinite(self.step) and 1e-5 <= self.step <= 1.0):
            raise ValueError(f"the communication step must be a time from 1e-5 to 1 s, got {self.step!r}")
        if self.coupling not in COUPLINGS:
            raise ValueError(f"coupling must be one of {', '.join(COUPLINGS)}, got {self.coupling!r}")
        if not (isinstance(self.passes, int) and 1 <= self.passes <= 20):
            raise ValueError(f"passes must be an integer from 1 to 20, got {self.passes!r}")
        if not (self.tolerance > 0 and self.newton_tolerance > 0):
            raise ValueError("tolerances must be positive")
        for tier in self.event_refinement:
            window, substeps = tier if isinstance(tier, tuple) and len(tier) == 2 else (None, None)
            if not (isinstance(substeps, int) and 1 <= substeps <= 100):
                raise ValueError(f"event_refinement: (window, substeps) pairs with substeps from 1 to 100, "
                                 f"got {tier!r}")
            if not (isinstance(window, (int, float)) and math.isfinite(window) and window >= 0):
                raise ValueError(f"event_refinement: (window, substeps) pairs with a window >= 0 s, got {tier!r}")


@dataclass
class Timing:
    """Where a run's wall time went [s]: FMU steps (inputs, derivatives, fmi2DoStep), network solves
    (Newton with the FMUs' outputs and derivatives), rollback (fmi2Get/SetFMUstate), the rest
    (`overhead`: the master's own bookkeeping); counts of steps, passes and Newton iterations."""

    total_s: float = 0.0
    fmu_step_s: float = 0.0
    network_s: float = 0.0
    rollback_s: float = 0.0
    steps: int = 0
    passes: int = 0
    newton_iterations: int = 0

    @property
    def overhead_s(self) -> float:
        return self.total_s - self.fmu_step_s - self.network_s - self.rollback_s

    def to_dict(self) -> dict:
        return {"total_s": self.total_s, "fmu_step_s": self.fmu_step_s, "network_s": self.network_s,
                "rollback_s": self.rollback_s, "overhead_s": self.overhead_s, "steps": self.steps,
                "passes": self.passes, "newton_iterations": self.newton_iterations}


@dataclass
class CosimResult:
    """A co-simulation run: `result` (monolithic.GridResult, one row per communication point), its
    `timing`, per generator the FMU kind and what the FMUs logged (status, message), and the
    master's notes on how it coupled them."""

    result: GridResult
    timing: Timing
    kinds: tuple
    messages: dict = field(default_factory=dict)
    notes: tuple = ()


RELAX_BOUNDS = (1.0, 50.0)  # the Aitken factor of an iterated step's end-voltage update
MAX_STEPS = 1_000_000  # communication steps of one run (a row each in the result)
# a network switch whose Newton solve fails from the voltages before it is continued from the network
# before it: in steps of lambda of at most this, each cut by 4 where it fails, down to the smallest
CONTINUATION_STEP = 0.25
SMALLEST_CONTINUATION_STEP = 1e-4


def check_steps(stop: float, step: float) -> None:
    """ValueError when a run to `stop` [s] in steps of `step` [s] has more than MAX_STEPS steps."""
    if stop / step > MAX_STEPS:
        raise ValueError(f"a run to {stop:g} s in steps of {step:g} s has {stop / step:.3g} communication steps "
                         f"(at most {MAX_STEPS:.0e}: shorten the run or lengthen the step)")


def communication_points(step: float, stop: float, changes):
    """The communication points after 0 up to `stop` [s], one at a time, each with the topology that
    starts there (or None): the multiples of `step` (the last one `stop`) and the start times of
    `changes` (contingency.Topology), points closer than 1e-9 s to the one before merged, each
    change at the point nearest to its start."""
    n_steps = int(math.ceil(stop / step - 1e-9))
    events = sorted(changes, key=lambda tp: tp.start)
    k, e = 1, 0
    previous_raw, kept = 0.0, 0.0
    pending, waiting = [], None  # changes dropped with their own point; the kept point not yet given

    def candidates():
        nonlocal k, e
        while k <= n_steps or e < len(events):
            g = min(k * step, stop) if k <= n_steps else math.inf
            ev = events[e].start if e < len(events) else math.inf
            if ev < g:
                e += 1
                yield ev, events[e - 1]
            elif ev == g:
                k += 1
                e += 1
                yield g, events[e - 1]
            else:
                k += 1
                yield g, None

    for p, change in candidates():
        if p == previous_raw and change is None:
            continue  # the same time twice (the stop)
        drop = p - previous_raw <= 1e-9
        previous_raw = p
        if drop:
            if change is not None:
                pending.append(change)
            continue
        here = change
        for tp in pending:  # each to the nearer of the kept point before and this one
            if abs(tp.start - kept) <= abs(p - tp.start):
                if waiting is not None:
                    waiting = (waiting[0], tp)
            else:
                here = tp
        pending = []
        if waiting is not None:
            yield waiting
        waiting, kept = (p, here), p
    for tp in pending:
        if waiting is not None:
            waiting = (waiting[0], tp)
    if waiting is not None:
        yield waiting


def refined_points(points, refinement):
    """The communication points `points` ((time, topology or None), as communication_points gives
    them) with each step that starts less than `window` [s] after a topology change cut into
    `substeps` equal steps, by the first (window, substeps) of `refinement` whose window holds the
    step's start, one at a time as (time, topology or None, recorded): the points added are not
    recorded (the result keeps its rows on the communication grid). Right after a fault or its
    clearing the machines' subtransient currents and the network move within milliseconds, and the
    exciters and stabilisers within the next second; with the voltage linear over a whole step they
    cost tenths of a degree of rotor angle (ieee39 at h = 10 ms: docs/grid.md)."""
    t0, changed = 0.0, -math.inf
    for t1, topology in points:
        substeps = next((n for window, n in refinement if t0 < changed + window - 1e-12), 1)
        if substeps > 1:
            for k in range(1, substeps):
                yield t0 + (t1 - t0) * k / substeps, None, False
        yield t1, topology, True
        if topology is not None:
            changed = t1
        t0 = t1


def _code(source) -> int:
    """The master's code of an input's Source: 0, 1 bus voltage magnitude, angle; 2, 3 terminal voltage
    magnitude, angle; 4 a link from another device; 5 a set point; 6 a network measurement."""
    if source.kind == "bus":
        return source.index
    if source.kind == "terminal":
        return 2 + source.index
    return {"device": 4, "measured": 6}.get(source.kind, 5)


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def _stepped(v, step, polar: bool):
    """v [2b] (V_re, V_im per bus) after a Newton step: v - step, or where `polar` the step in
    (|V|, angle) per bus."""
    if not polar:
        return v - step
    rho = np.hypot(v[0::2], v[1::2]) - step[0::2]
    angle = np.arctan2(v[1::2], v[0::2]) - step[1::2]
    out = np.empty_like(v)
    out[0::2], out[1::2] = rho * np.cos(angle), rho * np.sin(angle)
    return out


class _Unit:
    """The FMUs of one unit under the master: `fmus` (device order, the machine first), the wiring of
    their inputs from their ports, the bound inputs and outputs of each and where in them the
    master finds the bus current, the rotor angle, the states and the link outputs."""

    def __init__(self, unit, start, files, source, remote=None, given=None):
        self.bus = unit.bus
        self.fmus = []
        try:
            self._open(unit, start, files, source, remote or {}, given or {})
        except BaseException:
            self.close()
            raise

    def _open(self, unit, start, files, source, remote: dict, given: dict) -> None:
        """source(path, name): an FMU file's extraction, shared by its instances; remote: the unit's
        signals from other units (case.remote_wiring); given: {device: [outputs other units take]}."""
        for device, path in zip(unit.devices, files.paths):
            name = f"{device.name} at bus {unit.bus}"
            self.fmus.append(FMU(source(path, name), name, init=False))
        for fmu in self.fmus:
            if fmu.ports is None:
                raise CouplingError(f"{fmu.name}: the FMU {fmu.model_name} declares no ports (no <Ports> element in "
                                    "its model description) and is not an opfmu FMU of a known component")
        if self.fmus[0].ports.bus is None:
            raise CouplingError(f"{self.fmus[0].name}: the FMU {self.fmus[0].model_name} declares no bus port")
        from reference_models.grid.case import CaseError

        try:
            self.wiring = unit_wiring([f.ports for f in self.fmus], f"generator at bus {unit.bus}", remote)
        except CaseError as exc:
            raise CouplingError(str(exc)) from None
        for device, begin, fmu in zip(unit.devices, start, self.fmus):
            values = {f"{n}0": v for n, v in zip(device.component.state_names, begin.states)}
            values.update(begin.inputs)
            values.update(fmu.parameter_values(device.params))
            fmu.initialise(values, keep=True)
        self.order = step_order(self.wiring)
        needed = {j: list(given.get(j, ())) for j in range(len(self.fmus))}
        for wires in self.wiring:
            for source in wires.values():
                if source.kind == "device" and source.unit is None and source.variable not in needed[source.device]:
                    needed[source.device].append(source.variable)
        bus = self.fmus[0].ports.bus
        self.inputs, self.sources, self.held, self.state_rows, self.link_rows = [], [], [], [], []
        for j, (device, fmu) in enumerate(zip(unit.devices, self.fmus)):
            wires = self.wiring[j]
            names = [n for n in wires]
            outputs = list(device.component.state_names)
            if j == 0:
                outputs += [n for n in bus.current if n not in outputs]
            outputs += [n for n in needed[j] if n not in outputs]
            fmu.bind(names, outputs)
            self.inputs.append(names)
            self.sources.append([wires[n] for n in names])
            self.held.append([float(start[j].inputs[n]) if n in start[j].inputs else fmu.starts.get(n, 0.0)
                              for n in names])
            self.state_rows.append(len(device.component.state_names))
            self.link_rows.append({n: outputs.index(n) for n in needed[j]})
        self.plan = [[(_code(source), (source.unit, source.device, source.variable) if source.kind == "device" else
                       (j, source.index) if source.kind == "measured" else None, held)
                      for source, held in zip(sources, helds)]
                     for j, (sources, helds) in enumerate(zip(self.sources, self.held))]
        # the devices that measure the network: (device index, Measurement)
        self.measuring = tuple((j, d.measures) for j, d in enumerate(unit.devices)
                               if any(src.kind == "measured" for src in self.sources[j]))
        missing = [unit.devices[j].name for j, m in self.measuring if m is None]
        if missing:
            raise CouplingError(f"generator at bus {unit.bus}: {', '.join(missing)} measure the network, but the "
                                "case names no measured bus for them")
        self.state_names = [d.component.state_names for d in unit.devices]
        self.current_rows = tuple(outputs_index for outputs_index in
                                  (self.fmus[0].output_names.index(n) for n in bus.current))
        self.voltage_columns = tuple(self.inputs[0].index(n) for n in bus.voltage)
        # the machine's inputs that take the bus voltage's magnitude and angle (codes 0, 1)
        self.bus_columns = tuple(tuple(i for i, (code, _, _) in enumerate(self.plan[0]) if code == c) for c in (0, 1))
        angle = rotor_angle_state(unit.machine.component)
        self.angle_row = None if angle is None else unit.machine.component.state_names.index(angle)
        self.impedance = external_impedance(unit.machine)
        # the links' values at the start of a run: the consumers' start values, by (giving unit: None for
        # this one, device, variable)
        self.initial_links = {}
        for j, sources in enumerate(self.sources):
            for source, held in zip(sources, self.held[j]):
                if source.kind == "device":
                    self.initial_links[(source.unit, source.device, source.variable)] = held

    def close(self) -> None:
        for f in self.fmus:
            f.close()


class GridMaster:
    """The master over the FMUs of every unit of `case` (case.Case: network, load flow, units and
    their start values); files: cosim.fmus.UnitFiles per unit, in the case's unit order; scratch:
    the folder FMU files are extracted under (default: the system's temporary folder). Use as a
    context manager, or call close()."""

    def __init__(self, case: Case, files, settings: MasterSettings = MasterSettings(), scratch=None):
        self.case = case
        self.settings = settings
        self.files = tuple(files)
        if [f.bus for f in self.files] != list(case.generator_buses):
            raise CouplingError(f"one set of FMUs per generator bus {case.generator_buses} is needed")
        self.kinds = tuple(f.kind for f in self.files)
        self.units = []
        self._networks = {}
        self._solve_plans, self._step_plans = {}, {}
        buses = list(dict.fromkeys(case.generator_buses))  # the reduced network's buses (Case.reduced's order)
        self._slot = [buses.index(b) for b in case.generator_buses]  # unit -> its bus in the reduced network
        self._first = [self._slot.index(i) for i in range(len(buses))]  # bus -> the first unit on it
        remote = remote_wiring(case.units)
        given = [{} for _ in case.units]  # per unit {device: [the outputs other units take]}
        for wires in remote:
            for source in wires.values():
                given[source.unit].setdefault(source.device, []).append(source.variable)
        self._scratch = scratch
        self._extracted = {}  # FMU file -> (its extracted folder, model description), shared by its instances
        self._folders = []  # the folders extracted here, removed at close
        try:
            for k, f in enumerate(self.files):
                self.units.append(_Unit(case.units[k], case.starts[k], f, self._source, remote[k], given[k]))
        except BaseException:
            self.close()
            raise
        self.fmus = [fmu for u in self.units for fmu in u.fmus]
        self._layout()
        self._measuring = any(u.measuring for u in self.units)
        self._angles = any(code == 3 for u in self.units for plan in u.plan for code, _, _ in plan)
        self.rolls_back = all(s.rolls_back for s in self.fmus)
        self.notes = ()
        if not self.rolls_back and settings.coupling == "iterated" and settings.passes > 1:
            names = ", ".join(s.model_name for s in self.fmus if not s.rolls_back)
            self.notes = (f"{names} cannot restore an FMU state: steps are not iterated (one pass, inputs "
                          "linear to the extrapolated end voltage)",)
        self._gen_rows = [case.network.bus_index(b) for b in case.generator_buses]
        self._runs = 0

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _source(self, path, name: str) -> tuple:
        """The FMU file `path` extracted once under the scratch folder (cosim.fmu.extracted), its
        instances sharing the folder and the model description (one binary loaded)."""
        key = Path(path).resolve()
        if key not in self._extracted:
            if key.is_dir():  # an FMU given as its folder: used where it is
                self._extracted[key] = extracted(key, None, name)
                return self._extracted[key]
            folder = tempfile.mkdtemp(prefix="opfmu_fmu_", dir=self._scratch)
            self._folders.append(folder)
            self._extracted[key] = extracted(key, folder, name)
        return self._extracted[key]

    def close(self) -> None:
        for u in self.units:
            u.close()
        self.units, self.fmus = [], []
        for folder in self._folders:
            shutil.rmtree(folder, ignore_errors=True)
        self._extracted, self._folders = {}, []

    def network(self, topology):
        """Case.reduced of a topology (its fault shunt with its own impedance), kept per topology."""
        impedance = complex(topology.fault_impedance) if topology.fault_bus is not None else None
        key = (topology.fault_bus, impedance, topology.open, topology.loads_off)
        if key not in self._networks:
            self._networks[key] = self.case.reduced(topology.fault_bus, impedance, topology.open, topology.loads_off)
        return self._networks[key]

    def _layout(self) -> None:
        """Every FMU's buffers in the master's arrays (FMU.share), so that an input, rate or output
        of any FMU is set or read in one numpy operation with the others: `_inputs`, `_rates` (the
        bound inputs and their rates), `_outputs`, `_derivatives` (the bound outputs and their
        directional derivatives), device j of unit k at `_in_at[k][j]`, `_out_at[k][j]` (its
        control devices' outputs: `_controls[k]`, (start, end) each). And
        `_values`, where every input finds its value at a step's start and at its end, in regions
        (`_region`): "start", "end" (4 g each: per unit its bus voltage magnitude, angle and
        terminal voltage magnitude, angle: code * g + unit), "links", "ends" (each link's value at
        the step's start and end: `_link[(unit, (device, variable))]`, given by the output
        `_givers[link]`), "held" (each input's held value, by its index in `_inputs`),
        "measured", "measured_end" (the measurements at the step's start and end:
        `_measured_at[(unit, device)]` = (offset, count)); `_sources` = (start, end) indices in
        `_values` per input."""
        g = len(self.units)
        self._in_at, self._out_at = [], []
        n_in = n_out = 0
        for u in self.units:
            self._in_at.append([])
            self._out_at.append([])
            for f in u.fmus:
                self._in_at[-1].append(n_in)
                self._out_at[-1].append(n_out)
                n_in, n_out = n_in + len(f.input_names), n_out + len(f.output_names)
        self._inputs, self._rates, self._curvatures = np.zeros(n_in), np.zeros(n_in), np.zeros(n_in)
        self._outputs, self._derivatives = np.zeros(n_out), np.zeros(n_out)
        self._quadratic = np.zeros(n_in, dtype=bool)  # the inputs of FMUs that take second derivatives
        for k, u in enumerate(self.units):
            for j, f in enumerate(u.fmus):
                i, o = self._in_at[k][j], self._out_at[k][j]
                ni, no = len(f.input_names), len(f.output_names)
                f.share(self._inputs[i:i + ni], self._rates[i:i + ni], self._outputs[o:o + no],
                        self._derivatives[o:o + no], self._curvatures[i:i + ni])
                self._quadratic[i:i + ni] = f.input_order > 1
        self._link, givers, initial = {}, [], []
        for k, u in enumerate(self.units):
            for (unit, device, variable), value in u.initial_links.items():
                giver = k if unit is None else unit
                if (giver, (device, variable)) not in self._link:
                    self._link[(giver, (device, variable))] = len(givers)
                    givers.append(self._out_at[giver][device] + self.units[giver].link_rows[device][variable])
                    initial.append(value)
        self._givers = np.array(givers, dtype=np.intp)
        # per unit, its control devices' outputs in `_outputs` (start, end)
        self._controls = [[(o, o + len(f.output_names)) for o, f in zip(self._out_at[k][1:], u.fmus[1:])]
                          for k, u in enumerate(self.units)]
        self._initial_links = np.array(initial, dtype=float)
        self._measured_at, n_measured = {}, 0
        for k, u in enumerate(self.units):
            for j, _ in u.measuring:
                count = 1 + max(key[1] for code, key, _ in u.plan[j] if code == 6)
                self._measured_at[(k, j)] = (n_measured, count)
                n_measured += count
        sizes = (("start", 4 * g), ("end", 4 * g), ("links", len(givers)), ("ends", len(givers)), ("held", n_in),
                 ("measured", n_measured), ("measured_end", n_measured))
        self._region, at = {}, 0
        for name, size in sizes:
            self._region[name] = at
            at += size
        self._values = np.zeros(at)
        self._links = slice(self._region["links"], self._region["links"] + len(givers))
        self._ends = slice(self._region["ends"], self._region["ends"] + len(givers))
        self._before = np.zeros(len(givers))  # the links at the start of the step before
        self._extrapolates = False  # whether _before holds them (not on a run's first step)
        r = self._region
        starts, ends = np.zeros(n_in, dtype=np.intp), np.zeros(n_in, dtype=np.intp)
        for k, u in enumerate(self.units):
            for j, plan in enumerate(u.plan):
                for i, (code, key, held) in enumerate(plan):
                    p = self._in_at[k][j] + i
                    if code < 4:
                        starts[p], ends[p] = r["start"] + code * g + k, r["end"] + code * g + k
                    elif code == 4:
                        link = self._link[(k if key[0] is None else key[0], key[1:])]
                        starts[p], ends[p] = r["links"] + link, r["ends"] + link
                    elif code == 6:
                        at = self._measured_at[(k, key[0])][0] + key[1]
                        starts[p], ends[p] = r["measured"] + at, r["measured_end"] + at
                    else:
                        starts[p] = ends[p] = r["held"] + p
                    self._values[r["held"] + p] = held
        self._sources = (starts, ends)

    def _rewind_links(self) -> None:
        """The links back to their start values."""
        self._values[self._links] = self._values[self._ends] = self._initial_links
        self._extrapolates = False

    def _guess_ends(self, ratio: float | None) -> None:
        """The coming step's end values of the links guessed: extrapolated linearly from the step
        before (`ratio`: the coming step's length over that one's), or held (None)."""
        values = self._values
        links = values[self._links]
        if ratio is None or not self._extrapolates:
            values[self._ends] = links
        else:
            values[self._ends] = links + (links - self._before) * ratio

    def _advance_links(self) -> None:
        """The step done: its links' end values start the next."""
        self._before[:] = self._values[self._links]
        self._values[self._links] = self._values[self._ends]
        self._extrapolates = True

    def _machine_links(self, k: int) -> None:
        """Unit k's machine's link outputs (its electrical power, which jumps with the network at an
        event) as its outputs now hold them, as the start and end values of the coming step."""
        values, r = self._values, self._region
        for name in self.units[k].link_rows[0]:
            link = self._link[(k, (0, name))]
            values[r["links"] + link] = values[r["ends"] + link] = self._outputs[self._givers[link]]

    def _set_voltages(self, region: str, V, theta, Vt) -> None:
        """The bus voltages V [g] (complex), angles theta [g] and terminal voltages Vt (_terminal's)
        into the `region` ("start" or "end") of `_values`."""
        g, at, values = len(self.units), self._region[region], self._values
        values[at:at + g] = [abs(v) for v in V.tolist()]
        values[at + g:at + 2 * g] = theta
        values[at + 2 * g:at + 3 * g] = Vt[0]
        if Vt[1] is not None:
            values[at + 3 * g:at + 4 * g] = Vt[1]

    def _set_measured(self, region: str, measured: dict) -> None:
        """_measure's values into the `region` ("measured" or "measured_end") of `_values`."""
        at = self._region[region]
        for key, found in measured.items():
            offset, count = self._measured_at[key]
            self._values[at + offset:at + offset + count] = found[:count]

    def _solve_plan(self, active) -> dict:
        """What _solve needs of the `active` units (kept per set of them): their indices, their bus's
        rows in the reduced network, their machines' evaluate and (FMU, current rows, voltage
        columns) for block; in `_inputs`, the machine inputs (their sources in `_values`: a link's
        end value or the held value), those that take the bus voltage's magnitude and angle (and
        the active unit each takes it of); in `_outputs`, the currents and each machine's outputs;
        where each machine's d(I_re, I_im) / d(V_re, V_im) goes in the Jacobian (rows, columns;
        accumulated at a shared bus)."""
        key = tuple(active)
        plan = self._solve_plans.get(key)
        if plan is not None:
            return plan
        ends, r = self._sources[1], self._region
        machine_at, machine_from, magnitude, angle, currents, out = [], [], ([], []), ([], []), ([], []), []
        for n, k in enumerate(active):
            u = self.units[k]
            i, o = self._in_at[k][0], self._out_at[k][0]
            for c, (code, _, _) in enumerate(u.plan[0]):
                machine_at.append(i + c)
                machine_from.append(ends[i + c] if code == 4 else r["held"] + i + c)
            for where, columns in zip((magnitude, angle), u.bus_columns):
                where[0].extend(i + c for c in columns)
                where[1].extend([n] * len(columns))
            for where, row in zip(currents, u.current_rows):
                where.append(o + row)
            out.append((o, o + len(u.fmus[0].output_names)))
        rows = [2 * self._slot[k] for k in active]
        at = [(q + i, q + j) for q in rows for i in (0, 1) for j in (0, 1)]
        intp = lambda values: np.array(values, dtype=np.intp)  # noqa: E731
        plan = self._solve_plans[key] = {
            "units": intp(active), "rows": rows, "bus_rows": intp(rows),
            "evaluate": tuple(self.units[k].fmus[0].evaluate for k in active),
            "blocks": tuple((self.units[k].fmus[0], self.units[k].current_rows, self.units[k].voltage_columns)
                            for k in active),
            "machine_at": intp(machine_at), "machine_from": intp(machine_from),
            "magnitude": tuple(intp(x) for x in magnitude), "angle": tuple(intp(x) for x in angle),
            "currents": tuple(intp(x) for x in currents), "outputs": out,
            "jacobian": (intp([i for i, _ in at]), intp([j for _, j in at]))}
        return plan

    def _solve_switched(self, before, after, V, theta_ref, active, timing: Timing):
        """_solve on the network `after` a switch (a fault, its clearing, a line opened or closed) from
        V, theta_ref solved on the network `before` it. Where Newton from there fails (a deep fault at
        a bus of angle-following current sources: each inverter's current turns with its bus voltage,
        and the voltages move too far for one solve), the solution is continued from the network
        before: on Y(lambda) = (1 - lambda) Y_before + lambda Y_after, lambda from 0 (solved) to 1, in
        steps of at most CONTINUATION_STEP, each cut by 4 where its solve fails. CouplingError where a
        step below SMALLEST_CONTINUATION_STEP fails: no solution near the path (ANDES' Newton fails
        there as well)."""
        try:
            return self._solve(after.Y_real, V, theta_ref, active, timing)
        except CouplingError as exc:
            first = str(exc)
        Y0, Y1 = before.Y_real, after.Y_real
        lam, step = 0.0, CONTINUATION_STEP
        while True:
            target = min(1.0, lam + step)
            try:
                solved = self._solve((1.0 - target) * Y0 + target * Y1, V, theta_ref, active, timing)
            except CouplingError:
                step *= 0.25
                if step < SMALLEST_CONTINUATION_STEP:
                    raise CouplingError(f"{first} after the network switched, nor along a continuation from the "
                                        f"network before it (solved up to {100 * lam:.4g} % of the way): its devices "
                                        "have no operating point near there (a fault deeper than their currents "
                                        "allow; try a larger --fault-impedance)") from None
                continue
            if target == 1.0:
                return solved
            V, _, theta_ref, _ = solved
            lam, step = target, min(CONTINUATION_STEP, 2.0 * step)

    def _solve(self, Y, V, theta_ref, active, timing: Timing):
        """The unit-bus voltages [g] (complex, per unit) at which the network (its real admittance
        matrix Y [2b, 2b], Case.reduced's Y_real) and the currents I(V) of
        the `active` units' machines agree, Newton from V on the reduced network's buses (units at
        one bus inject into it together: their currents are summed and their Jacobians accumulated;
        a step that raises the mismatch is halved until it does not);
        the machines are left at those inputs. A unit not active injects nothing. Returns (V, I,
        theta [g], each active unit's machine outputs as read (None for the others))."""
        started = time.perf_counter()
        s = self.settings
        slot, units = self._slot, self.units
        b = len(self._first)
        v = np.empty(2 * b)
        Vb = V[self._first]
        v[0::2], v[1::2] = Vb.real, Vb.imag
        g = len(units)
        plan = self._solve_plan(active)
        inputs, outputs = self._inputs, self._outputs
        inputs[plan["machine_at"]] = self._values[plan["machine_from"]]  # all but the bus voltage, for every iteration
        refs = theta_ref[plan["units"]].tolist()
        rows, bus_rows = plan["rows"], plan["bus_rows"]
        (magnitude_at, magnitude_of), (angle_at, angle_of) = plan["magnitude"], plan["angle"]
        current_re, current_im = plan["currents"]
        atan2, hypot, pi, two_pi = math.atan2, math.hypot, math.pi, 2.0 * math.pi
        start = v.copy()
        polar = False  # Newton in (V_re, V_im) per bus; again in (|V|, angle) where that fails
        last = None  # the last Newton step: (its start, the step, the mismatch there), for backtracking
        for iteration in range(2 * s.newton_iterations + 2):
            if iteration == s.newton_iterations + 1:
                if mismatch < s.newton_tolerance:
                    break
                # a stiff voltage-holding device (a static PV generator: reactive power Kv (V0 - |V|)) bends its
                # current along the angle, where a step in (V_re, V_im) overshoots: from the start again in polar
                polar, last, v = True, None, start.copy()
            values = v.tolist()
            re = [values[q] for q in rows]
            im = [values[q + 1] for q in rows]
            angles = [ref + ((atan2(y, x) - ref + pi) % two_pi - pi) for x, y, ref in zip(re, im, refs)]  # _wrap
            Vs = [hypot(x, y) for x, y in zip(re, im)]
            inputs[magnitude_at] = np.array(Vs)[magnitude_of]
            inputs[angle_at] = np.array(angles)[angle_of]
            for evaluate in plan["evaluate"]:
                evaluate()
            i_re, i_im = outputs[current_re], outputs[current_im]
            i_bus = np.zeros(2 * b)
            np.add.at(i_bus, bus_rows, i_re)
            np.add.at(i_bus, bus_rows + 1, i_im)
            F = Y @ v - i_bus
            mismatch = float(np.max(np.abs(F)))
            if mismatch < s.newton_tolerance and (polar or iteration <= s.newton_iterations):
                break
            if iteration == s.newton_iterations or iteration == 2 * s.newton_iterations + 1:
                continue
            if last is not None and mismatch > last[2]:
                # the full step made it worse (a constant-power load at a deep voltage dip): half of it
                before_step, step, before = last
                last = before_step, 0.5 * step, before
                v = _stepped(before_step, last[1], polar)
                continue
            # d(I_re, I_im) / d(Vs, theta), row by row; the chain rule with
            # d(Vs, theta) / d(V_re, V_im) = [[c, sn], [-sn / Vs, c / Vs]]
            a, bb, d, e = np.array([m.block(r, c) for m, r, c in plan["blocks"]]).T
            Vs = np.array(Vs)
            c, sn = np.array(re) / Vs, np.array(im) / Vs
            blocks = np.stack((a * c - bb * sn / Vs, a * sn + bb * c / Vs, d * c - e * sn / Vs, d * sn + e * c / Vs),
                              axis=1)
            if polar:  # columns by d(V_re, V_im) / d(|V|, angle) per bus; the devices' blocks as they are
                rho = np.hypot(v[0::2], v[1::2])
                c_all, s_all = v[0::2] / rho, v[1::2] / rho
                M = np.empty_like(Y)
                M[:, 0::2] = Y[:, 0::2] * c_all + Y[:, 1::2] * s_all
                M[:, 1::2] = rho * (Y[:, 1::2] * c_all - Y[:, 0::2] * s_all)
                blocks = np.stack((a, bb, d, e), axis=1)
            else:
                M = Y.copy()
            np.subtract.at(M, plan["jacobian"], blocks.ravel())
            last = v, np.linalg.solve(M, F), mismatch
            v = _stepped(v, last[1], polar)
            timing.newton_iterations += 1
        if not mismatch < max(s.newton_tolerance, 1e-8):
            raise CouplingError(f"the network solve did not converge (current mismatch {mismatch:.3g} pu)")
        theta, current, machine = np.zeros(g), np.zeros((2, g)), [None] * g
        theta[plan["units"]] = angles
        current[0, plan["units"]], current[1, plan["units"]] = i_re, i_im
        for k, (o, o_end) in zip(active, plan["outputs"]):
            machine[k] = outputs[o:o_end].tolist()
        values = v.tolist()
        for k in range(g):
            if machine[k] is None:  # not active: the bus angle, continuous with its reference
                q = 2 * slot[k]
                ref = float(theta_ref[k])
                theta[k] = ref + _wrap(math.atan2(values[q + 1], values[q]) - ref)
        timing.network_s += time.perf_counter() - started
        Vb = v[0::2] + 1j * v[1::2]
        return Vb[slot], current[0] + 1j * current[1], theta, machine

    def _terminal(self, V, I, theta):
        """The terminal voltage behind each machine's external impedance: (magnitudes [g], angles [g],
        continuous with the bus angles theta; None where no device takes them), lists."""
        Vt = [v + u.impedance * i for v, i, u in zip(V.tolist(), I.tolist(), self.units)]
        angles = None
        if self._angles:
            angles = [t + _wrap(cmath.phase(v) - t) for v, t in zip(Vt, theta.tolist())]
        return [abs(v) for v in Vt], angles

    def _measure(self, V, theta, topology, active) -> dict:
        """{(unit, device): the MEASURED values} of the measuring devices of the `active` units at the
        unit-bus voltages V [g] (the other buses' by the topology's recovery), each measured angle
        continuous with its unit's bus angle theta[k]; {} where no device measures."""
        if not self._measuring:
            return {}
        V_bus = self.network(topology).recovery @ V[self._first]
        out = {}
        for k in active:
            for j, measures in self.units[k].measuring:
                values = [float(v) for v in measured_values(self.case.network, V_bus, measures, topology.open)]
                values[1] = float(theta[k]) + _wrap(values[1] - float(theta[k]))
                out[(k, j)] = values
        return out

    def _step_plan(self, active) -> tuple:
        """What _step needs of the `active` units (kept per set of them): per layer (the devices at
        one place of their unit's step order) the indices in `_inputs` of its FMUs that interpolate
        and their sources (start, end) in `_values`, the same of those that do not, their
        step_inputs, and the links they give (indices in `_values` of their end values, in
        `_outputs` of the outputs that give them)."""
        key = tuple(active)
        plan = self._step_plans.get(key)
        if plan is not None:
            return plan
        starts, ends = self._sources
        layers = []
        for place in range(max((len(self.units[k].order) for k in active), default=0)):
            inputs, steps, links, givers = ([], []), [], [], []
            for k in active:
                u = self.units[k]
                if place >= len(u.order):
                    continue
                j = u.order[place]
                fmu, first = u.fmus[j], self._in_at[k][j]
                inputs[0 if fmu.interpolates else 1].extend(range(first, first + len(fmu.input_names)))
                steps.append(fmu.step_inputs)
                for name, row in u.link_rows[j].items():
                    links.append(self._region["ends"] + self._link[(k, (j, name))])
                    givers.append(self._out_at[k][j] + row)
            layer = []
            for at in inputs:
                at = np.array(at, dtype=np.intp)
                layer += [at, starts[at], ends[at]]
            layers.append((*layer, tuple(steps), np.array(links, dtype=np.intp), np.array(givers, dtype=np.intp)))
        plan = self._step_plans[key] = tuple(layers)
        return plan

    def _step(self, t0, h, active, timing, before=None) -> None:
        """One pass over [t0, t0 + h]: every `active` unit's devices stepped in their order, each input
        from its start value to its end value as `_values` holds them (bus voltage and
        terminal voltage: _set_voltages; a link from a device stepped before in this pass: to its
        new output; from a device stepped after it: to that device's end value from the pass before,
        or its extrapolation on the first pass; a measurement: _set_measured), or held at the start
        values with coupling "held". An input runs linearly between the two, or, given `before`
        ((h_before [s], `_values` at the start of the step before, which ran smoothly into this one))
        and an FMU that takes second derivatives (FMU.input_order), on the parabola through its value
        there too: the coupling error is then third order in h. The devices' outputs at t0 + h are
        left in `_outputs`, and the links' end values are set to this pass's outputs."""
        started = time.perf_counter()
        held = self.settings.coupling == "held"
        values, inputs, rates, curvatures, outputs = self._values, self._inputs, self._rates, self._curvatures, self._outputs
        quadratic = before is not None and not held
        for at, start, end, at_held, start_held, end_held, steps, links, givers in self._step_plan(active):
            a = values[start]
            inputs[at] = a
            rates[at] = 0.0 if held else (values[end] - a) / h
            if quadratic:  # Newton's form through (-h_before, before), (0, a), (h, end): u'(0), u''
                h_before, previous = before
                bend = np.where(self._quadratic[at], (rates[at] - (a - previous[start]) / h_before) / (h + h_before), 0.0)
                rates[at] -= bend * h
                curvatures[at] = 2.0 * bend
            inputs[at_held] = values[start_held] if held else 0.5 * (values[start_held] + values[end_held])
            for step in steps:
                step(t0, h, None, quadratic)
            values[links] = outputs[givers]
        timing.fmu_step_s += time.perf_counter() - started

    def run(self, contingency: Contingency, stop: float = 5.0) -> CosimResult:
        """The system from its load-flow equilibrium through `contingency` until `stop` [s]. A unit
        its topology trips (Topology.tripped) injects nothing from then on, its FMUs are no longer
        stepped (its states stand at their values at the trip) and its rotor angle leaves the
        loss-of-synchronism spread."""
        if not (isinstance(stop, (int, float)) and math.isfinite(stop) and stop > 0):
            raise ValueError(f"stop must be a positive time, got {stop!r}")
        s = self.settings
        check_steps(stop, s.step)
        timing = Timing()
        started = time.perf_counter()
        if self._runs:
            for fmu in self.fmus:
                fmu.rewind()
        self._rewind_links()
        self._runs += 1
        topologies = contingency.topologies(stop)
        topology = topologies[0]
        n = len(self.units)
        standing = [[f.outputs() for f in u.fmus] for u in self.units]  # every device's outputs now
        # continuous angles: each bus angle kept near its machine's rotor angle (an inverter's: its load-flow angle)
        theta_ref = np.array([float(x[0][u.angle_row]) if u.angle_row is not None else float(self.case.flow.theta[i])
                              for x, u, i in zip(standing, self.units, self._gen_rows)])
        active = self._active(topology)
        V = self.case.flow.V_complex[self._gen_rows].copy()
        V, I, theta, machine = self._solve(self.network(topology).Y_real, V, theta_ref, active, timing)
        for k in active:
            standing[k][0] = machine[k]
        rows = [self._row(0.0, V, I, theta, standing, active)]
        lost = None
        V_prev, h_prev = None, None
        before = None  # (h, the start values `_values`) of the step before, where it ran smoothly into this one
        t0 = 0.0
        checkpoints, rollbacks = self._live(active)
        points = communication_points(s.step, stop, topologies[1:])
        for t1, new_topology, recorded in refined_points(points, s.event_refinement):
            h = t1 - t0
            self._set_voltages("start", V, theta, self._terminal(V, I, theta))
            self._set_measured("measured", self._measure(V, theta, topology, active))
            starts = self._values.copy()
            if V_prev is not None and s.coupling != "held":
                V1 = V + (V - V_prev) * (h / h_prev)
            else:
                V1 = V.copy()
            self._guess_ends(h / h_prev if V_prev is not None and s.coupling != "held" else None)
            theta1 = np.array([t + _wrap(cmath.phase(v) - t) for v, t in zip(V1.tolist(), theta.tolist())])
            I1 = I
            passes = s.passes if s.coupling == "iterated" else 1
            saved = passes > 1 and self.rolls_back  # each live FMU's state at t0 kept (FMU.checkpoint)
            if saved:
                t_save = time.perf_counter()
                for checkpoint in checkpoints:
                    checkpoint()
                timing.rollback_s += time.perf_counter() - t_save
            relax, previous = np.ones(n), None
            for p in range(passes if saved else 1):
                if p > 0:
                    t_save = time.perf_counter()
                    for rollback in rollbacks:
                        rollback()
                    timing.rollback_s += time.perf_counter() - t_save
                self._set_voltages("end", V1, theta1, self._terminal(V1, I1, theta1))
                self._set_measured("measured_end", self._measure(V1, theta1, topology, active))
                self._step(t0, h, active, timing, before)
                timing.passes += 1
                new_V, I1, new_theta, machine = self._solve(self.network(topology).Y_real, V1, theta1, active, timing)
                residual = new_V - V1
                change = float(np.max(np.abs(residual)))
                if change < s.tolerance or p == passes - 1 or not saved:
                    V1, theta1 = new_V, new_theta
                    break
                if previous is not None:
                    moved = residual - previous
                    norm = (moved * moved.conj()).real
                    found = norm > 0.0
                    relax[found] = np.clip(-relax[found] * (previous.conj() * moved).real[found] / norm[found],
                                           *RELAX_BOUNDS)
                previous = residual
                V1 = V1 + relax * residual
                theta1 = np.array([t + _wrap(cmath.phase(v) - t) for v, t in zip(V1.tolist(), new_theta.tolist())])
            timing.steps += 1
            V_prev, h_prev = V, h
            before = (h, starts)
            V, I, theta = V1, I1, theta1
            self._advance_links()
            outputs = self._outputs.tolist()
            for k in active:
                standing[k] = [machine[k]] + [outputs[o:o_end] for o, o_end in self._controls[k]]
            if new_topology is not None:
                before_switch, topology = self.network(topology), new_topology
                active = self._active(topology)
                checkpoints, rollbacks = self._live(active)
                V, I, theta, machine = self._solve_switched(before_switch, self.network(topology), V, theta, active,
                                                            timing)
                for k in active:
                    standing[k] = [machine[k]] + standing[k][1:]
                    self._machine_links(k)
                V_prev = before = None  # no extrapolation, no parabola across the jump
            if not recorded:
                t0 = t1
                continue
            rows.append(self._row(t1, V, I, theta, standing, active))
            if lost is None:
                lost = self._loss_time(rows, active)
                if lost is not None and s.stop_at_loss:
                    break
            t0 = t1
        timing.total_s = time.perf_counter() - started
        result = self._result(rows, topologies, lost)
        messages = {u.bus: list(dict.fromkeys(m for f in u.fmus for m in f.messages)) for u in self.units}
        return CosimResult(result=result, timing=timing, kinds=self.kinds, messages=messages, notes=self.notes)

    def _live(self, active) -> tuple:
        """The checkpoint and rollback methods of the `active` units' FMUs."""
        live = [f for k in active for f in self.units[k].fmus]
        return [f.checkpoint for f in live], [f.rollback for f in live]

    def _active(self, topology) -> list:
        """The indices of the units in service in `topology` (not among its tripped ones)."""
        out = set(topology.tripped)
        unknown = [k for k in out if not (isinstance(k, int) and 0 <= k < len(self.units))]
        if unknown:
            raise ValueError(f"{topology.description}: no unit {unknown[0]!r} to trip (units 0 to {len(self.units) - 1})")
        return [k for k in range(len(self.units)) if k not in out]

    def _row(self, t, V, I, theta, devices, active) -> dict:
        """A result row: every unit's device outputs (a tripped unit's as they stood at its trip), bus
        voltages, currents (0 where tripped), angles and machine inputs."""
        I = I.copy()
        off = [k for k in range(len(self.units)) if k not in active]
        I[off] = 0.0
        return {"time": t, "devices": list(devices), "V": V.copy(), "I": I,
                "theta": theta.copy(), "inputs": [list(u.fmus[0].inputs_now) for u in self.units]}

    def _loss_time(self, rows, active) -> float | None:
        """The time two rotor angles of the `active` units first got pi apart, linear between the last
        two rows; None if not."""
        def spread(row):
            d = [row["devices"][k][0][self.units[k].angle_row] for k in active if self.units[k].angle_row is not None]
            return float(max(d) - min(d)) if d else 0.0

        now = spread(rows[-1])
        if now <= math.pi:
            return None
        if len(rows) < 2:
            return rows[-1]["time"]
        before = spread(rows[-2])
        t0, t1 = rows[-2]["time"], rows[-1]["time"]
        return t0 + (t1 - t0) * (math.pi - before) / (now - before) if now > before else t1

    def _result(self, rows, topologies, lost) -> GridResult:
        time_ = np.array([r["time"] for r in rows])
        g = len(self.units)
        states, inputs, device_states = {}, {}, {}
        angles = np.full((len(rows), g), np.nan)
        for k, (u, labels) in enumerate(zip(self.units, device_labels(self.case.units))):
            for j, names in enumerate(u.state_names):
                values = np.array([r["devices"][k][j][:len(names)] for r in rows])
                for i, name in enumerate(names):
                    device_states[f"{labels[j]}_{name}"] = values[:, i]
                    if j == 0:
                        states.setdefault(name, np.full((len(rows), g), np.nan))[:, k] = values[:, i]
            if u.angle_row is not None:
                angles[:, k] = [r["devices"][k][0][u.angle_row] for r in rows]
            values = np.array([r["inputs"][k] for r in rows])
            for i, name in enumerate(u.inputs[0]):
                inputs.setdefault(name, np.full((len(rows), g), np.nan))[:, k] = values[:, i]
        V_gen = np.stack([r["V"] for r in rows])
        I_gen = np.stack([r["I"] for r in rows])
        S = V_gen * np.conj(I_gen)
        for k, labels in enumerate(device_labels(self.case.units)):
            device_states[f"{labels[0]}_P"], device_states[f"{labels[0]}_Q"] = S.real[:, k], S.imag[:, k]
            device_states[f"{labels[0]}_I_re"], device_states[f"{labels[0]}_I_im"] = I_gen.real[:, k], I_gen.imag[:, k]
        # bus voltages: the recovery of the topology in force at each row
        V_bus = np.empty((len(rows), len(self.case.buses)), dtype=complex)
        for i, t in enumerate(time_):
            tp = [tp for tp in topologies if tp.start <= t + 1e-12][-1]
            V_bus[i] = self.network(tp).recovery @ V_gen[i][self._first]
        theta_vs = np.stack([r["theta"] for r in rows])
        theta_bus = np.unwrap(np.angle(V_bus), axis=0)
        theta_bus[:, self._gen_rows] = theta_vs
        return GridResult(time=time_, states=states, Vs=np.abs(V_gen), theta_vs=theta_vs, P=S.real, Q=S.imag,
                          V_bus=np.abs(V_bus), theta_bus=theta_bus, stable=lost is None, loss_of_synchronism_s=lost,
                          events=tuple((tp.start, tp.description) for tp in topologies[1:]),
                          gen_buses=self.case.generator_buses, buses=self.case.buses, machine_inputs=inputs,
                          rotor_angle=angles, device_states=device_states)
