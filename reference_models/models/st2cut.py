"""ST2CUT: the dual-input stabiliser (PSS/E ST2CUT, ANDES), as ANDES 2.0.0 computes it, for the input
modes whose signals the project's machines give.

States  x = (L1_y, L2_y [pu] transducers of input 1 and 2, WO_x [pu] washout state, LL1_x, LL2_x,
        LL3_x [pu] lead-lag states)
Inputs  u = (omega [pu] rotor speed, Pe [pu] electrical power (machine base), Pm [pu] mechanical
        power (machine base), Vt [pu] terminal voltage: the signals and the output switch's input)
Outputs y = (Vss [pu] stabiliser signal)

Input modes MODE (input 1) and MODE2 (input 2), ANDES' numbering:
    0  none (signal 0; MODE2 left empty, NaN in ANDES' data, reads as 0)
    1  rotor speed deviation omega - 1
    3  electrical power Pe on the machine base (ANDES' te / (Sn / Sb))
    4  change of mechanical power (Pm - Pm0) Sn / Sb: ANDES' tm - tm0 on its system base, with
       Pm0 its tm0, the mechanical power at its initialisation (parameter Pm0, machine base)
    5  terminal (bus) voltage magnitude Vt
Modes 2 (bus frequency deviation: a frequency measurement the project has no signal of) and
6 (time derivative of the bus voltage) are refused with a ParameterError naming the mode, and so
is any other number. ANDES' remote buses busr, busr2 are not modelled: the voltage is the
machine's terminal voltage.

Equations (ANDES 2.0 model reference, PSS: ST2CUT):

    lag K1 / (1 + s T1) of signal 1 -> L1,  K2 / (1 + s T2) of signal 2 -> L2 (T = 0: the lag is
        its gain, the state held)
    IN = L1 + L2
    washout s T3 / (1 + s T4) of IN (T3 = 0: the lag 1 / (1 + s T4)) -> WO_y
    lead-lags (1 + s T5) / (1 + s T6), (1 + s T7) / (1 + s T8), (1 + s T9) / (1 + s T10) in
        series (a lag time of 0: a gain of 1) -> LL3_y
    Vss = LL3_y clipped to [LSMIN, LSMAX] (windup limiter), and 0 where Vt <= VCL + Vt0 or
        Vt >= VCU + Vt0 (a VCL, VCU of 0 is no limit: -999, 999), Vt0 ANDES' v0, the bus voltage
        at its initialisation (ANDES offsets the switch's thresholds by it; parameter Vt0)

Bases: Pe, Pm, Pm0 on the machine base Sn, the system base Sb (parameters Sn, Sb [MVA]; they enter
MODE 4 only, where ANDES takes the change of mechanical power on its system base).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..blocks import lag, lead_lag, washout_or_lag
from ..component import ParameterError, Component, Parameters, Quantity
from ..ports import Link, Ports
from .common import check_limits, check_ranges, finite_inputs
from .ieeest import switched_output

MODES = {0.0: "none", 1.0: "rotor speed deviation", 3.0: "electrical power", 4.0: "change of mechanical power",
         5.0: "terminal voltage"}
REFUSED_MODES = {2.0: "bus frequency deviation", 6.0: "derivative of the bus voltage"}
PARAMETER_RANGES = {"K1": (-100.0, 100.0, "pu"), "K2": (-100.0, 100.0, "pu"),
                    **{f"T{i}": (0.0, 100.0, "s") for i in range(1, 11)}, "T4": (0.001, 100.0, "s"),
                    "VCU": (-1000.0, 1000.0, "pu"), "VCL": (-1000.0, 1000.0, "pu"),
                    "Pm0": (-1000.0, 1000.0, "pu"), "Vt0": (0.0, 10.0, "pu"),
                    "Sn": (1e-3, 1e5, "MVA"), "Sb": (1e-3, 1e5, "MVA")}


@dataclass(frozen=True)
class ST2CUTParams(Parameters):
    """ANDES/PSS/E ST2CUT data: input modes MODE, MODE2 (above), transducer gains K1, K2 [pu] and
    time constants T1, T2 [s], washout T3, T4 [s], lead-lag time constants T5..T10 [s], output
    limits LSMAX, LSMIN [pu], output switch VCU, VCL [pu]; ANDES' initial values Pm0 (mechanical
    power, machine base) and Vt0 (bus voltage) [pu]; machine base Sn and system base Sb [MVA]."""

    MODE: float = 1.0
    MODE2: float = 0.0
    K1: float = 1.0
    K2: float = 1.0
    T1: float = 1.0
    T2: float = 1.0
    T3: float = 1.0
    T4: float = 0.2
    T5: float = 1.0
    T6: float = 0.5
    T7: float = 1.0
    T8: float = 1.0
    T9: float = 1.0
    T10: float = 0.2
    LSMAX: float = 0.3
    LSMIN: float = -0.3
    VCU: float = 999.0
    VCL: float = -999.0
    Pm0: float = 0.0
    Vt0: float = 1.0
    Sn: float = 100.0
    Sb: float = 100.0

    def __post_init__(self):
        if isinstance(self.MODE2, float) and math.isnan(self.MODE2):  # ANDES' empty MODE2: no second input
            object.__setattr__(self, "MODE2", 0.0)
        super().__post_init__()

    def check(self) -> None:
        for name in ("MODE", "MODE2"):
            mode = getattr(self, name)
            if mode not in MODES:
                what = f"mode {mode:g} ({REFUSED_MODES[mode]}) is not supported" if mode in REFUSED_MODES \
                    else f"mode {mode!r} does not exist"
                raise ParameterError(f"parameter {name} = {mode!r} must be one of "
                                     + ", ".join(f"{k:g} ({v})" for k, v in MODES.items()) + f": {what}")
        check_ranges(self, PARAMETER_RANGES)
        check_limits(self, "LSMIN", "LSMAX")

    @property
    def switch(self) -> tuple:
        """(low, high) thresholds of the output switch on Vt: VCL + Vt0, VCU + Vt0 (0 read as -999, 999)."""
        return ((self.VCL if self.VCL != 0 else -999.0) + self.Vt0, (self.VCU if self.VCU != 0 else 999.0) + self.Vt0)


def _signal(mode: float, u, p: ST2CUTParams):
    """The input signal of `mode` from u = (omega, Pe, Pm, Vt)."""
    omega, Pe, Pm, Vt = u
    if mode == 1.0:
        return omega - 1.0
    if mode == 3.0:
        return Pe
    if mode == 4.0:
        return (Pm - p.Pm0) * (p.Sn / p.Sb)
    if mode == 5.0:
        return Vt
    return 0.0 * omega


def _chain(x, u, p: ST2CUTParams, m):
    """(derivatives [6], LL3_y)."""
    L1_y, L2_y, WO_x, LL1_x, LL2_x, LL3_x = x
    d_L1, y1 = lag(m, _signal(p.MODE, u, p), L1_y, p.K1, p.T1)
    d_L2, y2 = lag(m, _signal(p.MODE2, u, p), L2_y, p.K2, p.T2)
    d_WO, WO_y = washout_or_lag(m, y1 + y2, WO_x, p.T3, p.T4)
    d_LL1, y = lead_lag(m, WO_y, LL1_x, 1.0, p.T5, p.T6)
    d_LL2, y = lead_lag(m, y, LL2_x, 1.0, p.T7, p.T8)
    d_LL3, y = lead_lag(m, y, LL3_x, 1.0, p.T9, p.T10)
    return (d_L1, d_L2, d_WO, d_LL1, d_LL2, d_LL3), y


def derivatives(x, u, p: ST2CUTParams, m):
    """d/dt of (L1_y, L2_y, WO_x, LL1_x, LL2_x, LL3_x) for u = (omega, Pe, Pm, Vt)."""
    return _chain(x, u, p, m)[0]


def outputs(x, u, p: ST2CUTParams, m):
    """(Vss,): the limited lead-lag output, 0 outside the terminal-voltage switch (ieeest.switched_output)."""
    return (switched_output(_chain(x, u, p, m)[1], u[3], p, m),)


def equilibrium(u, p: ST2CUTParams) -> np.ndarray:
    """The steady state [6] at constant (omega, Pe, Pm, Vt): every block at its input."""
    u = finite_inputs(u, "ST2CUT")
    y1, y2 = p.K1 * _signal(p.MODE, u, p), p.K2 * _signal(p.MODE2, u, p)
    WO_y = 0.0 if p.T3 > 0 else y1 + y2
    return np.array([y1, y2, y1 + y2, WO_y, WO_y, WO_y])


ST2CUT = Component(
    name="st2cut",
    description="ST2CUT dual-input stabiliser (PSS/E, ANDES 2.0.0), input modes 0, 1, 3, 4, 5",
    states=(Quantity("L1_y", "pu", "transducer of input 1"), Quantity("L2_y", "pu", "transducer of input 2"),
            Quantity("WO_x", "pu", "washout state"), Quantity("LL1_x", "pu", "first lead-lag state"),
            Quantity("LL2_x", "pu", "second lead-lag state"), Quantity("LL3_x", "pu", "third lead-lag state")),
    inputs=(Quantity("omega", "pu", "rotor speed", start=1.0, operating_range=(0.95, 1.05), minimum=0.0),
            Quantity("Pe", "pu", "electrical power (machine base)", start=0.7, operating_range=(0.0, 1.2)),
            Quantity("Pm", "pu", "mechanical power (machine base)", start=0.7, operating_range=(0.0, 1.2)),
            Quantity("Vt", "pu", "terminal voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0)),
    outputs=(Quantity("Vss", "pu", "stabiliser signal"),),
    params_type=ST2CUTParams,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 0.1, 0.1, 0.1, 0.1, 0.1),
    ports=Ports(inputs=(Link("rotor_speed", "omega"), Link("electrical_power", "Pe"),
                        Link("mechanical_power", "Pm"), Link("terminal_voltage", "Vt")),
                outputs=(Link("stabiliser_signal", "Vss"),)),
)
