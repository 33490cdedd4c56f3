"""Coverage of the stock cases ANDES ships (issue 33): which of ANDES' own case files opfmu reads and
runs, and what keeps it from the others.

    python benchmarks/stock_cases.py [--only PATTERN] [--jobs 1] [--timeout 300] [--stop 2]
        [--no-resume] [--redo-opfmu] [--table-only] [--out runs/stock_cases] [--doc docs/stock-cases.md]

The files: every .xlsx and .json under andes/cases, and the PSS/E raw files with a dyr beside them,
paired as ANDES' examples load them (RAW_DYR_PAIRS, listed explicitly). Per file, each step in a
subprocess of its own with a timeout of --timeout s per step (--build-timeout for a case's FMU
builds; a hang or crash of one file does not stop the rest; a step past its time is recorded as a
timeout):
* ANDES: the file loads (andes.load, default config), its power flow converges (ANDES' defaults) and
  --stop s of its time-domain simulation (TDS, default step) run; the models it uses (ANDES' model
  names with n > 0).
* opfmu: case_from_file reads it (converted into a cache folder of its own, so the converter of
  today is what is checked; a refusal is its one line), and a --stop s run of the case with native
  FMUs (`reference`: the co-simulation master, h = 10 ms, the FMUs built into the FMU cache) and of
  the monolithic DAE finish, with the case's own events and no fault: the run `opfmu grid run --case
  FILE [--dyr DYR] --stop 2 --fmus reference|monolithic` makes, except that the command needs a
  --fault (cosim.runners.open_runner, the defaults of the command: h = 10 ms, 3 passes).
Status of a file: "runs" (ANDES and opfmu both), "refused: REASON" (case_from_file refuses it, ANDES
runs it), "fails: KIND: REASON" (opfmu reads it but a run does not finish), "ANDES fails: REASON"
(not counted); the coverage is the share of the files ANDES runs that opfmu runs.

Each file's record goes into OUT/stock_cases.json, written atomically after each file; a run resumes
where it stopped (files with a record are skipped unless --no-resume). --redo-opfmu checks opfmu
again on every selected file and keeps the stored ANDES part (ANDES is pinned; its part does not
change). --table-only writes the table from the records. The table (--doc): every file with its
ANDES status, opfmu status, reason and models (those opfmu does not have in bold), the coverage, and
the models opfmu does not have with how many files each blocks. Needs ANDES (pip install andes==2.0.0).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import queue
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from fnmatch import fnmatch
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
# PSS/E raw files with the dyr files beside them, paired as ANDES' examples and tests load them (the
# raw files without a dyr, ieee39.raw, wscc9.raw, wscc9_3wxfr.raw, hold a power flow only: left out)
RAW_DYR_PAIRS = (
    ("kundur/kundur.raw", "kundur/kundur_full.dyr"),
    ("kundur/kundur.raw", "kundur/kundur_gencls.dyr"),
    ("ieee14/ieee14.raw", "ieee14/ieee14.dyr"),
    ("ieee14/ieee14_ieeevc.raw", "ieee14/ieee14_ieeevc.dyr"),
    ("wecc/wecc.raw", "wecc/wecc_full.dyr"),
    ("wecc/wecc.raw", "wecc/wecc_gencls.dyr"),
    ("npcc/npcc.raw", "npcc/npcc_full.dyr"),
    ("nordic44/N44_BC.raw", "nordic44/N44_BC.dyr"),
)
CASE_SUFFIXES = (".xlsx", ".json")
STEP_TIMEOUT_S = 300.0
BUILD_TIMEOUT_S = 900.0  # building a case's FMUs (about 1 s each where the FMU cache misses: npcc has 140)
STOP_S = 2.0
RUN_KINDS = ("reference", "monolithic")  # opfmu's runs: native FMUs through the master, the monolithic DAE
MARK = "@@stock "  # the children's report lines on stdout (ANDES prints there too)
RECORDS = "stock_cases.json"


def andes_cases_dir() -> Path:
    """ANDES' case folder (andes/cases), found without importing ANDES."""
    import importlib.util

    spec = importlib.util.find_spec("andes")
    if spec is None or not spec.submodule_search_locations:
        raise SystemExit("needs ANDES: pip install andes==2.0.0")
    return Path(list(spec.submodule_search_locations)[0]) / "cases"


def stock_files(root: Path | None = None) -> list:
    """[(key, case file, dyr file or None)] of every stock case, sorted by key: the .xlsx and .json
    files under `root` (ANDES' case folder) and RAW_DYR_PAIRS (key "RAW+DYR's name"). SystemExit
    where a dyr file under root is in no pair (a new ANDES: pair it here)."""
    root = root or andes_cases_dir()
    files = [(p.relative_to(root).as_posix(), p, None) for p in root.rglob("*")
             if p.suffix.lower() in CASE_SUFFIXES and p.is_file()]
    for raw, dyr in RAW_DYR_PAIRS:
        if (root / raw).is_file() and (root / dyr).is_file():
            files.append((f"{raw}+{Path(dyr).name}", root / raw, root / dyr))
    paired = {dyr for _, dyr in RAW_DYR_PAIRS}
    unpaired = [p.relative_to(root).as_posix() for p in root.rglob("*.dyr")
                if p.relative_to(root).as_posix() not in paired]
    if unpaired:
        raise SystemExit(f"dyr files in no pair of RAW_DYR_PAIRS: {', '.join(unpaired)}")
    return sorted(files, key=lambda f: f[0].lower())


def _one_line(text, limit: int = 240) -> str:
    return " ".join(str(text).split())[:limit]


# ---------------------------------------------------------------------------------------------------
# children: one step per report line "@@stock {json}" on stdout


def _report(**item) -> None:
    sys.__stdout__.write(MARK + json.dumps(item, default=float) + "\n")
    sys.__stdout__.flush()


def _child_andes(file: str, dyr: str | None, stop: float) -> None:
    """Stages load, pflow, tds of ANDES on the file; the ANDES log's warnings and errors kept for the
    reasons."""
    import logging
    from contextlib import redirect_stdout

    import andes

    andes.config_logger(stream_level=logging.CRITICAL + 1, file=False, log_path=tempfile.gettempdir())
    kept = []

    class Keep(logging.Handler):
        def emit(self, record):
            kept.append((record.levelno, record.getMessage()))

    logging.getLogger("andes").addHandler(Keep(logging.WARNING))

    def why(default: str) -> str:
        errors = [m for level, m in kept if level >= logging.ERROR and m.strip()]
        return _one_line("; ".join(errors[-2:]) if errors else default)  # ANDES says why, then that it stopped

    with redirect_stdout(sys.stderr):  # whatever ANDES prints: away from the report lines
        started = time.perf_counter()
        try:
            kwargs = {"addfile": dyr} if dyr else {}
            ss = andes.load(file, no_output=True, default_config=True, **kwargs)
            error = None if ss is not None else why("andes.load returned nothing")
        except Exception as exc:
            ss, error = None, f"{type(exc).__name__}: {_one_line(exc)}"
        if ss is None:
            _report(stage="load", ok=False, s=time.perf_counter() - started, error=error)
            return
        models = [name for name, model in ss.models.items() if getattr(model, "n", 0) > 0]
        _report(stage="load", ok=True, s=time.perf_counter() - started, models=models,
                buses=int(ss.Bus.n))
        started = time.perf_counter()
        try:
            ok = bool(ss.PFlow.run()) and bool(ss.PFlow.converged)
            error = None if ok else why("the power flow does not converge")
        except Exception as exc:
            ok, error = False, f"{type(exc).__name__}: {_one_line(exc)}"
        _report(stage="pflow", ok=ok, s=time.perf_counter() - started, error=error)
        if not ok:
            return
        started = time.perf_counter()
        try:
            ss.TDS.config.tf = stop
            if "no_tqdm" in ss.TDS.config.as_dict():
                ss.TDS.config.no_tqdm = 1
            ok = bool(ss.TDS.run())
            t = float(ss.dae.t)
            ok = ok and t >= stop - 1e-6
            error = None if ok else why(f"the simulation stopped at {t:g} s")
        except Exception as exc:
            ok, t, error = False, None, f"{type(exc).__name__}: {_one_line(exc)}"
        _report(stage="tds", ok=ok, s=time.perf_counter() - started, t_end=t, error=error)


def _child_read(file: str, dyr: str | None, cache: str) -> None:
    """Stage read: case_from_file into `cache`."""
    from reference_models.grid.andes_case import case_from_file
    from reference_models.grid.case import CaseError

    started = time.perf_counter()
    known = sorted(known_models())  # what this converter takes, at the time of the check
    try:
        case = case_from_file(file, dyr, cache)
    except CaseError as exc:
        _report(stage="read", ok=False, s=time.perf_counter() - started, error=_one_line(exc, 400), refused=True,
                known=known)
        return
    except Exception as exc:  # a converter bug, reported as what it is
        _report(stage="read", ok=False, s=time.perf_counter() - started,
                error=f"{type(exc).__name__}: {_one_line(exc)}", known=known)
        return
    components = sorted({d.component.name for u in case.units for d in u.devices})
    _report(stage="read", ok=True, s=time.perf_counter() - started, units=len(case.units),
            buses=len(case.network.buses), events=len(case.events), components=components, known=known)


def _child_run(kind: str, file: str, dyr: str | None, cache: str, stop: float, fmu_cache: str | None) -> None:
    """Stages build (the runner: FMUs built) and run (`stop` s, the case's own events, no fault)."""
    import numpy as np

    from cosim.master import MasterSettings
    from cosim.runners import open_runner
    from reference_models.grid.andes_case import case_from_file
    from reference_models.grid.contingency import Contingency

    stage, started = "build", time.perf_counter()
    try:
        case = case_from_file(file, dyr, cache)
        contingency = Contingency(None, None, None, 0.0, network=case.network, events=case.events)
        runner = open_runner(kind, case, MasterSettings(step=0.01), fmu_cache)
        _report(stage=stage, ok=True, s=time.perf_counter() - started)
        stage, started = "run", time.perf_counter()
        try:
            result, _ = runner.run(contingency, stop)
        finally:
            runner.close()
        t = float(result.time[-1])
        # a state is NaN throughout for the units whose devices do not have it (GENCLS has no e1q): every
        # value that is finite at the start stays so
        finite = bool(np.all(np.isfinite(result.Vs)) and all(np.all(np.isfinite(v[:, np.isfinite(v[0])]))
                                                              for v in map(np.asarray, result.states.values())))
        ok = finite and t >= stop - 1e-9
        error = None if ok else (f"non-finite values (ended at {t:g} s)" if not finite else f"ended at {t:g} s")
        _report(stage=stage, ok=ok, s=time.perf_counter() - started, t_end=t, stable=bool(result.stable),
                loss_s=result.loss_of_synchronism_s, error=error)
    except Exception as exc:
        _report(stage=stage, ok=False, s=time.perf_counter() - started,
                error=f"{type(exc).__name__}: {_one_line(exc)}")


def _child(argv) -> None:
    p = argparse.ArgumentParser()
    p.add_argument("what", choices=("andes", "read") + RUN_KINDS)
    p.add_argument("file")
    p.add_argument("--dyr")
    p.add_argument("--cache")
    p.add_argument("--stop", type=float, default=STOP_S)
    p.add_argument("--fmu-cache")
    a = p.parse_args(argv)
    if a.what == "andes":
        _child_andes(a.file, a.dyr, a.stop)
    elif a.what == "read":
        _child_read(a.file, a.dyr, a.cache)
    else:
        _child_run(a.what, a.file, a.dyr, a.cache, a.stop, a.fmu_cache)


# ---------------------------------------------------------------------------------------------------
# the parent: steps in subprocesses, each with its timeout


def _staged(args: list, stages: tuple, timeout: float, timeouts: dict | None = None) -> dict:
    """{stage: report} of a child (`args` after --child) that reports `stages` in order; a stage not
    reported within `timeout` s (timeouts.get(stage, timeout)) of the one before is a timeout (the
    child's process group killed), a child that ends without reporting it crashed (its exit code and
    last stderr line)."""
    out = {}
    with tempfile.TemporaryFile(mode="w+") as err:
        proc = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--child", *args], cwd=REPO,
                                stdout=subprocess.PIPE, stderr=err, stdin=subprocess.DEVNULL, text=True,
                                start_new_session=True)
        items = queue.Queue()

        def read():
            for line in proc.stdout:
                if line.startswith(MARK):
                    try:
                        items.put(json.loads(line[len(MARK):]))
                    except ValueError:
                        pass
            items.put(None)

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        try:
            for stage in stages:
                limit = (timeouts or {}).get(stage, timeout)
                try:
                    item = items.get(timeout=limit)
                except queue.Empty:
                    out[stage] = {"stage": stage, "ok": False, "timeout": True, "s": limit,
                                  "error": f"timeout after {limit:g} s"}
                    break
                if item is None:
                    rc = proc.wait()
                    err.seek(0)
                    lines = [line for line in err.read().splitlines() if line.strip()]
                    out[stage] = {"stage": stage, "ok": False, "crashed": True,
                                  "error": f"crashed (exit code {rc})" + (f": {_one_line(lines[-1])}" if lines else "")}
                    break
                out[item.get("stage", stage)] = item
                if not item.get("ok"):
                    break
        finally:
            if proc.poll() is None:
                try:
                    os.killpg(proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
            proc.wait()
            reader.join(timeout=10)
    return out


def andes_check(file: Path, dyr: Path | None, timeout: float = STEP_TIMEOUT_S, stop: float = STOP_S) -> dict:
    """ANDES' part of a record: load, pflow, tds stages, the models, ok and the reason it fails."""
    args = ["andes", str(file), "--stop", repr(stop)] + (["--dyr", str(dyr)] if dyr else [])
    stages = _staged(args, ("load", "pflow", "tds"), timeout)
    reason = _failure(stages, ("load", "pflow", "tds"))
    return {"ok": reason is None, "stages": stages, "models": stages.get("load", {}).get("models", []),
            "buses": stages.get("load", {}).get("buses"), "reason": reason,
            "s": sum(v.get("s", 0.0) for v in stages.values())}


def _failure(stages: dict, names: tuple) -> str | None:
    """None where every stage of `names` passed, else "STAGE: its error" of the first that did not."""
    failed = next((n for n in names if not stages.get(n, {}).get("ok")), None)
    return None if failed is None else f"{failed}: {stages.get(failed, {}).get('error') or 'not reached'}"


def opfmu_check(file: Path, dyr: Path | None, cache: Path, timeout: float = STEP_TIMEOUT_S, stop: float = STOP_S,
                fmu_cache=None, kinds=RUN_KINDS, build_timeout: float = BUILD_TIMEOUT_S) -> dict:
    """opfmu's part of a record: read (case_from_file, converted afresh into `cache`), then each run
    kind's build (`build_timeout` s) and run stages; ok where every one passes, else the reason of
    the first that fails."""
    shutil.rmtree(cache, ignore_errors=True)
    common = [str(file), "--cache", str(cache), "--stop", repr(stop)] + (["--dyr", str(dyr)] if dyr else [])
    read = _staged(["read", *common], ("read",), timeout).get("read", {})
    out = {"read": read, "runs": {}, "ok": False, "refused": not read.get("ok"), "reason": None}
    if not read.get("ok"):
        out["reason"] = read.get("error") or "not read"
        return out
    extra = ["--fmu-cache", str(fmu_cache)] if fmu_cache else []
    for kind in kinds:
        stages = _staged([kind, *common, *extra], ("build", "run"), timeout, {"build": build_timeout})
        reason = _failure(stages, ("build", "run"))
        out["runs"][kind] = {"ok": reason is None, "stages": stages, "reason": reason,
                             "stable": stages.get("run", {}).get("stable"),
                             "s": sum(v.get("s", 0.0) for v in stages.values())}
    bad = [k for k in kinds if not out["runs"][k]["ok"]]
    out["ok"] = not bad
    out["reason"] = "; ".join(f"{k}: {out['runs'][k]['reason']}" for k in bad) or None
    return out


def classify(record: dict) -> tuple:
    """(status, reason) of a record: runs, refused, fails, ANDES fails (see the module docstring)."""
    a, o = record["andes"], record["opfmu"]
    if not a["ok"]:
        return "ANDES fails", a["reason"]
    if o["ok"]:
        unstable = [k for k, r in o["runs"].items() if r.get("stable") is False]
        return "runs", (f"lost synchronism with no fault ({', '.join(unstable)})" if unstable else "")
    if o["refused"]:
        return "refused", o["reason"]
    return "fails", o["reason"]


def check_file(key: str, file: Path, dyr: Path | None, work: Path, timeout: float = STEP_TIMEOUT_S,
               stop: float = STOP_S, fmu_cache=None, andes: dict | None = None, kinds=RUN_KINDS,
               build_timeout: float = BUILD_TIMEOUT_S) -> dict:
    """The record of one stock file: ANDES' part (or `andes`, a stored one), opfmu's part (its case
    converted into work/cases/KEY), the status and the reason."""
    started = time.perf_counter()
    slug = key.replace("/", "__").replace("+", "__")
    if andes is None:
        andes = andes_check(file, dyr, timeout, stop)
    o = opfmu_check(file, dyr, Path(work) / "cases" / slug, timeout, stop, fmu_cache, kinds, build_timeout)
    record = {"key": key, "file": str(file), "dyr": None if dyr is None else str(dyr), "stop_s": stop,
              "timeout_s": timeout, "build_timeout_s": build_timeout, "andes": andes, "opfmu": o,
              "checked": time.strftime("%Y-%m-%d %H:%M:%S"), "commit": _commit()}
    record["missing_models"] = record_missing(record)
    record["status"], record["reason"] = classify(record)
    record["s"] = time.perf_counter() - started
    return record


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True,
                              timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


# ---------------------------------------------------------------------------------------------------
# the table


def known_models() -> set:
    """The ANDES models opfmu converts or leaves out on purpose (reference_models.grid.andes_case)."""
    from reference_models.grid import andes_case
    from reference_models.models import STANDARD_MODELS

    return (set(getattr(andes_case, "NETWORK_MODELS", ())) | set(getattr(andes_case, "IGNORED_MODELS", ()))
            | set(STANDARD_MODELS))


def record_missing(record: dict, known: set | None = None) -> list:
    """The models of a record's file that opfmu did not have when it was checked: its
    "missing_models", else those its read step did not know (its "known"), else those its refusal
    names ("the case uses the models A, B, which opfmu does not have") and those not in `known`
    (default: known_models() of today), in ANDES' order."""
    import re

    if "missing_models" in record:
        return list(record["missing_models"])
    models = record["andes"]["models"]
    read = record["opfmu"]["read"]
    if "known" in read:
        return [m for m in models if m not in set(read["known"])]
    known = known_models() if known is None else known
    named = re.search(r"uses the models? (.*?), which opfmu does not have", read.get("error") or "")
    names = set(named.group(1).split(", ")) if named else set()  # an older converter named the first one only
    return [m for m in models if m in names or m not in known]


def missing_models(records: list, known: set | None = None) -> list:
    """[(model, files it blocks, files it alone blocks)] over the files ANDES runs (record_missing),
    most first."""
    blocks, alone = {}, {}
    for r in records:
        if not r["andes"]["ok"]:
            continue
        missing = record_missing(r, known)
        for m in missing:
            blocks[m] = blocks.get(m, 0) + 1
            if len(missing) == 1:
                alone[m] = alone.get(m, 0) + 1
    return sorted(((m, n, alone.get(m, 0)) for m, n in blocks.items()), key=lambda x: (-x[1], -x[2], x[0]))


def coverage(records: list) -> dict:
    counted = [r for r in records if r["andes"]["ok"]]
    runs = sum(r["status"] == "runs" for r in counted)
    read = sum(bool(r["opfmu"]["read"].get("ok")) for r in counted)
    return {"files": len(records), "andes_runs": len(counted), "runs": runs, "read": read,
            "refused": sum(r["status"] == "refused" for r in counted),
            "fails": sum(r["status"] == "fails" for r in counted),
            "andes_fails": len(records) - len(counted),
            "percent": 100.0 * runs / len(counted) if counted else math.nan}


def _cell(text) -> str:
    return _one_line(text or "", 400).replace("|", "\\|")


def short_reason(reason, record: dict) -> str:
    """A reason for the table: the file's path cut to its key, opfmu's list of the models it has left out."""
    import re

    text = reason or ""
    for path in (record.get("file"), record.get("dyr")):
        if path:
            text = text.replace(f"{path}: ", "").replace(str(path), Path(path).name)
    return re.sub(r",? ?\(it has [^)]*(\)|$)", "", text).strip()


def _andes_cell(a: dict) -> str:
    if a["ok"]:
        return f"runs ({a['s']:.1f} s)"
    failed = a["reason"].split(":")[0]
    return "timeout" if any(v.get("timeout") for v in a["stages"].values()) else f"fails at {failed}"


def _opfmu_cell(r: dict) -> str:
    o = r["opfmu"]
    if o["ok"]:
        return "runs (" + ", ".join(f"{k} {v['s']:.1f} s" for k, v in o["runs"].items()) + ")"
    if o["refused"]:
        return "timeout" if o["read"].get("timeout") else ("refused" if o["read"].get("refused") else "read fails")
    return "read; " + ", ".join(f"{k} {'runs' if v['ok'] else 'fails'}" for k, v in o["runs"].items())


def write_table(records: list, path: Path, stop: float, timeout: float, build_timeout: float = BUILD_TIMEOUT_S) -> str:
    """docs/stock-cases.md: coverage, missing models, every file's row. Returns the text."""
    from reference_models.files import atomic_path

    c = coverage(records)
    by_time = sorted(records, key=lambda r: r["checked"])
    first, last = (by_time[0], by_time[-1]) if by_time else ({"checked": "-", "commit": "-"},) * 2
    commits = first["commit"] if first["commit"] == last["commit"] else f"{first['commit']} to {last['commit']}"
    lines = ["# The stock cases ANDES ships: what opfmu reads and runs", "",
             f"Generated by `python benchmarks/stock_cases.py` (issue 33): files checked from {first['checked']} to "
             f"{last['checked']} (opfmu {commits}, with the working tree of then), ANDES 2.0.0. "
             "Every .xlsx and .json file under andes/cases and the PSS/E raw files with a dyr beside them (paired "
             "as ANDES' examples load them: `RAW_DYR_PAIRS`). Per file, each step in a subprocess with a "
             f"{timeout:g} s timeout (a case's FMU builds: {build_timeout:g} s): ANDES loads it, solves its power "
             f"flow and runs {stop:g} s of its time-domain simulation (default step); opfmu reads it "
             f"(`case_from_file`) and runs {stop:g} s of it, the case's own events and no fault, with native FMUs "
             "(`--fmus reference`, h = 10 ms) and the monolithic DAE (`--fmus monolithic`).", "",
             f"**Coverage: opfmu runs {c['runs']} of the {c['andes_runs']} files ANDES runs "
             f"({c['percent']:.0f} %)**; it reads {c['read']}, refuses {c['refused']}"
             + (f", reads but does not run {c['fails']}" if c["fails"] else "")
             + f". ANDES fails on {c['andes_fails']} of the {c['files']} files (not counted)."
             + f" The checks took {sum(r['s'] for r in records) / 60:.0f} min in all.", "",
             "## Models opfmu does not have", "",
             "Over the files ANDES runs: how many files use each (and in how many it is the only model missing), "
             "as each file was checked.", "",
             "| model | files it blocks | only one missing |", "| --- | ---: | ---: |"]
    for m, n, alone in missing_models(records):
        lines.append(f"| {m} | {n} | {alone} |")
    other = sorted(r["key"] for r in records if r["andes"]["ok"] and r["status"] != "runs" and not record_missing(r))
    if other:
        lines += ["", f"Not run with every model there ({len(other)}; reasons in the table): {', '.join(other)}."]
    lines += ["", "## Every file", "",
              "Models: ANDES' model names with n > 0; those opfmu did not have when the file was checked in bold.", "",
              "| file | ANDES | opfmu | status | reason | models |", "| --- | --- | --- | --- | --- | --- |"]
    for r in sorted(records, key=lambda r: r["key"].lower()):
        missing = set(record_missing(r))
        models = ", ".join(f"**{m}**" if m in missing else m for m in r["andes"]["models"])
        lines.append(f"| {r['key']} | {_andes_cell(r['andes'])} | {_opfmu_cell(r)} | {r['status']} | "
                     f"{_cell(short_reason(r['reason'], r))} | {models} |")
    text = "\n".join(lines) + "\n"
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return text


# ---------------------------------------------------------------------------------------------------


def main(argv=None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--child"]:
        _child(argv[1:])
        return
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", default=None, metavar="PATTERN",
                        help="files whose key (e.g. kundur/kundur.raw+kundur_full.dyr) or file name matches the "
                             "glob PATTERN, or whose key contains it (the table keeps every file with a record)")
    parser.add_argument("--jobs", type=int, default=1, help="files checked at once (default 1)")
    parser.add_argument("--timeout", type=float, default=STEP_TIMEOUT_S, help="seconds per step (default 300)")
    parser.add_argument("--build-timeout", type=float, default=BUILD_TIMEOUT_S,
                        help="seconds for a case's FMU builds (default 900)")
    parser.add_argument("--stop", type=float, default=STOP_S, help="simulated seconds (default 2)")
    parser.add_argument("--resume", action=argparse.BooleanOptionalAction, default=True,
                        help="skip the files with a record (default on)")
    parser.add_argument("--redo-opfmu", action="store_true",
                        help="check opfmu again on the selected files, keeping their stored ANDES part")
    parser.add_argument("--table-only", action="store_true", help="write the table from the records only")
    parser.add_argument("--out", default=str(REPO / "runs" / "stock_cases"), metavar="DIR",
                        help="records and converted cases (default runs/stock_cases)")
    parser.add_argument("--doc", default=str(REPO / "docs" / "stock-cases.md"), metavar="FILE")
    parser.add_argument("--fmu-cache", default=None, metavar="DIR", help="FMU build cache (default opfmu's)")
    args = parser.parse_args(argv)
    from reference_models.files import write_json

    out = Path(args.out)
    store = out / RECORDS
    records = json.loads(store.read_text())["files"] if store.is_file() else {}
    every = stock_files()
    files = [f for f in every if args.only is None or args.only in f[0]
             or any(fnmatch(name, args.only) for name in (f[0], Path(f[1]).name, f[0].split("+")[-1]))]
    started = time.perf_counter()
    if not args.table_only:
        todo = [f for f in files if args.redo_opfmu or not (args.resume and f[0] in records)]
        print(f"{len(files)} stock files, {len(todo)} to check ({len(files) - len(todo)} recorded), "
              f"{args.jobs} at once, {args.timeout:g} s per step", flush=True)
        lock = threading.Lock()
        done = [0]

        def one(entry):
            key, file, dyr = entry
            stored = records.get(key, {}).get("andes") if args.redo_opfmu else None
            r = check_file(key, file, dyr, out, args.timeout, args.stop, args.fmu_cache, stored,
                           build_timeout=args.build_timeout)
            with lock:
                records[key] = r
                write_json(store, {"stop_s": args.stop, "timeout_s": args.timeout, "files": records})
                done[0] += 1
                print(f"[{done[0]}/{len(todo)}] {key}: {r['status']}"
                      + (f": {_one_line(r['reason'], 160)}" if r["reason"] else "")
                      + f" (ANDES {r['andes']['s']:.1f} s, {r['s']:.1f} s in all)", flush=True)

        if args.jobs <= 1:
            for entry in todo:
                one(entry)
        else:
            from concurrent.futures import ThreadPoolExecutor

            with ThreadPoolExecutor(args.jobs) as pool:
                list(pool.map(one, todo))
    chosen = [records[k] for k, _, _ in every if k in records]  # the table: every file with a record
    wall = time.perf_counter() - started if not args.table_only else None
    write_table(chosen, Path(args.doc), args.stop, args.timeout, args.build_timeout)
    c = coverage(chosen)
    print(f"opfmu runs {c['runs']} of the {c['andes_runs']} files ANDES runs ({c['percent']:.0f} %) and reads "
          f"{c['read']}; ANDES fails on {c['andes_fails']}; written {args.doc}"
          + (f" in {wall:.0f} s" if wall else ""))


if __name__ == "__main__":
    main()
