"""What a grid run leaves in its folder: result.csv (the columns of docs/grid.md, "What a run
leaves": time, delta, omega [rad/s deviation], Efd per unit and V per bus, then the rest of
GridResult.columns),
a figure of rotor angles relative to machine 1, speeds, terminal voltages and field voltages with
every compared run on the same axes, and a Markdown report. All written atomically."""
from __future__ import annotations

import csv
import io
import math
import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from reference_models.files import atomic_path

RUN_FILES = ("result.csv", "result.png", "report.md", "summary.json")
SCREENING_FILES = ("screening.csv", "screening.json", "screening.md", "screening.png")

LABELS = {"surrogate": "surrogate FMUs", "reference": "native reference FMUs", "python": "pythonfmu reference FMUs",
          "file": "user FMUs", "monolithic": "monolithic DAE", "andes": "ANDES"}
STYLES = {"monolithic": dict(color="k", lw=2.2, alpha=0.35), "reference": dict(ls="--", lw=1.2),
          "surrogate": dict(lw=1.0), "python": dict(ls=":", lw=1.2), "file": dict(ls="-.", lw=1.0),
          "andes": dict(ls=(0, (5, 1, 1, 1)), lw=1.2)}


PNG = {"compress_level": 1}  # zlib's fastest: the figure's lines compress well at any level (6 % larger than at 6)
REFERENCES = {"monolithic": "monolithic", "andes": "ANDES"}  # the runs others are compared with, where present


class OutputError(ValueError):
    """An output folder that cannot take a result set (one line)."""


def check_output(out, names) -> Path:
    """The folder `out`, created if absent, checked to take the files `names`: OutputError when it is a
    file, cannot be written or one of the targets exists and is not a file."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {out} is a file, not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = tempfile.NamedTemporaryFile(dir=out, prefix=".opfmu-probe-")
        probe.close()
    except OSError as exc:
        raise OutputError(f"cannot write into the output folder {out} ({exc.strerror or 'not writable'})") from None
    for name in names:
        target = out / name
        if target.exists() and not target.is_file():
            raise OutputError(f"cannot write {target}: it exists and is not a file")
    return out


@contextmanager
def result_set(out, names):
    """Writes a set of files whole or not at all: yields a staging folder beside them in `out`; when
    the block ends without an error every file `names` written there is moved into `out` (each
    move atomic), and the staging folder is removed in any case."""
    out = check_output(out, names)
    staging = Path(tempfile.mkdtemp(dir=out, prefix=".opfmu-staging-"))
    try:
        yield staging
        missing = [n for n in names if not (staging / n).is_file()]
        if missing:
            raise OutputError(f"the result set lacks {', '.join(missing)}")
        for name in names:
            os.replace(staging / name, out / name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _figure(figsize):
    """A matplotlib Figure on the Agg canvas (no pyplot)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig


def write_csv(path, result, case=None) -> None:
    """result.csv: one row per communication point (17 significant digits); `case`: the Case the
    result is of (speeds as deviations in rad/s, every unit's field voltage: GridResult.columns)."""
    columns = result.columns(case)
    names = list(columns)
    data = np.column_stack([np.asarray(columns[n], dtype=float) for n in names])
    text = io.StringIO()
    csv.writer(text, lineterminator="\n").writerow(names)
    row = ",".join(["%.17g"] * len(names))  # one format per row: the same text as csv's, 3 times faster
    text.write("".join(row % tuple(values) + "\n" for values in data.tolist()))
    with atomic_path(path) as tmp:
        tmp.write_text(text.getvalue())


def on_times(result, times: np.ndarray, column: np.ndarray) -> np.ndarray:
    """A result column [n] or [n, k] at `times` (linear between rows; at a repeated time the row
    after an event)."""
    t = result.time
    keep = np.r_[np.diff(t) > 0, True]
    column = np.asarray(column)
    if column.ndim == 1:
        return np.interp(times, t[keep], column[keep])
    return np.stack([np.interp(times, t[keep], column[keep, j]) for j in range(column.shape[1])], axis=1)


EVENT_TOLERANCE = 1e-9  # s: rows this close to an event time are at it; times this close are one


def common_rows(result, reference) -> tuple:
    """(rows of `result`, rows of `reference`) at the times both have (within EVENT_TOLERANCE),
    leaving out every time either run holds twice and every event time of either run (where a
    run switches, its row holds one side of the switch: the two runs need not hold the same)."""
    def single(t):
        t = np.asarray(t, dtype=float)
        once = np.ones(len(t), bool)
        same = np.diff(t) <= EVENT_TOLERANCE
        once[1:] &= ~same
        once[:-1] &= ~same
        return np.flatnonzero(once)

    mine, theirs = single(result.time), single(reference.time)
    if not len(mine) or not len(theirs):
        return mine[:0], theirs[:0]
    t, t_ref = result.time[mine], reference.time[theirs]
    j = np.searchsorted(t_ref, t)
    lo, hi = np.clip(j - 1, 0, len(t_ref) - 1), np.clip(j, 0, len(t_ref) - 1)
    nearest = np.where(np.abs(t_ref[lo] - t) <= np.abs(t_ref[hi] - t), lo, hi)
    match = np.abs(t_ref[nearest] - t) <= EVENT_TOLERANCE
    events = np.array([te for te, _ in tuple(result.events) + tuple(reference.events)], dtype=float)
    if len(events):
        match &= np.min(np.abs(t[:, None] - events[None, :]), axis=1) > EVENT_TOLERANCE
    return mine[match], theirs[nearest[match]]


def errors(result, reference, fault=None, case=None) -> dict:
    """Largest differences from `reference`, compared at the rows both runs have outside their event
    times (`common_rows`; no value is interpolated, none is taken across a switching): rotor angles
    relative to machine 1 [deg], speeds [rad/s deviation where `case` is given, else the speed
    states as stored], bus voltages at the machines outside the fault's own steps [pu] (the rows
    with a fault on, times in [start, clear), are left out: fault = (start, clear), a sequence of
    such pairs, or None), field voltages [pu] (with `case`: every unit's, GridResult's
    field_voltage), and the power P, Q [pu, system base] into the bus of every unit without a rotor
    angle (an inverter, a load) outside the fault's steps. ValueError where the runs share no such
    row."""
    from reference_models.grid.result import field_voltage, speed_deviation

    mine, theirs = common_rows(result, reference)
    if not len(mine):
        raise ValueError("the two runs have no row at a common time outside their events")
    t = result.time[mine]
    out = {}
    differences = [np.abs(result.angle_difference(b)[mine] - reference.angle_difference(b)[theirs])
                   for b in result.gen_buses[1:]]
    differences = [d for d in differences if np.any(np.isfinite(d))]
    angle = max((float(np.nanmax(d)) for d in differences), default=0.0)
    out["angle_deg"] = math.degrees(angle)
    if case is not None:
        pairs = {"omega": (speed_deviation(result, case), speed_deviation(reference, case)),
                 "Efd": (field_voltage(result, case), field_voltage(reference, case))}
    else:
        pairs = {name: (result.states.get(name), reference.states.get(name)) for name in ("omega", "Efd")}
    rows = np.ones(len(t), bool)
    intervals = [] if fault is None or not len(fault) else [fault] if np.isscalar(fault[0]) else list(fault)
    for start, clear in intervals:
        rows &= ~((t >= start - EVENT_TOLERANCE) & (t < clear - EVENT_TOLERANCE))
    out["V"] = float(np.max(np.abs(result.Vs[mine] - reference.Vs[theirs])[rows])) if rows.any() else math.nan
    for name, (a, b) in pairs.items():
        out[name] = _largest(None if a is None or b is None else np.abs(a[mine] - b[theirs]))
    # the power of the units without a rotor angle (inverters, loads) where both runs give it
    others = ~np.any(np.isfinite(reference.angles), axis=0) & ~np.any(np.isfinite(result.angles), axis=0)
    for name in ("P", "Q"):
        a, b = getattr(result, name)[mine][:, others], getattr(reference, name)[theirs][:, others]
        out[name] = _largest(np.abs(a - b)[rows]) if rows.any() else math.nan
    return {key: out[key] for key in ("angle_deg", "omega", "V", "Efd", "P", "Q")}


def _largest(values) -> float:
    """The largest finite entry of `values` (NaN where there is none)."""
    if values is None:
        return math.nan
    finite = np.asarray(values)[np.isfinite(values)]
    return float(finite.max()) if finite.size else math.nan


def plot(path, runs: dict, title: str, case=None) -> None:
    """The figure: runs {kind: GridResult}, 2 x 2 panels; with the `case` they are of, speeds as
    deviations [rad/s] and every unit's field voltage (GridResult's speed_deviation,
    field_voltage), else the states of those names as stored."""
    from matplotlib import rcParams

    from reference_models.grid.result import field_voltage, speed_deviation

    fig = _figure((12, 7.5))
    axes = fig.subplots(2, 2, sharex=True)
    first = next(iter(runs.values()))
    colors = rcParams["axes.prop_cycle"].by_key()["color"]
    # a legend entry per machine while each machine has a colour of its own; beyond that one per run
    per_machine = len(first.gen_buses) <= len(colors)
    for kind, result in runs.items():
        style = STYLES.get(kind, {})
        nan = np.full(result.Vs.shape, np.nan)
        omega = speed_deviation(result, case) if case is not None else nan
        Efd = field_voltage(result, case) if case is not None else nan
        for k, bus in enumerate(result.gen_buses):
            color = style.get("color", colors[k % len(colors)])
            kw = {key: v for key, v in style.items() if key != "color"}
            label = (f"{LABELS.get(kind, kind)}, machine {bus}" if per_machine else
                     f"{LABELS.get(kind, kind)}, {len(result.gen_buses)} machines" if k == 0 else None)
            if k > 0:
                axes[0, 0].plot(result.time, np.degrees(result.angle_difference(bus)), color=color, label=label, **kw)
            axes[0, 1].plot(result.time, omega[:, k], color=color, label=label, **kw)
            axes[1, 0].plot(result.time, result.Vs[:, k], color=color, label=label, **kw)
            axes[1, 1].plot(result.time, Efd[:, k], color=color, label=label, **kw)
    axes[0, 0].set_ylabel(f"rotor angle - machine {first.gen_buses[0]} [deg]")
    axes[0, 1].set_ylabel("speed deviation [rad/s]")
    axes[1, 0].set_ylabel("terminal voltage [pu]")
    axes[1, 1].set_ylabel("field voltage Efd [pu]")
    for ax in axes[1]:
        ax.set_xlabel("time [s]")
    for ax in axes.flat:
        ax.grid(alpha=0.3)
    axes[0, 1].legend(fontsize=7, ncol=1 if len(runs) < 3 else 2)
    fig.suptitle(title)
    fig.subplots_adjust(left=0.07, right=0.985, bottom=0.07, top=0.93, wspace=0.2, hspace=0.08)  # tight_layout's, fixed
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110, pil_kwargs=PNG)


def _number(value, digits=4) -> str:
    return "-" if value is None else f"{value:.{digits}g}"


def report(path, title: str, runs: dict, timings: dict, contingency, case=None, notes=()) -> None:
    """report.md: the contingency and the case's own events applied with it, per run its verdict,
    first-swing peak and time split, and every other run's largest differences from the monolithic
    run and from ANDES' (REFERENCES, where the report has them; `case`: the Case the runs are of,
    see `errors`)."""
    from .stability import first_swing_peak

    lines = [f"# {title}", "", f"Contingency: {contingency.label}.", ""]
    stop = max(float(r.time[-1]) for r in runs.values())
    if contingency.case_event_labels(stop + 1e-9):
        lines += ["The case's own events: " + "; ".join(contingency.case_event_labels(stop + 1e-9)) + ".", ""]
    lines += ["| run | stable | loss of synchronism [s] | first-swing peak [deg] | wall time [s] |",
              "| --- | --- | --- | --- | --- |"]
    for kind, result in runs.items():
        peak = math.degrees(first_swing_peak(result, contingency.clear_s))
        wall = timings.get(kind, {}).get("total_s")
        lines.append(f"| {LABELS.get(kind, kind)} | {'yes' if result.stable else 'no'} | "
                     f"{_number(result.loss_of_synchronism_s)} | {peak:.2f} | {_number(wall, 3)} |")
    fmu_timings = {k: v for k, v in timings.items() if "fmu_step_s" in v}
    if fmu_timings:
        lines += ["", "Time split of the co-simulation runs [s]:", "",
                  "| run | total | FMU steps | network solves | rollback | overhead | passes per step |",
                  "| --- | --- | --- | --- | --- | --- | --- |"]
        for kind, tm in fmu_timings.items():
            lines.append(f"| {LABELS.get(kind, kind)} | {tm['total_s']:.3f} | {tm['fmu_step_s']:.3f} | "
                         f"{tm['network_s']:.3f} | {tm['rollback_s']:.3f} | {tm['overhead_s']:.3f} | "
                         f"{tm['passes'] / max(tm['steps'], 1):.2f} |")
    fault = contingency.fault_intervals(math.inf)
    for reference in REFERENCES:
        if reference not in runs or len(runs) < 2:
            continue
        lines += ["", f"Largest differences from the {REFERENCES[reference]} run, at the rows both runs have outside "
                  "the event times (terminal voltages also outside the steps with a fault on):", "",
                  "| run | rotor angle rel. machine 1 [deg] | speed [rad/s] | terminal voltage [pu] | Efd [pu] | "
                  "P, Q of inverters and loads [pu] |",
                  "| --- | --- | --- | --- | --- | --- |"]
        for kind, result in runs.items():
            if kind == reference:
                continue
            e = errors(result, runs[reference], fault, case)
            lines.append(f"| {LABELS.get(kind, kind)} | {e['angle_deg']:.3f} | {e['omega']:.3g} | {e['V']:.3g} | "
                         f"{e['Efd']:.3g} | {e['P']:.3g}, {e['Q']:.3g} |")
    if notes:
        lines += ["", *notes]
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")


SCREENING_COLUMNS = ("bus", "trip", "clear_s", "stable", "first_swing_peak_deg", "cct_s", "bounded", "runs")


def screening_table(rows) -> str:
    """The screening as a Markdown table, one contingency per row."""
    lines = ["| fault bus | trip | verdict at clearing | first-swing peak [deg] | CCT [s] |",
             "| --- | --- | --- | --- | --- |"]
    for r in rows:
        cct = "-" if r["cct_s"] is None else (f"> {r['cct_s']:.3f}" if not r["bounded"] else f"{r['cct_s']:.3f}")
        peak = "-" if r["first_swing_peak_deg"] is None else f"{r['first_swing_peak_deg']:.1f}"
        lines.append(f"| {r['bus']} | {r['trip'] or '-'} | {'stable' if r['stable'] else 'unstable'} "
                     f"({r['clear_s']:g} s) | {peak} | {cct} |")
    return "\n".join(lines)


def write_screening(out, rows, title: str, notes=(), fault_start: float = 0.0) -> None:
    """screening.csv, screening.json, screening.md (with `notes`, lines of text, after the table) and
    screening.png (per contingency the critical fault duration [ms]: CCT - `fault_start` [s]) in `out`."""
    import json

    out = Path(out)
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(SCREENING_COLUMNS)
    for r in rows:
        writer.writerow(["" if r[c] is None else r[c] for c in SCREENING_COLUMNS])
    with atomic_path(out / "screening.csv") as tmp:
        tmp.write_text(text.getvalue())
    with atomic_path(out / "screening.json") as tmp:
        tmp.write_text(json.dumps(rows, indent=1) + "\n")
    with atomic_path(out / "screening.md") as tmp:
        tmp.write_text(f"# {title}\n\n{screening_table(rows)}\n\nCCT: critical clearing time by bisection "
                       "(stable: no two rotor angles pi apart before the run's stop); '> x': stable up to x.\n"
                       + "".join(f"\n{n}\n" for n in notes))
    fig = _figure((max(6.0, 0.45 * len(rows)), 4.0))
    ax = fig.subplots()
    labels = [f"{r['bus']}" + (f"\n{r['trip']}" if r["trip"] else "") for r in rows]
    values = [np.nan if r["cct_s"] is None else (r["cct_s"] - fault_start) * 1e3 for r in rows]
    colors = ["tab:green" if r["stable"] else "tab:red" for r in rows]
    ax.bar(range(len(rows)), values, color=colors)
    if rows:
        ax.axhline((rows[0]["clear_s"] - fault_start) * 1e3, color="k", lw=0.8, ls="--",
                   label="screening clearing time")
        ax.legend(fontsize=8)
    ax.set_xticks(range(len(rows)), labels, fontsize=7)
    ax.set_xlabel("fault bus / line opened")
    ax.set_ylabel(f"critical clearing time - fault start ({fault_start:g} s) [ms]" if fault_start
                  else "critical clearing time [ms]")
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    with atomic_path(out / "screening.png") as tmp:
        fig.savefig(tmp, format="png", dpi=110, pil_kwargs=PNG)
