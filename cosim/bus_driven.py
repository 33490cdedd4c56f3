"""A unit (a machine with a bus port and its control devices, each an FMU) on a bus whose voltage is
prescribed, coupled by a Gauss-Seidel master; checked against the monolithic solve of the same
unit (reference_models.grid.monolithic.simulate_unit).

The coupling, every communication step [t_k, t_k + h], wired by the FMUs' ports (case.unit_wiring):

1. set the machine's bus voltage and its set-point links (the columns of `bus` at t_k, held over
   the step);
2. read its bus current (outputs that depend on the voltage directly; the FMUs recompute them after
   a set) and compute the terminal voltage behind the machine's external impedance;
3. set every control device's inputs (the terminal voltage and the machine's links at t_k, set
   points at their start values) and step it over [t_k, t_k + h];
4. set the machine's links from the controls to their outputs at t_k + h and step the machine.

So the controls hold their inputs at t_k and the machine holds the controls' outputs at t_k + h: a
coupling error of first order in h, the same for any machine FMU.

A device's parameters are read from its FMU (resources/machine.json of the reference FMUs, the
operator's metadata of a surrogate FMU) unless given, so a master knows the external impedance of
the machine; `same_parameters` refuses two FMUs of different parameters. Errors: CouplingError, one line.
"""
from __future__ import annotations

import json
import shutil
import tempfile
import time
import weakref
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from reference_models.grid.case import CaseError, Device, at_rest, external_impedance, held_inputs, unit_wiring

from .fmu import FMU, CouplingError, component_described


def fmu_parameters(directory: Path, component):
    """The parameters of `component` an extracted FMU was built with: resources/machine.json, or the
    operator's metadata (resources/model.onnx). CouplingError where it carries neither."""
    from reference_models.component import ParameterError

    record, operator = directory / "resources" / "machine.json", directory / "resources" / "model.onnx"
    if record.is_file():
        try:
            return component.params(json.loads(record.read_text(encoding="utf-8")))
        except (OSError, ValueError, ParameterError) as exc:
            raise CouplingError(f"{directory.name}: resources/machine.json holds no {component.name} parameters "
                                f"({' '.join(str(exc).split())[:160]})") from None
    if operator.is_file():
        from surrogate.contract import ContractError, metadata_of, operator_metadata

        try:
            meta = operator_metadata(metadata_of(operator))
        except ContractError as exc:
            raise CouplingError(f"{directory.name}: {exc}") from None
        except OSError as exc:
            raise CouplingError(f"{directory.name}: resources/model.onnx is not a readable operator "
                                f"({' '.join(str(exc).split())[:120]})") from None
        if meta["component"].name != component.name:
            raise CouplingError(f"{directory.name}: its operator is of {meta['component'].name}, not {component.name}")
        return meta["params"]
    raise CouplingError(f"{directory.name}: the FMU records no {component.name} parameters (no resources/machine.json "
                        "or resources/model.onnx); give them")


class UnitFMU:
    """One device of a unit as an FMU: the FMU file (or extracted folder) at `path`, extracted once
    (into a temporary folder removed with this object), its component (the one its model description
    names) and parameters (read from the FMU unless given), its ports, the time inside its steps
    (`do_step_s`) and what it logged in its last run."""

    def __init__(self, path, params=None, name: str | None = None):
        from fmpy import extract, read_model_description

        path = Path(path)
        try:
            if path.is_file():
                directory = Path(tempfile.mkdtemp(prefix="opfmu_unit_"))
                weakref.finalize(self, shutil.rmtree, str(directory), True)
                extract(str(path), unzipdir=str(directory))
            else:
                directory = path
            md = read_model_description(str(directory))
        except Exception as exc:  # fmpy raises plain Exceptions for unreadable files
            raise CouplingError(f"{path.name} is not a readable FMU: {' '.join(str(exc).split())[:160]}") from None
        self.path, self.directory, self.md = path, directory, md
        self.name = name or md.modelName
        probe = FMU((directory, md), self.name, init=False)
        self.ports = probe.ports
        probe.close()
        if self.ports is None:
            raise CouplingError(f"{self.name} declares no ports and is not an opfmu FMU of a known component")
        self.component = component_described(md.description)
        if params is None and self.component is None:
            raise CouplingError(f"{self.name}: its component is unknown; give its parameters")
        self.params = params if params is not None else fmu_parameters(directory, self.component)
        self.fmu, self.do_step_s, self.messages = None, 0.0, []

    def device(self) -> Device:
        """The case.Device of this FMU (its component and parameters)."""
        return Device(self.name, self.component, self.params)

    def start(self, values: dict) -> FMU:
        """A new initialised instance with the start values `values` (by variable name)."""
        self.close()
        self.do_step_s, self.messages = 0.0, []
        self.fmu = FMU((self.directory, self.md), self.name, start=values)
        return self.fmu

    def step(self, h: float) -> None:
        began = time.perf_counter()
        try:
            self.fmu.do_step(self.fmu.t, h)
        finally:
            self.do_step_s += time.perf_counter() - began
        self.fmu.t += h

    def close(self) -> None:
        if self.fmu is not None:
            self.messages = list(self.fmu.messages)
            self.fmu.close()
            self.fmu = None


def same_parameters(a: UnitFMU, b: UnitFMU) -> None:
    """CouplingError unless the two FMUs were built for the same parameters (two machine FMUs of
    different machines are no comparison)."""
    if a.params != b.params:
        pa, pb = a.params.to_dict(), b.params.to_dict()
        differ = [f"{k} {pa[k]!r} / {pb[k]!r}" for k in pa if pa[k] != pb[k]]
        raise CouplingError(f"{a.name} and {b.name} model different {a.component.name} parameters: "
                            f"{', '.join(differ[:5])}")


def _wiring(units) -> tuple:
    if units[0].ports.bus is None:
        raise CouplingError(f"{units[0].name} declares no bus port: the unit's first FMU must be its machine")
    try:
        return unit_wiring([u.ports for u in units], "the unit")
    except CaseError as exc:
        raise CouplingError(str(exc)) from None


def start_at_rest(units, x0, bus_row, links: dict) -> tuple:
    """case.DeviceStart of every unit FMU (the machine first) with the machine at rest in state x0
    under the bus row (magnitude, angle, set points: see `couple`) and the other links it takes
    (`links`: {variable: value}, e.g. the field voltage): the controls started holding them."""
    machine = units[0]
    ports = machine.ports
    held = held_inputs(ports, _wiring(units)[0])
    values = {ports.bus.voltage[0]: float(bus_row[0]), ports.bus.voltage[1]: float(bus_row[1])}
    values.update(zip(held, map(float, bus_row[2:])))
    values.update({k: float(v) for k, v in links.items()})
    try:
        return at_rest([u.device() for u in units], x0, values)
    except (CaseError, KeyError) as exc:
        raise CouplingError(f"no start at rest: {exc}") from None


@dataclass
class Run:
    """A coupled run: at the communication points times [T], the states of every device [T, n_j]
    (`states[0]` the machine's, `states[1:]` the controls'), the terminal voltage [T] the controls
    saw (the last one at the final state); seconds inside each FMU's steps and of the whole run
    (wall_s: instantiation to freeing); a surrogate machine's in_envelope (all points; None for an
    FMU without it) and largest residual; what the FMUs logged."""

    times: np.ndarray
    states: list
    terminal_voltage: np.ndarray
    do_step_s: list
    wall_s: float
    in_envelope: bool | None = None
    max_residual: float | None = None
    messages: list = field(default_factory=list)

    @property
    def machine(self) -> np.ndarray:
        return self.states[0]


def check_inputs(times, bus, columns: int) -> tuple:
    times, bus = np.asarray(times, dtype=float), np.asarray(bus, dtype=float)
    if times.ndim != 1 or len(times) < 2 or times[0] != 0 or not np.all(np.diff(times) > 0):
        raise CouplingError("the communication points must start at 0 and increase (at least two)")
    if bus.shape != (len(times), columns) or not np.all(np.isfinite(bus)):
        raise CouplingError(f"the bus inputs must be finite at every communication point, [{len(times)}, {columns}] "
                            f"(voltage magnitude, angle, set points); got {list(bus.shape)}")
    return times, bus


def couple(units, times, bus, starts, machine_parameters: dict | None = None) -> Run:
    """Run the unit's FMUs (units: UnitFMU, the machine first) by the module docstring's scheme over
    the communication points `times` [T] with bus [T, 2 + k] (bus voltage magnitude [pu], angle
    [rad] and the machine's k set-point links, at each point held over the step after it), from
    `starts` (case.DeviceStart per unit, e.g. start_at_rest). machine_parameters: further start
    values of the machine FMU (e.g. a surrogate's rollover_horizon)."""
    units = list(units)
    wiring = _wiring(units)
    machine_unit = units[0]
    held = held_inputs(machine_unit.ports, wiring[0])
    times, bus = check_inputs(times, bus, 2 + len(held))
    ports = machine_unit.ports
    impedance = external_impedance(machine_unit.device())
    n = len(times)
    states = [np.empty((n, len(s.states))) for s in starts]
    Vt = np.empty(n)
    began = time.perf_counter()
    fmus = []
    try:
        for u, s in zip(units, starts):
            names = u.component.state_names if u.component is not None else ()
            values = {f"{name}0": v for name, v in zip(names, s.states)} | dict(s.inputs)
            if u is machine_unit:
                values |= dict(machine_parameters or {})
            fmus.append(u.start(values))
        state_names = [tuple(f"{name}" for name in (u.component.state_names if u.component else ())) for u in units]
        machine = fmus[0]
        has_envelope = "in_envelope" in machine.vr and "residual" in machine.vr
        envelope, residual = True, 0.0
        for j, f in enumerate(fmus):
            states[j][0] = f.get(*state_names[j])
        for k in range(n - 1):
            h = times[k + 1] - times[k]
            row = bus[k]
            machine.set(**{ports.bus.voltage[0]: row[0], ports.bus.voltage[1]: row[1]}, **dict(zip(held, row[2:])))
            I_re, I_im = machine.get(*ports.bus.current)
            V = row[0] * np.exp(1j * row[1])
            terminal = V + impedance * complex(I_re, I_im)
            Vt[k] = abs(terminal)
            for j in range(1, len(fmus)):
                inputs = {}
                for name, source in wiring[j].items():
                    if source.kind == "terminal":
                        inputs[name] = Vt[k] if source.index == 0 else float(np.angle(terminal))
                    elif source.kind == "device" and source.device == 0:
                        inputs[name] = machine.get(source.variable)[0]
                if inputs:
                    fmus[j].set(**inputs)
                units[j].step(h)
                states[j][k + 1] = fmus[j].get(*state_names[j])
            links = {name: fmus[source.device].get(source.variable)[0] for name, source in wiring[0].items()
                     if source.kind == "device"}
            if links:
                machine.set(**links)
            machine_unit.step(h)
            states[0][k + 1] = machine.get(*state_names[0])
            if has_envelope:
                envelope = envelope and machine.get_boolean("in_envelope")
                residual = max(residual, machine.get("residual")[0])
        I_re, I_im = machine.get(*ports.bus.current)  # at the last point, under the last bus inputs held
        Vt[-1] = abs(bus[-1, 0] * np.exp(1j * bus[-1, 1]) + impedance * complex(I_re, I_im))
    except CouplingError:
        raise
    except Exception as exc:  # fmpy's FMICallException
        failed = next((u for u in units if u.fmu is not None and u.fmu.messages), units[0])
        raise CouplingError(f"{failed.name} failed: {' '.join(str(exc).split())[:160]}"
                            + (f" ({failed.fmu.messages[-1][1]})" if failed.fmu and failed.fmu.messages else "")) from None
    finally:
        for u in units:
            u.close()
    return Run(times, states, Vt, [u.do_step_s for u in units], time.perf_counter() - began,
               envelope if has_envelope else None, residual if has_envelope else None, [u.messages for u in units])
