"""Sub-systems behind a bus, as case files ANDES reads: a generator of radial distribution feeders
full of PV inverters (PVD1: ANDES' WECC distributed PV, with its voltage and frequency trip curves),
seeded, written as ANDES JSON ({model: [records]}).

    python -m reference_models.grid.subsystems feeder OUT.json [--units N] [--seed S]

A sub-system file is a whole case on its own: its boundary bus (the bus it connects through) holds
its only Slack, which stands for the grid it is attached to; `reference_models.grid.attach` replaces
that Slack by the host's bus.

The feeder (`feeder`): the boundary bus at 69 kV, a substation transformer (x = 0.08 pu on a rating
of 1.25 times the feeder's load, its tap at 1) to the feeder head at 12.47 kV, and a radial trunk
of `sections` line sections (X/R = 1, charging neglected), sized so that the head-to-end voltage
drop at full load is about `drop` pu. Each section's far bus has a constant-impedance load (ANDES'
PQ, as its time domain takes it) and a share of the PV units; each bus with units has one static
generator (PV) carrying their sum, each unit a PVD1 with its share of it (gammap, gammaq). The PV
set points are the voltages a sweep of the feeder gives with every unit at unity power factor, so
that the load flow leaves the units near zero reactive power, as distribution PV runs.

Spread, per unit, drawn from one numpy Generator of `seed` (uniform in the ranges below, ordered
where the curve needs it): rating Sn, active power, the Q-V droop and its dead band, the frequency
droop gain, the current limit, the current lag time constants, the voltage-trip curve (vt0 < vt1 <
1 < vt2 < vt3) and the frequency-trip curve (ft0 < ft1 < fn < ft2 < ft3), latching (vrflag = frflag =
0: a unit that trips stays off, so a deep fault trips part of the feeder). The loads' power factor
is spread too. All powers on ANDES' system base, 100 MVA.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

BASE_MVA = 100.0
F_HZ = 60.0
BOUNDARY_KV, FEEDER_KV = 69.0, 12.47


@dataclass(frozen=True)
class FeederSpec:
    """A feeder's size and spread: `units` PVD1 units over `sections` line sections (default: one
    section per 10 units, 3 to 30), unit ratings in [unit_mva_min, unit_mva_max] MVA at a loading
    in [loading_min, loading_max] of their rating, loads of `load_ratio` times the units' power at a
    power factor in [pf_min, pf_max], the head-to-end drop at full load `drop` pu."""

    units: int = 30
    seed: int = 0
    sections: int | None = None
    unit_mva_min: float = 0.1
    unit_mva_max: float = 0.5
    loading_min: float = 0.5
    loading_max: float = 0.9
    load_ratio: float = 1.5
    pf_min: float = 0.92
    pf_max: float = 0.98
    drop: float = 0.04

    def __post_init__(self):
        if not (isinstance(self.units, int) and self.units >= 1):
            raise ValueError(f"a feeder needs at least one unit, got {self.units!r}")
        if self.sections is not None and not (isinstance(self.sections, int) and self.sections >= 1):
            raise ValueError(f"sections must be a positive integer, got {self.sections!r}")

    @property
    def n_sections(self) -> int:
        return self.sections if self.sections is not None else min(30, max(3, math.ceil(self.units / 10)))


def _sweep(z: np.ndarray, loads: np.ndarray, source: complex = 1.0 + 0j, iterations: int = 100) -> np.ndarray:
    """[n] complex: the bus voltages of a radial chain of n sections of series impedances z [n, pu]
    from `source`, the far bus of section k drawing loads[k] [pu, complex power], by
    backward-forward sweeps."""
    V = np.full(len(loads), source, dtype=complex)
    for _ in range(iterations):
        current = np.conj(loads / V)
        through = np.cumsum(current[::-1])[::-1]  # the current of each section: everything beyond it
        V_new = source - np.cumsum(z * through)
        if np.max(np.abs(V_new - V)) < 1e-14:
            return V_new
        V = V_new
    raise ValueError("the feeder's load flow does not converge: the feeder is loaded beyond its limit")


def feeder(spec: FeederSpec) -> dict:
    """The ANDES records {model: [record]} of the feeder `spec` (module docstring)."""
    rng = np.random.default_rng(spec.seed)
    n, m = spec.units, spec.n_sections
    sn = rng.uniform(spec.unit_mva_min, spec.unit_mva_max, n) / BASE_MVA  # [pu] ratings
    p = sn * rng.uniform(spec.loading_min, spec.loading_max, n)
    at = np.sort(rng.integers(0, m, n))  # the section whose far bus holds each unit
    p_bus = np.bincount(at, weights=p, minlength=m)
    pf = rng.uniform(spec.pf_min, spec.pf_max, m)
    load_p = spec.load_ratio * p.sum() * rng.dirichlet(np.full(m, 4.0))
    load_q = load_p * np.tan(np.arccos(pf))
    total = abs(complex(load_p.sum(), load_q.sum()))
    # the drop of a uniformly loaded trunk: |z| S m / 2 (X/R = 1, so R P + X Q ~ |z| S / sqrt(2) * 1.4)
    z = spec.drop / (total * m / 2.0) * (1 + 1j) / math.sqrt(2.0)
    rating = 1.25 * total
    x_tr = 0.08 / rating  # on the system base
    # the transformer, then the trunk: the voltages with every unit at unity power factor
    V = _sweep(np.array([1j * x_tr] + [z] * m), np.concatenate([[0.0], (load_p - p_bus) + 1j * load_q]))[1:]

    boundary, head = 1, 2
    buses = [{"idx": boundary, "name": "boundary", "Vn": BOUNDARY_KV, "v0": 1.0, "a0": 0.0},
             {"idx": head, "name": "head", "Vn": FEEDER_KV, "v0": 1.0, "a0": 0.0}]
    buses += [{"idx": 3 + k, "name": f"section {k + 1}", "Vn": FEEDER_KV, "v0": float(abs(V[k])), "a0": 0.0}
              for k in range(m)]
    lines = [{"idx": "transformer", "name": "transformer", "bus1": boundary, "bus2": head, "Sn": BASE_MVA,
              "fn": F_HZ, "Vn1": BOUNDARY_KV, "Vn2": FEEDER_KV, "r": 0.0, "x": x_tr, "b": 0.0, "trans": 1,
              "tap": 1.0, "phi": 0.0}]
    lines += [{"idx": f"section {k + 1}", "name": f"section {k + 1}", "bus1": head if k == 0 else 2 + k,
               "bus2": 3 + k, "Sn": BASE_MVA, "fn": F_HZ, "Vn1": FEEDER_KV, "Vn2": FEEDER_KV, "r": z.real, "x": z.imag,
               "b": 0.0} for k in range(m)]
    loads = [{"idx": f"load {k + 1}", "name": f"load {k + 1}", "bus": 3 + k, "Vn": FEEDER_KV,
              "p0": float(load_p[k]), "q0": float(load_q[k])} for k in range(m)]
    slack = [{"idx": "grid", "name": "grid", "bus": boundary, "Sn": BASE_MVA, "Vn": BOUNDARY_KV, "v0": 1.0,
              "a0": 0.0, "p0": 0.0, "q0": 0.0, "pmax": 999.0, "pmin": -999.0, "qmax": 999.0, "qmin": -999.0}]
    pvs, units = [], []
    for k in range(m):
        here = np.flatnonzero(at == k)
        if not len(here):
            continue
        gen = f"pv {k + 1}"
        share = p[here] / p[here].sum()
        pvs.append({"idx": gen, "name": gen, "bus": 3 + k, "Sn": float(sn[here].sum() * BASE_MVA), "Vn": FEEDER_KV,
                    "v0": float(abs(V[k])), "p0": float(p_bus[k]), "q0": 0.0, "pmax": float(sn[here].sum()),
                    "pmin": 0.0, "qmax": float(sn[here].sum()), "qmin": -float(sn[here].sum())})
        for i, s in zip(here, share):
            units.append(_pvd1(rng, f"unit {i + 1}", 3 + k, gen, float(sn[i]), float(s)))
    return {"Bus": buses, "Line": lines, "PQ": loads, "Slack": slack, "PV": pvs, "PVD1": units}


def _pvd1(rng, name: str, bus: int, gen: str, sn: float, share: float) -> dict:
    """One PVD1 record with its settings drawn from `rng` (module docstring)."""
    u = rng.uniform
    vt0, vt1 = sorted(u(0.80, 0.92, 2))
    vt2, vt3 = sorted(u(1.08, 1.20, 2))
    ft0, ft1 = sorted(u(59.0, 59.8, 2))
    ft2, ft3 = sorted(u(60.2, 61.0, 2))
    return {"idx": name, "name": name, "bus": bus, "gen": gen, "Sn": sn * BASE_MVA, "fn": F_HZ, "xc": 0.0,
            "pqflag": int(rng.integers(0, 2)), "qmx": 0.33, "qmn": -0.33, "pmx": 9999.0,
            "v0": float(u(0.86, 0.92)), "v1": float(u(1.06, 1.10)), "dqdv": float(u(-3.0, -0.5)),
            "fdbd": float(-u(0.01, 0.05)), "ddn": float(u(0.0, 20.0)), "ialim": float(u(1.1, 1.3)),
            "vt0": vt0, "vt1": vt1, "vt2": vt2, "vt3": vt3, "vrflag": 0.0,
            "ft0": ft0, "ft1": ft1, "ft2": ft2, "ft3": ft3, "frflag": 0.0,
            "tip": float(u(0.01, 0.05)), "tiq": float(u(0.01, 0.05)), "gammap": share, "gammaq": share,
            "recflag": 1}


def write_case(records: dict, path) -> Path:
    """Writes ANDES JSON records to `path` atomically (a temporary file beside it, then renamed)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "w") as f:
            json.dump(records, f, indent=1)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m reference_models.grid.subsystems",
                                     description="writes a generated sub-system as an ANDES JSON case file")
    sub = parser.add_subparsers(dest="kind", required=True)
    f = sub.add_parser("feeder", help="a radial feeder of PVD1 units and loads")
    f.add_argument("out")
    f.add_argument("--units", type=int, default=30)
    f.add_argument("--seed", type=int, default=0)
    f.add_argument("--sections", type=int, default=None)
    args = parser.parse_args(argv)
    try:
        spec = FeederSpec(units=args.units, seed=args.seed, sections=args.sections)
    except ValueError as exc:
        parser.exit(2, f"error: {exc}\n")
    path = write_case(feeder(spec), args.out)
    print(f"feeder of {spec.units} PVD1 units on {spec.n_sections} sections (seed {spec.seed}): {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
