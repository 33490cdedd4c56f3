"""Datasets of a sub-system seen through its boundary bus, recorded from its full detail: the windows a
`subsystem` operator (reference_models.models.subsystem) learns from (issue 35, docs/subsystems.md).

The sub-system file is attached at buses of host cases (reference_models.grid.attach), and each
joint case runs through contingencies in opfmu's master with every device a native FMU: faults near
and far (at the boundary bus itself, at its neighbours, anywhere), through 1e-4j pu (not at the
boundary bus itself, where neither opfmu's master nor ANDES solves the detail) or an impedance,
cleared in 50-200 ms, with or without a line opened, and generator trips (frequency events). What
the host records at the boundary becomes the component's inputs and states, each row of the run:
    Vs, theta_vs       the boundary bus voltage;
    theta_f, theta_w   a BusFreq at the boundary (the sub-system's own settings) driven by theta_vs,
                       linear between rows (blocks.bus_frequency, integrated exactly);
    n                  V0 / V_own, the run's load-flow voltage at the boundary over the sub-system's own;
    Ip, Iq             the devices' part of the current the sub-system injects (boundary.boundary_current,
                       less the passive part (G + jB) V / n^2), in the voltage's frame;
    Vf .. Vhold        where the plan carries the plant controller (component `subsystem_pc`): its
                       REPCA1's states (the master's device states), the integrators and lags
                       summed over the sub-system's REPCA1, the filtered and held voltage (alike in
                       all) averaged;
    Vm1 .. Vm3         where the plan carries a memory (`subsystem_mem`, `subsystem_pc_mem`): Vs
                       through the lags MEMORY_LAGS, linear between rows, integrated exactly;
    df_units           where the plan carries the devices' measured frequency (`subsystem_uf`): the
                       rating-weighted mean of the frequency deviation [Hz] that the devices behind
                       the boundary which measure one (a BusFreq's theta_f, theta_w among their
                       states) read at their own buses, less the boundary's measurement above;
    Ip_full, Ip_res    where the plan passes the devices' active current through a low-voltage gain
                       (`subsystem_lvg`, `subsystem_pc_lvg`): Ip_full (in Ip's place) is Ip and what
                       the REGCA1 behind the boundary hold back at low voltage, the sum of S0_y
                       (1 - LVG(V)) with V each one's own bus voltage (system base, as ANDES'
                       currents); Ip_res (last) is Ip less Ip_full through the sub-system's gain
                       at the boundary (reference_models.models.subsystem.low_voltage_gain);
    Vd, Iq_dip         where the plan knows the devices' reactive dip current (`--dip-current`,
                       components `subsystem*_dip`): Vs / n through the lag dip_Trv, linear between
                       rows, and the dip current through the lag dip_Tg of its drive
                       (reference_models.models.subsystem.dip_drive), linear between rows, both
                       integrated exactly, the voltage held over the step up to a switching (the
                       master's step ends there in the network before it); Iq_rest (in Iq's place)
                       is Iq less Iq_dip.
So the component's outputs give back the injected current of the detail row by row, exactly.
Windows of `horizon` s start every `stride` s of each run (sensor = query times every `step` s); the
runs, not the windows, are split into train, val and test, so a test window comes from a contingency
no training window saw.

The files are a dataset like any other (surrogate.data.datasets: x0, u, t, x per split and
metadata.json written last), so training, export and the FMU builder take them unchanged. Every run's
rows are kept under `.partial/` (atomically, by index): an interrupted generation resumes with the
runs still missing, and a rerun of a finished one returns its metadata. Deterministic for a seed.
"""
from __future__ import annotations

import hashlib
import json
import math
import shutil
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from reference_models.blocks import dead_band, lag_of_ramp, lags_of_ramp
from reference_models.components import component
from reference_models.files import write_json, write_npz
from reference_models.grid.boundary import boundary_current, passive_admittance, subsystem_buses
from reference_models.grid.case import operating_point
from reference_models.grid.contingency import ANDES_FAULT_IMPEDANCE, Contingency
from reference_models.grid.result import device_labels
from reference_models.models.reeca1 import LOWEST_VOLTAGE, NO_CURRENT_LIMIT, current_limits
from reference_models.models.regca1 import low_voltage_gain
from reference_models.models.subsystem import (DIP_KNOTS, DIP_STATES, MEMORY_LAGS, MEMORY_STATES, N_BOUNDARY,
                                              PLANT_CONTROLLER_FIELDS, PLANT_CONTROLLER_STATES,
                                              RESIDUAL_CURRENT_STATE, UNIT_FREQUENCY_STATE, dip_drive)
from reference_models.models.subsystem import low_voltage_gain as subsystem_gain
from reference_models.progress import progress_bar
from reference_models.version import __version__
from surrogate.data.datasets import FORMAT_VERSION, DatasetError, envelope_of, in_frame, load_metadata

SPLIT_SHARES = (("train", 0.7), ("val", 0.15), ("test", 0.15))  # of the runs
GENERATING_MODELS = ("PVD1", "REGCA1", "REGCP1", "REGF1", "REGF2", "REGF3", "ESD1", "GENROU", "GENCLS")
BUSFREQ_DEFAULTS = {"Tf": 0.02, "Tw": 0.1}  # ANDES' BusFreq defaults [s]


@dataclass(frozen=True)
class Plan:
    """What a sub-system dataset records: `runs` contingencies over the host cases `hosts` (ANDES
    case names or files), `buses` attachment buses per host (drawn among its buses), each run to
    `stop` s at `step` s; faults from `fault_start` s cleared after `clear` (low, high) s in whole
    steps, a share `trips` of the runs a generator trip instead and a share `opened` of the faults
    cleared with a line at the fault bus opened; windows of `horizon` s every `stride` s;
    `carry_controller`: the windows carry the sub-system's plant controller states too (component
    `subsystem_pc`, which needs an REPCA1; docs/subsystems.md); `memory`: and a memory of the boundary
    voltage (components `subsystem_mem`, `subsystem_pc_mem`); `unit_frequency`: the devices' own
    measured frequency (component `subsystem_uf`, neither of those); `voltage_gain`: its devices'
    active current through a low-voltage gain, for a sub-system of REGCA1 (components
    `subsystem_lvg`, `subsystem_pc_lvg`, not with a memory or the devices' measured frequency);
    `dip_current`: its devices' reactive dip current as known states, for a sub-system of REECA1
    (components `subsystem*_dip`, not with a memory or the devices' measured frequency)."""

    hosts: tuple = ("ieee14", "kundur", "ieee39")
    buses: int = 3
    runs: int = 240
    stop: float = 3.0
    step: float = 0.01
    fault_start: float = 0.5
    clear: tuple = (0.05, 0.2)
    trips: float = 0.2
    opened: float = 0.25
    horizon: float = 0.2
    stride: float = 0.02
    carry_controller: bool = False
    memory: bool = False
    unit_frequency: bool = False
    voltage_gain: bool = False
    dip_current: bool = False

    def to_dict(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


def subsystem_params(records: dict, case, bus: int, carry_controller: bool = False, voltage_gain: bool = False,
                     dip_current: bool = False) -> dict:
    """The `subsystem` component's parameters of the sub-system `records` (ANDES JSON records, its
    own file) attached at `bus` of `case` (the joint case): its rating, its own boundary voltage,
    its passive admittance referred to that voltage and the devices' currents there, its BusFreq;
    carry_controller: also its plant controller's (`subsystem_pc`: plant_controller_params);
    voltage_gain: also its low-voltage gain's (`subsystem_lvg`: gain_params); dip_current: also its
    dip current's (`subsystem_dip`: dip_params)."""
    behind = subsystem_buses(case.network, bus)
    b = case.network.bus_index(bus)
    V0 = float(case.flow.V[b])
    slack = records["Slack"][0]
    V_own = float(slack.get("v0", 1.0))
    n = V0 / V_own
    Y = passive_admittance(case.network, case.flow.load_admittances(), bus, behind) * n ** 2
    I0 = boundary_current(case.network, case.flow.V[None, :], case.flow.theta[None, :], bus, behind)[0]
    V = V0 * np.exp(1j * case.flow.theta[b])
    device = (I0 + Y / n ** 2 * V) * np.exp(-1j * case.flow.theta[b]) * n  # at the sub-system's own voltage
    freq = records.get("BusFreq", [])
    rating = sum(float(r.get("Sn", 0.0)) for model in GENERATING_MODELS for r in records.get(model, []))
    params = {"Sb": float(case.network.base_mva), "S": rating, "G": float(Y.real), "B": float(Y.imag), "V_own": V_own,
              "Ip_own": float(device.real), "Iq_own": float(-device.imag),
              "busf_Tf": float(np.median([r.get("Tf", BUSFREQ_DEFAULTS["Tf"]) for r in freq])) if freq else BUSFREQ_DEFAULTS["Tf"],
              "busf_Tw": float(np.median([r.get("Tw", BUSFREQ_DEFAULTS["Tw"]) for r in freq])) if freq else BUSFREQ_DEFAULTS["Tw"],
              "busf_fn": float(case.network.f_hz)}
    if carry_controller:
        params.update(plant_controller_params(case, bus, params))
    if voltage_gain:
        params.update(gain_params(case, bus, V_own))
    return {**params, **dip_params(case, bus, V_own)} if dip_current else params


def gain_params(case, bus: int, V_own: float) -> dict:
    """The knees lvg_V0 < lvg_V1 of `subsystem_lvg`'s low-voltage gain [pu of the sub-system's own
    boundary voltage V_own]: the rating-weighted means over the REGCA1 behind the boundary `bus` of
    `case` of their Lvpnt0, Lvpnt1, each over its terminal voltage's ratio to V_own in the load flow
    (the inside keeps its own voltages behind the settled tap: a unit at 1.03 pu where the boundary
    is at 1.0 reaches its knee at a boundary voltage 1.03 times lower). DatasetError where there is
    none."""
    units = [(q, float(case.flow.V[case.network.bus_index(at)]) / V_own) for _, at, q in regca1_behind(case, bus)]
    weights = [q.Sn for q, _ in units]
    return {"lvg_V0": float(np.average([q.Lvpnt0 / r for q, r in units], weights=weights)),
            "lvg_V1": float(np.average([q.Lvpnt1 / r for q, r in units], weights=weights))}


def dip_params(case, bus: int, V_own: float) -> dict:
    """The parameters of `subsystem_dip`'s reactive dip current [system base; voltages in pu of the
    sub-system's own boundary voltage V_own] from the REECA1 behind the boundary `bus` of `case`,
    each with its REGCA1 and its unit's load-flow power P and terminal voltage, ratio r to V_own (the
    inside keeps its own voltages behind the settled tap): dip_Trv, dip_Tg the rating-weighted means
    of their Trv and Tg; dip_V0, dip_V1 the lowest and highest of their Vdip / r (the share of the
    units in a dip falls from 1 to 0 between them); the table at each filtered voltage v of DIP_KNOTS
    the sum over the units of the reactive current their REECA1 commands in a dip at the voltage r v,
    Kqv db(Vref - r v) within the current limit its VDL tables and priority leave beside P / (r v) of
    active current (Vref: Vref0, or the unit's load-flow voltage where that is 0; the unit's own
    reactive command, its held s4_y or voltage PI, is left to the operator). DatasetError where there
    is no REECA1."""
    behind = set(subsystem_buses(case.network, bus)) - {bus}
    units = []
    for k, unit in enumerate(case.units):
        kinds = {d.component.name: d.params for d in unit.devices}
        if unit.bus in behind and "reeca1" in kinds and "regca1" in kinds:
            V = operating_point(unit, k, case.flow)
            units.append((kinds["reeca1"], kinds["regca1"], V["V"] / V_own, V["P"]))
    if not units:
        raise DatasetError(f"no REECA1 behind bus {bus}: no reactive dip current")
    knots = np.array(DIP_KNOTS)
    table = np.zeros_like(knots)
    for q, _, r, P in units:
        v = r * knots
        Vref = q.Vref0 if q.Vref0 > 0.0 else r * V_own
        cap = q.current_cap("p" if q.PQFLAG else "q")
        vp = np.maximum(v, LOWEST_VOLTAGE)
        injection = q.Kqv * dead_band(np, Vref - v, q.dbd1, q.dbd2)
        limits = current_limits(np, q, NO_CURRENT_LIMIT + 0.0 * v if cap is None else cap(np, v), lambda c: c,
                                0.0 * v, 0.0 * v, 0.0 * v, injection, P + 0.0 * v, vp)
        table += limits["IqHL_y"]
    weights = [g.Sn for _, g, _, _ in units]
    low, high = min(q.Vdip / r for q, _, r, _ in units), max(q.Vdip / r for q, _, r, _ in units)
    return {"dip_Trv": float(max(np.average([q.Trv for q, _, _, _ in units], weights=weights), 1e-3)),
            "dip_Tg": float(max(np.average([g.Tg for _, g, _, _ in units], weights=weights), 1e-3)),
            "dip_V0": float(low), "dip_V1": float(max(high, low + 1e-3)),
            **{f"dip_I{k}": float(value) for k, value in enumerate(table)}}


def dip_states(t: np.ndarray, V: np.ndarray, n: float, params, events=()) -> np.ndarray:
    """[len(t), 2]: the dip current's states (Vd, Iq_dip) of the component parameters `params` along
    the boundary voltage V [len(t)] at the rows t, at rest at the first row: Vd the lag dip_Trv of
    V / n linear between rows, Iq_dip the lag dip_Tg of dip_drive linear between rows, each
    integrated exactly (blocks.lag_of_ramp), as the surrogate FMU steps them over a step of the
    master. A row at one of the run's switching times `events` [s] holds the network after it, but
    the master's step up to it ends in the network before it (cosim.master): over that interval the
    voltage stands at the row before's, and the switched voltage drives from that row on."""
    out = np.empty((len(t), 2))
    switching = np.zeros(len(t), bool)
    for at in events:
        switching |= np.abs(t - at) < 1e-9

    def drive(Vd, Vs):
        return float(dip_drive(math, Vs / n, Vd, params))
    out[0] = V[0] / n, drive(V[0] / n, V[0])
    for k in range(1, len(t)):
        h = t[k] - t[k - 1]
        if h <= 0.0:
            out[k] = out[k - 1]
            continue
        end = V[k - 1] if switching[k] else V[k]
        out[k, 0] = lag_of_ramp(out[k - 1, 0], V[k - 1] / n, end / n, h, params.dip_Trv)
        out[k, 1] = lag_of_ramp(out[k - 1, 1], drive(out[k - 1, 0], V[k - 1]), drive(out[k, 0], end), h, params.dip_Tg)
    return out


# the REPCA1 parameters that are the unit's share of the plant's (gains, output limits); the others are
# the plant's own in every share
SHARED_OUT = ("Kp", "Ki", "Qmax", "Qmin", "Kpg", "Kig", "Pmax", "Pmin")


def plant_controller_params(case, bus: int, params: dict) -> dict:
    """The pc_ parameters of `subsystem_pc` (reference_models.models.subsystem): the one REPCA1 that
    the REPCA1 behind the boundary `bus` of `case` are shares of, each gain and output limit the sum
    of theirs. DatasetError where they are not: where one measures another bus or a branch, reads
    another frequency measurement than the boundary's BusFreq (`params`' busf_*), or where their
    gains and limits are not one share per unit of the plant's, or their other settings differ."""
    behind = set(subsystem_buses(case.network, bus))
    devices = [d for unit in case.units if unit.bus in behind for d in unit.devices if d.component.name == "repca1"]
    if not devices:
        raise DatasetError(f"the sub-system at bus {bus} has no plant controller (REPCA1) whose states it could carry")
    for d in devices:
        m = d.measures
        if m is None or m.bus != bus or m.branch is not None:
            what = "a branch (its line)" if m is not None and m.bus == bus else "another bus than the boundary (its busr)"
            raise DatasetError(f"a REPCA1 of the sub-system measures {what}: its plant controller is carried as "
                               "known physics only where every REPCA1 reads the boundary bus alone")
        for name in ("busf_Tf", "busf_Tw", "busf_fn"):
            if not np.isclose(getattr(d.params, name), params[name], rtol=1e-9, atol=0.0):
                raise DatasetError(f"a REPCA1 of the sub-system reads a frequency measurement with {name} = "
                                   f"{getattr(d.params, name):g}, the boundary's has {params[name]:g}")
    values = {f.name: np.array([getattr(d.params, f.name) for d in devices]) for f in PLANT_CONTROLLER_FIELDS}
    totals = {name: float(values[name].sum()) for name in SHARED_OUT}
    shares = np.array([values[name] / totals[name] for name in SHARED_OUT if totals[name] != 0.0])
    if len(shares) and not np.allclose(shares, shares[:1], rtol=1e-6, atol=1e-12):
        raise DatasetError("the sub-system's REPCA1 are not shares of one plant controller: their gains and output "
                           f"limits ({', '.join(SHARED_OUT)}) are not one share per unit of their sums")
    for name, v in values.items():
        if name not in SHARED_OUT and not np.allclose(v, v[0], rtol=1e-9, atol=0.0):
            raise DatasetError(f"the sub-system's REPCA1 are not shares of one plant controller: their {name} differ")
    out = {"pc_" + name: (totals[name] if name in SHARED_OUT else float(v[0])) for name, v in values.items()}
    # a share's anti-windup tracking acts on its own output's excess, a share of the plant's: the sum
    # of the shares' integrators moves as the plant's PI with a tracking gain of ks times the sum of the
    # shares' squares (exact while the shares' normalised integrators run alike: below their limits)
    weight = float(np.sum(shares[0] ** 2)) if len(shares) else 1.0
    out["pc_kqs"], out["pc_ksg"] = out["pc_kqs"] * weight, out["pc_ksg"] * weight
    return out


def bus_frequency_states(t: np.ndarray, theta: np.ndarray, Tf: float, Tw: float) -> tuple:
    """(theta_f, theta_w) [n] of a BusFreq at rest at theta[0], driven by theta [n] linear between
    the times t [n]: both lags integrated exactly over each interval (reference_models.blocks.lags_of_ramp)."""
    theta_f, theta_w = np.empty_like(theta), np.empty_like(theta)
    theta_f[0] = theta_w[0] = theta[0]
    for k in range(1, len(t)):
        theta_f[k], theta_w[k] = lags_of_ramp(theta_f[k - 1], theta_w[k - 1], theta[k - 1], theta[k],
                                              t[k] - t[k - 1], Tf, Tw)
    return theta_f, theta_w


def subsystem_model(records: dict, carry_controller: bool = False, memory: bool = False,
                    unit_frequency: bool = False, voltage_gain: bool = False, dip_current: bool = False):
    """The component a sub-system's operator is of (ANDES JSON records of its file): `subsystem_pc`,
    which carries its plant controller's states, where asked (DatasetError where it has no REPCA1;
    plant_controller_params refuses the others), else `subsystem`; with a memory of the boundary
    voltage (`_mem`) or its devices' active current through a low-voltage gain (`_lvg`, DatasetError
    where it has no REGCA1) where asked, and its devices' reactive dip current known (`_dip`, DatasetError
    where it has no REECA1 or with a memory); `subsystem_uf` where the devices' measured frequency is
    asked (DatasetError together with any of the others)."""
    if unit_frequency:
        if carry_controller or memory or voltage_gain or dip_current:
            raise DatasetError("the devices' measured frequency is carried without a plant controller, a memory, "
                               "a low-voltage gain or a dip current")
        return component("subsystem_uf")
    if dip_current:
        if memory:
            raise DatasetError("a dip current is known without a memory")
        if not records.get("REECA1"):
            raise DatasetError("the sub-system has no REECA1, whose reactive dip current it would know")
    if voltage_gain:
        if memory:
            raise DatasetError("a low-voltage gain is learned without a memory")
        if not records.get("REGCA1"):
            raise DatasetError("the sub-system has no REGCA1, whose low-voltage gain it would pass its current through")
    suffix = ("_lvg" if voltage_gain else "_mem" if memory else "") + ("_dip" if dip_current else "")
    if not carry_controller:
        return component("subsystem" + suffix)
    if not records.get("REPCA1"):
        raise DatasetError("the sub-system has no plant controller (REPCA1) whose states it could carry")
    return component("subsystem_pc" + suffix)


def memory_states(t: np.ndarray, V: np.ndarray, lags) -> np.ndarray:
    """[n, len(lags)]: a sub-system's memory (T dVm/dt = V - Vm for each T of `lags` [s]) at rest at V[0],
    driven by the boundary voltage V [n] linear between the times t [n], integrated exactly over each
    interval (blocks.lag_of_ramp); a lag holds its value across the two rows of a switching (rows at
    one time)."""
    out = np.empty((len(t), len(lags)))
    out[0] = V[0]
    for k in range(1, len(t)):
        h = t[k] - t[k - 1]
        out[k] = [lag_of_ramp(m, V[k - 1], V[k], h, T) if h > 0 else m for m, T in zip(out[k - 1], lags)]
    return out


def controller_columns(case, bus: int, model) -> list:
    """Per state the `model` carries beyond the boundary's five (PLANT_CONTROLLER_STATES), the device
    state columns of a grid result it combines, those of the REPCA1 behind the boundary `bus` of
    `case`, and how ("sum" or "mean")."""
    recorded = {name for name, *_ in PLANT_CONTROLLER_STATES}
    carried = [name for name in model.state_names[N_BOUNDARY:] if name in recorded]
    if not carried:
        return []
    behind = set(subsystem_buses(case.network, bus))
    devices = [label for unit, labels in zip(case.units, device_labels(case.units)) if unit.bus in behind
               for d, label in zip(unit.devices, labels) if d.component.name == "repca1"]
    if not devices:
        raise ValueError(f"the sub-system at bus {bus} has no REPCA1 for its {model.name} states")
    state = {name: (own, how) for name, own, how, _ in PLANT_CONTROLLER_STATES}
    return [([f"{label}_{state[name][0]}" for label in devices], state[name][1]) for name in carried]


def frequency_deviation(theta_f, theta_w, Tw: float):
    """The frequency deviation [Hz] a BusFreq of washout Tw [s] measures from its states theta_f,
    theta_w [rad] (blocks.bus_frequency: (f - 1) fn)."""
    return (np.asarray(theta_f) - np.asarray(theta_w)) / (2.0 * math.pi * Tw)


def unit_frequency_columns(case, bus: int, model) -> list:
    """Where the `model` carries df_units, (bus, weight, busf_Tf, busf_Tw) of each device behind the
    boundary `bus` of `case` that measures the frequency at its own bus (theta_f, theta_w among its
    states; its BusFreq's busf_Tf, busf_Tw [s]) and has a rating Sn (the weight); else []. ValueError
    where the sub-system has none."""
    if UNIT_FREQUENCY_STATE.name not in model.state_names:
        return []
    behind = set(subsystem_buses(case.network, bus)) - {bus}
    out = [(unit.bus, float(d.params.Sn), float(d.params.busf_Tf), float(d.params.busf_Tw))
           for unit in case.units for d in unit.devices
           if unit.bus in behind and {"theta_f", "theta_w"} <= set(d.component.state_names)
           and all(hasattr(d.params, k) for k in ("Sn", "busf_Tf", "busf_Tw"))]
    if not out:
        raise ValueError(f"no device behind bus {bus} measures the frequency at its own bus: nothing for df_units")
    return out


def held_current_columns(case, bus: int, model) -> list:
    """Where the `model` passes its current through a low-voltage gain (carries Ip_res), (S0_y column
    of the grid result, its bus, its REGCA1Params) of each REGCA1 behind the boundary `bus` of
    `case`; else []. DatasetError (a ValueError) where it has none."""
    if RESIDUAL_CURRENT_STATE.name not in model.state_names:
        return []
    return [(f"{label}_S0_y", at, q) for label, at, q in regca1_behind(case, bus)]


def regca1_behind(case, bus: int) -> list:
    """(device label, bus, REGCA1Params) of each REGCA1 behind the boundary `bus` of `case`;
    DatasetError where there is none."""
    behind = set(subsystem_buses(case.network, bus)) - {bus}
    out = [(label, unit.bus, d.params) for unit, labels in zip(case.units, device_labels(case.units))
           if unit.bus in behind for d, label in zip(unit.devices, labels) if d.component.name == "regca1"]
    if not out:
        raise DatasetError(f"no REGCA1 behind bus {bus}: no low-voltage gain")
    return out


def run_rows(result, case, bus: int, params: dict, columns: list = (), units: list = (), held: list = ()) -> dict:
    """The component's inputs u [n, 2] and states x [n, 5 + len(columns)] at the rows t [n] of a grid
    result (module docstring); columns: per carried state the result's device states it combines and
    how (controller_columns); units: the devices whose measured frequency the rows' f_units [n] (Hz
    from nominal, their rating-weighted mean) averages (unit_frequency_columns; none: no f_units),
    each a BusFreq of its settings along its own bus' recorded angle as the boundary's measurement is
    (bus_frequency_states), so that at a switching both see the same angles; held: the REGCA1 whose
    held-back current the rows' held [n] sums (held_current_columns; none: no held)."""
    net = case.network
    b = net.bus_index(bus)
    t = np.asarray(result.time, float)
    V, theta = np.asarray(result.V_bus)[:, b], np.asarray(result.theta_bus)[:, b]
    current = boundary_current(net, result.V_bus, result.theta_bus, bus)
    n = float(case.flow.V[b]) / params["V_own"]
    device = (current + complex(params["G"], params["B"]) / n ** 2 * V * np.exp(1j * theta)) * np.exp(-1j * theta)
    theta_f, theta_w = bus_frequency_states(t, theta, params["busf_Tf"], params["busf_Tw"])
    combine = {"sum": np.sum, "mean": np.mean}
    carried = [combine[how]([np.asarray(result.device_states[c], float) for c in group], axis=0)
               for group, how in columns]
    x = np.stack([theta_f, theta_w, device.real, -device.imag, np.full_like(t, n), *carried], axis=1)
    rows = {"t": t, "u": np.stack([V, theta], axis=1), "x": x}
    if units:
        theta_bus = np.asarray(result.theta_bus)
        measured = [frequency_deviation(*bus_frequency_states(t, theta_bus[:, net.bus_index(at)], Tf, Tw), Tw)
                    for at, _, Tf, Tw in units]
        rows["f_units"] = np.average(measured, axis=0, weights=[w for _, w, _, _ in units])
    if held:
        V_bus = np.asarray(result.V_bus)
        rows["held"] = sum(np.asarray(result.device_states[column], float)
                           * (1.0 - low_voltage_gain(np, V_bus[:, net.bus_index(at)], p)) for column, at, p in held)
    return rows


def windows(rows: dict, plan: Plan) -> tuple:
    """(x0 [W, n_x], u [W, S, 2], x [W, S, n_x]) of the windows of one run's rows on the grid of `plan`
    (rows at whole steps; a run that ended early, at a loss of synchronism, gives fewer)."""
    t = rows["t"]
    grid = np.round(t / plan.step).astype(int)
    keep = np.concatenate([grid[1:] != grid[:-1], [True]])  # the row after an event at a step
    index = {g: k for g, k in zip(grid[keep], np.nonzero(keep)[0])}
    size = int(round(plan.horizon / plan.step)) + 1
    every = int(round(plan.stride / plan.step))
    out = [], [], []
    for start in range(0, int(grid[-1]) - size + 2, every):
        picks = [index.get(start + s) for s in range(size)]
        if any(p is None for p in picks):
            continue
        out[0].append(rows["x"][picks[0]])
        out[1].append(rows["u"][picks])
        out[2].append(rows["x"][picks])
    if not out[0]:
        n_x = rows["x"].shape[1]
        return np.zeros((0, n_x)), np.zeros((0, size, 2)), np.zeros((0, size, n_x))
    return np.array(out[0]), np.array(out[1]), np.array(out[2])


@dataclass(frozen=True)
class Run:
    """One contingency of a dataset: the attachment (index into the plan's), the fault (bus,
    impedance as (re, im) pu, clearing time; None: none), the line opened at clearing, the host
    generator tripped (bus, name) at the fault start, and its split."""

    attachment: int
    split: str
    fault_bus: int | None = None
    impedance: tuple = (0.0, 0.0)
    clear_s: float | None = None
    opened: str | None = None
    trip: tuple | None = None

    def label(self, host: str, bus: int) -> str:
        what = (f"fault at bus {self.fault_bus} ({complex(*self.impedance):.4g} pu) cleared at {self.clear_s:g} s"
                + (f", {self.opened} opened" if self.opened else "")) if self.fault_bus is not None else \
            f"generator {self.trip[1] or ''} at bus {self.trip[0]} tripped"
        return f"{host} at bus {bus}: {what}"


def attachment_buses(case_network, rng: np.random.Generator, count: int) -> list:
    """`count` host buses (sorted) to attach at, drawn among the buses that carry no slack."""
    slack = {g.bus for g in case_network.generators if g.kind == "slack"}
    candidates = [b for b in case_network.buses if b not in slack]
    return sorted(int(b) for b in rng.choice(candidates, size=min(count, len(candidates)), replace=False))


def behind_bus(network, bus: int) -> set:
    """The buses of the sub-system attached at `bus` (none where the case has none there)."""
    try:
        return set(subsystem_buses(network, bus))
    except ValueError:
        return set()


def draw_runs(plan: Plan, cases: list, rng: np.random.Generator) -> list:
    """The plan's runs over the attachments (joint case, host bus) of `cases`, in the order of the
    attachments (module docstring: faults near and far, trips, the split by run)."""
    splits = [name for name, share in SPLIT_SHARES for _ in range(int(round(share * plan.runs)))]
    splits = (splits + ["train"] * plan.runs)[:plan.runs]
    splits = [splits[i] for i in rng.permutation(plan.runs)]
    runs = []
    for k in range(plan.runs):
        a = k % len(cases)
        case, bus = cases[a]
        behind = behind_bus(case.network, bus)
        host = [b for b in case.network.buses if b not in behind]
        if rng.uniform() < plan.trips:
            gens = [g for g in case.network.generators if g.bus not in behind and g.kind != "slack"]
            g = gens[rng.integers(len(gens))]
            runs.append(Run(a, splits[k], trip=(int(g.bus), g.name)))
            continue
        near = [br.to_bus if br.from_bus == bus else br.from_bus for br in case.network.branches
                if br.connects(bus) and not behind.intersection((br.from_bus, br.to_bus))]
        where = rng.uniform()
        fault_bus = bus if where < 0.4 else (near[rng.integers(len(near))] if where < 0.7 and near
                                             else host[rng.integers(len(host))])
        # 1e-4j at the boundary bus itself is beyond the detail: neither opfmu's master nor ANDES solves
        # the feeder's network there (the units' currents follow bus angles of voltages near 0)
        bolted = rng.uniform() < 0.5 and fault_bus != bus
        impedance = ANDES_FAULT_IMPEDANCE if bolted else 1j * 10 ** rng.uniform(-2.5, -0.5)
        steps = rng.integers(int(round(plan.clear[0] / plan.step)), int(round(plan.clear[1] / plan.step)) + 1)
        opened = None
        if rng.uniform() < plan.opened:
            branch = case.network.branch
            lines = [n for n in case.network.trips_at(fault_bus)
                     if not behind.intersection((branch(n).from_bus, branch(n).to_bus))]
            opened = lines[rng.integers(len(lines))] if lines else None
        runs.append(Run(a, splits[k], int(fault_bus), (float(impedance.real), float(impedance.imag)),
                        round(plan.fault_start + steps * plan.step, 9), opened))
    return runs


def contingency_of(run: Run, case, plan: Plan) -> Contingency:
    """The run's contingency on the joint case (without the case's own events)."""
    if run.fault_bus is None:
        from reference_models.grid.case import Event

        trip = Event(kind="generator", time=plan.fault_start, bus=run.trip[0], generator=run.trip[1], status=0)
        return Contingency(network=case.network, events=(trip,))
    return Contingency(fault_bus=run.fault_bus, fault_start=plan.fault_start, clear_s=run.clear_s, trip=run.opened,
                       fault_impedance=complex(*run.impedance), network=case.network)


_WORKER_RUNNERS: dict = {}  # per process: attached case file -> (case, MasterRunner), reused across runs


def _runner(attached: str, fmu_cache: str, step: float):
    if attached not in _WORKER_RUNNERS:
        from reference_models.grid.andes_case import case_from_file

        from .fmus import generator_files
        from .master import MasterSettings
        from .runners import MasterRunner

        case = case_from_file(Path(attached))
        files = generator_files(case, "reference", Path(fmu_cache))
        _WORKER_RUNNERS[attached] = (case, MasterRunner(files, case, MasterSettings(step=step)))
    return _WORKER_RUNNERS[attached]


def record_run(task: tuple) -> str:
    """Runs one task (index, Run as dict, attached case file, host bus, params, plan as dict, FMU
    cache, partial folder, component name) and writes its rows (or why it failed) to
    partial/run_<index>.npz; returns the file's name."""
    index, run, attached, bus, params, plan, fmu_cache, partial, model = task
    plan = Plan(**{k: tuple(v) if isinstance(v, list) else v for k, v in plan.items()})
    out = Path(partial) / f"run_{index:05d}.npz"
    case, runner = _runner(attached, fmu_cache, plan.step)
    try:
        result, _ = runner.run(contingency_of(Run(**run), case, plan), plan.stop, stop_at_loss=True)
        model = component(model)
        rows = run_rows(result, case, bus, params, controller_columns(case, bus, model),
                        unit_frequency_columns(case, bus, model), held_current_columns(case, bus, model))
        write_npz(out, **rows, failed=np.array(""))
    except (RuntimeError, ValueError, ArithmeticError) as exc:  # the master's one-line errors
        write_npz(out, failed=np.array(str(exc).splitlines()[0][:300] if str(exc) else type(exc).__name__))
    return out.name


def finished(out: Path, key: str) -> dict | None:
    """The metadata of the complete dataset in `out` made with fingerprint `key`, None where there is
    none yet; DatasetError where `out` holds another."""
    if not (out / "metadata.json").exists():
        return None
    meta = load_metadata(out)
    if meta.get("fingerprint") != key:
        raise DatasetError(f"{out} holds another dataset; choose another --out")
    return meta


def _use_scratch(folder: str) -> None:
    """A worker process' temporary files (its extracted FMUs) in `folder`."""
    tempfile.tempdir = folder


def run_all(record, tasks: list, total: int, desc: str, workers: int, progress: bool) -> None:
    """Runs record(task) for each task (on `workers` processes where more than one), a progress bar
    over all `total` runs of the dataset (those done before counted as done)."""
    bar = progress_bar(total, desc, "run", progress, initial=total - len(tasks))
    if workers > 1 and len(tasks) > 1:
        # the workers' FMU folders go into one scratch folder, removed here: a worker process ends
        # without running its own clean-ups
        scratch = tempfile.mkdtemp(prefix="opfmu_workers_")
        try:
            with ProcessPoolExecutor(workers, initializer=_use_scratch, initargs=(scratch,)) as pool:
                for _ in pool.map(record, tasks, chunksize=1):
                    bar.update(1)
        finally:
            shutil.rmtree(scratch, ignore_errors=True)
    else:
        for task in tasks:
            record(task)
            bar.update(1)
    bar.close()


def fingerprint(subsystem: bytes, boundary: int, plan: Plan, seed: int) -> str:
    digest = hashlib.sha256(subsystem)
    digest.update(json.dumps([boundary, plan.to_dict(), seed, FORMAT_VERSION, __version__]).encode())
    return digest.hexdigest()[:20]


def generate(subsystem, boundary: int, out, plan: Plan = Plan(), seed: int = 0, workers: int = 1,
             progress: bool = True, host_files: dict | None = None) -> dict:
    """Generate (or resume, or find complete) the dataset of the sub-system file `subsystem`, whose
    boundary is its bus `boundary` (its Slack's), in `out`; returns its metadata. host_files: {name:
    case file} of hosts the plan names that are not ANDES' (default: ANDES' stock files).
    DatasetError for a boundary that is not the sub-system's Slack bus or another dataset in `out`."""
    import andes

    from reference_models.grid.andes_case import ANDES_CASES, case_from_file
    from reference_models.grid.attach import attached_file

    from .fmus import generator_files

    subsystem, out = Path(subsystem), Path(out)
    records = json.loads(subsystem.read_text())
    slack = records.get("Slack", [])
    if len(slack) != 1 or int(slack[0]["bus"]) != int(boundary):
        raise DatasetError(f"{subsystem}: its boundary is the bus of its one Slack "
                           f"({', '.join(str(r['bus']) for r in slack) or 'none'}), not bus {boundary}")
    model = subsystem_model(records, plan.carry_controller, plan.memory, plan.unit_frequency, plan.voltage_gain,
                            plan.dip_current)
    key = fingerprint(subsystem.read_bytes(), int(boundary), plan, seed)
    if (meta := finished(out, key)) is not None:
        return meta
    partial = out / ".partial"
    partial.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    rng = np.random.default_rng(seed)
    attachments, cases = [], []
    for name in plan.hosts:
        host = Path((host_files or {}).get(name) or andes.get_case(ANDES_CASES[name]))
        plain = case_from_file(host)
        for bus in attachment_buses(plain.network, rng, plan.buses):
            path = attached_file(host, [(bus, subsystem)], out / ".attached")
            attachments.append((name, bus, str(path)))
            cases.append((case_from_file(path), bus))
    params = subsystem_params(records, cases[0][0], cases[0][1], plan.carry_controller, plan.voltage_gain,
                              plan.dip_current)
    model.params(params)  # checked before anything is built or runs
    for case, _ in cases:
        generator_files(case, "reference", out / ".fmus")  # built once, before the workers start
    runs = draw_runs(plan, cases, rng)
    tasks = [(k, asdict(r), attachments[r.attachment][2], attachments[r.attachment][1], params, plan.to_dict(),
              str(out / ".fmus"), str(partial), model.name) for k, r in enumerate(runs)
             if not (partial / f"run_{k:05d}.npz").exists()]
    run_all(record_run, tasks, len(runs), "sub-system runs", workers, progress)
    return _assemble(out, runs, attachments, params, plan, seed, key, started,
                     {"kind": "detail", "subsystem": subsystem.name, "boundary": int(boundary)}, model)


def _assemble(out: Path, runs: list, attachments: list, params: dict, plan: Plan, seed: int, key: str,
              started: float, source: dict, model) -> dict:
    """The splits and metadata.json from the runs' rows under out/.partial (metadata last) of the
    component `model`; `source`: what the rows came from (metadata `source`)."""
    p = model.params(params)
    size = int(round(plan.horizon / plan.step)) + 1
    t = np.round(np.arange(size) * plan.step, 12)
    parts = {name: ([], [], [], []) for name, _ in SPLIT_SHARES}
    failed, labels = [], {name: [] for name, _ in SPLIT_SHARES}
    for k, run in enumerate(runs):
        host, bus, _ = attachments[run.attachment]
        with np.load(out / ".partial" / f"run_{k:05d}.npz") as data:
            rows = {name: data[name] for name in data.files}
        label = run.label(host, bus)
        if str(rows["failed"]):
            failed.append(f"{label}: {rows['failed']}")
            continue
        # the measurement from the recorded angle here, not in the worker: one definition per dataset
        rows["x"][:, 0], rows["x"][:, 1] = bus_frequency_states(rows["t"], rows["u"][:, 1], p.busf_Tf, p.busf_Tw)
        if MEMORY_STATES[0].name in model.state_names:  # the memory from the recorded voltage, as the measurement
            rows["x"] = np.concatenate([rows["x"], memory_states(rows["t"], rows["u"][:, 0], MEMORY_LAGS)], axis=1)
        if UNIT_FREQUENCY_STATE.name in model.state_names:  # the devices' measurement less the boundary's
            boundary = frequency_deviation(rows["x"][:, 0], rows["x"][:, 1], p.busf_Tw)
            rows["x"] = np.concatenate([rows["x"], (rows["f_units"] - boundary)[:, None]], axis=1)
        if DIP_STATES[0].name in model.state_names:  # the dip current from the recorded voltage, Iq_rest in Iq's place
            events = (plan.fault_start,) + ((run.clear_s,) if run.clear_s is not None else ())
            dips = dip_states(rows["t"], rows["u"][:, 0], float(rows["x"][0, 4]), p, events)
            rows["x"] = np.concatenate([rows["x"], dips], axis=1)
            rows["x"][:, 3] -= dips[:, 1]
        if RESIDUAL_CURRENT_STATE.name in model.state_names:  # Ip_full in Ip's place, Ip_res last
            full = rows["x"][:, 2] + rows["held"]
            gain = subsystem_gain(rows["x"].T, rows["u"].T, p, np)
            rows["x"] = np.concatenate([rows["x"], (rows["x"][:, 2] - full * gain)[:, None]], axis=1)
            rows["x"][:, 2] = full
        x0, u, x = windows(rows, plan)
        group = parts[run.split]
        group[0].append(x0), group[1].append(u), group[2].append(x), group[3].extend([label] * len(x0))
        labels[run.split].append(label)
    counts, trained_on = {}, []
    for name, _ in SPLIT_SHARES:
        x0, u, x, family = parts[name]
        if not x0:
            raise DatasetError(f"no run of the {name} split succeeded ({len(failed)} failed: {failed[:1]})")
        arrays = {"x0": np.concatenate(x0), "u": np.concatenate(u), "t": t, "x": np.concatenate(x),
                  "family": np.array(family)}
        write_npz(out / f"{name}.npz", **arrays)
        counts[name] = len(arrays["x0"])
        if name == "train":
            trained_on.append(in_frame(arrays, model, p)[:2])
    meta = {"format": FORMAT_VERSION, "fingerprint": key, "seed": seed,
            "preset": {"name": "subsystem", **plan.to_dict()}, "component": model.name, "params": params,
            "state_names": list(model.state_names), "input_names": list(model.input_names),
            "horizon_s": plan.horizon, "n_points": size, "counts": counts,
            "envelope": envelope_of(*trained_on[0], model),
            "source": source, "attachments": [{"host": h, "bus": b} for h, b, _ in attachments],
            "runs": {name: labels[name] for name in labels}, "failed_runs": failed,
            "versions": {"opfmu": __version__}, "wall_time_s": round(time.perf_counter() - started, 2)}
    write_json(out / "metadata.json", meta)
    return meta
