"""The surrogate FMU against the reference FMU: fmpy runs both on the same inputs.

The FMUs are of a machine on a bus: any component with a bus port and the mechanical_power and
field_voltage links (reference_models.ports.machine_inputs), the one the surrogate's operator names
(SM4 by default, the machine the scenarios were drawn for; GENROU's shipped operators too). Its
inputs are found by its ports: the bus voltage of its bus port, its mechanical power and field
voltage links (SM4: Vs, theta_vs, Pm, Efd; the examples below use SM4's names). Both FMUs are run
through cosim.fmu.FMU (the one FMU wrapper) by `fmpy.simulate_fmu` from the same input table (time
and every input) with
communication step h: at each communication point fmpy sets the table's value there and the FMU
holds it over the step. Both start from the same state (the initial-state parameters <state>0,
SM4: delta0..Eq_p0: the machine at rest under the first input value). Outputs are recorded at
every communication point; the errors are the surrogate minus the reference over all of them. Two
times are taken per FMU (extracted beforehand; in this process, one after the other): the whole
`simulate_fmu` call, what an fmpy user waits for with fmpy's own work per step included, and the
time spent inside fmi2DoStep alone, what the FMU itself costs an importer.
"""
from __future__ import annotations

import csv
import os
import re
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from reference_models.scenarios import COMPONENT, DEFAULT_PARAMS, scenario

# the default machine's names (SM4); a comparison of another machine takes them from its component
STATE_NAMES, INPUT_NAMES, OUTPUT_NAMES = COMPONENT.state_names, COMPONENT.input_names, COMPONENT.output_names
INPUT_UNITS = tuple(q.unit for q in COMPONENT.inputs)
OUTPUTS = STATE_NAMES + OUTPUT_NAMES
UNITS = {q.name: q.unit for q in COMPONENT.states + COMPONENT.outputs}
DIAGNOSTICS = ("residual", "in_envelope")  # surrogate only


def outputs_of(component) -> tuple:
    """The outputs a comparison records and rates: the component's states, then its derived outputs."""
    return component.state_names + component.output_names


class CompareError(ValueError):
    """Inputs or FMUs that cannot be compared (bad CSV, wrong variables, a failed simulation)."""


@dataclass(frozen=True)
class Inputs:
    """What both FMUs are driven with: times [T] (s), values [T, n_u] (the machine's inputs in its
    order; SM4: Vs [pu], theta_vs [rad], Pm [pu], Efd [pu]) and the start state x0 [n_x];
    component: the machine (default SM4)."""

    label: str
    times: np.ndarray
    values: np.ndarray
    x0: np.ndarray
    component: object = COMPONENT

    @property
    def names(self) -> tuple:
        """The input names, in the order of the columns of `values`."""
        return self.component.input_names

    def table(self) -> np.ndarray:
        """The structured array fmpy takes as `input`."""
        rows = np.zeros(len(self.times), dtype=[("time", float)] + [(n, float) for n in self.names])
        rows["time"] = self.times
        for i, name in enumerate(self.names):
            rows[name] = self.values[:, i]
        return rows


def scenario_inputs(name: str, seed: int, stop_time: float, step: float, params=DEFAULT_PARAMS,
                    operating: tuple | None = None, component=COMPONENT) -> Inputs:
    """A built-in scenario sampled at the communication points k h, k = 0..stop_time/h, for machine
    params (of `component`, default SM4) at the operating point (Pm, Efd) (default: their start values)."""
    s = scenario(name, seed, stop_time, params, operating, component)
    times = communication_points(stop_time, step)
    return Inputs(f"{name} (seed {seed})", times, s.inputs(times), s.initial_state(), component)


def communication_points(stop_time: float, step: float) -> np.ndarray:
    if not (step > 0 and stop_time > 0):
        raise CompareError(f"step and stop time must be positive, got step {step}, stop time {stop_time}")
    n = int(round(stop_time / step))
    if n < 1 or abs(n * step - stop_time) > 1e-9 * max(1.0, stop_time):
        raise CompareError(f"stop time {stop_time} s is not a whole number of steps of {step} s")
    return np.arange(n + 1) * step


# time and the bus voltage of the bus port (SM4: Vs, theta_vs); the other inputs may be left out
REQUIRED_COLUMNS = ("time", *COMPONENT.ports.bus.voltage)


def required_columns(component=COMPONENT) -> tuple:
    """time and the bus voltage inputs of the component's bus port."""
    return ("time", *component.ports.bus.voltage)


def csv_inputs(path, params=DEFAULT_PARAMS, component=COMPONENT, starts: dict | None = None) -> Inputs:
    """Inputs from a CSV file with the columns required_columns(component) (time [s] and the bus
    voltage's magnitude [pu] and angle [rad]; SM4: time, Vs, theta_vs) and optionally the machine's
    other inputs (SM4: Pm, Efd [pu]); a header row; times non-decreasing from 0; a repeated time is a
    jump, as fmpy reads it. A column left out holds its input's start value: `starts` {input: value}
    (an FMU's), else the component's (SM4: Pm 0.7048, Efd 1.08, Table I's operating point). The
    machine params (of `component`, default SM4) starts at rest under the first row."""
    path = Path(path)
    required = required_columns(component)
    names = component.input_names
    try:
        with path.open(newline="") as f:
            rows = list(csv.DictReader(f))
    except (OSError, UnicodeDecodeError) as exc:
        raise CompareError(f"cannot read inputs {path}: {exc}") from None
    if not rows or any(c not in rows[0] for c in required):
        optional = [n for n in names if n not in required]
        raise CompareError(f"inputs {path} need a header with the columns {', '.join(required)} (and "
                           f"optionally {', '.join(optional)}) and at least one row")
    starts = {"time": None} | {q.name: (starts or {}).get(q.name, q.start) for q in component.inputs}
    try:
        data = np.array([[float(r[c]) if c in r else starts[c] for c in starts] for r in rows])
    except (TypeError, ValueError) as exc:
        raise CompareError(f"inputs {path}: not a number ({exc})") from None
    if not np.all(np.isfinite(data)):
        raise CompareError(f"inputs {path} hold NaN or inf")
    times = data[:, 0]
    if times[0] != 0 or np.any(np.diff(times) < 0):
        raise CompareError(f"inputs {path}: times must start at 0 and never decrease")
    return Inputs(path.name, times, data[:, 1:], component.rest_state(data[0, 1:], params), component)


def fmu_machine(fmu_dir):
    """The machine an extracted surrogate FMU models: that of its operator (resources/model.onnx),
    which must be of the scenarios' machine (SM4; fmu_component takes any)."""
    return operator_machine(Path(fmu_dir) / "resources" / "model.onnx")


def fmu_component(fmu_dir) -> tuple:
    """(component, parameters) of the machine an extracted surrogate FMU models (its operator's);
    CompareError, one line, where it is no machine on a bus (a bus port and the mechanical_power and
    field_voltage links)."""
    return operator_component(Path(fmu_dir) / "resources" / "model.onnx")


def input_starts(fmu_dir, component) -> dict:
    """The start values of an extracted FMU's inputs: {"inputs": {name: value}, "power": the mechanical
    power's, "field": the field voltage's} (the component's start value where the FMU gives none)."""
    from fmpy import read_model_description

    from reference_models.ports import machine_inputs

    given = {v.name: v.start for v in read_model_description(str(fmu_dir)).modelVariables}
    values = {q.name: float(given[q.name]) if given.get(q.name) is not None else float(q.start)
              for q in component.inputs}
    wiring = machine_inputs(component)
    return {"inputs": values, "power": values[wiring.power], "field": values[wiring.field]}


def operator_machine(path):
    """The machine (parameters) an operator file was trained for (its validated metadata);
    CompareError, one line, when the file is unreadable, not an operator of the scenarios' machine
    or its metadata is not valid."""
    component, params = _operator(path)
    if component is not COMPONENT:
        raise CompareError(f"the operator {path} is not of {COMPONENT.name} (component {component.name!r})")
    return params


def operator_component(path, machine: bool = True) -> tuple:
    """(component, parameters) an operator file was trained for; CompareError, one line, when the file
    is unreadable, its metadata is not valid or (machine) its component is no machine on a bus."""
    from reference_models.ports import PortError, machine_inputs

    component, params = _operator(path)
    if not machine:
        return component, params
    try:
        machine_inputs(component)
    except PortError as exc:
        raise CompareError(f"the operator {path}: {exc}") from None
    return component, params


def _operator(path) -> tuple:
    """(component, parameters) of an operator file's validated metadata; CompareError otherwise."""
    from surrogate.contract import ContractError, metadata_of, operator_metadata

    if Path(path).is_dir():
        raise CompareError(f"operator file {path} is a folder, not a file")
    if not Path(path).exists():
        raise CompareError(f"there is no operator file at {path}")
    try:
        meta = operator_metadata(metadata_of(path))
    except ContractError as exc:
        raise CompareError(f"{path}: {exc}") from None
    except OSError as exc:
        raise CompareError(f"{path} is not a readable operator file: {' '.join(str(exc).split())[:200]}") from None
    return meta["component"], meta["params"]


def same_machine(surrogate_dir, reference_dir, component=COMPONENT) -> None:
    """CompareError unless both FMUs start from the same default state (their machine's equilibrium
    at the start inputs): two FMUs of different machines are no comparison. component: the
    surrogate's (default SM4); a reference FMU opfmu built of another component is refused by name."""
    from fmpy import read_model_description

    from cosim.fmu import component_described

    starts = []
    for directory in (surrogate_dir, reference_dir):
        md = read_model_description(str(directory))
        described = component_described(md.description) if str(md.generationTool or "").startswith("opfmu") else None
        if described is not None and described is not component:
            raise CompareError(f"the {'surrogate' if directory is surrogate_dir else 'reference'} FMU {md.modelName} "
                               f"is of {described.name}, the other of {component.name}: no comparison")
        values = {v.name: v.start for v in md.modelVariables}
        starts.append(np.array([float(values.get(f"{s}0") or "nan") for s in component.state_names]))
    if not np.allclose(starts[0], starts[1], rtol=0, atol=1e-9):
        raise CompareError("the surrogate and reference FMUs model different machines (their default initial states "
                           f"differ: {np.round(starts[0], 6).tolist()} against {np.round(starts[1], 6).tolist()})")


@dataclass
class Run:
    """One FMU's simulation: recorded outputs by name [T]; wall_s, the whole simulation with fmpy
    (instantiation to freeing) [s]; do_step_s, the time spent inside fmi2DoStep alone [s]; what the
    FMU logged."""

    outputs: dict
    wall_s: float
    do_step_s: float
    messages: list = field(default_factory=list)


def simulate(fmu_dir, inputs: Inputs, stop_time: float, step: float, names, parameters=None,
             role: str = "the") -> Run:
    """Simulate an extracted FMU (directory) under fmpy, opened by cosim.fmu.FMU (debug logging on,
    every message kept); records `names` at every communication point. parameters: further start
    values by name (e.g. the surrogate's rollover_horizon); role: which FMU it is, for messages ("the
    surrogate"). The machine is that of `inputs` (its component)."""
    from fmpy import read_model_description, simulate_fmu

    from cosim.fmu import FMU, CouplingError

    component = inputs.component
    md = read_model_description(str(fmu_dir))
    known = {v.name for v in md.modelVariables}
    missing = [n for n in list(names) + [f"{s}0" for s in component.state_names] + list(component.input_names)
               if n not in known]
    if missing:
        raise CompareError(f"{md.modelName} lacks the variables {', '.join(missing)}: not an FMU of {component.name}")
    unknown = sorted(set(parameters or {}) - known)
    if unknown:
        raise CompareError(f"{md.modelName} has no parameter {', '.join(unknown)}")
    messages, in_step = [], [0.0]

    def keep(status, category, message):
        messages.append(f"{category}: {message}")

    started = time.perf_counter()
    try:  # fmpy's default instance name (the model identifier), as an importer that knows nothing of opfmu
        instance = FMU((fmu_dir, md), name=md.coSimulation.modelIdentifier, init=False, logging_on=True,
                       on_message=keep)
    except CouplingError as exc:  # a missing or unloadable binary: fmpy's reason is the exception's context
        reason = exc.__cause__ or exc.__context__ or exc
        raise CompareError(f"{role} FMU {md.modelName} cannot be loaded: {_load_failure(reason, fmu_dir)}") from None
    fmu = instance.fmu
    do_step = fmu.doStep

    def timed_step(*args, **kwargs):
        begin = time.perf_counter()
        try:
            return do_step(*args, **kwargs)
        finally:
            in_step[0] += time.perf_counter() - begin

    fmu.doStep = timed_step
    start_values = {f"{s}0": float(v) for s, v in zip(component.state_names, inputs.x0)} | dict(parameters or {})
    try:
        result = simulate_fmu(str(fmu_dir), validate=False, model_description=md, fmu_instance=fmu, start_time=0.0,
                              stop_time=stop_time, output_interval=step, input=inputs.table(), output=list(names),
                              start_values=start_values, terminate=False)  # close() terminates and frees it
    except Exception as exc:  # fmpy raises plain Exceptions for failed FMI calls
        said = f" ({messages[-1]})" if messages else ""
        raise CompareError(f"{md.modelName} failed: {exc}{said}") from None
    finally:
        instance.close()
        fmu.freeLibrary()
    wall = time.perf_counter() - started
    return Run({n: np.asarray(result[n], dtype=float) for n in ["time", *names]}, wall, in_step[0], messages)


def _load_failure(exc: Exception, fmu_dir) -> str:
    """Why fmpy could not load an extracted FMU's binary, with the binary's path inside the FMU."""
    text = " ".join(str(exc).replace(f"{Path(fmu_dir)}{os.sep}", "").split())
    binary = re.search(r"binaries/\S+?(?=\.?(?:\s|$))", text)
    where = binary.group(0) if binary else "its binary"
    if text.startswith("Cannot find"):
        return f"{where} is missing"
    return f"{where}: {text.rsplit(': ', 1)[-1][:200] if ': ' in text else text[:200]}"


def compare(surrogate_dir, reference_dir, inputs: Inputs, stop_time: float, step: float,
            surrogate_parameters=None) -> dict:
    """Both FMUs on `inputs`; returns the comparison (metrics, timings, trajectories).
    surrogate_parameters: start values of the surrogate's own parameters (rollover_horizon). The
    machine is that of `inputs` (its component); the result names it under "component" (the
    Component, which summary() leaves out)."""
    component = inputs.component
    outputs = outputs_of(component)
    reference = simulate(reference_dir, inputs, stop_time, step, outputs, role="the reference")
    surrogate = simulate(surrogate_dir, inputs, stop_time, step, outputs + DIAGNOSTICS, surrogate_parameters,
                         role="the surrogate")
    if len(reference.outputs["time"]) != len(surrogate.outputs["time"]):
        raise CompareError("the two FMUs recorded different numbers of communication points")
    return {
        "inputs": inputs.label, "stop_time_s": stop_time, "step_s": step, "x0": inputs.x0.tolist(),
        "metrics": error_metrics(reference.outputs, surrogate.outputs, outputs),
        "wall_s": {"surrogate": surrogate.wall_s, "reference": reference.wall_s},
        "speedup": reference.wall_s / surrogate.wall_s,
        "do_step_s": {"surrogate": surrogate.do_step_s, "reference": reference.do_step_s},
        "do_step_speedup": reference.do_step_s / surrogate.do_step_s,
        "max_residual": float(np.max(surrogate.outputs["residual"])),
        "in_envelope": bool(np.all(surrogate.outputs["in_envelope"] > 0.5)),
        "messages": {"surrogate": surrogate.messages, "reference": reference.messages},
        "trajectories": {"reference": reference.outputs, "surrogate": surrogate.outputs,
                         "inputs": np.array([np.interp(reference.outputs["time"], inputs.times, inputs.values[:, i])
                                             for i in range(len(inputs.names))]).T},
        "component": component,
    }


def error_metrics(reference: dict, surrogate: dict, names=OUTPUTS) -> dict:
    """MAE, RMSE and MaxAE of surrogate - reference per output `names` (physical units)."""
    out = {}
    for name in names:
        e = np.abs(surrogate[name] - reference[name])
        out[name] = {"mae": float(e.mean()), "rmse": float(np.sqrt(np.mean(e ** 2))), "maxae": float(e.max())}
    return out


def format_table(result: dict) -> str:
    """Per-output errors, then wall times and the speedup, as text."""
    component = result.get("component", COMPONENT)
    units = {q.name: q.unit for q in component.states + component.outputs}
    width = max(10, 2 + max(map(len, result["metrics"]), default=0))  # a name column that fits every name
    lines = [f"{result['inputs']}: {result['stop_time_s']:g} s at h = {result['step_s'] * 1e3:g} ms",
             f"{'output':<{width}}{'unit':<7}{'MAE':>11}{'RMSE':>11}{'MaxAE':>11}"]
    for name, m in result["metrics"].items():
        lines.append(f"{name:<{width}}{units[name]:<7}{m['mae']:>11.3e}{m['rmse']:>11.3e}{m['maxae']:>11.3e}")
    wall = result["wall_s"]
    inside = result["do_step_s"]
    steps = round(result["stop_time_s"] / result["step_s"])
    lines.append(f"wall time under fmpy: surrogate {wall['surrogate']:.3f} s, reference {wall['reference']:.3f} s "
                 f"({_ratio(result['speedup'])})")
    lines.append(f"time inside fmi2DoStep: surrogate {1e6 * inside['surrogate'] / steps:.2f} us per step, reference "
                 f"{1e6 * inside['reference'] / steps:.2f} us per step ({_ratio(result['do_step_speedup'])})")
    said = result["messages"]["surrogate"]
    lines.append(f"surrogate diagnostics: max residual {result['max_residual']:.3g}, "
                 f"in envelope throughout: {'yes' if result['in_envelope'] else 'NO'}, warnings logged: {len(said)}")
    lines += [f"  {message}" for message in said[:5]]
    return "\n".join(lines)


def _ratio(speedup: float) -> str:
    """reference time / surrogate time as words."""
    return f"surrogate {speedup:.1f}x faster" if speedup >= 1 else f"surrogate {1 / speedup:.1f}x slower"


class ComparisonPlots:
    """Draws plot_comparison's figures: built once per machine (its states, outputs and inputs) and
    drawn again with the data of each further comparison, which costs half of building them anew
    (their axes and ticks are kept). A context manager; `close` frees the figures."""

    def __init__(self):
        self._figures = {}  # (suffix, machine, its variables) -> (figure, {series: Line2D}, axes, title)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self) -> None:
        if not self._figures:
            return
        import matplotlib.pyplot as plt

        for fig, *_ in self._figures.values():
            plt.close(fig)
        self._figures = {}

    def draw(self, result: dict, out_dir, stem: str) -> list[Path]:
        """The two PNGs of `result` (compare's) in out_dir: <stem>_states.png (the inputs and the
        states) and <stem>_currents_powers.png (the derived outputs)."""
        component = result.get("component", COMPONENT)
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        traj = result["trajectories"]
        t = traj["reference"]["time"]
        paths = []
        for suffix, names in (("states", component.state_names), ("currents_powers", component.output_names)):
            key = (suffix, component.name, names, component.input_names)
            if key not in self._figures:
                self._figures[key] = _comparison_figure(component, names, suffix == "states")
            fig, lines, axes, title = self._figures[key]
            for i in range(len(component.input_names) if suffix == "states" else 0):
                lines[("input", i)].set_data(t, traj["inputs"][:, i])
            for name in names:
                ref, sur = traj["reference"][name], traj["surrogate"][name]
                lines[("reference", name)].set_data(t, ref)
                lines[("surrogate", name)].set_data(t, sur)
                lines[("error", name)].set_data(t, sur - ref)
            for ax in axes:
                ax.relim()
                ax.autoscale_view()
            title.set_text(f"{result['inputs']}, h = {result['step_s'] * 1e3:g} ms: surrogate FMU against reference FMU")
            path = out_dir / f"{stem}_{suffix}.png"
            fig.savefig(path, dpi=110, pil_kwargs={"compress_level": 1})
            paths.append(path)
        return paths


def _comparison_figure(component, names, with_inputs: bool) -> tuple:
    """(figure, {series: Line2D}, axes, suptitle) of one comparison figure without its data: the
    inputs two a row (with_inputs), then each output with both curves (left) and the surrogate's
    error (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    units = {q.name: q.unit for q in component.states + component.outputs}
    input_rows = (len(component.input_names) + 1) // 2 if with_inputs else 0
    rows = len(names) + input_rows
    fig, axes = plt.subplots(rows, 2, figsize=(11, 2.1 * rows), sharex=True, squeeze=False)
    lines = {}
    for i, q in enumerate(component.inputs if with_inputs else ()):
        ax = axes[i // 2, i % 2]
        lines[("input", i)], = ax.plot([], [], color="tab:gray", drawstyle="steps-post")
        ax.set_ylabel(f"{q.name} [{q.unit}]")
        ax.set_title("input" if i == 0 else "")
    for row, name in enumerate(names, start=input_rows):
        lines[("reference", name)], = axes[row, 0].plot([], [], label="reference (RK45)", color="black", lw=1.2)
        lines[("surrogate", name)], = axes[row, 0].plot([], [], label="surrogate", color="tab:red", lw=1.0, ls="--")
        axes[row, 0].set_ylabel(f"{name} [{units[name]}]")
        lines[("error", name)], = axes[row, 1].plot([], [], color="tab:red", lw=0.9)
        axes[row, 1].set_ylabel(f"error [{units[name]}]")
    axes[input_rows, 0].legend(loc="best", fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    for ax in axes.ravel():
        ax.grid(alpha=0.3)
    # fixed margins [in] for the titles, the labels and the ticks: tight_layout would draw every figure twice
    height = 2.1 * rows
    title = fig.suptitle("", y=1.0 - 0.12 / height)
    fig.subplots_adjust(left=0.09, right=0.985, wspace=0.28, hspace=0.12, top=1.0 - 0.7 / height,
                        bottom=0.5 / height)
    return fig, lines, list(axes.ravel()), title


def plot_comparison(result: dict, out_dir, stem: str, plots: ComparisonPlots | None = None) -> list[Path]:
    """Two PNGs: the inputs and the states, and the derived outputs (SM4: currents and powers);
    each output with both curves (left) and the surrogate's error (right). plots: the figures to
    draw them in (kept for the next comparison of the same machine); None: built for these alone."""
    if plots is not None:
        return plots.draw(result, out_dir, stem)
    with ComparisonPlots() as own:
        return own.draw(result, out_dir, stem)


def summary(result: dict) -> dict:
    """The comparison without its trajectories and component object (what comparison JSON files hold)."""
    return {k: v for k, v in result.items() if k not in ("trajectories", "component")}
