"""What a grid run leaves in its folder: result.csv (the columns of docs/grid.md, "What a run
leaves": time, delta, omega [rad/s deviation], Efd per unit and V per bus, then the rest of
GridResult.columns, then P_attach_<bus>, Q_attach_<bus> [pu] at each bus a sub-system is attached
at; a second line `# s,rad,...` gives each column's unit, and the times are
rounded to 1 ns, so that a time on the step grid reads as the multiple of the step it is),
a figure of rotor angles relative to machine 1, speeds, terminal voltages and field voltages with
every compared run on the same axes (beyond 10 machines the ones that swing most are coloured and
named, the others grey), and a Markdown report. All written atomically; a result set whole or not
at all, into a folder made only then."""
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
    """The folder `out` (not made here: result_set makes it), checked to take the files `names`:
    OutputError when `out` is empty text, a file, under a file, in a folder that cannot be written
    (its nearest existing folder is probed), or one of the targets exists and is not a file."""
    if not str(out).strip():
        raise OutputError(f"--out must name a folder, got {str(out)!r}")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {out} is a file, not a folder")
    existing = next(p for p in (out, *out.parents, Path.cwd()) if p.exists())
    if not existing.is_dir():
        raise OutputError(f"cannot write into the output folder {out} ({existing} is a file)")
    try:
        probe = tempfile.NamedTemporaryFile(dir=existing, prefix=".opfmu-probe-")
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
    """Writes a set of files whole or not at all: makes `out` where it is absent and yields a staging
    folder in it; when the block ends without an error every file `names` written there is moved
    into `out` (each move atomic). The staging folder is removed in any case, and where the block
    fails, so are the folders made here that it left empty."""
    out = check_output(out, names)
    made = [p for p in (out, *out.parents) if not p.exists()]  # the folders made here, innermost first
    out.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(dir=out, prefix=".opfmu-staging-"))
    written = False
    try:
        yield staging
        missing = [n for n in names if not (staging / n).is_file()]
        if missing:
            raise OutputError(f"the result set lacks {', '.join(missing)}")
        for name in names:
            os.replace(staging / name, out / name)
        written = True
    finally:
        shutil.rmtree(staging, ignore_errors=True)
        if not written:
            for folder in made:
                try:
                    folder.rmdir()  # only while empty
                except OSError:
                    break


def _figure(figsize):
    """A matplotlib Figure on the Agg canvas (no pyplot)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig


TIME_DECIMALS = 9  # result.csv's times are rounded to 1 ns (EVENT_TOLERANCE): 0.3, not 0.30000000000000004


def column_units(columns, case=None) -> list:
    """The unit of each of the result columns `columns` (names of GridResult.columns(case)): s, rad,
    rad/s (a speed deviation), pu (voltages, field voltages, and P, Q, I_re, I_im on the system
    base), and for a device's state the unit its component gives ("" where unknown: without the
    `case`, or a state no component of it names)."""
    from reference_models.grid.result import device_labels

    fixed = {"time": "s", "delta": "rad", "omega": "rad/s", "Efd": "pu", "V": "pu", "theta": "rad", "Vs": "pu",
             "theta_vs": "rad", "P": "pu", "Q": "pu"}
    states = {}
    if case is not None:
        for unit, labels in zip(case.units, device_labels(case.units)):
            for device, label in zip(unit.devices, labels):
                states.update({f"{label}_{q.name}": q.unit for q in device.component.states})
                states.update({f"{label}_{n}": "pu" for n in ("P", "Q", "I_re", "I_im")})
    out = []
    for name in columns:
        prefix = "theta_vs" if name.startswith("theta_vs_") else name.partition("_")[0]
        out.append(states.get(name, fixed.get(prefix, "")))
    return out


def _time_text(t: float) -> str:
    """A time [s] rounded to TIME_DECIMALS, without trailing zeros."""
    return (f"{t:.{TIME_DECIMALS}f}".rstrip("0").rstrip(".") or "0") if math.isfinite(t) else f"{t}"


def attachment_columns(result, case, buses) -> dict:
    """{"P_attach_<bus>", "Q_attach_<bus>": [n]} for each host bus of `buses` with a sub-system
    attached (opfmu grid run --attach): the power the sub-system injects into that bus [pu, system
    base, generator convention], from the result's bus voltages (reference_models.grid.boundary), or
    for a sub-system run as its equivalent, the equivalent's own P and Q."""
    from reference_models.grid.boundary import boundary_power, equivalent_units

    out = {}
    for bus in buses:
        units = equivalent_units(case, bus)
        if units:
            S = result.P[:, units].sum(axis=1) + 1j * result.Q[:, units].sum(axis=1)
        else:
            S = boundary_power(case.network, result.V_bus, result.theta_bus, bus)
        out[f"P_attach_{bus}"], out[f"Q_attach_{bus}"] = S.real, S.imag
    return out


def write_csv(path, result, case=None, attached=()) -> None:
    """result.csv: a header line of the column names, a second line `# ` and each column's unit
    (column_units; readers skip it as a comment: numpy's genfromtxt(names=True), pandas'
    read_csv(comment="#")), then one row per communication point: the time rounded to 1 ns, the
    rest to 17 significant digits. `case`: the Case the result is of (speeds as deviations in
    rad/s, every unit's field voltage: GridResult.columns); `attached`: the host buses with a
    sub-system attached, whose P_attach_<bus>, Q_attach_<bus> [pu] come last (attachment_columns;
    needs `case`)."""
    columns = result.columns(case)
    columns.update(attachment_columns(result, case, attached))
    names = list(columns)
    data = np.column_stack([np.asarray(columns[n], dtype=float) for n in names])
    text = io.StringIO()
    csv.writer(text, lineterminator="\n").writerow(names)
    text.write("# " + ",".join(column_units(names, case)) + "\n")
    row = ",".join(["%s"] + ["%.17g"] * (len(names) - 1))  # one format per row: as csv's text, 3 times faster
    text.write("".join(row % (_time_text(values[0]), *values[1:]) + "\n" for values in data.tolist()))
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


def errors(result, reference, fault=None, case=None, trips=None) -> dict:
    """Largest differences from `reference`, compared at the rows both runs have outside their event
    times (`common_rows`; no value is interpolated, none is taken across a switching): rotor angles
    relative to the first machine that is not tripped [deg], speeds [rad/s deviation where `case` is given, else the speed
    states as stored], bus voltages at the machines outside the fault's own steps [pu] (the rows
    with a fault on, times in [start, clear), are left out: fault = (start, clear), a sequence of
    such pairs, or None), field voltages [pu] (with `case`: every unit's, GridResult's
    field_voltage), and the power P, Q [pu, system base] into the bus of every unit without a rotor
    angle (an inverter, a load) outside the fault's steps. trips {unit index: time [s]}
    (Contingency.trip_times): a unit tripped is left out from its trip on (what each run keeps of a
    device that is off differs: opfmu's stands still, ANDES' voltage falls to 0). ValueError where
    the runs share no such row."""
    from reference_models.grid.result import field_voltage, speed_deviation

    mine, theirs = common_rows(result, reference)
    if not len(mine):
        raise ValueError("the two runs have no row at a common time outside their events")
    t = result.time[mine]
    off = np.zeros((len(t), len(result.gen_buses)), bool)  # [row, unit]: tripped by then
    for k, trip in (trips or {}).items():
        off[:, k] = t >= trip - EVENT_TOLERANCE
    out = {}
    # rotor angles relative to the first machine that is not tripped
    g = result.gen_buses
    first = next((k for k in range(len(g)) if k not in (trips or {}) and np.any(np.isfinite(result.angles[:, k]))),
                 0)
    differences = [np.where(off[:, k] | off[:, first], np.nan,
                            np.abs(result.angle_difference(b, g[first])[mine] - reference.angle_difference(b, g[first])[theirs]))
                   for k, b in enumerate(g) if k != first]
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
    out["V"] = _largest(np.where(off, np.nan, np.abs(result.Vs[mine] - reference.Vs[theirs]))[rows]) if rows.any() \
        else math.nan
    for name, (a, b) in pairs.items():
        out[name] = _largest(None if a is None or b is None else np.where(off, np.nan, np.abs(a[mine] - b[theirs])))
    # the power of the units without a rotor angle (inverters, loads) where both runs give it
    others = ~np.any(np.isfinite(reference.angles), axis=0) & ~np.any(np.isfinite(result.angles), axis=0)
    for name in ("P", "Q"):
        a, b = getattr(result, name)[mine][:, others], getattr(reference, name)[theirs][:, others]
        out[name] = _largest(np.where(off[:, others], np.nan, np.abs(a - b))[rows]) if rows.any() else math.nan
    return {key: out[key] for key in ("angle_deg", "omega", "V", "Efd", "P", "Q")}


def _largest(values) -> float:
    """The largest finite entry of `values` (NaN where there is none)."""
    if values is None:
        return math.nan
    finite = np.asarray(values)[np.isfinite(values)]
    return float(finite.max()) if finite.size else math.nan


def _coloured(result, omega, colours: int) -> list:
    """The machines (unit indices of `result`) drawn in colours of their own, at most `colours`: all
    where there are no more, else those whose speed deviation `omega` [n, units] swings most (the
    rotor angle's excursion where there is no speed; a unit with neither last)."""
    n = len(result.gen_buses)
    if n <= colours:
        return list(range(n))
    angle = result.angles
    with np.errstate(invalid="ignore"):
        swing = np.nanmax(np.abs(omega), axis=0, initial=-np.inf, where=np.isfinite(omega))
        excursion = np.nanmax(np.abs(angle - angle[:1]), axis=0, initial=-np.inf, where=np.isfinite(angle))
    has_speed = np.isfinite(swing) & np.any(np.isfinite(omega), axis=0)
    key = [(bool(has_speed[k]), swing[k] if has_speed[k] else excursion[k]) for k in range(n)]
    return sorted(sorted(range(n), key=lambda k: key[k], reverse=True)[:colours])


def plot(path, runs: dict, title: str, case=None) -> None:
    """The figure: runs {kind: GridResult}, 2 x 2 panels; with the `case` they are of, speeds as
    deviations [rad/s] and every unit's field voltage (GridResult's speed_deviation,
    field_voltage), else the states of those names as stored. A machine's colour is the same in
    every run and a run's line style the same for every machine; the legend, below the panels in
    columns, names each coloured machine and each run. Beyond 10 machines (the colour cycle) the
    10 that swing most (`_coloured`) are coloured and the others drawn thin and grey, as one entry."""
    from matplotlib import rcParams
    from matplotlib.lines import Line2D

    from reference_models.grid.result import field_voltage, speed_deviation, unit_labels

    fig = _figure((12, 7.5))
    axes = fig.subplots(2, 2, sharex=True)
    first = next(iter(runs.values()))
    colors = rcParams["axes.prop_cycle"].by_key()["color"]
    omega_first = speed_deviation(first, case) if case is not None else np.full(first.Vs.shape, np.nan)
    coloured = _coloured(first, omega_first, len(colors))
    colour_of = {k: colors[i] for i, k in enumerate(coloured)}
    others = dict(color="0.6", lw=0.6, alpha=0.6)
    for kind, result in runs.items():
        style = {key: v for key, v in STYLES.get(kind, {}).items() if key != "color"}
        nan = np.full(result.Vs.shape, np.nan)
        omega = speed_deviation(result, case) if case is not None else nan
        Efd = field_voltage(result, case) if case is not None else nan
        for k, bus in enumerate(result.gen_buses):
            kw = {**style, "color": colour_of[k]} if k in colour_of else {**style, **others}
            if k > 0:
                axes[0, 0].plot(result.time, np.degrees(result.angle_difference(bus)), **kw)
            axes[0, 1].plot(result.time, omega[:, k], **kw)
            axes[1, 0].plot(result.time, result.Vs[:, k], **kw)
            axes[1, 1].plot(result.time, Efd[:, k], **kw)
    labels = unit_labels(first.gen_buses)
    handles = [Line2D([], [], color=colour_of[k], lw=1.5, label=f"machine {labels[k]}") for k in coloured]
    rest = len(first.gen_buses) - len(coloured)
    if rest:
        handles.append(Line2D([], [], **{**others, "lw": 1.0}, label=f"the other {rest} machines"))
    handles += [Line2D([], [], color="0.25", **{key: v for key, v in STYLES.get(kind, {}).items() if key != "color"},
                       label=LABELS.get(kind, kind)) for kind in runs]
    columns = min(len(handles), 6)
    rows = -(-len(handles) // columns)
    axes[0, 0].set_ylabel(f"rotor angle - machine {first.gen_buses[0]} [deg]")
    axes[0, 1].set_ylabel("speed deviation [rad/s]")
    axes[1, 0].set_ylabel("terminal voltage [pu]")
    axes[1, 1].set_ylabel("field voltage Efd [pu]")
    for ax in axes[1]:
        ax.set_xlabel("time [s]")
    for ax in axes.flat:
        ax.grid(alpha=0.3)
    fig.legend(handles=handles, loc="lower center", ncol=columns, fontsize=8, frameon=False)
    fig.suptitle(title)
    legend = 0.03 * rows + 0.02  # figure fraction under the panels that the legend takes
    fig.subplots_adjust(left=0.07, right=0.985, bottom=0.07 + legend, top=0.93, wspace=0.2, hspace=0.08)
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
    fault, trips = contingency.fault_intervals(math.inf), contingency.trip_times(math.inf)
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
            e = errors(result, runs[reference], fault, case, trips)
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
