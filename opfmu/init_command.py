"""`opfmu init`: start values of a machine and its exciter from a load-flow result.

The machine and the exciter are the components reference_models/initialisation.py gives start
values for (MACHINE, EXCITER: SM4 and IEEE1; the examples below use their names), wired by their
ports: the bus voltage goes to the machine's bus port, the mechanical power and field voltage that
hold it to its `mechanical_power` and `field_voltage` links, the terminal voltage and set point to
the exciter's `terminal_voltage` and `voltage_reference` links.

The values are keyed by the FMU variable names, so they go straight into an importer, e.g. fmpy's
`simulate_fmu(..., start_values=result["machine"])`:

* machine FMU: the initial-state parameters (delta0, omega0, Ed_p0, Eq_p0) and the inputs
  (Vs, theta_vs, Pm, Efd) that hold it in equilibrium;
* exciter FMU: the initial-state parameters (Efd0, RF0, VR0) and the inputs (Vt, Vref).

One operating point from flags (`--V --theta-deg|--theta --P --Q`), or every generator of a
load-flow file (`--load-flow FILE`, format in `load_flow_points`). The equations are in
reference_models/initialisation.py and docs/initialisation.md.

`--component NAME` takes another machine (any registered component with a bus port: GENROU,
GENCLS, ...): its start comes from its own initialisation (Component.start with the load-flow point
V0, theta0, P0, Q0, as a grid case starts it), keyed the same way (its `<state>0` parameters and its
inputs); the exciter (IEEE1) is started from the field voltage its field_voltage link takes and the
terminal voltage, and is refused for a machine without that link. SM4's values are those above.
"""
from __future__ import annotations

import json
import math
from numbers import Real
from pathlib import Path

from reference_models.component import ParameterError
from reference_models.initialisation import EXCITER, MACHINE, exciter_start, machine_start
from reference_models.messages import explain
from reference_models.ports import machine_inputs

MAX_LOAD_FLOW_BYTES = 1024 * 1024
MAX_GENERATORS = 1000
DEFAULT_EXCITER = EXCITER.params()  # the WSCC exciter
POINT_KEYS = ("V", "theta", "theta_deg", "P", "Q")
GENERATOR_KEYS = POINT_KEYS + ("name", "bus", "machine", "exciter")


class InitError(ValueError):
    """A load-flow point, file or parameter set `opfmu init` cannot start from (one line)."""


def start_parameter_names(component, params, x0) -> list:
    """The names of the FMU's initial-state parameters, in state order (fmu_export.variables' table)."""
    from fmu_export.variables import fmu_variables

    return [v.name for v in fmu_variables(component, params, x0) if v.causality == "parameter"]


def machine_component(name):
    """The registered component `name` if it can be started from a load flow (a bus port);
    InitError naming what init takes otherwise."""
    from reference_models.components import component

    try:
        found = component(name)
    except ValueError as exc:
        raise InitError(str(exc)) from None
    if found.ports.bus is None:
        raise InitError(f"the {found.name} component has no bus port: init takes a machine on a bus (sm4, genrou, ...)")
    return found


def component_of(machine):
    """The registered component whose parameters `machine` is (an SM4Params: SM4)."""
    from reference_models.components import COMPONENTS

    if isinstance(machine, MACHINE.params_type):
        return MACHINE
    found = [c for c in COMPONENTS.values() if isinstance(machine, c.params_type) and c.ports.bus is not None]
    if not found:
        raise TypeError(f"no machine on a bus has parameters of type {type(machine).__name__}")
    return found[0]


def start_values(V: float, theta: float, P: float, Q: float, machine, exciter=None) -> dict:
    """{"machine": {FMU variable: value}, "exciter": {...} (absent when exciter is None),
    "operating_point": {...}} for the generator at bus voltage V [pu] at angle theta [rad] that
    injects P + jQ [pu]; machine, exciter: the parameters of MACHINE (or of another machine on a bus:
    generic_start_values), EXCITER (exciter None: none). ValueError (one line) where there is no
    such start."""
    if not isinstance(machine, MACHINE.params_type):
        return generic_start_values(V, theta, P, Q, machine, exciter)
    ms = machine_start(V, theta, P, Q, machine)
    out = {"machine": {**dict(zip(start_parameter_names(MACHINE, machine, ms.x0), map(float, ms.x0))),
                       **_machine_inputs(V, theta, ms.Pm, ms.Efd)}}
    if exciter is not None:
        es = exciter_start(ms.Efd, ms.Vt, exciter)
        links = {EXCITER.ports.input("terminal_voltage"): ms.Vt, EXCITER.ports.input("voltage_reference"): es.Vref}
        out["exciter"] = {**dict(zip(start_parameter_names(EXCITER, exciter, es.x0), map(float, es.x0))),
                          **{name: links[name] for name in EXCITER.input_names}}
    out["operating_point"] = {"V": float(V), "theta": float(theta), "theta_deg": math.degrees(theta),
                              "P": float(P), "Q": float(Q), "Vt": ms.Vt, "Id": ms.Id, "Iq": ms.Iq,
                              "I_re": ms.I_re, "I_im": ms.I_im, "delta_deg": math.degrees(ms.x0[0]),
                              "stable_at_constant_field": _on_stable_branch(ms, V, theta, machine)}
    return out


def generic_start_values(V: float, theta: float, P: float, Q: float, machine, exciter=None) -> dict:
    """start_values of any machine on a bus (its component found by its parameters' type): its start
    from its own initialisation (Component.start with V0, theta0, P0, Q0 and the bus voltage), the
    exciter's from the field voltage its field_voltage link takes and the terminal voltage behind its
    external impedance (Re + j Xep where it has them). operating_point: V, theta, theta_deg, P, Q, Vt,
    I_re, I_im, delta_deg (where it gives a rotor angle) and stable_at_constant_field."""
    import cmath

    import numpy as np

    component = component_of(machine)
    numbers = {"V": V, "theta": theta, "P": P, "Q": Q}
    bad = [k for k, v in numbers.items() if not (isinstance(v, Real) and math.isfinite(float(v)))]
    if bad:
        raise ValueError(f"{', '.join(bad)} must be finite numbers")
    bus = component.ports.bus
    given = {bus.voltage[0]: float(V), bus.voltage[1]: float(theta), "V0": float(V), "theta0": float(theta),
             "P0": float(P), "Q0": float(Q)}
    try:
        x0, inputs = component.start(given, machine)
    except ValueError as exc:
        raise ValueError(f"{component.name.upper()} has no start at V={V} pu, theta={theta} rad, P={P} pu, Q={Q} pu: "
                         f"{' '.join(str(exc).split())[:160]}") from None
    u = np.array([inputs[n] for n in component.input_names])
    if not (np.all(np.isfinite(x0)) and np.all(np.isfinite(u))):
        raise ValueError(f"no finite start of the {component.name} machine at V={V} pu, theta={theta} rad, "
                         f"P={P} pu, Q={Q} pu")
    y = dict(zip(component.output_names, component.output_values(x0, u, machine)))
    current = complex(y[bus.current[0]], y[bus.current[1]])
    Vt = abs(cmath.rect(V, theta) + complex(float(getattr(machine, "Re", 0.0)), float(getattr(machine, "Xep", 0.0)))
             * current)
    names = start_parameter_names(component, machine, x0)
    out = {"machine": {**dict(zip(names, map(float, x0))), **{n: float(inputs[n]) for n in component.input_names}}}
    field = component.ports.input("field_voltage")
    if exciter is not None:
        if field is None:
            raise ValueError(f"the {component.name} machine takes no field voltage (no field_voltage link): "
                             "no exciter; use --no-exciter")
        es = exciter_start(float(inputs[field]), Vt, exciter)
        links = {EXCITER.ports.input("terminal_voltage"): Vt, EXCITER.ports.input("voltage_reference"): es.Vref}
        out["exciter"] = {**dict(zip(start_parameter_names(EXCITER, exciter, es.x0), map(float, es.x0))),
                          **{name: links[name] for name in EXCITER.input_names}}
    op = {"V": float(V), "theta": float(theta), "theta_deg": math.degrees(theta), "P": float(P), "Q": float(Q),
          "Vt": float(Vt), "I_re": current.real, "I_im": current.imag}
    rotor = _rotor_state(component)
    if rotor is not None:
        op["delta_deg"] = math.degrees(x0[rotor])
    try:
        rest = component.steady_state(u, machine)
        stable = bool(np.allclose(rest, x0, rtol=1e-6, atol=1e-6)) if rotor is None else \
            bool(abs(math.remainder(rest[rotor] - x0[rotor], 2 * math.pi)) < 1e-6)
    except ValueError:
        stable = False
    op["stable_at_constant_field"] = stable
    out["operating_point"] = op
    return out


def _rotor_state(component):
    """The index of the state giving the rotor angle (its rotor_angle link, else its drift's first
    angle state), or None."""
    name = component.ports.output("rotor_angle")
    if name in component.state_names:
        return component.state_names.index(name)
    return component.drift.angle_states[0] if component.drift is not None else None


def _machine_inputs(V: float, theta: float, Pm: float, Efd: float) -> dict:
    """{input name: value} of the machine, in its input order, by its ports: the bus voltage V [pu]
    at angle theta [rad] to its bus port, Pm and Efd [pu] to its mechanical_power and field_voltage links."""
    wiring = machine_inputs(MACHINE)
    given = {wiring.magnitude: float(V), wiring.angle: float(theta), wiring.power: Pm, wiring.field: Efd}
    return {name: given[name] for name in MACHINE.input_names}


def _on_stable_branch(ms, V, theta, machine) -> bool:
    """Whether the start is the machine's own stable equilibrium at its inputs (SM4: on the rising
    side of the steady-state power-angle curve at constant field voltage; false past its peak,
    where only a voltage regulator holds the machine)."""
    try:
        x = MACHINE.steady_state(tuple(_machine_inputs(V, theta, ms.Pm, ms.Efd).values()), machine)
    except ValueError:
        return False
    rotor = MACHINE.drift.angle_states[0]
    return bool(abs(math.remainder(x[rotor] - ms.x0[rotor], 2 * math.pi)) < 1e-6)


# --- the load-flow file -------------------------------------------------------------------------

def _refuse_constant(name: str):
    raise ValueError(f"{name} is not a number this file may hold")


def _read_json(path: Path, what: str, limit: int):
    try:
        if path.stat().st_size > limit:
            raise InitError(f"{what} {path} is larger than {limit} bytes")
        return json.loads(path.read_text(encoding="utf-8"), parse_constant=_refuse_constant)
    except InitError:
        raise
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
        reason = explain(exc)
        raise InitError(f"cannot read {what} {path}: {reason}") from None


def _label(text) -> str:
    """A name from a file, printable on one line."""
    return "".join(c if c.isprintable() else "?" for c in str(text))[:60]


def _parameters(spec, component, base: Path, where: str):
    """Parameters of `component` from a load-flow entry: a file name (relative to the load-flow
    file), {"file": NAME} or {"params": {...}}, optionally with "component"."""
    try:
        if isinstance(spec, str):
            return component.load_params(base / spec)
        if isinstance(spec, dict):
            unknown = sorted(set(spec) - {"component", "file", "params"})
            if unknown:
                raise InitError(f"{where}: unknown key(s) {', '.join(map(repr, unknown))[:100]} "
                                "(known: component, file, params)")
            if spec.get("component", component.name) != component.name:
                raise InitError(f"{where}: component must be {component.name!r}, got {_label(spec['component'])!r}")
            if ("file" in spec) == ("params" in spec):
                raise InitError(f"{where}: give one of file or params")
            if "file" in spec:
                if not isinstance(spec["file"], str):
                    raise InitError(f"{where}: file must be a file name")
                return component.load_params(base / spec["file"])
            return component.params(spec["params"])
    except ParameterError as exc:
        raise InitError(f"{where}: {exc}") from None
    raise InitError(f"{where}: must be a file name or an object with file or params")


def _point_number(entry: dict, key: str, where: str) -> float:
    value = entry[key]
    try:
        if not isinstance(value, bool) and isinstance(value, Real) and math.isfinite(float(value)):
            return float(value)
    except OverflowError:  # an integer beyond the floats
        pass
    raise InitError(f"{where}: {key} must be a finite number, got {_label(json.dumps(value))[:40]}")


def load_flow_points(path, machine=None, exciter=DEFAULT_EXCITER, component=MACHINE) -> list:
    """The generators of a load-flow file: [(name, V, theta [rad], P, Q, machine, exciter)].

    The file is a JSON object {"generators": [entry, ...]}, a list of entries or one entry. An entry
    has V [pu], theta_deg [deg] or theta [rad], P and Q [pu] (injected into the bus) and optionally
    name or bus (a label), machine and exciter: a parameter file name (relative to the load-flow
    file), {"file": NAME} or {"params": {...}} (with an optional "component": "sm4" / "ieee1", as in
    reference_models/grid/data/wscc9.json); exciter null: no exciter. Without them, `machine` and
    `exciter` (parameters of MACHINE / EXCITER, or None) apply; component: the machine's component
    (default MACHINE, SM4), whose parameters the entries give. InitError (one line) for anything else."""
    path = Path(path)
    data = _read_json(path, "load-flow file", MAX_LOAD_FLOW_BYTES)
    if isinstance(data, dict) and "generators" in data:
        unknown = sorted(set(data) - {"generators", "case", "description"})
        if unknown:
            raise InitError(f"{path}: unknown key(s) {', '.join(map(repr, unknown))[:100]} "
                            "(known: generators, case, description)")
        entries = data["generators"]
    else:
        entries = [data] if isinstance(data, dict) else data
    if not isinstance(entries, list) or not entries:
        raise InitError(f"{path}: needs a generator (an object) or a non-empty list of them")
    if len(entries) > MAX_GENERATORS:
        raise InitError(f"{path}: more than {MAX_GENERATORS} generators")
    machine = component.params() if machine is None else machine
    points = []
    for k, entry in enumerate(entries):
        where = f"{path}: generator {k + 1}"
        if not isinstance(entry, dict):
            raise InitError(f"{where}: must be an object with V, theta_deg (or theta), P, Q")
        unknown = sorted(set(entry) - set(GENERATOR_KEYS))
        if unknown:
            raise InitError(f"{where}: unknown key(s) {', '.join(_label(repr(u)) for u in unknown)[:100]} "
                            f"(known: {', '.join(GENERATOR_KEYS)})")
        name = _label(entry["name"]) if "name" in entry else f"bus {_label(entry['bus'])}" if "bus" in entry \
            else f"generator {k + 1}"
        where = f"{path}: {name}"
        missing = [key for key in ("V", "P", "Q") if key not in entry]
        if missing or ("theta" in entry) == ("theta_deg" in entry):
            raise InitError(f"{where}: needs V, P, Q and one of theta_deg or theta"
                            + (f" (missing {', '.join(missing)})" if missing else ""))
        V, P, Q = (_point_number(entry, key, where) for key in ("V", "P", "Q"))
        theta = (_point_number(entry, "theta", where) if "theta" in entry
                 else math.radians(_point_number(entry, "theta_deg", where)))
        m = _parameters(entry["machine"], component, path.parent, f"{where}: machine") if "machine" in entry \
            else machine
        if "exciter" not in entry:
            e = exciter
        elif entry["exciter"] is None:
            e = None
        else:
            e = _parameters(entry["exciter"], EXCITER, path.parent, f"{where}: exciter")
        points.append((name, V, theta, P, Q, m, e))
    return points


# --- the command --------------------------------------------------------------------------------

def add_init_parser(sub) -> None:
    """Registers `opfmu init` on the subcommand parsers `sub`."""
    def names(component) -> str:
        return (f"{', '.join(f'{n}0' for n in component.state_names)} and inputs "
                f"{', '.join(component.input_names)}")

    init = sub.add_parser(
        "init", help="machine and exciter start values from a load-flow result",
        description=f"Start values of a machine ({MACHINE.name}) and its exciter ({EXCITER.name}) "
                    f"in equilibrium at a load-flow point (Sauer-Pai), keyed by the FMU variable names: the machine "
                    f"FMU's {names(MACHINE)}; the exciter FMU's {names(EXCITER)}. P + jQ is the power the "
                    "generator injects into its bus.")
    init.add_argument("--component", default=None, metavar="NAME",
                      help=f"the machine's component: any registered one with a bus port (default {MACHINE.name}; "
                           "e.g. genrou), started by its own initialisation")
    init.add_argument("--machine", default=None, metavar="FILE",
                      help=f"JSON file of the machine's parameters (default: the component's; {MACHINE.name}: paper "
                           "Table I; with --load-flow: for generators that name none)")
    exciter = init.add_mutually_exclusive_group()
    exciter.add_argument("--exciter", default=None, metavar="FILE",
                         help=f"JSON file of {EXCITER.name} parameters (default: the WSCC exciter)")
    exciter.add_argument("--no-exciter", action="store_true", help="the machine only (its field voltage held)")
    init.add_argument("--V", type=float, default=None, metavar="PU", help="bus voltage magnitude [pu]")
    angle = init.add_mutually_exclusive_group()
    angle.add_argument("--theta-deg", type=float, default=None, metavar="DEG", help="bus voltage angle [deg]")
    angle.add_argument("--theta", type=float, default=None, metavar="RAD", help="bus voltage angle [rad]")
    init.add_argument("--P", type=float, default=None, metavar="PU", help="active power into the bus [pu]")
    init.add_argument("--Q", type=float, default=None, metavar="PU", help="reactive power into the bus [pu]")
    init.add_argument("--load-flow", default=None, metavar="FILE",
                      help="JSON file of generators instead of --V/--theta/--P/--Q: {\"generators\": [{\"name\" or "
                           "\"bus\", \"V\", \"theta_deg\" (or \"theta\"), \"P\", \"Q\", optional \"machine\" and "
                           "\"exciter\": a parameter file name, {\"file\": ...} or {\"params\": {...}}}, ...]}")
    init.add_argument("--json", action="store_true", help="print JSON (full precision) instead of a table")
    init.set_defaults(func=run_init)


def run_init(args) -> None:
    from opfmu.errors import UserError

    point = {"--V": args.V, "--P": args.P, "--Q": args.Q,
             "--theta-deg/--theta": args.theta if args.theta is not None else args.theta_deg}
    try:
        component = MACHINE if args.component is None else machine_component(args.component)
        machine = component.params() if args.machine is None else component.load_params(args.machine)
        exciter = None if args.no_exciter else DEFAULT_EXCITER if args.exciter is None \
            else EXCITER.load_params(args.exciter)
        if args.load_flow is not None:
            given = [flag for flag, value in point.items() if value is not None]
            if given:
                raise UserError(f"init: --load-flow gives the operating points; drop {', '.join(given)}")
            points = load_flow_points(args.load_flow, machine, exciter, component)
        else:
            missing = [flag for flag, value in point.items() if value is None]
            if missing:
                raise UserError(f"init: needs {', '.join(missing)} (or --load-flow FILE)")
            theta = args.theta if args.theta is not None else math.radians(args.theta_deg)
            points = [(None, args.V, theta, args.P, args.Q, machine, exciter)]
        results = []
        for name, V, theta, P, Q, m, e in points:
            try:
                results.append((name, start_values(V, theta, P, Q, m, e)))
            except ValueError as exc:
                raise InitError(f"{name}: {exc}" if name else str(exc)) from None
    except (ParameterError, InitError) as exc:
        raise UserError(f"init: {exc}") from None
    if args.json:
        if args.load_flow is None:
            print(json.dumps(results[0][1], indent=2))
        else:
            print(json.dumps({"generators": [{"name": n, **r} for n, r in results]}, indent=2))
        return
    print("\n\n".join(format_table(r, n, component) for n, r in results))


def format_table(result: dict, name: str | None = None, component=MACHINE) -> str:
    """The start values of one generator (its machine of `component`) as a readable table."""
    op = result["operating_point"]
    title = f"{name}: " if name else ""
    lines = [(f"{title}bus V = {op['V']:.6g} pu at {op['theta_deg']:.6g} deg, P = {op['P']:.6g} pu, "
              f"Q = {op['Q']:.6g} pu (injected)")]
    for key, model in (("machine", component), ("exciter", EXCITER)):
        if key not in result:
            continue
        units = {f"{q.name}0": (q.unit, "initial state") for q in model.states}
        units.update({q.name: (q.unit, "input") for q in model.inputs})
        lines.append(f"  {key} FMU ({model.name})")
        for variable, value in result[key].items():
            unit, kind = units.get(variable, ("", ""))
            extra = f" ({math.degrees(value):.6g} deg)" if unit == "rad" else ""
            lines.append(f"    {variable:<10}{value:>16.10g} {unit:<6}{kind}{extra}")
    stator = f"stator currents Id = {op['Id']:.10g}, Iq = {op['Iq']:.10g} pu; " if "Id" in op else ""
    lines.append(f"  terminal voltage Vt = {op['Vt']:.10g} pu; {stator}bus current {op['I_re']:.10g} "
                 f"{'-' if op['I_im'] < 0 else '+'} {abs(op['I_im']):.10g}j pu")
    if not op["stable_at_constant_field"]:
        lines.append("  note: past the peak of the machine's steady-state power-angle curve: with Efd held (no "
                     "exciter) this equilibrium is unstable")
    return "\n".join(lines)
