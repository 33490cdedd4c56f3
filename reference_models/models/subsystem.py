"""SUBSYSTEM: a whole sub-system (a feeder of inverters, a plant) seen through its boundary bus, the
component its learned operator is an operator of (issue 35, docs/subsystems.md).

States  x = (theta_f, theta_w [rad]: the boundary's frequency measurement, ANDES' BusFreq, network
        frame; Ip, Iq [pu, system base]: the active and reactive current the sub-system's devices
        deliver at the boundary, in the frame of the boundary voltage, > 0 generating; n [1]: the
        boundary's load-flow voltage over the sub-system's own, V0 / V_own); a sub-system with a plant
        controller (SUBSYSTEM_PC, `subsystem_pc`) carries that controller's states too: Vf [pu] its
        filtered boundary voltage (REPCA1 s0_y), Vhold [pu] the voltage its reactive PI reads, held
        through a dip (s_hold), Qpi, Qcmd, Ppi, Pcmd [pu, system base] its reactive PI integrator
        (s2_xi) and command lag (s3_x), active PI integrator (s5_xi) and command lag (s6_y), each
        summed over the plant's REPCA1 (in this order: each reads only those before it); a sub-system
        with a memory (SUBSYSTEM_MEM, SUBSYSTEM_PC_MEM) carries after those Vm1, Vm2, Vm3 [pu]: the
        boundary voltage through lags of MEMORY_LAGS (0.05, 0.25, 1 s); a sub-system whose devices' own
        measured frequency is carried (SUBSYSTEM_UF, `subsystem_uf`) carries last df_units [Hz]: the
        rating-weighted mean of the frequency its devices measure at their own buses, less the
        boundary's measured frequency; a sub-system whose active current passes a low-voltage gain
        (SUBSYSTEM_LVG, SUBSYSTEM_PC_LVG) has Ip_full [pu, system base] in Ip's place, the current its
        devices would deliver at full voltage, and carries last Ip_res [pu, system base], what they
        deliver less Ip_full through the gain; a sub-system whose devices' reactive dip current is
        known (SUBSYSTEM_*_DIP) has Iq_rest [pu, system base] in Iq's place, the reactive current
        less the dip current, and carries after a controller's states Vd [pu of V_own], the devices'
        voltage through their dip filter, and Iq_dip [pu, system base], the dip current
Inputs  u = (Vs [pu], theta_vs [rad]: the boundary bus voltage)
Outputs y = (I_re, I_im [pu, system base]: the current injected into the boundary bus, network
        frame; P, Q [pu, system base]: the power injected, generator convention; f [pu]: the
        measured boundary frequency)

What is known is written here; what is not is learned:
    the sub-system's boundary transformer has settled its tap to keep its inside at the voltages of
    the sub-system's own load flow (an on-load tap changer before the study:
    reference_models.grid.attach), so the inside sees the boundary voltage divided by about
    n = V0 / V_own, a constant of the study (dn/dt = 0);
    the network's passive part (lines, transformers and constant-impedance loads with every device's
    current taken out, Kron-reduced onto the boundary at the sub-system's own voltage: G + jB [pu,
    system base]) then draws
        I_passive = -(G + jB) V / n^2,
    the devices deliver I_dev = (Ip - j Iq) e^{j theta_vs}, so that
        I = I_dev + I_passive,  P = Ip Vs - G Vs^2 / n^2,  Q = Iq Vs + B Vs^2 / n^2;
    the boundary frequency is what a BusFreq at the boundary measures (blocks.bus_frequency):
        busf_Tf dtheta_f/dt = theta_vs - theta_f,  busf_Tw dtheta_w/dt = theta_f - theta_w;
    Ip and Iq follow the devices' controls, trips and limits, hundreds of states that the sub-system's
    operator replaces: their rate is learned (`learned_states`), written here as 0;
    a plant controller acts on every unit at once through states of seconds (its PI integrators) and
    its command lags (50-150 ms, most of a window), which two boundary currents do not tell; where
    every REPCA1 of the sub-system reads the boundary bus alone (its voltage and frequency, no
    monitored branch) and they are shares of one controller (every gain and output limit the
    unit's share of the plant's, the rest alike), their sums are one REPCA1 with the plant's gains
    and limits driven by the boundary voltage: SUBSYSTEM_PC carries its states (`--carry-controller`)
    with their known equations (reference_models.models.repca1, its set point Vref = n V_own, the
    load flow's boundary voltage); only its effect on the devices' currents is learned; the units'
    own states are too many and too fast to carry;
    how deep and how long ago the last dip was, which the units' lags, limits and holds after a dip
    went through, is a function of the boundary voltage's recent past that two currents do not
    tell a window started after a fault: a memory (`--memory`) carries that past as the boundary
    voltage through three lags,
        T_k dVm_k/dt = Vs - Vm_k  (T_k: MEMORY_LAGS),
    known states the FMU steps exactly, which the operator reads at each window's start (a fading
    memory of the dip's depth, length and age: a delay embedding of the hidden states);
    the devices inside measure the frequency at their own buses, whose angles move against the
    boundary's as the sub-system's currents change through its impedances: a droop or trip acting
    on it sees, just after a clearing and while the generation falls, a frequency some 0.01-0.05 Hz
    off the boundary's, in a filter whose state a window started there does not see: with
    `--unit-frequency` the operator carries that difference, df_units (learned: it follows the
    devices' currents), and reads it at each window's start;
    a REGCA1 delivers its active current S0_y through a low-voltage gain, Ipout = S0_y LVG(V) (0
    below Lvpnt0, 1 above Lvpnt1), and keeps S0_y through a dip: at a fault and at its clearing the
    current falls and comes back with the voltage at once, which a learned state cannot; with
    `--voltage-gain` (SUBSYSTEM_LVG, SUBSYSTEM_PC_LVG) the delivered active current is
        Ip = Ip_full LVG_s(Vs / n) + Ip_res,
    LVG_s the sub-system's gain at the boundary voltage on its own base (knees lvg_V0, lvg_V1: the
    units' Lvpnt0, Lvpnt1 over their voltage's ratio to the boundary's in the load flow, rating-
    weighted), Ip_full (in Ip's place) the delivered current and what the units hold back, Ip_res
    (last) the rest: both learned and both moving only as the units' states move;
    a REECA1 in a voltage dip (V < Vdip) adds to its reactive current command Kqv db(Vref - s0), its
    voltage s0 through a lag Trv, within the current its limits leave, and drops it the moment the
    voltage is back; its REGCA1 delivers the command through the lag Tg: the reactive current
    rises through a fault and falls after its clearing in some 20 ms, faster than a window's
    learned state follows; with `--dip-current` (SUBSYSTEM_*_DIP) that current is known:
        dip_Trv dVd/dt = Vs / n - Vd,   dip_Tg dIq_dip/dt = share(Vs / n) I_dip(Vd) - Iq_dip,
        Iq = Iq_rest + Iq_dip,
    share the part of the devices in a dip (1 below dip_V0, linear to 0 at dip_V1: their Vdip over
    their voltage's ratio to the boundary's), I_dip the table dip_I0 .. dip_I11 at DIP_KNOTS, the
    sum over the REECA1 of the current they command in a dip at that filtered voltage (their own
    reactive command, held or a voltage PI, left out: it is in Iq_rest), dip_Trv and dip_Tg their
    rating-weighted Trv and Tg (cosim.subsystem_data.dip_params); Vd and Iq_dip are affine in
    themselves and the FMU steps them exactly; what the aggregate misses (the spread of the lags,
    the units' own voltages standing above the boundary's while they inject) is left to Iq_rest.

A deep fault acts on the passive part exactly (its admittance is the Norton admittance of the port)
and on the devices through the operator. The state is rotation invariant but not speed invariant
(the devices' frequency droops and trips read the speed): the drift frame only turns.

Parameters: the system base Sb and the sub-system's rating S [MVA] (the sum of its generating
devices' Sn); G, B; the boundary voltage V_own [pu] of the sub-system's own load flow and the
devices' currents Ip_own, Iq_own there (its rest: the learned rates have none of their own); the
measurement's busf_Tf, busf_Tw [s], busf_fn [Hz] (the sub-system's own BusFreq settings);
SUBSYSTEM_PC's also the plant controller's, REPCA1's named with pc_ (pc_Kp, ..., system base: the
sums of its REPCA1's gains and limits); SUBSYSTEM_LVG's and SUBSYSTEM_PC_LVG's also the knees of the
low-voltage gain lvg_V0 < lvg_V1 [pu of V_own]; SUBSYSTEM_*_DIP's also the dip current's dip_Trv,
dip_Tg [s], dip_V0 < dip_V1 [pu of V_own] and dip_I0 .. dip_I11 [pu, system base]. An operator of it
is trained for one sub-system: its FMU holds them fixed.

Start from the load flow (V0, theta0, P0, Q0 at the boundary): theta_f = theta_w = theta0,
n = V0 / V_own, Ip = (P0 + G V0^2 / n^2) / V0, Iq = (Q0 - B V0^2 / n^2) / V0; a plant controller's
filter and held voltage at V0, its integrators and lags at 0 (ANDES' REPCA1 start); a memory's lags
at V0; a dip current's filter at V0 / n and the current at its drive (Iq_rest the rest of Iq).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, make_dataclass

import numpy as np

from ..blocks import bus_frequency, lags_of_ramp, piecewise_linear
from ..component import Component, Initialisation, Parameters, Quantity
from ..drift import Drift
from ..piecewise import where
from ..ports import BusPort, Ports
from .common import check_limits, check_ranges, finite_inputs
from .repca1 import REPCA1Params, signals as plant_controller_signals

PARAMETER_RANGES = {
    "Sb": (1e-3, 1e5, "MVA"), "S": (1e-6, 1e6, "MVA"), "G": (-1e4, 1e4, "pu"), "B": (-1e4, 1e4, "pu"),
    "V_own": (0.5, 1.5, "pu"), "Ip_own": (-1e4, 1e4, "pu"), "Iq_own": (-1e4, 1e4, "pu"),
    "busf_Tf": (0.0, 10.0, "s"), "busf_Tw": (1e-3, 10.0, "s"), "busf_fn": (16.0, 400.0, "Hz"),
}


@dataclass(frozen=True)
class SubsystemParams(Parameters):
    """A sub-system at its boundary (module docstring): bases Sb, S [MVA]; passive admittance G, B
    [pu, system base]; its own boundary voltage V_own [pu] and the devices' currents there Ip_own, Iq_own
    [pu, system base]; the boundary
    measurement busf_Tf, busf_Tw [s], busf_fn [Hz]."""

    Sb: float = 100.0
    S: float = 10.0
    G: float = 0.0
    B: float = 0.0
    V_own: float = 1.0
    Ip_own: float = 0.0
    Iq_own: float = 0.0
    busf_Tf: float = 0.02
    busf_Tw: float = 0.1
    busf_fn: float = 60.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)


# REPCA1's parameters but its measurement's (the sub-system's busf_* are the boundary's BusFreq)
PLANT_CONTROLLER_FIELDS = tuple(f for f in fields(REPCA1Params) if not f.name.startswith("busf_"))


def _plant_controller(self) -> REPCA1Params:
    """The one REPCA1 that the sub-system's are shares of (its pc_ parameters, the boundary's BusFreq)."""
    return REPCA1Params(**{f.name: getattr(self, "pc_" + f.name) for f in PLANT_CONTROLLER_FIELDS},
                        busf_Tf=self.busf_Tf, busf_Tw=self.busf_Tw, busf_fn=self.busf_fn)


def _check_with_controller(self) -> None:
    SubsystemParams.check(self)
    try:
        self.plant_controller()
    except ValueError as exc:  # REPCA1Params' ParameterError, named as this component's parameter
        raise type(exc)(str(exc).replace("parameter ", "parameter pc_", 1)) from None


SubsystemPCParams = make_dataclass(
    "SubsystemPCParams", [("pc_" + f.name, float, f.default) for f in PLANT_CONTROLLER_FIELDS],
    bases=(SubsystemParams,), frozen=True,
    namespace={"plant_controller": _plant_controller, "check": _check_with_controller,
               "__doc__": "A sub-system with a plant controller: SubsystemParams and, named pc_ + REPCA1's, "
                          "the parameters of the one REPCA1 its REPCA1 are shares of (system base)."})
SubsystemPCParams.__module__ = __name__

# the low-voltage gain's knees [pu of the sub-system's own boundary voltage] (SUBSYSTEM_LVG, SUBSYSTEM_PC_LVG)
GAIN_RANGES = {"lvg_V0": (0.0, 2.0, "pu"), "lvg_V1": (0.0, 2.0, "pu")}


def _extended(base, name: str, fields: list, ranges: dict, knees: tuple, doc: str):
    """The frozen parameters `name`: `base` and `fields` ((name, type, default) each), checked by
    base's check, `ranges` and the order of the two `knees` (field names, low < high); `doc`: what
    the fields are (the class docstring after base's name)."""
    def check(self) -> None:
        base.check(self)
        check_ranges(self, ranges)
        check_limits(self, *knees)

    made = make_dataclass(name, fields, bases=(base,), frozen=True,
                          namespace={"check": check, "__doc__": f"{base.__name__} and {doc}"})
    made.__module__ = __name__
    return made


def _with_gain(base, name: str):
    """`base` and the knees of the low-voltage gain, lvg_V0 < lvg_V1 (module docstring)."""
    return _extended(base, name, [("lvg_V0", float, 0.35), ("lvg_V1", float, 0.85)], GAIN_RANGES,
                     ("lvg_V0", "lvg_V1"), "the knees lvg_V0 < lvg_V1 [pu of the sub-system's own boundary voltage] "
                     "of its devices' low-voltage gain (SUBSYSTEM_LVG, SUBSYSTEM_PC_LVG).")


SubsystemLVGParams = _with_gain(SubsystemParams, "SubsystemLVGParams")
SubsystemPCLVGParams = _with_gain(SubsystemPCParams, "SubsystemPCLVGParams")

# the devices' filtered voltage [pu of the sub-system's own boundary voltage] at which the dip current's
# table gives dip_I0 .. dip_I11 (SUBSYSTEM_*_DIP), linear between, flat beyond
DIP_KNOTS = tuple(round(0.1 * k, 1) for k in range(12))
DIP_RANGES = {"dip_Trv": (1e-3, 10.0, "s"), "dip_Tg": (1e-3, 10.0, "s"), "dip_V0": (0.0, 2.0, "pu"),
              "dip_V1": (0.0, 2.0, "pu"), **{f"dip_I{k}": (-1e4, 1e4, "pu") for k in range(len(DIP_KNOTS))}}


def _with_dip(base, name: str):
    """`base` and the dip current's parameters (module docstring): its lags dip_Trv, dip_Tg [s], the
    knees dip_V0 < dip_V1 [pu of the sub-system's own boundary voltage] between which the share of the
    devices in a dip falls from 1 to 0, and its table dip_I0 .. dip_I11 [pu, system base] at DIP_KNOTS."""
    table = [(f"dip_I{k}", float, 0.0) for k in range(len(DIP_KNOTS))]
    return _extended(base, name, [("dip_Trv", float, 0.02), ("dip_Tg", float, 0.02), ("dip_V0", float, 0.85),
                                  ("dip_V1", float, 0.9)] + table, DIP_RANGES, ("dip_V0", "dip_V1"),
                     "the devices' reactive dip current: its lags dip_Trv, dip_Tg [s], the knees dip_V0 < dip_V1 "
                     "[pu of the sub-system's own boundary voltage] of the share in a dip, its table dip_I0 .. "
                     "dip_I11 [pu, system base] at DIP_KNOTS.")


SubsystemDipParams = _with_dip(SubsystemParams, "SubsystemDipParams")
SubsystemPCDipParams = _with_dip(SubsystemPCParams, "SubsystemPCDipParams")
SubsystemLVGDipParams = _with_dip(SubsystemLVGParams, "SubsystemLVGDipParams")
SubsystemPCLVGDipParams = _with_dip(SubsystemPCLVGParams, "SubsystemPCLVGDipParams")


# the plant controller's states a sub-system with one carries (SUBSYSTEM_PC): (name, its REPCA1's state,
# how the REPCA1's are combined: summed where each is a share of the plant's, else alike in all, averaged)
PLANT_CONTROLLER_STATES = (("Vf", "s0_y", "mean", "plant controller's filtered boundary voltage"),
                           ("Vhold", "s_hold", "mean", "boundary voltage the plant controller's reactive PI reads, "
                            "held through a dip"),
                           ("Qpi", "s2_xi", "sum", "plant controller's reactive PI integrator"),
                           ("Qcmd", "s3_x", "sum", "plant controller's reactive command (lag state)"),
                           ("Ppi", "s5_xi", "sum", "plant controller's active PI integrator"),
                           ("Pcmd", "s6_y", "sum", "plant controller's active command (lag)"))
N_BOUNDARY = 5  # theta_f, theta_w, Ip, Iq, n: the states of every sub-system
N_CONTROLLER = len(PLANT_CONTROLLER_STATES)
MEMORY_LAGS = (0.05, 0.25, 1.0)  # s: the memory's lags of the boundary voltage (Vm1, Vm2, Vm3)


def _controller_rates(x, u, p, m) -> tuple:
    """The rates of a carried plant controller's states (x[5:]: Vf, Vhold, Qpi, Qcmd, Ppi, Pcmd): its
    REPCA1 (repca1.signals) reading the boundary voltage and measurement, no branch (its filtered
    branch powers stay 0), the set point Vref = n V_own (the load flow's boundary voltage)."""
    zero = 0.0 * x[4]
    Vf, Vhold, Qpi, Qcmd, Ppi, Pcmd = x[N_BOUNDARY:N_BOUNDARY + N_CONTROLLER]
    rates = plant_controller_signals((x[0], x[1], Vf, zero, Qpi, Qcmd, zero, Ppi, Pcmd, Vhold),
                                     (u[0], u[1], zero, zero, zero, zero, x[4] * p.V_own, zero, zero, zero, zero),
                                     p.plant_controller(), m)["rates"]
    return rates[2], rates[9], rates[4], rates[5], rates[7], rates[8]


def low_voltage_gain(x, u, p, m):
    """The devices' low-voltage gain [1] at the boundary voltage on the sub-system's own base, Vs / n:
    0 up to lvg_V0, linear to 1 at lvg_V1 (SUBSYSTEM_LVG, SUBSYSTEM_PC_LVG; module docstring)."""
    V = u[0] / x[4]
    return where(m, V <= p.lvg_V0, 0.0 * V,
                 where(m, V <= p.lvg_V1, (V - p.lvg_V0) / (p.lvg_V1 - p.lvg_V0), 1.0 + 0.0 * V))


def dip_drive(m, V, Vd, p):
    """The dip current's drive [pu, system base] (SUBSYSTEM_*_DIP; module docstring): the share of the
    devices in a dip at the boundary voltage on the sub-system's own base V = Vs / n (1 up to dip_V0,
    linear to 0 at dip_V1), times the table at their filtered voltage Vd [pu of V_own]."""
    share = piecewise_linear(m, V, (p.dip_V0, p.dip_V1), (1.0, 0.0))
    return share * piecewise_linear(m, Vd, DIP_KNOTS, tuple(getattr(p, f"dip_I{k}") for k in range(len(DIP_KNOTS))))


def delivered_active_current(x, u, p, m, gain: bool = False):
    """Ip [pu, system base]: the devices' active current at the boundary, the state Ip, or with a
    low-voltage gain (`gain`) the full-voltage current through it and the residual (the last state),
    Ip_full LVG + Ip_res."""
    return x[2] * low_voltage_gain(x, u, p, m) + x[len(x) - 1] if gain else x[2]


def _equations(carried: int, memory: tuple, learned: int = 0, gain: bool = False, dip: bool = False) -> tuple:
    """(derivatives, start_equations) of a sub-system that carries `carried` plant controller states
    (0 or N_CONTROLLER), a memory of the lags `memory` [s] (after them), with `dip` the dip current's
    two states (Vd, Iq_dip, after those) and `learned` more states of its devices (last: learned, 0 at
    rest: df_units; with a low-voltage gain, `gain`, Ip_res, the full-voltage current's part the gain
    holds back at rest)."""
    first = N_BOUNDARY + carried  # the memory's first state
    at = first + len(memory)  # the dip current's filtered voltage, where carried
    last = at + 2 * dip  # the devices' carried states, where any

    def derivatives(x, u, p: SubsystemParams, m):
        """(dtheta_f, dtheta_w, dIp, dIq, dn, then a carried plant controller's, then a memory's)/dt:
        the measurement's, the controller's, the memory's and the dip current's; the devices'
        currents' are learned (0); n is a constant of the study."""
        d_f, d_w, _ = bus_frequency(m, u[1], x[0], x[1], p.busf_Tf, p.busf_Tw, p.busf_fn)
        controller = _controller_rates(x, u, p, m) if carried else ()
        lags = tuple((u[0] - x[first + k]) / T for k, T in enumerate(memory))
        dips = ((u[0] / x[4] - x[at]) / p.dip_Trv,
                (dip_drive(m, u[0] / x[4], x[at], p) - x[at + 1]) / p.dip_Tg) if dip else ()
        units = tuple(0.0 * x[last + k] for k in range(learned))
        return (d_f, d_w, 0.0 * x[2], 0.0 * x[3], 0.0 * x[4], *controller, *lags, *dips, *units)

    def start_equations(x, u, p: SubsystemParams, m):
        """The start's residuals: the measurement at rest, the tap settled to the load flow's boundary
        voltage (n V_own = Vs), a carried controller's filter and held voltage at Vs and its PI
        integrators and command lags at 0 (ANDES' REPCA1 start), a memory's lags at Vs, the dip
        current's filter at Vs / n and its current at its drive, the devices' carried states at 0
        (their measurement at the boundary's), Ip_res at Ip_full (1 - LVG); the learned currents'
        rows are unread (the load flow's P, Q fix them)."""
        d_f, d_w, _ = bus_frequency(m, u[1], x[0], x[1], p.busf_Tf, p.busf_Tw, p.busf_fn)
        controller = (x[5] - u[0], x[6] - u[0], x[7], x[8], x[9], x[10]) if carried else ()
        lags = tuple(x[first + k] - u[0] for k in range(len(memory)))
        dips = (x[at] - u[0] / x[4], x[at + 1] - dip_drive(m, u[0] / x[4], x[at], p)) if dip else ()
        units = ((x[last] - x[2] * (1.0 - low_voltage_gain(x, u, p, m)),) if gain
                 else tuple(x[last + k] for k in range(learned)))
        return (d_f, d_w, 0.0 * x[2], 0.0 * x[3], x[4] * p.V_own - u[0], *controller, *lags, *dips, *units)

    return derivatives, start_equations


def _outputs(gain: bool = False, dip_at: int | None = None):
    def outputs(x, u, p: SubsystemParams, m):
        """(I_re, I_im, P, Q) [pu, system base], f [pu]; with a dip current (its filter the state
        dip_at) the devices' reactive current is Iq_rest + Iq_dip."""
        Ip = delivered_active_current(x, u, p, m, gain)
        Iq = x[3] if dip_at is None else x[3] + x[dip_at + 1]
        Vs, theta = u[0], u[1]
        c, s = m.cos(theta), m.sin(theta)
        f = bus_frequency(m, theta, x[0], x[1], p.busf_Tf, p.busf_Tw, p.busf_fn)[2]
        G, B = p.G / (x[4] * x[4]), p.B / (x[4] * x[4])  # the passive part through the settled tap
        V_re, V_im = Vs * c, Vs * s
        I_re = Ip * c + Iq * s - (G * V_re - B * V_im)
        I_im = Ip * s - Iq * c - (G * V_im + B * V_re)
        return I_re, I_im, Ip * Vs - G * Vs * Vs, Iq * Vs + B * Vs * Vs, f
    return outputs


def _carried_at_rest(x: list, Vs: float, p, learned: int, gain: bool) -> list:
    """x (the rest's states, Ip at the delivered current) with its `learned` carried states at 0, or
    with a low-voltage gain Ip_res = Ip (1 - LVG) (Ip is then the full-voltage current)."""
    if not gain:
        return x + [0.0] * learned
    return x + [x[2] * (1.0 - float(low_voltage_gain(x, (Vs,), p, math)))]


def _dip_at_rest(x: list, Vs: float, p, dip: bool) -> list:
    """x (the rest's states up to a memory, Iq at the devices' whole reactive current) with the dip
    current's states at rest under the boundary voltage Vs appended (the filter at Vs / n, the current
    at its drive) and Iq_rest = Iq less it; x itself where there is no dip current."""
    if not dip:
        return x
    V = Vs / x[4]
    drive = float(dip_drive(math, V, V, p))
    return x[:3] + [x[3] - drive] + x[4:] + [V, drive]


def _equilibrium(carried: int, memory: int, learned: int = 0, gain: bool = False, dip: bool = False):
    def equilibrium(u, p: SubsystemParams) -> np.ndarray:
        """The rest [5 + carried + memory + learned] under constant (Vs, theta_vs), as if the load flow had
        put the boundary at Vs: the measurement at theta_vs, n = Vs / V_own, the devices delivering
        the power of the sub-system's own load flow (Ip_own V_own, Iq_own V_own) through the settled
        tap, a carried controller at its start (_controller_start), a memory at Vs, a dip current at
        rest (_dip_at_rest), the devices' carried states at rest (_carried_at_rest)."""
        Vs, theta = (float(v) for v in finite_inputs(u, "SUBSYSTEM")[:2])
        if not Vs > 0.0:
            raise ValueError(f"SUBSYSTEM: no rest at a boundary voltage of {Vs:.6g} pu")
        n = Vs / p.V_own
        return np.array(_carried_at_rest(_dip_at_rest([theta, theta, p.Ip_own / n, p.Iq_own / n, n]
                                                      + _controller_start(Vs, carried) + [Vs] * memory, Vs, p, dip),
                                         Vs, p, learned, gain))
    return equilibrium


def _controller_start(Vs: float, carried: int) -> list:
    """A carried plant controller's states at its start under the boundary voltage Vs: its filter and
    held voltage there, its integrators and lags at 0."""
    return [Vs, Vs, 0.0, 0.0, 0.0, 0.0] if carried else []


def measured_frequency_map(p: SubsystemParams, sensor_times, n_x: int) -> np.ndarray:
    """A [S, n_x + 2 S]: the measured boundary frequency's deviation [Hz] at each sensor time of a
    window as a linear function of the window's x0 (its theta_f, theta_w: states 0, 1) and its sensors
    (Vs, theta_vs) flattened time-major, exact for a boundary angle linear between sensors: the
    measurement (blocks.lags_of_ramp) stepped on rows of coefficients, f - fn = (theta_f - theta_w) /
    (2 pi busf_Tw) (busf_Tf = 0: the angle passes). A common rotation of every angle leaves it
    unchanged, so it reads a window's frame as well."""
    t = np.asarray(sensor_times, float)
    n_v = n_x + 2 * t.size
    angle = np.zeros((t.size, n_v))  # theta_vs at each sensor as a row over (x0, sensors)
    angle[np.arange(t.size), n_x + 2 * np.arange(t.size) + 1] = 1.0
    filtered, washed = (np.eye(n_v)[0] if p.busf_Tf > 0.0 else angle[0]), np.eye(n_v)[1]
    out = np.zeros((t.size, n_v))
    out[0] = filtered - washed
    for j in range(1, t.size):
        filtered, washed = lags_of_ramp(filtered, washed, angle[j - 1], angle[j], t[j] - t[j - 1], p.busf_Tf, p.busf_Tw)
        out[j] = filtered - washed
    return out / (2.0 * math.pi * p.busf_Tw)


def _starter(carried: int, memory: int, learned: int = 0, gain: bool = False, dip: bool = False):
    def start(given, p: SubsystemParams) -> tuple:
        V0, theta0, P0, Q0 = (float(given[k]) for k in ("V0", "theta0", "P0", "Q0"))
        if not (math.isfinite(V0) and V0 > 0.0):
            raise ValueError(f"SUBSYSTEM: no start at a boundary voltage of {V0:.6g} pu")
        n = V0 / p.V_own
        return np.array(_carried_at_rest(_dip_at_rest([theta0, theta0, (P0 + p.G * V0 * V0 / n ** 2) / V0,
                                                       (Q0 - p.B * V0 * V0 / n ** 2) / V0, n]
                                                      + _controller_start(V0, carried) + [V0] * memory, V0, p, dip),
                                         V0, p, learned, gain)), {}
    return start


BOUNDARY_STATES = (
    Quantity("theta_f", "rad", "boundary angle through the measurement's filter (BusFreq)"),
    Quantity("theta_w", "rad", "washout state of the boundary's frequency measurement (BusFreq)"),
    Quantity("Ip", "pu", "devices' active current at the boundary, voltage frame (system base)"),
    Quantity("Iq", "pu", "devices' reactive current at the boundary, voltage frame (system base; > 0 "
             "delivers reactive power)"),
    Quantity("n", "1", "boundary load-flow voltage over the sub-system's own (V0 / V_own)"))

BOUNDARY_INPUTS = (
    Quantity("Vs", "pu", "boundary bus voltage magnitude", start=1.0, operating_range=(0.0, 1.2), minimum=0.0),
    Quantity("theta_vs", "rad", "boundary bus voltage angle", start=0.0, operating_range=(-0.5, 0.5)))
BOUNDARY_OUTPUTS = (
    Quantity("I_re", "pu", "current injected into the boundary bus, real part (network frame, system base)"),
    Quantity("I_im", "pu", "current injected into the boundary bus, imaginary part (network frame, system base)"),
    Quantity("P", "pu", "active power injected into the boundary bus (system base)"),
    Quantity("Q", "pu", "reactive power injected into the boundary bus (system base)"),
    Quantity("f", "pu", "measured boundary frequency (1: nominal)"))


MEMORY_STATES = tuple(Quantity(f"Vm{k + 1}", "pu", f"boundary voltage through a lag of {T:g} s (the memory)")
                      for k, T in enumerate(MEMORY_LAGS))
UNIT_FREQUENCY_STATE = Quantity("df_units", "Hz", "the devices' own measured frequency (rating-weighted mean) "
                                "less the boundary's")
FULL_CURRENT_STATE = Quantity("Ip_full", "pu", "devices' active current at the boundary at full voltage: the "
                              "delivered and what their low-voltage gain holds back (system base)")
RESIDUAL_CURRENT_STATE = Quantity("Ip_res", "pu", "devices' delivered active current at the boundary less "
                                  "Ip_full through the sub-system's low-voltage gain (system base)")
DIP_STATES = (Quantity("Vd", "pu", "devices' voltage through their reactive dip current's filter (Trv), on the "
                       "sub-system's own base"),
              Quantity("Iq_dip", "pu", "devices' reactive dip current at the boundary (system base; > 0 delivers "
                       "reactive power)"))
REACTIVE_REST_STATE = Quantity("Iq_rest", "pu", "devices' reactive current at the boundary less Iq_dip, voltage "
                               "frame (system base; > 0 delivers reactive power)")
# the scale of each learned carried state (what a state's changes are measured against)
LEARNED_SCALES = {UNIT_FREQUENCY_STATE.name: 0.02, RESIDUAL_CURRENT_STATE.name: 0.05}
CONTROLLER_STATES = tuple(Quantity(n, "pu", f"{what} (" + ("summed over its REPCA1, system base)" if how == "sum"
                                                          else "alike in every REPCA1)"))
                          for n, _, how, what in PLANT_CONTROLLER_STATES)


def _subsystem(name: str, description: str, carried: tuple, params_type, memory: tuple = (),
               learned: tuple = (), gain: bool = False, dip: bool = False) -> Component:
    """The sub-system component with the boundary's states, a plant controller's `carried` (Quantity
    each; their equations: _controller_rates), a memory of the lags `memory` [s] (MEMORY_STATES) and
    the devices' `learned` carried states (Quantity each: UNIT_FREQUENCY_STATE;
    learned, 0 at rest); `gain`: Ip is the full-voltage current (FULL_CURRENT_STATE) that the devices
    deliver through the low-voltage gain, plus the learned residual (RESIDUAL_CURRENT_STATE, last);
    `dip`: the dip current's known states (DIP_STATES, after a memory) and Iq_rest in Iq's place."""
    learned = learned + (RESIDUAL_CURRENT_STATE,) * gain
    extra = tuple(range(N_BOUNDARY, N_BOUNDARY + len(carried) + len(memory) + 2 * dip))
    units = tuple(range(N_BOUNDARY + len(extra), N_BOUNDARY + len(extra) + len(learned)))
    dip_at = N_BOUNDARY + len(carried) + len(memory) if dip else None
    derivatives, start_equations = _equations(len(carried), memory, len(learned), gain, dip)
    n_x = N_BOUNDARY + len(extra) + len(units)
    return Component(
        name=name,
        description=description,
        states=BOUNDARY_STATES[:2] + ((FULL_CURRENT_STATE,) if gain else BOUNDARY_STATES[2:3])
        + ((REACTIVE_REST_STATE,) if dip else BOUNDARY_STATES[3:4]) + BOUNDARY_STATES[4:]
        + carried + MEMORY_STATES[:len(memory)] + DIP_STATES * dip + learned,
        inputs=BOUNDARY_INPUTS,
        outputs=BOUNDARY_OUTPUTS,
        params_type=params_type,
        derivatives=derivatives,
        output_equations=_outputs(gain, dip_at),
        equilibrium=_equilibrium(len(carried), len(memory), len(learned), gain, dip),
        state_scales=(0.1, 0.1, 0.05, 0.05, 0.05) + (0.05,) * len(extra)
        + tuple(LEARNED_SCALES[q.name] for q in learned),
        # busf_Tf dtheta_f/dt = theta_vs - theta_f, busf_Tw dtheta_w/dt = theta_f - theta_w, dn/dt = 0; a
        # plant controller's lags, PIs and hold, piecewise affine in their own state; the memory's lags;
        # the dip current's filter and lag
        affine_states=(0, 1, 4) + extra,
        drift=Drift(angle_states=(0, 1), angle_inputs=(1,), speed_state=None),
        ports=Ports(bus=BusPort(voltage=("Vs", "theta_vs"), current=("I_re", "I_im"))),
        initialisation=Initialisation((), _starter(len(carried), len(memory), len(learned), gain, dip)),
        learned_states=(2, 3) + units,
        started_states=units,
        start_equations=start_equations,
        window_features=lambda p, sensor_times: measured_frequency_map(p, sensor_times, n_x),
    )


_KNOWN = "passive network and measurement known, devices learned"
_KNOWN_PC = "passive network, measurement and plant controller known, devices learned"
_MEMORY = " and a memory of its boundary voltage"
SUBSYSTEM = _subsystem("subsystem", f"a sub-system seen through its boundary bus: {_KNOWN}", (), SubsystemParams)
SUBSYSTEM_PC = _subsystem("subsystem_pc", f"a sub-system with a plant controller seen through its boundary bus: "
                          f"{_KNOWN_PC}", CONTROLLER_STATES, SubsystemPCParams)
SUBSYSTEM_MEM = _subsystem("subsystem_mem", f"a sub-system{_MEMORY} seen through its boundary bus: {_KNOWN}", (),
                           SubsystemParams, MEMORY_LAGS)
SUBSYSTEM_PC_MEM = _subsystem("subsystem_pc_mem", f"a sub-system with a plant controller{_MEMORY} seen through its "
                              f"boundary bus: {_KNOWN_PC}", CONTROLLER_STATES, SubsystemPCParams, MEMORY_LAGS)
SUBSYSTEM_UF = _subsystem("subsystem_uf", "a sub-system seen through its boundary bus, its devices' own measured "
                          f"frequency carried: {_KNOWN}", (), SubsystemParams, learned=(UNIT_FREQUENCY_STATE,))
_GAIN = ", its devices' active current through a low-voltage gain"
SUBSYSTEM_LVG = _subsystem("subsystem_lvg", f"a sub-system seen through its boundary bus{_GAIN}: {_KNOWN}", (),
                           SubsystemLVGParams, gain=True)
SUBSYSTEM_PC_LVG = _subsystem("subsystem_pc_lvg", f"a sub-system with a plant controller seen through its boundary "
                              f"bus{_GAIN}: {_KNOWN_PC}", CONTROLLER_STATES, SubsystemPCLVGParams, gain=True)
_DIP = ", its devices' reactive dip current known"
SUBSYSTEM_DIP = _subsystem("subsystem_dip", f"a sub-system seen through its boundary bus{_DIP}: {_KNOWN}", (),
                           SubsystemDipParams, dip=True)
SUBSYSTEM_PC_DIP = _subsystem("subsystem_pc_dip", f"a sub-system with a plant controller seen through its boundary "
                              f"bus{_DIP}: {_KNOWN_PC}", CONTROLLER_STATES, SubsystemPCDipParams, dip=True)
SUBSYSTEM_LVG_DIP = _subsystem("subsystem_lvg_dip", f"a sub-system seen through its boundary bus{_GAIN}{_DIP}: "
                               f"{_KNOWN}", (), SubsystemLVGDipParams, gain=True, dip=True)
SUBSYSTEM_PC_LVG_DIP = _subsystem("subsystem_pc_lvg_dip", f"a sub-system with a plant controller seen through its "
                                  f"boundary bus{_GAIN}{_DIP}: {_KNOWN_PC}", CONTROLLER_STATES,
                                  SubsystemPCLVGDipParams, gain=True, dip=True)
