"""Sub-systems behind a bus, as case files ANDES reads: a generator of radial distribution feeders
full of PV inverters (PVD1: ANDES' WECC distributed PV, with its voltage and frequency trip curves),
seeded, written as ANDES JSON ({model: [records]}).

    python -m reference_models.grid.subsystems feeder OUT.json [--units N] [--seed S]
    python -m reference_models.grid.subsystems plant OUT.json [--units N] [--seed S] [--feeders F]

(`opfmu grid feeder|plant --units N --seed S --out FILE` writes the same.) The shipped names of
DESIGN section 11, `feeder` and `plant` (`SHIPPED`: 30 and 20 units, seed 0), are written once into a
cache folder and found there after (`shipped_file`). A sub-system has 1 to MAX_UNITS units and a
seed >= 0 (numpy's Generator takes no negative seed).

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

The plant (`plant`, issue 35's utility-scale PV plant; default 20 units, 100 and more scale): the
boundary bus is the point of interconnection (POI, 230 kV), a main step-up transformer (1.1 times
the units' ratings, z = 0.3 + j10 % on it, tap 1) to the 34.5 kV collector bus, and `feeders`
collector feeders (one per 8 units, at least 2): a home run of 1-4 km of heavier cable to the first
unit's junction, then 0.2-0.6 km between junctions (500 kcmil cable, 0.125 + j0.12 ohm/km, 0.3
uF/km, its charging as the lines' b). Each unit sits on its own 0.69 kV terminal bus behind its
pad-mount transformer (1.1 times its rating, X = 5.5-6.5 %, X/R 8) and is an REGCA1 (converter)
with an REECA1 (electrical control) and an REPCA1 (plant control) and its own static generator (PV)
carrying its power. The PV set points are the voltages a backward-forward sweep of the plant gives
with every unit at unity power factor and the POI at `v_poi`, so ANDES' power flow leaves them at
zero reactive power and its time domain starts at rest.

Spread per unit: the rating (2-4 MVA), the loading (irradiance, 0.55-0.9 of the rating: inside the
current limit Imax, 1.1-1.3), the REGCA1 lag, low-voltage power logic and high-voltage management
settings, the REECA1 voltage-dip thresholds Vdip (0.85-0.9) and Vup (1.1-1.15), its dip dead band
and reactive-current gain Kqv, its inner gains and time constants. Plant-wide (one draw): the
current priority PQFLAG; every REECA1 takes its reactive power from the plant controller (PFFLAG =
VFLAG = QFLAG = 0: Iqcmd = Qref / V) and its voltage-dependent current limits (VDL1, VDL2) lie below
its Imax (ANDES starts those limits as if they did: its VDL1c, VDL2c are 1 at initialisation).

The plant controller: ANDES attaches one REPCA1 to each REECA1. All of a plant's REPCA1 measure the
POI (busr) and its frequency, in voltage control (RefFlag = 1, VCFlag = 0, Kc = 0) with frequency
droop (Fflag = 1, 3-5 % on the plant's rating); their gains Kp, Ki, Kpg, Kig and output limits are
the plant's times the unit's share of its rating (REPCA1 works on the system base), their
references, filters, dead bands and droop the plant's: the set acts as one plant controller whose
output is split by rating. They measure no line (line = None, PLflag = 0): ANDES' REPCA1 takes the
current of its `line` only where its converter's bus is one of that line's ends (CurrentSign:
"bus 4 is not terminal of the line connecting 1 and 2"), which a unit behind a pad-mount
transformer and a collector never is, so the power through the main transformer is not measured.
"""
from __future__ import annotations

import argparse
import hashlib
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
MAX_UNITS = 1000  # the most units of a generated sub-system (beyond, ANDES and the runners take many minutes)


def _check_size(what: str, units, seed) -> None:
    """ValueError unless `units` is an integer in [1, MAX_UNITS] and `seed` one >= 0."""
    if not (isinstance(units, int) and 1 <= units <= MAX_UNITS):
        raise ValueError(f"a {what} needs at least one unit and at most {MAX_UNITS}, got {units!r}")
    if not (isinstance(seed, int) and seed >= 0):
        raise ValueError(f"the seed must be an integer >= 0, got {seed!r}")


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
        _check_size("feeder", self.units, self.seed)
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


# ---------------------------------------------------------------------------------------------------
# the plant


@dataclass(frozen=True)
class PlantSpec:
    """A PV plant's size and spread: `units` inverters (REGCA1 + REECA1 + REPCA1) of ratings in
    [unit_mva_min, unit_mva_max] MVA at a loading (irradiance) in [loading_min, loading_max] of their
    rating, on `feeders` collector feeders (default: one per 8 units, at least 2), the POI at
    `poi_kv` held at `v_poi` by the boundary's Slack."""

    units: int = 20
    seed: int = 0
    feeders: int | None = None
    unit_mva_min: float = 2.0
    unit_mva_max: float = 4.0
    loading_min: float = 0.55
    loading_max: float = 0.9
    poi_kv: float = 230.0
    v_poi: float = 1.0

    def __post_init__(self):
        _check_size("plant", self.units, self.seed)
        if self.feeders is not None and not (isinstance(self.feeders, int) and 1 <= self.feeders <= self.units):
            raise ValueError(f"feeders must be an integer from 1 to the number of units, got {self.feeders!r}")
        if not 0.0 < self.loading_min <= self.loading_max <= 0.95:
            raise ValueError("the units' loading must lie in (0, 0.95] of their rating, for their current headroom")

    @property
    def n_feeders(self) -> int:
        return self.feeders if self.feeders is not None else min(self.units, max(2, math.ceil(self.units / 8)))


COLLECTOR_KV, UNIT_KV = 34.5, 0.69
# a 34.5 kV collector cable per km (500 kcmil aluminium, XLPE): ohm, ohm, microfarad
CABLE_R, CABLE_X, CABLE_C = 0.125, 0.12, 0.30


def _tree_sweep(parent: np.ndarray, z: np.ndarray, shunt: np.ndarray, injection: np.ndarray,
                source: complex = 1.0 + 0j, iterations: int = 200) -> np.ndarray:
    """[n] complex: the bus voltages of a radial network of n buses, bus 0 held at `source`, bus k > 0
    fed from parent[k] < k through the series impedance z[k] [pu], with a shunt admittance shunt[k]
    to ground and a complex power injection[k] into the network [pu], by backward-forward sweeps."""
    n = len(parent)
    V = np.full(n, source, dtype=complex)
    for _ in range(iterations):
        current = shunt * V - np.conj(injection / V)  # drawn from each bus
        for k in range(n - 1, 0, -1):  # each branch's current: everything beyond it
            current[parent[k]] += current[k]
        V_new = V.copy()
        V_new[0] = source
        for k in range(1, n):
            V_new[k] = V_new[parent[k]] - z[k] * current[k]
        if np.max(np.abs(V_new - V)) < 1e-13:
            return V_new
        V = V_new
    raise ValueError("the plant's load flow does not converge")


def plant(spec: PlantSpec) -> dict:
    """The ANDES records {model: [record]} of the PV plant `spec` (module docstring)."""
    rng = np.random.default_rng(spec.seed)
    u = rng.uniform
    n, m = spec.units, spec.n_feeders
    sn = np.round(u(spec.unit_mva_min, spec.unit_mva_max, n), 2)  # [MVA]
    p = sn * u(spec.loading_min, spec.loading_max, n) / BASE_MVA  # [pu]
    total_mva = float(sn.sum())
    feeder_of = np.repeat(np.arange(m), np.diff(np.linspace(0, n, m + 1).round().astype(int)))
    # buses: 0 the POI, 1 the collector bus, 2 + 2k unit k's junction on its feeder, 3 + 2k its terminal
    nb = 2 + 2 * n
    parent = np.zeros(nb, dtype=int)
    z = np.zeros(nb, dtype=complex)
    shunt = np.zeros(nb, dtype=complex)
    injection = np.zeros(nb, dtype=complex)
    main_mva = 1.1 * total_mva  # the main transformer: 10 % above the units' ratings, z 0.3 + j10 % on it
    z[1] = (0.003 + 0.10j) * BASE_MVA / main_mva
    z_base = COLLECTOR_KV ** 2 / BASE_MVA
    cable_z = (CABLE_R + 1j * CABLE_X) / z_base  # [pu/km]
    cable_b = 2 * math.pi * F_HZ * CABLE_C * 1e-6 * z_base  # [pu/km]
    lengths = np.zeros(n)
    pad_x = u(0.055, 0.065, n)  # the pad-mount transformers: 1.1 times the unit's rating, X/R 8
    previous = {}
    for k in range(n):
        f = feeder_of[k]
        j, t = 2 + 2 * k, 3 + 2 * k
        first = f not in previous
        lengths[k] = u(1.0, 4.0) if first else u(0.2, 0.6)  # the home run to the first unit, then between units
        parent[j] = 1 if first else previous[f]
        # the home run is a heavier cable (about half the impedance, twice the charging)
        z[j] = cable_z * lengths[k] * (0.5 if first else 1.0)
        b = cable_b * lengths[k] * (2.0 if first else 1.0)
        shunt[j] += 0.5j * b
        shunt[parent[j]] += 0.5j * b
        parent[t] = j
        z[t] = pad_x[k] * (1 / 8 + 1j) * BASE_MVA / (1.1 * sn[k])
        injection[t] = p[k]
        previous[f] = j
    V = _tree_sweep(parent, z, shunt, injection, spec.v_poi)

    def line(idx, bus1, bus2, vn1, vn2, zz, b=0.0, trans=False, sn_mva=BASE_MVA):
        r = {"idx": idx, "name": idx, "bus1": int(bus1) + 1, "bus2": int(bus2) + 1, "Sn": BASE_MVA, "fn": F_HZ,
             "Vn1": vn1, "Vn2": vn2, "r": float(zz.real), "x": float(zz.imag), "b": float(b)}
        if trans:
            r.update(trans=1, tap=1.0, phi=0.0)
        return r

    kv = [spec.poi_kv, COLLECTOR_KV] + [COLLECTOR_KV, UNIT_KV] * n
    names = ["poi", "collector"] + [x for k in range(n) for x in (f"feeder {feeder_of[k] + 1} junction {k + 1}",
                                                                 f"unit {k + 1} terminal")]
    buses = [{"idx": b + 1, "name": names[b], "Vn": kv[b], "v0": float(abs(V[b])), "a0": float(np.angle(V[b]))}
             for b in range(nb)]
    lines = [line("main transformer", 0, 1, spec.poi_kv, COLLECTOR_KV, z[1], trans=True)]
    for k in range(n):
        j, t = 2 + 2 * k, 3 + 2 * k
        b = cable_b * lengths[k] * (2.0 if parent[j] == 1 else 1.0)
        lines.append(line(f"cable {k + 1}", parent[j], j, COLLECTOR_KV, COLLECTOR_KV, z[j], b))
        lines.append(line(f"pad-mount {k + 1}", j, t, COLLECTOR_KV, UNIT_KV, z[t], trans=True))
    slack = [{"idx": "grid", "name": "grid", "bus": 1, "Sn": BASE_MVA, "Vn": spec.poi_kv, "v0": spec.v_poi,
              "a0": 0.0, "p0": 0.0, "q0": 0.0, "pmax": 999.0, "pmin": -999.0, "qmax": 999.0, "qmin": -999.0}]
    # plant-wide choices: the current priority (PQFLAG) of every unit, the plant controller's gains (on
    # the plant's rating) and its filters
    pqflag = int(rng.integers(0, 2))
    ctl = {"Kp": u(5.0, 20.0), "Ki": u(2.0, 10.0), "Kpg": u(0.1, 0.5), "Kig": u(0.05, 0.2), "Tfltr": u(0.02, 0.05),
           "Tfv": u(0.05, 0.15), "Tp": u(0.02, 0.05), "Tg": u(0.05, 0.15), "Vfrz": u(0.7, 0.85),
           "dbv": u(0.0, 0.005), "droop": u(0.03, 0.05), "fdbd": u(0.0004, 0.0006), "qcap": u(0.33, 0.48)}
    plant_pu = total_mva / BASE_MVA
    headroom, output = float(sn.sum() / BASE_MVA - p.sum()), float(p.sum())
    pvs, gens, elecs, plants = [], [], [], []
    for k in range(n):
        t = 4 + 2 * k  # the terminal's bus idx
        name, share, rating = f"unit {k + 1}", sn[k] / total_mva, sn[k] / BASE_MVA
        pvs.append({"idx": name, "name": name, "bus": t, "Sn": float(sn[k]), "Vn": UNIT_KV, "v0": float(abs(V[t - 1])),
                    "p0": float(p[k]), "q0": 0.0, "pmax": float(rating), "pmin": 0.0, "qmax": float(rating),
                    "qmin": -float(rating)})
        imax = float(u(1.1, 1.3))
        gens.append({"idx": name, "name": name, "bus": t, "gen": name, "Sn": float(sn[k]), "Tg": float(u(0.01, 0.03)),
                     "Rrpwr": float(u(5.0, 20.0)), "Brkpt": float(u(0.85, 0.95)), "Zerox": float(u(0.35, 0.5)),
                     "Lvplsw": 1, "Lvpl1": float(u(1.0, 1.2)), "Volim": float(u(1.15, 1.25)),
                     "Lvpnt1": float(u(0.8, 0.9)), "Lvpnt0": float(u(0.3, 0.4)), "Iolim": -float(u(1.3, 1.5)),
                     "Tfltr": float(u(0.02, 0.1)), "Khv": float(u(0.5, 0.9)), "Iqrmax": 999.0, "Iqrmin": -999.0,
                     "Accel": 0.0, "gammap": 1.0, "gammaq": 1.0})
        vdip = float(u(0.85, 0.9))
        elecs.append({"idx": name, "name": name, "reg": name, "PFFLAG": 0, "VFLAG": 0, "QFLAG": 0,
                      "PFLAG": 0, "PQFLAG": pqflag, "Vdip": vdip, "Vup": float(u(1.1, 1.15)),
                      "Trv": float(u(0.01, 0.03)), "dbd1": -float(u(0.05, 0.1)), "dbd2": float(u(0.05, 0.1)),
                      # ANDES takes REECA1's gains on the system base: Kqv [pu current / pu voltage] and Kvp,
                      # Kvi scaled by the unit's rating, Kqp, Kqi [pu voltage / pu power] by its inverse
                      "Kqv": float(u(2.0, 4.0) * rating), "Vref0": 0.0, "Iqfrz": 0.0, "Thld": 0.0, "Thld2": 0.0,
                      "Tp": float(u(0.02, 0.05)), "QMax": float(ctl["qcap"] * 1.1), "QMin": -float(ctl["qcap"] * 1.1),
                      "Kqp": float(u(0.5, 1.5) / rating), "Kqi": float(u(5.0, 15.0) / rating),
                      "Kvp": float(u(0.5, 1.5) * rating), "Kvi": float(u(20.0, 60.0) * rating), "Vref1": 1.0,
                      "Tiq": float(u(0.01, 0.03)), "PMAX": 1.0, "PMIN": 0.0, "Imax": imax,
                      "Tpord": float(u(0.01, 0.05)),
                      # the voltage-dependent current limits, below Imax (machine base) so that ANDES starts
                      # them where they run: its VDL1c, VDL2c (Lt(VDL_y, Imax)) are 1 at initialisation
                      **_vdl("q", imax, (0.2, 0.5, 0.8, 1.0), (0.9, 0.95, 0.98, 0.99)),
                      **_vdl("p", imax, (0.2, 0.5, 0.8, 1.0), (0.2, 0.5, 0.9, 0.99))})
        # one plant controller split over the units by rating: its gains (on the plant's rating, ANDES
        # takes them on the system base) times the unit's share, the same reference, measurement and
        # filters everywhere; the V error, the frequency droop and dead bands are the plant's
        plants.append({"idx": name, "name": name, "ree": name, "line": None, "busr": 1, "VCFlag": 0, "RefFlag": 1,
                       "Fflag": 1, "PLflag": 0, "Tfltr": ctl["Tfltr"], "Kp": ctl["Kp"] * plant_pu * share,
                       "Ki": ctl["Ki"] * plant_pu * share, "Tft": 0.0, "Tfv": ctl["Tfv"], "Vfrz": ctl["Vfrz"],
                       "Rc": 0.0, "Xc": 0.0, "Kc": 0.0, "emax": 0.1, "emin": -0.1, "dbd1": -ctl["dbv"], "dbd2": ctl["dbv"],
                       "Qmax": ctl["qcap"] * plant_pu * share, "Qmin": -ctl["qcap"] * plant_pu * share,
                       "Kpg": ctl["Kpg"] * share, "Kig": ctl["Kig"] * share, "Tp": ctl["Tp"],
                       "fdbd1": -ctl["fdbd"], "fdbd2": ctl["fdbd"], "femax": plant_pu, "femin": -plant_pu,
                       "Pmax": headroom * share, "Pmin": -output * share, "Tg": ctl["Tg"],
                       "Ddn": plant_pu / ctl["droop"], "Dup": plant_pu / ctl["droop"]})
    plants = [{k: (float(v) if isinstance(v, (float, np.floating)) else v) for k, v in r.items()} for r in plants]
    return {"Bus": buses, "Line": lines, "Slack": slack, "PV": pvs, "REGCA1": gens, "REECA1": elecs,
            "REPCA1": plants}


def _vdl(kind: str, imax: float, voltages: tuple, fractions: tuple) -> dict:
    """A REECA1 voltage-dependent current limit (VDL1 for "q", VDL2 for "p"): its four voltages and
    the currents `fractions` of `imax` there."""
    return {**{f"V{kind}{i + 1}": v for i, v in enumerate(voltages)},
            **{f"I{kind}{i + 1}": float(f * imax) for i, f in enumerate(fractions)}}


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


SHIPPED = {"feeder": FeederSpec(units=30, seed=0), "plant": PlantSpec(units=20, seed=0)}  # DESIGN section 11's names


def records(spec) -> dict:
    """The ANDES records {model: [record]} of the sub-system `spec` (a FeederSpec or a PlantSpec)."""
    return plant(spec) if isinstance(spec, PlantSpec) else feeder(spec)


def describe(spec) -> str:
    """One line naming the sub-system `spec`: its kind, units, sections or feeders and seed."""
    if isinstance(spec, PlantSpec):
        return f"PV plant of {spec.units} units on {spec.n_feeders} collector feeders (seed {spec.seed})"
    return f"feeder of {spec.units} PVD1 units on {spec.n_sections} sections (seed {spec.seed})"


def shipped_file(name: str, folder) -> Path:
    """The case file of the shipped sub-system `name` (a key of SHIPPED) in `folder`: written there
    the first time (atomically: write_case), found after. Its name holds the spec and a hash of this
    module's source, so that a changed generator writes a new file rather than reusing a stale one."""
    spec = SHIPPED[name]
    digest = hashlib.sha256(Path(__file__).read_bytes()).hexdigest()[:12]
    path = Path(folder) / f"{name}_{spec.units}_units_seed_{spec.seed}_{digest}.json"
    if not path.is_file():
        write_case(records(spec), path)
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
    pl = sub.add_parser("plant", help="a PV plant of REGCA1/REECA1/REPCA1 units behind a main transformer")
    pl.add_argument("out")
    pl.add_argument("--units", type=int, default=20)
    pl.add_argument("--seed", type=int, default=0)
    pl.add_argument("--feeders", type=int, default=None)
    args = parser.parse_args(argv)
    try:
        if args.kind == "plant":
            spec = PlantSpec(units=args.units, seed=args.seed, feeders=args.feeders)
        else:
            spec = FeederSpec(units=args.units, seed=args.seed, sections=args.sections)
    except ValueError as exc:
        parser.exit(2, f"error: {exc}\n")
    path = write_case(records(spec), args.out)
    print(f"{describe(spec)}: {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
