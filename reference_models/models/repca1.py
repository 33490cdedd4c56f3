"""REPCA1: the renewable energy plant controller model A (PSS/E REPCA1, WECC REPC_A, ANDES), as ANDES
2.0.0 computes it, with the bus-frequency measurement it reads (ANDES' BusFreq) as its own states.

States  x = (theta_f [rad]: the measured bus angle through the measurement's filter, theta_w [rad]:
        the measurement's washout state, both network-frame angles; s0_y [pu] filtered (compensated)
        voltage; s1_y [pu] filtered branch reactive power; s2_xi [pu] reactive PI's integrator; s3_x
        [pu] its output lead-lag's state; s4_y [pu] filtered branch active power; s5_xi [pu] active
        PI's integrator; s6_y [pu] the active power command's lag)
Inputs  u = (Vm [pu], theta_m [rad]: the voltage at the measured bus; Pbr, Qbr [pu]: the power of the
        monitored branch, Ibr_re, Ibr_im [pu]: its current (ANDES' Pline, Qline, Iline, see below);
        Vref [pu], Qlinef [pu], Plant_pref [pu]: the plant's set points (ANDES' Vref, Qlinef,
        Plant_pref); Pref0, Qref0 [pu]: the electrical controller's own references, to which the
        plant controller adds its commands (ANDES' REECA1 Pref0 and -qref0))
Outputs y = (Pext, Qext [pu]: the active and reactive power references of the electrical controller
        (ANDES' Pext, Qext: REECA1's Pref and Qref); f [pu]: the measured frequency)

Equations (ANDES 2.0 model reference, RenPlant: REPCA1; FreqMeasurement: BusFreq), system base:

    measurement (blocks.bus_frequency, the BusFreq's busf_Tf, busf_Tw, busf_fn):
        busf_Tf dtheta_f/dt = theta_m - theta_f,  busf_Tw dtheta_w/dt = theta_f - theta_w,
        f = 1 + (theta_f - theta_w) / (2 pi busf_fn busf_Tw)
    VCsel = |Vm e^{j theta_m} - (Rc + j Xc) (Ibr_re + j Ibr_im)| (VCFlag = 1: line-drop compensation)
          or Kc Qbr + Vm (VCFlag = 0: reactive droop)
    Tfltr ds0_y/dt = VCsel - s0_y,  Tfltr ds1_y/dt = Qbr - s1_y  (Tfltr = 0: held, the input used)
    Refsel = Vref - s0_y (RefFlag = 1: voltage control) or Qlinef - s1_y (RefFlag = 0: Q control)
    enf = db(Refsel) (dead band [dbd1, dbd2], the excess beyond its edges) clipped to [emin, emax]
    frozen = freeze and Vm < Vfrz;  e = enf, but where frozen the error of the held measurement:
        e = db(Vref - s_hold) (RefFlag = 1; Qlinef - s_hold, RefFlag = 0) clipped to [emin, emax]
    ds_hold/dt = 0 where frozen, else d read/dt + (read - s_hold) / HOLD_SYNC_S (read: s0_y,
        RefFlag = 1; s1_y, RefFlag = 0): s_hold equals read until the dip and comes back to it
        within 10 ms after it
    s2: PI kp = Kp, ki = Ki with tracking anti-windup (ks = kqs) on e, output s2_y within [Qmin, Qmax]
    s3: lead-lag (1 + s Tft) / (1 + s Tfv) of s2_y:  Tfv ds3_x/dt = s2_y - s3_x,
        s3_y = Tft / Tfv (s2_y - s3_x) + s3_x  (Tfv = 0: a gain of 1, s3_x held)
    Qext = Qref0 + s3_y
    Tp ds4_y/dt = Pbr - s4_y
    ferr = 1 - f,  fdbd = db(ferr) ([fdbd1, fdbd2]),  fdroop = Ddn fdbd where fdbd < 0, else Dup fdbd
    Perr = fdroop + PLflag (Plant_pref - s4_y),  feout = Perr clipped to [femin, femax]
    s5: PI kp = Kpg, ki = Kig with tracking anti-windup (ks = ksg) on feout, output s5_y within [Pmin, Pmax]
    Tg ds6_y/dt = s5_y - s6_y,   Pext = Pref0 + Fflag s6_y

The freeze: ANDES holds the reactive PI's input (its VarHold eHld) at the value enf had when the
measured voltage fell below Vfrz, and the PI keeps running on that held value: its integrator
moves at Ki (e_hold - kqs (ys - y)) and its output is Kp e_hold + s2_xi (limited). Here the state
s_hold is the measurement enf reads, stopped at the instant Vm crosses Vfrz (a located switching),
so the held error is enf's there (with the set point of the moment: a Vref stepped during the dip
moves it, ANDES' not), and the PI runs on it as ANDES' does. After the dip s_hold comes back to the
live measurement with HOLD_SYNC_S (ANDES: at once). With Tfltr = 0 there is no filter state to
hold: the frozen PI takes the input 0 and stops.

The measured inputs, as ANDES computes them (its REPCA1 services Iline, Pline, Qline): the voltage
Vm e^{j theta_m} of the measured bus (busr, else the converter's bus); with V1, V2 the voltages of
the monitored line's buses bus1, bus2 and r + j x its series impedance (system base),
    Ibr = Isign (V1 - V2) / (r + j x),   Pbr + j Qbr = Isign V1 conj((V1 - V2) / (r + j x)),
Isign = +1 where the converter's bus is the line's bus1, -1 where it is bus2: the series branch
alone (no charging b, b1, b2, g, no tap ratio or phase shift), its power at bus1 with the sign
Isign (where Isign = -1, minus the power entering the series branch at bus1, not the power at
bus2); 0 where the device names no line. The frequency is that of the BusFreq `busf`, else of the
one ANDES finds or adds at the measured bus; here it is measured from theta_m, so a `busf` at
another bus than the measured one is not represented (the conversion has to refuse it).

Parameters: all on the system base, unconverted (ANDES' REPCA1 has no Sn: its per-unit conversion
of Pmax, Pmin is by 1). Rc, Xc are the compensation impedance used (ANDES' Rcs, Xcs): the case's
Rc, Xc, or the monitored line's r, x where the case leaves them empty or 0 (ANDES' NumSelect); the
case conversion fills them. busf_Tf, busf_Tw, busf_fn are those of the BusFreq (defaults 0.02 s,
0.1 s, 60 Hz: the one ANDES adds). kqs, ksg, freeze are ANDES' configuration (2, 2, 1). ANDES has no
defaults for the flags VCFlag, RefFlag, Fflag (mandatory there); ours are 1.

Start (ANDES' initialisation), given the measured inputs and the references the electrical
controller demands (Pext, Qext at its start): theta_f = theta_w = theta_m (f = 1), s0_y = Vref =
VCsel, s1_y = Qlinef = Qbr, s4_y = Plant_pref = Pbr, the PIs, the lead-lag and s6_y at 0, s_hold
at the measurement it holds,
Pref0 = Pext, Qref0 = Qext; ValueError where a limit keeps a PI's input or output off 0 there (0
outside [emin, emax], [Qmin, Qmax], [femin, femax] or [Pmin, Pmax]: ANDES starts off its rest then).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..blocks import bus_frequency, clip, dead_band, lag, lead_lag, pi_tracking
from ..component import Component, Initialisation, Parameters, Quantity
from ..piecewise import where
from ..ports import Link, Ports
from .common import check_limits, check_ranges, finite_inputs
from .reeca1 import _pi_rest as pi_rest

FLAGS = ("VCFlag", "RefFlag", "Fflag", "PLflag", "freeze")
# s [s]: the time constant that brings the held measurement back to the live one after a dip (ANDES:
# at its next step); short against the plant's control, long against a 10 ms step's stability
HOLD_SYNC_S = 0.01

PARAMETER_RANGES = {
    "Tfltr": (0.0, 100.0, "s"), "Kp": (0.0, 1e4, "pu"), "Ki": (0.0, 1e4, "pu/s"), "Tft": (0.0, 100.0, "s"),
    "Tfv": (0.0, 100.0, "s"), "Vfrz": (0.0, 2.0, "pu"), "Rc": (-10.0, 10.0, "pu"), "Xc": (-10.0, 10.0, "pu"),
    "Kc": (-100.0, 100.0, "pu"), "emax": (-1e4, 1e4, "pu"), "emin": (-1e4, 1e4, "pu"), "dbd1": (-1.0, 0.0, "pu"),
    "dbd2": (0.0, 1.0, "pu"), "Qmax": (-1e4, 1e4, "pu"), "Qmin": (-1e4, 1e4, "pu"), "Kpg": (0.0, 1e4, "pu"),
    "Kig": (0.0, 1e4, "pu/s"), "Tp": (0.0, 100.0, "s"), "fdbd1": (-1.0, 0.0, "pu"), "fdbd2": (0.0, 1.0, "pu"),
    "femax": (-100.0, 100.0, "pu"), "femin": (-100.0, 100.0, "pu"), "Pmax": (-1e4, 1e4, "pu"),
    "Pmin": (-1e4, 1e4, "pu"), "Tg": (0.0, 100.0, "s"), "Ddn": (0.0, 1e4, "pu"), "Dup": (0.0, 1e4, "pu"),
    "kqs": (0.0, 1e4, "pu"), "ksg": (0.0, 1e4, "pu"),
    "busf_Tf": (0.0, 10.0, "s"), "busf_Tw": (1e-3, 10.0, "s"), "busf_fn": (16.0, 400.0, "Hz"),
}


@dataclass(frozen=True)
class REPCA1Params(Parameters):
    """ANDES/PSS/E REPCA1 data (system base): the flags VCFlag (1: line-drop compensation, 0:
    reactive droop Kc), RefFlag (1: voltage, 0: reactive power control), Fflag (1: the active power
    command in service), PLflag (1: the branch power error in the active power control), freeze
    (ANDES' configuration, 1: the reactive PI frozen below Vfrz [pu]); time constants [s]; PI gains;
    the compensation impedance Rc, Xc [pu] (ANDES' Rcs, Xcs) and droop Kc; dead bands dbd1, dbd2
    [pu], fdbd1, fdbd2 [pu of frequency]; limits emax, emin, Qmax, Qmin, femax, femin, Pmax, Pmin
    [pu]; frequency droop gains Ddn, Dup [pu/pu]; tracking gains kqs, ksg; the BusFreq measuring the
    frequency: busf_Tf, busf_Tw [s], busf_fn [Hz]."""

    VCFlag: float = 1.0
    RefFlag: float = 1.0
    Fflag: float = 1.0
    PLflag: float = 1.0
    Tfltr: float = 0.02
    Kp: float = 1.0
    Ki: float = 0.1
    Tft: float = 1.0
    Tfv: float = 1.0
    Vfrz: float = 0.8
    Rc: float = 0.0
    Xc: float = 0.0
    Kc: float = 0.0
    emax: float = 999.0
    emin: float = -999.0
    dbd1: float = -0.1
    dbd2: float = 0.1
    Qmax: float = 999.0
    Qmin: float = -999.0
    Kpg: float = 1.0
    Kig: float = 0.1
    Tp: float = 0.02
    fdbd1: float = -0.0002833
    fdbd2: float = 0.0002833
    femax: float = 0.05
    femin: float = -0.05
    Pmax: float = 999.0
    Pmin: float = -999.0
    Tg: float = 0.02
    Ddn: float = 10.0
    Dup: float = 10.0
    kqs: float = 2.0
    ksg: float = 2.0
    freeze: float = 1.0
    busf_Tf: float = 0.02
    busf_Tw: float = 0.1
    busf_fn: float = 60.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        for flag in FLAGS:
            self.require(flag, getattr(self, flag) in (0.0, 1.0), "be 0 or 1")
        for low, high in (("emin", "emax"), ("Qmin", "Qmax"), ("femin", "femax"), ("Pmin", "Pmax")):
            check_limits(self, low, high)


def _frozen(m, Vm, p: REPCA1Params, frozen, otherwise):
    """`frozen` where the reactive PI is frozen (freeze = 1 and Vm < Vfrz), else `otherwise`."""
    return where(m, Vm < p.Vfrz, frozen, otherwise) if p.freeze else otherwise


def signals(x, u, p: REPCA1Params, m) -> dict:
    """The controller's rates and algebraic signals (ANDES' names) at x, u."""
    theta_f, theta_w, s0, s1, s2_xi, s3_x, s4, s5_xi, s6, s_hold = x
    Vm, theta_m, Pbr, Qbr, Ibr_re, Ibr_im, Vref, Qlinef, Plant_pref, Pref0, Qref0 = u
    d_f, d_w, f = bus_frequency(m, theta_m, theta_f, theta_w, p.busf_Tf, p.busf_Tw, p.busf_fn)
    if p.VCFlag:  # |V - (Rc + j Xc) Ibr|
        re = Vm * m.cos(theta_m) - (p.Rc * Ibr_re - p.Xc * Ibr_im)
        im = Vm * m.sin(theta_m) - (p.Rc * Ibr_im + p.Xc * Ibr_re)
        VCsel = m.sqrt(re * re + im * im)
    else:
        VCsel = p.Kc * Qbr + Vm
    d_s0, s0_y = lag(m, VCsel, s0, 1.0, p.Tfltr)
    d_s1, s1_y = lag(m, Qbr, s1, 1.0, p.Tfltr)
    Refsel = Vref - s0_y if p.RefFlag else Qlinef - s1_y
    enf = clip(m, dead_band(m, Refsel, p.dbd1, p.dbd2), p.emin, p.emax)
    # the hold (ANDES' VarHold eHld): s_hold follows the measurement Refsel reads (its rate, and back to it
    # within HOLD_SYNC_S after a dip) and stops where frozen; the frozen PI runs on the error it gives
    read, read_rate = (s0_y, d_s0) if p.RefFlag else (s1_y, d_s1)
    if p.Tfltr > 0:
        held = clip(m, dead_band(m, (Vref if p.RefFlag else Qlinef) - s_hold, p.dbd1, p.dbd2), p.emin, p.emax)
        e = _frozen(m, Vm, p, held, enf)
        d_hold = _frozen(m, Vm, p, 0.0 * s_hold, read_rate + (read - s_hold) / HOLD_SYNC_S)
    else:  # no filter state to hold: a frozen PI takes the input 0 and stops
        e = _frozen(m, Vm, p, 0.0 * enf, enf)
        d_hold = 0.0 * s_hold
    d_s2, s2_y = pi_tracking(m, e, s2_xi, p.Kp, p.Ki, p.kqs, p.Qmin, p.Qmax)
    if p.Tfltr <= 0:
        d_s2 = _frozen(m, Vm, p, 0.0 * d_s2, d_s2)
    d_s3, s3_y = lead_lag(m, s2_y, s3_x, 1.0, p.Tft, p.Tfv)
    d_s4, s4_y = lag(m, Pbr, s4, 1.0, p.Tp)
    fdbd = dead_band(m, 1.0 - f, p.fdbd1, p.fdbd2)
    fdroop = where(m, fdbd < 0.0, p.Ddn * fdbd, p.Dup * fdbd)
    Perr = fdroop + (Plant_pref - s4_y) if p.PLflag else fdroop
    feout = clip(m, Perr, p.femin, p.femax)
    d_s5, s5_y = pi_tracking(m, feout, s5_xi, p.Kpg, p.Kig, p.ksg, p.Pmin, p.Pmax)
    d_s6, s6_y = lag(m, s5_y, s6, 1.0, p.Tg)
    return dict(rates=(d_f, d_w, d_s0, d_s1, d_s2, d_s3, d_s4, d_s5, d_s6, d_hold),
                f=f, VCsel=VCsel, e=e, s2_y=s2_y, s3_y=s3_y, feout=feout, s5_y=s5_y,
                Pext=Pref0 + p.Fflag * s6_y, Qext=Qref0 + s3_y)


def derivatives(x, u, p: REPCA1Params, m):
    """dx/dt for x = (theta_f, theta_w, s0_y, s1_y, s2_xi, s3_x, s4_y, s5_xi, s6_y, s_hold),
    u = (Vm, theta_m, Pbr, Qbr, Ibr_re, Ibr_im, Vref, Qlinef, Plant_pref, Pref0, Qref0)."""
    return signals(x, u, p, m)["rates"]


def outputs(x, u, p: REPCA1Params, m):
    """(Pext, Qext) [pu, system base], f [pu]."""
    s = signals(x, u, p, m)
    return s["Pext"], s["Qext"], s["f"]


def equilibrium(u, p: REPCA1Params) -> np.ndarray:
    """The steady state [9] at constant inputs: the measurement at theta_m (f = 1), the filters at
    their inputs, each PI's integrator at rest (0 where its input is 0 or it is frozen, else on the
    limit its input drives it to), the lead-lag and s6_y at their inputs."""
    Vm, theta_m, Pbr, Qbr = finite_inputs(u, "REPCA1")[:4]
    x = np.array([theta_m, theta_m, 0.0, Qbr, 0.0, 0.0, Pbr, 0.0, 0.0, 0.0])
    x[2] = signals(x, u, p, math)["VCsel"]
    x[9] = x[2] if p.RefFlag else x[3]
    s = signals(x, u, p, math)
    x[4] = pi_rest(s["e"], p.Kp, p.kqs, p.Qmin, p.Qmax, 0.0)
    x[7] = pi_rest(s["feout"], p.Kpg, p.ksg, p.Pmin, p.Pmax, 0.0)
    s = signals(x, u, p, math)
    x[5], x[8] = s["s2_y"], s["s5_y"]
    return x


MEASURED = ("Vm", "theta_m", "Pbr", "Qbr", "Ibr_re", "Ibr_im")


def _start(given, p: REPCA1Params) -> tuple:
    Vm, theta_m, Pbr, Qbr, Ibr_re, Ibr_im = (float(given[n]) for n in MEASURED)
    u = [Vm, theta_m, Pbr, Qbr, Ibr_re, Ibr_im, 0.0, Qbr, Pbr, float(given["Pext"]), float(given["Qext"])]
    x = [theta_m, theta_m, 0.0, Qbr, 0.0, 0.0, Pbr, 0.0, 0.0, 0.0]
    x[2] = u[6] = float(signals(x, u, p, math)["VCsel"])
    x[9] = x[2] if p.RefFlag else x[3]
    moving = [n for n, r in zip(REPCA1.state_names, signals(x, u, p, math)["rates"]) if r != 0.0]
    if moving:
        raise ValueError(f"REPCA1: no rest at the start ({', '.join(moving)} move): a limit keeps a PI's input or "
                         "output off 0 (each of [emin, emax], [Qmin, Qmax], [femin, femax], [Pmin, Pmax] must hold 0)")
    return np.array(x), {"Vref": u[6], "Qlinef": u[7], "Plant_pref": u[8], "Pref0": u[9], "Qref0": u[10]}


INPUTS = (Quantity("Vm", "pu", "voltage magnitude at the measured bus", start=1.0, operating_range=(0.7, 1.2),
                   minimum=0.0),
          Quantity("theta_m", "rad", "voltage angle at the measured bus (network frame)", start=0.0,
                   operating_range=(-0.5, 0.5)),
          Quantity("Pbr", "pu", "active power of the monitored branch (ANDES' Pline, system base)", start=0.5,
                   operating_range=(0.0, 1.0)),
          Quantity("Qbr", "pu", "reactive power of the monitored branch (ANDES' Qline, system base)", start=0.1,
                   operating_range=(-0.5, 0.5)),
          Quantity("Ibr_re", "pu", "current of the monitored branch, real part (ANDES' Iline, network frame)",
                   start=0.5, operating_range=(0.0, 1.0)),
          Quantity("Ibr_im", "pu", "current of the monitored branch, imaginary part (ANDES' Iline, network frame)",
                   start=-0.1, operating_range=(-0.5, 0.5)),
          Quantity("Vref", "pu", "voltage set point (voltage control)", start=1.0, operating_range=(0.9, 1.1)),
          Quantity("Qlinef", "pu", "branch reactive power set point (Q control, system base)", start=0.1,
                   operating_range=(-0.5, 0.5)),
          Quantity("Plant_pref", "pu", "branch active power set point (system base)", start=0.5,
                   operating_range=(0.0, 1.0)),
          Quantity("Pref0", "pu", "the electrical controller's own active power reference (system base)", start=0.5,
                   operating_range=(0.0, 1.0)),
          Quantity("Qref0", "pu", "the electrical controller's own reactive power reference (system base)",
                   start=0.0, operating_range=(-0.5, 0.5)))

REPCA1 = Component(
    name="repca1",
    description="REPCA1 renewable energy plant controller model A (PSS/E, WECC REPC_A, ANDES) with its "
                "bus-frequency measurement",
    states=(Quantity("theta_f", "rad", "measured bus angle through the measurement's filter (ANDES' BusFreq L_y "
                     "+ theta0)"),
            Quantity("theta_w", "rad", "washout state of the measurement (ANDES' BusFreq WO_x + theta0)"),
            Quantity("s0_y", "pu", "filtered (compensated) voltage"),
            Quantity("s1_y", "pu", "filtered branch reactive power"),
            Quantity("s2_xi", "pu", "reactive power PI integrator"),
            Quantity("s3_x", "pu", "lead-lag state of the reactive command"),
            Quantity("s4_y", "pu", "filtered branch active power"),
            Quantity("s5_xi", "pu", "active power PI integrator"),
            Quantity("s6_y", "pu", "active power command (lag)"),
            Quantity("s_hold", "pu", "the measurement the reactive PI's error reads (s0_y, RefFlag = 1; s1_y, "
                     "RefFlag = 0), held through a voltage dip (ANDES' eHld)")),
    inputs=INPUTS,
    outputs=(Quantity("Pext", "pu", "active power reference of the electrical controller (system base)"),
             Quantity("Qext", "pu", "reactive power reference of the electrical controller (system base)"),
             Quantity("f", "pu", "measured frequency (1: nominal)")),
    params_type=REPCA1Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.2, 0.1, 0.1, 0.1),
    # busf_Tf dtheta_f/dt = theta_m - theta_f, busf_Tw dtheta_w/dt = theta_f - theta_w
    affine_states=(0, 1),
    ports=Ports(inputs=(Link("measured_voltage", "Vm"), Link("measured_voltage_angle", "theta_m"),
                        Link("branch_active_power", "Pbr"), Link("branch_reactive_power", "Qbr"),
                        Link("branch_current_real", "Ibr_re"), Link("branch_current_imaginary", "Ibr_im")),
                outputs=(Link("active_power_reference", "Pext"), Link("reactive_power_reference", "Qext"))),
    initialisation=Initialisation(("Vref", "Qlinef", "Plant_pref", "Pref0", "Qref0"), _start),
)
