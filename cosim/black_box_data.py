"""Datasets of a sub-system given only as an FMU with the bus port (a black box: exported by another
tool, or an opfmu FMU), driven through fmpy and never read inside (issue 35, docs/subsystems.md).

What drives it is what a host grid does at a bus: each run of the plan (cosim.subsystem_data.Plan,
the same draw of faults near and far, line openings and generator trips) runs the host case alone
in opfmu's master with native FMUs, and the voltage it records at the attachment bus is replayed
into the black box, open loop: the box starts at its own start values, settles for SETTLE_S with
the run's load-flow voltage held, then follows the recorded voltage step by step (10 ms, linear
within a step where the FMU interpolates its inputs), and its bus current after each input is set
is the row. Nothing inside is known, so the `subsystem` component's passive part is zero (G = B =
0) and the operator learns the whole current; the box's own voltage start is V_own, and its rest
there gives Ip_own, Iq_own.

The rows go through the same windows, splits, metadata and resumption as the detail's
(cosim.subsystem_data), so training, export and the FMU builder take the dataset unchanged.
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from reference_models.files import write_npz
from surrogate.data.datasets import DatasetError

from .fmu import FMU, CouplingError
from .subsystem_data import (Plan, Run, _assemble, attachment_buses, contingency_of, draw_runs, finished, fingerprint,
                             run_all)

SETTLE_S = 2.0  # s the box rests at the run's load-flow voltage before the replay


POWER_FLOOR_PU = 1e-3  # pu: below this boundary voltage a box that gives P and Q has no current to give

# what a unit of a port variable is in opfmu's: rad per angle unit; pu (system base) per power unit
_ANGLE_UNITS = {"": 1.0, "rad": 1.0, "deg": math.pi / 180.0}
_PER_UNIT = {"", "pu", "p.u."}
_POWER_UNITS = {"W": 1e-6, "var": 1e-6, "VA": 1e-6, "kW": 1e-3, "kvar": 1e-3, "kVA": 1e-3, "MW": 1.0, "Mvar": 1.0,
                "MVAr": 1.0, "MVAR": 1.0, "MVA": 1.0}  # MW per unit: divided by the system base
_SPEC_KEYS = {"V", "theta", "I_re", "I_im", "P", "Q"}


@dataclass(frozen=True)
class BoxPort:
    """How a black box's bus is read. magnitude, angle: its voltage inputs (magnitude in pu);
    outputs: the real and imaginary part of its current, kind "current", or its P and Q, kind
    "power"; angle_scale: rad per unit of the angle; output_scales: what one unit of each output is
    in opfmu's convention (pu of the system base, into the bus; a negative scale for a box that
    gives what it draws)."""
    magnitude: str
    angle: str
    outputs: tuple
    kind: str = "current"
    angle_scale: float = 1.0
    output_scales: tuple = (1.0, 1.0)

    def current(self, V: float, theta: float, values) -> complex:
        """The bus current [pu, system base, network frame, into the bus] the box's outputs `values`
        give at its voltage V [pu], theta [rad]; ValueError where a power box's voltage is below
        POWER_FLOOR_PU (no current follows from P and Q there)."""
        a, b = values[0] * self.output_scales[0], values[1] * self.output_scales[1]
        if self.kind == "current":
            return complex(a, b)
        if abs(V) < POWER_FLOOR_PU:
            raise ValueError(f"the box gives P and Q, not its current: at V = {V:.3g} pu its current is undefined")
        return (complex(a, b) / (V * complex(math.cos(theta), math.sin(theta)))).conjugate()


def parse_bus_port(text: str) -> dict:
    """{key: (variable name, sign)} of a --bus-port text "V=NAME,theta=NAME,I_re=NAME,I_im=NAME" or
    "V=...,theta=...,P=NAME,Q=NAME" (a name after "-": its value negated); ValueError (one line)
    for any other."""
    found = {}
    for part in str(text).split(","):
        key, eq, name = part.strip().partition("=")
        sign = -1.0 if name.startswith("-") else 1.0
        name = name[1:] if sign < 0 else name
        if not eq or key not in _SPEC_KEYS or not name or key in found:
            raise ValueError(f"{part.strip()[:60]!r}: each part is KEY=NAME once, KEY one of "
                             f"{', '.join(sorted(_SPEC_KEYS))}")
        found[key] = (name, sign)
    if set(found) not in ({"V", "theta", "I_re", "I_im"}, {"V", "theta", "P", "Q"}):
        raise ValueError("it names V and theta, and either I_re and I_im or P and Q")
    if found["V"][1] < 0 or found["theta"][1] < 0:
        raise ValueError("V and theta are inputs: no sign")
    return found


def _unit(variable) -> str:
    unit = getattr(variable, "unit", None)
    if unit is None and getattr(variable, "declaredType", None) is not None:
        unit = getattr(variable.declaredType, "unit", None)
    return str(unit or "")


def bus_port(fmu: FMU, spec: str | None = None, base_mva: float = 100.0) -> BoxPort:
    """The box's BoxPort: from `spec` (a --bus-port text, parse_bus_port) checked against its
    variables and their units (powers in MW and the like divided by the system base base_mva), else
    its model description's bus port. DatasetError where it has neither, or the spec does not fit it."""
    if spec is None:
        bus = fmu.ports.bus if fmu.ports is not None else None
        if bus is None or len(bus.voltage) != 2 or len(bus.current) != 2:
            reals = [n for n, v in fmu.variables.items() if v.type in ("Real", "Float64")]
            ins = [n for n in reals if fmu.variables[n].causality == "input"]
            outs = [n for n in reals if fmu.variables[n].causality == "output"]
            raise DatasetError(f"{fmu.model_name}: the FMU declares no bus port (a voltage phasor in, a current phasor "
                               "out) in its model description: say where its bus is with --bus-port V=NAME,theta=NAME,"
                               f"P=NAME,Q=NAME (or I_re=NAME,I_im=NAME); its Real inputs: {', '.join(ins[:12]) or 'none'}; "
                               f"outputs: {', '.join(outs[:12]) or 'none'}")
        return BoxPort(*bus.voltage, tuple(bus.current))
    try:
        found = parse_bus_port(spec)
    except ValueError as exc:
        raise DatasetError(f"--bus-port {spec[:80]!r}: {exc}") from None
    units = {}
    for key, (name, _) in found.items():
        variable = fmu.variables.get(name)
        causality = "input" if key in ("V", "theta") else "output"
        if variable is None or variable.type not in ("Real", "Float64") or variable.causality != causality:
            raise DatasetError(f"--bus-port {key}={name}: {fmu.model_name} has no Real {causality} {name!r}")
        units[key] = _unit(variable)
    if units["V"] not in _PER_UNIT:
        raise DatasetError(f"--bus-port V={found['V'][0]}: its unit {units['V']!r}: the voltage magnitude must be in pu")
    if units["theta"] not in _ANGLE_UNITS:
        raise DatasetError(f"--bus-port theta={found['theta'][0]}: its unit {units['theta']!r}: the angle must be in "
                           "rad or deg")
    kind, keys = ("current", ("I_re", "I_im")) if "I_re" in found else ("power", ("P", "Q"))
    scales = []
    for key in keys:
        unit = units[key]
        if unit in _PER_UNIT:
            scale = 1.0
        elif kind == "power" and unit in _POWER_UNITS:
            scale = _POWER_UNITS[unit] / base_mva
        else:
            raise DatasetError(f"--bus-port {key}={found[key][0]}: its unit {unit!r}: a "
                               f"{'current must be in pu' if kind == 'current' else 'power must be in pu, W, kW or MW (var, kvar, Mvar)'}")
        scales.append(found[key][1] * scale)
    return BoxPort(found["V"][0], found["theta"][0], (found[keys[0]][0], found[keys[1]][0]), kind,
                   _ANGLE_UNITS[units["theta"]], tuple(scales))


def replay(fmu_path, t: np.ndarray, V: np.ndarray, theta: np.ndarray, name: str = "box", spec: str | None = None,
           base_mva: float = 100.0) -> np.ndarray:
    """[n] complex: the bus current [pu, system base, network frame] the box injects at the rows t
    [n] (uniform steps) while its bus voltage follows V, theta [n] (module docstring); spec: its
    --bus-port (bus_port), base_mva: the system base its powers in MW are taken to."""
    with FMU(fmu_path, name, init=False) as box:
        port = bus_port(box, spec, base_mva)
        v, a, scale = port.magnitude, port.angle, 1.0 / port.angle_scale
        box.initialise({v: float(V[0]), a: float(theta[0]) * scale})
        h = float(t[1] - t[0])
        for _ in range(int(round(SETTLE_S / h))):
            box.step(h, **{v: float(V[0]), a: float(theta[0]) * scale})
        out = np.empty(len(t), complex)
        for k in range(len(t)):
            box.set(**{v: float(V[k]), a: float(theta[k]) * scale})
            out[k] = port.current(float(V[k]), float(theta[k]), box.get(*port.outputs))
            if k + 1 < len(t):
                box.step(h, **{v: float(V[k]), a: float(theta[k]) * scale})
    return out


def own_rest(fmu_path, spec: str | None = None, base_mva: float = 100.0) -> dict:
    """The box's own voltage start V_own [pu] and its devices' currents at rest there (Ip_own,
    Iq_own: its whole current, in the voltage's frame), after SETTLE_S at its start voltage."""
    with FMU(fmu_path, "--subsystem", init=False) as box:
        port = bus_port(box, spec, base_mva)
        V_own = float(box.starts.get(port.magnitude, 1.0))
        theta = float(box.starts.get(port.angle, 0.0)) * port.angle_scale
    t = np.arange(2) * 0.01
    current = replay(fmu_path, t, np.full(2, V_own), np.full(2, theta), spec=spec, base_mva=base_mva)[-1] \
        * np.exp(-1j * theta)
    return {"V_own": V_own, "Ip_own": float(current.real), "Iq_own": float(-current.imag)}


_HOSTS: dict = {}  # per process: host case file -> (case, MasterRunner)


def record_replay(task: tuple) -> str:
    """One task (index, Run as dict, host case file, bus, params, plan as dict, FMU cache, partial
    folder, box, its --bus-port or None): the host's run, the box's replay of its voltage at `bus`,
    the rows written to partial/run_<index>.npz (or why the run failed)."""
    index, run, host, bus, params, plan, fmu_cache, partial, box, spec = task
    plan = Plan(**{k: tuple(v) if isinstance(v, list) else v for k, v in plan.items()})
    out = Path(partial) / f"run_{index:05d}.npz"
    if host not in _HOSTS:
        from reference_models.grid.andes_case import case_from_file

        from .fmus import generator_files
        from .master import MasterSettings
        from .runners import MasterRunner

        case = case_from_file(Path(host))
        _HOSTS[host] = (case, MasterRunner(generator_files(case, "reference", Path(fmu_cache)), case,
                                           MasterSettings(step=plan.step)))
    case, runner = _HOSTS[host]
    try:
        result, _ = runner.run(contingency_of(Run(**run), case, plan), plan.stop, stop_at_loss=True)
        b = case.network.bus_index(bus)
        t, V, theta = np.asarray(result.time), result.V_bus[:, b], result.theta_bus[:, b]
        current = replay(box, t, V, theta, f"box{index}", spec, params["Sb"])
        n = float(V[0]) / params["V_own"]
        device = current * np.exp(-1j * theta)
        x = np.stack([theta, theta, device.real, -device.imag, np.full_like(t, n)], axis=1)
        write_npz(out, t=t, u=np.stack([V, theta], axis=1), x=x, failed=np.array(""))
    except (RuntimeError, ValueError, ArithmeticError, CouplingError) as exc:
        write_npz(out, failed=np.array(str(exc).splitlines()[0][:300] if str(exc) else type(exc).__name__))
    return out.name


def generate_black_box(box, out, rating_mva: float, plan: Plan = Plan(), seed: int = 0, workers: int = 1,
                       progress: bool = True, bus_port_spec: str | None = None) -> dict:
    """Generate (or resume, or find complete) the dataset of the black-box FMU `box` (its rating
    rating_mva [MVA]) in `out`; returns its metadata. bus_port_spec: where its bus is when its model
    description declares no bus port (bus_port). DatasetError for an FMU without a bus port, a
    spec that does not fit it, a plan that carries a plant controller, the devices' measured
    frequency, their low-voltage gain or dip current (a box is not read inside) or another dataset in `out`."""
    box, out = Path(box), Path(out)
    if plan.carry_controller:
        raise DatasetError(f"{box.name}: a black box is not read inside, so it has no plant controller states to carry")
    if plan.unit_frequency:
        raise DatasetError(f"{box.name}: a black box is not read inside, so what its devices measure is not known")
    if plan.voltage_gain:
        raise DatasetError(f"{box.name}: a black box is not read inside, so its devices' low-voltage gain is not known")
    if plan.dip_current:
        raise DatasetError(f"{box.name}: a black box is not read inside, so its devices' dip current is not known")
    import andes

    from reference_models.components import component
    from reference_models.grid.andes_case import ANDES_CASES, case_from_file

    from .fmus import generator_files

    hosts = {name: Path(andes.get_case(ANDES_CASES[name])) for name in plan.hosts}
    read = {plan.hosts[0]: case_from_file(hosts[plan.hosts[0]])}  # the first host's base and frequency
    first = read[plan.hosts[0]].network
    rest = own_rest(box, bus_port_spec, first.base_mva)
    key = fingerprint(box.read_bytes() + json.dumps(bus_port_spec).encode(), 0, plan, seed)
    if (meta := finished(out, key)) is not None:
        return meta
    partial = out / ".partial"
    partial.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    rng = np.random.default_rng(seed)
    attachments, cases = [], []
    for name, host in hosts.items():
        case = read[name] if name in read else case_from_file(host)
        generator_files(case, "reference", out / ".fmus")
        for bus in attachment_buses(case.network, rng, plan.buses):
            attachments.append((name, bus, str(host)))
            cases.append((case, bus))
    params = {"Sb": float(first.base_mva), "S": float(rating_mva), "G": 0.0, "B": 0.0, **rest,
              "busf_fn": float(first.f_hz)}
    model = component("subsystem_mem" if plan.memory else "subsystem")
    model.params(params)  # checked before anything runs
    runs = draw_runs(plan, cases, rng)
    tasks = [(k, asdict(r), attachments[r.attachment][2], attachments[r.attachment][1], params, plan.to_dict(),
              str(out / ".fmus"), str(partial), str(box), bus_port_spec) for k, r in enumerate(runs)
             if not (partial / f"run_{k:05d}.npz").exists()]
    run_all(record_replay, tasks, len(runs), "black-box replays", workers, progress)
    return _assemble(out, runs, attachments, params, plan, seed, key, started, {"kind": "black box", "fmu": box.name,
                                                                           "bus_port": bus_port_spec},
                     model)
