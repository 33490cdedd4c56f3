"""Portable FMUs, measured in one run: the native reference FMU (paper Table I machine) and the surrogate
FMU of the shipped operator, each built for FMI 2.0 and FMI 3.0 with every platform whose compiler
is here; the size of each FMU and binary; and how far each platform's binary is from the linux64
one on the standard check scenarios (fmu_export.cross_check: rest, a dip, random held levels at
2-20 ms steps with directional derivatives, input ramps in FMI 2.0, FMU state round trips, bad
values) run long (--steps per scenario) for several seeds, through the C harness natively, under
wine (win64) and under qemu-user (aarch64-linux). FMI 3.0 is also compared with FMI 2.0 on the host
(their outputs and derivatives, on the same held inputs).

    python benchmarks/platforms.py [--steps 400] [--seeds 3] [--out DIR]

Writes DIR/platforms.json, DIR/platforms.md and DIR/platforms.png (the difference of the states and
bus outputs from linux64 along the dip scenario, per platform and FMU) and prints the tables.
"""
import argparse
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fmu_export import cross_check, platforms  # noqa: E402
from fmu_export.surrogate_fmu import build_surrogate_fmu, load_operator, surrogate_variables as variables_of  # noqa: E402
from fmu_export.native_reference_fmu import build_native_reference_fmu, native_reference_variables  # noqa: E402
from reference_models.files import write_json  # noqa: E402
from surrogate.operator import DEFAULT_OPERATOR  # noqa: E402


def surrogate_variables():
    _, meta = load_operator(DEFAULT_OPERATOR)
    return variables_of(meta, DEFAULT_OPERATOR)


def binary(fmu: Path, p, version: int, model: str, folder: Path) -> Path:
    path = folder / f"{model}-{p.name}-fmi{version}{p.extension}"
    with zipfile.ZipFile(fmu) as z:
        path.write_bytes(z.read(p.binary_path(model, version)))
    return path


def numbers(lines, kinds=("get", "dd")):
    """The doubles of the output lines of those kinds, one array per line."""
    out = []
    for line in lines:
        tokens = line.split(" ")
        if tokens[0] in kinds and tokens[1] in ("0", "1"):
            out.append(np.array([cross_check.double_of(t) for t in tokens[2:]]))
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=400, help="steps per scenario")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--out", default=str(Path(__file__).parent))
    args = parser.parse_args()
    chosen, notes = platforms.select(None)
    for note in notes:
        print(note)
    host = platforms.host()
    others = [p for p in chosen if p != host and p.runs_here()]
    fmus = {"reference": (native_reference_variables(), "SM4Reference"),
            "surrogate": (surrogate_variables(), "SM4Surrogate")}
    result = {"platforms": [p.name for p in chosen], "steps": args.steps, "seeds": args.seeds, "fmus": {}}
    traces = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for kind, (variables, model) in fmus.items():
            outputs = [v.name for v in variables if v.kind == "Real" and v.causality == "output"]
            for version in (2, 3):
                path = tmp / f"{kind}-fmi{version}.fmu"
                print(f"building the {kind} FMU, FMI {version}, for {', '.join(p.name for p in chosen)}", flush=True)
                if kind == "reference":
                    info = build_native_reference_fmu(path, platforms=chosen, fmi_version=version)
                else:
                    info = build_surrogate_fmu(DEFAULT_OPERATOR, path, platforms=chosen, fmi_version=version)
                entry = {"fmu_bytes": info["size_bytes"],
                         "binary_bytes": {n: b["size_bytes"] for n, b in info["binaries"].items()},
                         "differences": {}}
                host_binary = binary(path, host, version, model, tmp)
                for p in others:
                    worst = {"numbers": 0, "differing": 0, "max_difference": 0.0, "max_abs": 0.0, "mismatch": ""}
                    for seed in range(args.seeds):
                        script = cross_check.scenario_script(variables, info["guid"], version, version == 2, seed,
                                                             args.steps)
                        work = tmp / f"{kind}-{version}-{seed}"
                        base = cross_check.run_script(host, host_binary, script, work, version)
                        lines = cross_check.run_script(p, binary(path, p, version, model, tmp), script, work, version)
                        c = cross_check.compare(base, lines)
                        columns = dict(zip(outputs, cross_check.column_differences(base, lines)))
                        worst = {"numbers": worst["numbers"] + c.numbers, "differing": worst["differing"] + c.differing,
                                 "max_difference": max(worst["max_difference"], c.max_difference),
                                 "max_abs": max(worst["max_abs"], c.max_abs), "mismatch": worst["mismatch"] or c.mismatch,
                                 "outputs": {n: max(worst.get("outputs", {}).get(n, 0.0), float(g))
                                             for n, g in columns.items()}}
                        if seed == 0 and version == 2:
                            traces[(kind, p.name)] = dip_trace(base, lines, outputs)
                    entry["differences"][p.name] = worst
                    print(f"  {p.name}: {worst}", flush=True)
                result["fmus"][f"{kind}-fmi{version}"] = entry
            # FMI 3.0 against FMI 2.0 on the host: the same held inputs (no ramps), outputs and derivatives
            gaps = []
            for seed in range(args.seeds):
                runs = []
                for version in (2, 3):
                    path = tmp / f"{kind}-fmi{version}.fmu"
                    guid = _guid(path)
                    script = cross_check.scenario_script(variables, guid, version, False, seed, args.steps)
                    runs.append(numbers(cross_check.run_script(host, binary(path, host, version, model, tmp), script,
                                                               tmp / f"{kind}-v{version}-{seed}", version)))
                gaps.append(max(float(np.max(np.abs(a - b))) if a.size else 0.0 for a, b in zip(*runs)))
                assert len(runs[0]) == len(runs[1])
            result["fmus"][f"{kind}-fmi3-vs-fmi2"] = {"max_abs": max(gaps), "lines": len(runs[0])}
            print(f"  FMI 3 against FMI 2 on {host.name}: {max(gaps):.1e}", flush=True)
    out = Path(args.out)
    write_json(out / "platforms.json", result)
    table = markdown(result)
    (out / "platforms.md").write_text(table)
    print(table)
    if traces:
        plot(traces, out / "platforms.png")


def _guid(fmu: Path) -> str:
    from fmpy import read_model_description

    md = read_model_description(str(fmu))
    return md.guid if md.fmiVersion == "2.0" else md.instantiationToken


def dip_trace(base, lines, outputs):
    """Largest |difference| / max(1, |value|) of the states and bus outputs (all but the residual
    diagnostic) at each step of the dip scenario (the second instance)."""
    starts = [i for i, line in enumerate(base) if line.startswith("instantiate")]
    keep = np.array([name != "residual" for name in outputs])
    a, b = (numbers(run[starts[1]:starts[2]], ("get",)) for run in (base, lines))
    return [float(np.max((np.abs(x - y) / np.maximum(1.0, np.abs(x)))[keep])) for x, y in zip(a, b)]


def markdown(result) -> str:
    rows = ["| FMU | FMI | FMU size | " + " | ".join(f"{p} binary" for p in result["platforms"]) + " |",
            "| --- | --- | --- | " + " | ".join("---" for _ in result["platforms"]) + " |"]
    for key, entry in result["fmus"].items():
        if "fmu_bytes" in entry:
            kind, version = key.split("-fmi")
            rows.append(f"| {kind} | {version} | {entry['fmu_bytes'] / 1e6:.2f} MB | "
                        + " | ".join(f"{entry['binary_bytes'].get(p, 0) / 1e3:.0f} kB" for p in result["platforms"])
                        + " |")
    rows += ["", "Differences from linux64, relative to max(1, |value|); states and bus outputs: delta ... Q; "
             "all: every double of the run (outputs, directional derivatives, the residual diagnostic).", "",
             "| FMU | FMI | platform | doubles compared | not bit-identical | states and bus outputs | residual | all |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for key, entry in result["fmus"].items():
        for p, d in entry.get("differences", {}).items():
            kind, version = key.split("-fmi")
            physical = max(g for n, g in d["outputs"].items() if n != "residual")
            residual = f"{d['outputs']['residual']:.1e}" if "residual" in d["outputs"] else "-"
            rows.append(f"| {kind} | {version} | {p} | {d['numbers']} | {d['differing']} | {physical:.1e} | {residual} | "
                        f"{d['max_difference']:.1e} |" + (f" {d['mismatch']}" if d["mismatch"] else ""))
    rows += ["", "| FMU | FMI 3.0 against FMI 2.0 on the host: largest abs difference | output lines |", "| --- | --- | --- |"]
    for key, entry in result["fmus"].items():
        if key.endswith("vs-fmi2"):
            rows.append(f"| {key.split('-')[0]} | {entry['max_abs']:.1e} | {entry['lines']} |")
    return "\n".join(rows) + "\n"


def plot(traces, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.5))
    for (kind, name), trace in traces.items():
        ax.semilogy(np.arange(len(trace)) * 0.01, np.maximum(trace, 1e-18), label=f"{kind} FMU, {name}")
    ax.axhline(cross_check.TOLERANCE, color="k", ls="--", lw=0.8, label="1e-12")
    ax.set_xlabel("time in the dip scenario [s] (Vs at 70 % from 0.1 to 0.25 s)")
    ax.set_ylabel("states and bus outputs: largest |difference|\n/ max(1, |value|) against linux64 (0 as 1e-18)")
    ax.set_title("Outputs of the other platforms' binaries against linux64 (FMI 2.0)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    main()
