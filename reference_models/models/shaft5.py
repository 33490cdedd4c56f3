"""SHAFT5: the five-mass torsional shaft of a steam turbine-generator (ANDES' SHAFT5; Milano, Power
System Modelling and Scripting, 2010, section 15.1.10): the high-, intermediate- and low-pressure
turbine masses HP, IP, LP, the generator rotor (its machine's) and the exciter mass EX on one shaft.

States  x = (dHP, wHP, dIP, wIP, dLP, wLP, dEX, wEX: each mass's angle [rad] and speed [pu])
Inputs  u = (tm [pu] the governor's mechanical torque, which drives the HP mass; omega [pu] and
        delta [rad] the generator rotor's speed and angle, its machine's)
Outputs y = (Tsh [pu]: the torque the shaft applies to the generator rotor, the machine's
        mechanical torque in place of the governor's)

Equations (ANDES 2.0 model reference, DynShaft: SHAFT5), wB = 2 pi fn:

    d dX/dt = wB (wX - 1)  for X = HP, IP, LP, EX
    MHP dwHP/dt = tm - DHP (wHP - 1) - D12 (wHP - wIP) + KHP (dIP - dHP)
    MIP dwIP/dt = -DIP (wIP - 1) - D12 (wIP - wHP) - D23 (wIP - wLP) + KHP (dHP - dIP) + KIP (dLP - dIP)
    MLP dwLP/dt = -DLP (wLP - 1) - D23 (wLP - wIP) - D34 (wLP - omega) + KIP (dIP - dLP) + KLP (delta - dLP)
    MEX dwEX/dt = -DEX (wEX - 1) - D45 (wEX - omega) + KEX (delta - dEX)
    Tsh = KLP (dLP - delta) + KEX (dEX - delta) - D34 (omega - wLP) - D45 (omega - wEX)

ANDES adds -tm + Tsh to its machine's swing equation, M domega/dt = tm - te - D (omega - 1): the
generator rotor then moves by M domega/dt = Tsh - te - D (omega - 1), which is the machine's own
equation with its mechanical power input Pm = Tsh, the governor's tm driving the HP mass instead:
the shaft takes and gives `mechanical_power`, in series on it (case.unit_wiring: it takes the
governor's, the machine takes its). The machine's rotor angle
and speed are the generator mass's; the angles are electrical radians in the network frame, as
the machine's delta.

Bases: the inertias MX = 2 HX [s], the springs KX [pu torque / rad] and the dampings [pu] on the
machine base Sn, as the case data give them, and the torques tm, Tsh on the machine base (our
machine's Pm); ANDES converts all of them to the system base by Sn / Sb, which scales every
equation alike.

Start (ANDES' initialisation): at the machine's rotor angle delta0 and speed 1 with the mechanical
torque tm0 it demands, every mass at speed 1 and each spring twisted by the torque it carries:
dEX = delta0, dLP = delta0 + tm0 / KLP, dIP = dLP + tm0 / KIP, dHP = dIP + tm0 / KHP; the governor
has to give tm = tm0.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..component import Component, Initialisation, Parameters, Quantity
from ..ports import Link, Ports
from .common import check_ranges, finite_inputs

INERTIAS = ("MHP", "MIP", "MLP", "MEX")
SPRINGS = ("KHP", "KIP", "KLP", "KEX")
DAMPINGS = ("DHP", "DIP", "DLP", "DEX", "D12", "D23", "D34", "D45")
PARAMETER_RANGES = {"fn": (16.0, 400.0, "Hz"),
                    **{name: (1e-4, 100.0, "s") for name in INERTIAS},
                    **{name: (1e-3, 1e4, "pu") for name in SPRINGS},
                    **{name: (0.0, 1e3, "pu") for name in DAMPINGS}}


@dataclass(frozen=True)
class SHAFT5Params(Parameters):
    """ANDES' SHAFT5 data: the rated frequency fn [Hz] (its machine's); the masses' start-up times
    MHP, MIP, MLP, MEX = 2 H [s], the springs KHP (HP-IP), KIP (IP-LP), KLP (LP-rotor), KEX
    (rotor-EX) [pu / rad], the self-dampings DHP, DIP, DLP, DEX and the mutual dampings D12 (HP-IP),
    D23 (IP-LP), D34 (LP-rotor), D45 (rotor-EX) [pu], all on the machine base."""

    fn: float = 60.0
    MHP: float = 0.092
    MIP: float = 0.156
    MLP: float = 0.858
    MEX: float = 0.068
    KHP: float = 19.303
    KIP: float = 34.929
    KLP: float = 52.038
    KEX: float = 1.55
    DHP: float = 0.0
    DIP: float = 0.0
    DLP: float = 0.0
    DEX: float = 0.0
    D12: float = 0.0
    D23: float = 0.0
    D34: float = 0.0
    D45: float = 0.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)


def derivatives(x, u, p: SHAFT5Params, m):
    """d/dt of (dHP, wHP, dIP, wIP, dLP, wLP, dEX, wEX) for u = (tm, omega, delta)."""
    dHP, wHP, dIP, wIP, dLP, wLP, dEX, wEX = x
    tm, omega, delta = u
    wB = 2.0 * math.pi * p.fn
    return (wB * (wHP - 1.0),
            (tm - p.DHP * (wHP - 1.0) - p.D12 * (wHP - wIP) + p.KHP * (dIP - dHP)) / p.MHP,
            wB * (wIP - 1.0),
            (-p.DIP * (wIP - 1.0) - p.D12 * (wIP - wHP) - p.D23 * (wIP - wLP) + p.KHP * (dHP - dIP)
             + p.KIP * (dLP - dIP)) / p.MIP,
            wB * (wLP - 1.0),
            (-p.DLP * (wLP - 1.0) - p.D23 * (wLP - wIP) - p.D34 * (wLP - omega) + p.KIP * (dIP - dLP)
             + p.KLP * (delta - dLP)) / p.MLP,
            wB * (wEX - 1.0),
            (-p.DEX * (wEX - 1.0) - p.D45 * (wEX - omega) + p.KEX * (delta - dEX)) / p.MEX)


def outputs(x, u, p: SHAFT5Params, m):
    """(Tsh,) [pu, machine base]: the shaft's torque on the generator rotor."""
    _, _, _, _, dLP, wLP, dEX, wEX = x
    _, omega, delta = u
    return (p.KLP * (dLP - delta) + p.KEX * (dEX - delta) - p.D34 * (omega - wLP) - p.D45 * (omega - wEX),)


def equilibrium(u, p: SHAFT5Params) -> np.ndarray:
    """The steady state [8] at constant (tm, omega, delta): every mass at speed 1 (its angle at rest),
    the springs carrying tm through the turbine masses, the LP spring also the mutual damping
    D34 (omega - 1) and the EX spring D45 (omega - 1) (none where the rotor is at speed 1)."""
    tm, omega, delta = finite_inputs(u, "SHAFT5")
    dLP = delta + (tm + p.D34 * (omega - 1.0)) / p.KLP
    dIP = dLP + tm / p.KIP
    dHP = dIP + tm / p.KHP
    dEX = delta + p.D45 * (omega - 1.0) / p.KEX
    return np.array([dHP, 1.0, dIP, 1.0, dLP, 1.0, dEX, 1.0])


def _start(given, p: SHAFT5Params) -> tuple:
    tm = float(given["Tsh"])
    return equilibrium((tm, given["omega"], given["delta"]), p), {"tm": tm}


SHAFT5 = Component(
    name="shaft5",
    description="SHAFT5 five-mass torsional shaft (HP, IP, LP, rotor, EX) of a turbine-generator (ANDES)",
    states=(Quantity("dHP", "rad", "HP turbine mass angle"), Quantity("wHP", "pu", "HP turbine mass speed"),
            Quantity("dIP", "rad", "IP turbine mass angle"), Quantity("wIP", "pu", "IP turbine mass speed"),
            Quantity("dLP", "rad", "LP turbine mass angle"), Quantity("wLP", "pu", "LP turbine mass speed"),
            Quantity("dEX", "rad", "exciter mass angle"), Quantity("wEX", "pu", "exciter mass speed")),
    # start inputs at which the rest is exact in floating point: with ANDES' default dampings (0) the
    # torsional modes are undamped, and an explicit integrator's error grows a rounding residual of the
    # rest (1e-14 at tm = 0.8, delta = 0.5) to 1e-8 rad within 1 s at rtol 1e-10
    inputs=(Quantity("tm", "pu", "the governor's mechanical torque (machine base)", start=0.5,
                     operating_range=(0.0, 1.0)),
            Quantity("omega", "pu", "generator rotor speed", start=1.0, operating_range=(0.95, 1.05)),
            Quantity("delta", "rad", "generator rotor angle (network frame)", start=0.0,
                     operating_range=(-1.0, 1.5))),
    outputs=(Quantity("Tsh", "pu", "the shaft's torque on the generator rotor (machine base)"),),
    params_type=SHAFT5Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.05, 0.001, 0.05, 0.001, 0.05, 0.001, 0.05, 0.001),
    ports=Ports(inputs=(Link("mechanical_power", "tm"), Link("rotor_speed", "omega"), Link("rotor_angle", "delta")),
                outputs=(Link("mechanical_power", "Tsh"),)),  # in series: the governor's in, the rotor's out
    initialisation=Initialisation(("tm",), _start),
)
