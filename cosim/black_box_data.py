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

import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from reference_models.files import write_npz
from surrogate.data.datasets import DatasetError

from .fmu import FMU, CouplingError
from .subsystem_data import (Plan, Run, _assemble, attachment_buses, contingency_of, draw_runs, finished, fingerprint,
                             run_all)

SETTLE_S = 2.0  # s the box rests at the run's load-flow voltage before the replay


def bus_port(fmu: FMU) -> tuple:
    """(Vs, theta, I_re, I_im) variable names of the box's bus port; DatasetError where it has none."""
    bus = fmu.ports.bus if fmu.ports is not None else None
    if bus is None or len(bus.voltage) != 2 or len(bus.current) != 2:
        raise DatasetError(f"{fmu.model_name}: the FMU declares no bus port (a voltage phasor in, a current phasor "
                           "out) in its model description: a black box needs one")
    return (*bus.voltage, *bus.current)


def replay(fmu_path, t: np.ndarray, V: np.ndarray, theta: np.ndarray, name: str = "box") -> np.ndarray:
    """[n] complex: the bus current [pu, system base, network frame] the box injects at the rows t
    [n] (uniform steps) while its bus voltage follows V, theta [n] (module docstring)."""
    with FMU(fmu_path, name, init=False) as box:
        v, a, i_re, i_im = bus_port(box)
        box.initialise({v: float(V[0]), a: float(theta[0])})
        h = float(t[1] - t[0])
        for _ in range(int(round(SETTLE_S / h))):
            box.step(h, **{v: float(V[0]), a: float(theta[0])})
        out = np.empty(len(t), complex)
        for k in range(len(t)):
            box.set(**{v: float(V[k]), a: float(theta[k])})
            re, im = box.get(i_re, i_im)
            out[k] = complex(re, im)
            if k + 1 < len(t):
                box.step(h, **{v: float(V[k]), a: float(theta[k])})
    return out


def own_rest(fmu_path) -> dict:
    """The box's own voltage start V_own [pu] and its devices' currents at rest there (Ip_own,
    Iq_own: its whole current, in the voltage's frame), after SETTLE_S at its start voltage."""
    with FMU(fmu_path, "--subsystem", init=False) as box:
        v, a, _, _ = bus_port(box)
        V_own, theta = float(box.starts.get(v, 1.0)), float(box.starts.get(a, 0.0))
    t = np.arange(2) * 0.01
    current = replay(fmu_path, t, np.full(2, V_own), np.full(2, theta))[-1] * np.exp(-1j * theta)
    return {"V_own": V_own, "Ip_own": float(current.real), "Iq_own": float(-current.imag)}


_HOSTS: dict = {}  # per process: host case file -> (case, MasterRunner)


def record_replay(task: tuple) -> str:
    """One task (index, Run as dict, host case file, bus, params, plan as dict, FMU cache, partial
    folder, box): the host's run, the box's replay of its voltage at `bus`, the rows written to
    partial/run_<index>.npz (or why the run failed)."""
    index, run, host, bus, params, plan, fmu_cache, partial, box = task
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
        current = replay(box, t, V, theta, f"box{index}")
        n = float(V[0]) / params["V_own"]
        device = current * np.exp(-1j * theta)
        x = np.stack([theta, theta, device.real, -device.imag, np.full_like(t, n)], axis=1)
        write_npz(out, t=t, u=np.stack([V, theta], axis=1), x=x, failed=np.array(""))
    except (RuntimeError, ValueError, ArithmeticError, CouplingError) as exc:
        write_npz(out, failed=np.array(str(exc).splitlines()[0][:300] if str(exc) else type(exc).__name__))
    return out.name


def generate_black_box(box, out, rating_mva: float, plan: Plan = Plan(), seed: int = 0, workers: int = 1,
                       progress: bool = True) -> dict:
    """Generate (or resume, or find complete) the dataset of the black-box FMU `box` (its rating
    rating_mva [MVA]) in `out`; returns its metadata. DatasetError for an FMU without a bus port or
    another dataset in `out`."""
    import andes

    from reference_models.components import component
    from reference_models.grid.andes_case import ANDES_CASES, case_from_file

    from .fmus import generator_files

    box, out = Path(box), Path(out)
    rest = own_rest(box)
    key = fingerprint(box.read_bytes(), 0, plan, seed)
    if (meta := finished(out, key)) is not None:
        return meta
    partial = out / ".partial"
    partial.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    rng = np.random.default_rng(seed)
    attachments, cases = [], []
    for name in plan.hosts:
        host = Path(andes.get_case(ANDES_CASES[name]))
        case = case_from_file(host)
        generator_files(case, "reference", out / ".fmus")
        for bus in attachment_buses(case.network, rng, plan.buses):
            attachments.append((name, bus, str(host)))
            cases.append((case, bus))
    params = {"Sb": float(cases[0][0].network.base_mva), "S": float(rating_mva), "G": 0.0, "B": 0.0, **rest,
              "busf_fn": float(cases[0][0].network.f_hz)}
    component("subsystem").params(params)  # checked before anything runs
    runs = draw_runs(plan, cases, rng)
    tasks = [(k, asdict(r), attachments[r.attachment][2], attachments[r.attachment][1], params, plan.to_dict(),
              str(out / ".fmus"), str(partial), str(box)) for k, r in enumerate(runs)
             if not (partial / f"run_{k:05d}.npz").exists()]
    run_all(record_replay, tasks, len(runs), "black-box replays", workers, progress)
    return _assemble(out, runs, attachments, params, plan, seed, key, started, {"kind": "black box", "fmu": box.name})
