"""IEEEST: the IEEE stabiliser (PSS/E IEEEST, ANDES), input modes 1 (rotor speed deviation) and 3
(electrical power on the machine base), the modes the ANDES cases use.

States  x = (F1_x, F1_y [pu] second-order filter, F2_x1, F2_x2 [pu] second-order lead-lag,
        LL1_x, LL2_x [pu] lead-lags, WO_x [pu] washout state)
Inputs  u = (omega [pu] rotor speed, Pe [pu] electrical power (machine base), Vt [pu] terminal
        voltage: the output switch's input)
Outputs y = (Vss [pu] stabiliser signal)

Equations (ANDES 2.0 model reference, PSS: IEEEST):

    sig = omega - 1 (MODE 1) or Pe (MODE 3)
    1 / (1 + s A1 + s^2 A2) -> F1_y;  (1 + s A5 + s^2 A6) / (1 + s A3 + s^2 A4) -> F2_y
    (1 + s T1) / (1 + s T2), (1 + s T3) / (1 + s T4) -> LL2_y (a T2, T4 of 0: a gain of 1)
    washout s T5 / (1 + s T6) of KS LL2_y (T5 = 0: the lag 1 / (1 + s T6)) -> WO_y
    Vss = WO_y clipped to [LSMIN, LSMAX] (windup limiter), and 0 where Vt <= VCL or Vt >= VCU
        (a VCL, VCU of 0 is no limit: -999, 999 as ANDES)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..blocks import clip, lag_second_order, lead_lag, lead_lag_second_order, washout_or_lag
from ..component import Component, Parameters, Quantity
from ..piecewise import where
from ..ports import Link, Ports
from .common import check_limits, check_ranges, finite_inputs

MODES = (1.0, 3.0)
PARAMETER_RANGES = {**{f"A{i}": (0.0, 100.0, "s or s^2") for i in range(1, 7)},
                    **{f"T{i}": (0.0, 100.0, "s") for i in range(1, 6)},
                    "T6": (0.001, 100.0, "s"), "KS": (-1000.0, 1000.0, "pu")}


@dataclass(frozen=True)
class IEEESTParams(Parameters):
    """ANDES/PSS/E IEEEST data: MODE (1 or 3), filter coefficients A1..A6 [s, s^2], time constants
    T1..T6 [s], gain KS [pu], output limits LSMIN, LSMAX [pu], output switch VCL, VCU [pu]."""

    MODE: float = 1.0
    A1: float = 0.0
    A2: float = 0.0
    A3: float = 0.0
    A4: float = 0.0
    A5: float = 0.0
    A6: float = 0.0
    T1: float = 1.0
    T2: float = 1.0
    T3: float = 1.0
    T4: float = 1.0
    T5: float = 1.0
    T6: float = 0.5
    KS: float = 10.0
    LSMAX: float = 0.1
    LSMIN: float = -0.1
    VCU: float = 0.0
    VCL: float = 0.0

    def check(self) -> None:
        self.require("MODE", self.MODE in MODES, "be 1 (rotor speed) or 3 (electrical power)")
        check_ranges(self, PARAMETER_RANGES)
        check_limits(self, "LSMIN", "LSMAX")

    @property
    def switch(self) -> tuple:
        """(VCL, VCU) of the output switch, 0 read as -999, 999."""
        return (self.VCL if self.VCL != 0 else -999.0, self.VCU if self.VCU != 0 else 999.0)


def _signal(u, p: IEEESTParams):
    omega, Pe = u[0], u[1]
    return omega - 1.0 if p.MODE == 1.0 else Pe


def _chain(x, u, p: IEEESTParams, m):
    """(derivatives [7], WO_y)."""
    F1_x, F1_y, F2_x1, F2_x2, LL1_x, LL2_x, WO_x = x
    d_F1x, d_F1y, y1 = lag_second_order(m, _signal(u, p), F1_x, F1_y, 1.0, p.A1, p.A2)
    d_F2x1, d_F2x2, y2 = lead_lag_second_order(m, y1, F2_x1, F2_x2, p.A3, p.A4, p.A5, p.A6)
    d_LL1, y3 = lead_lag(m, y2, LL1_x, 1.0, p.T1, p.T2)
    d_LL2, y4 = lead_lag(m, y3, LL2_x, 1.0, p.T3, p.T4)
    d_WO, WO_y = washout_or_lag(m, p.KS * y4, WO_x, p.T5, p.T6)
    return (d_F1x, d_F1y, d_F2x1, d_F2x2, d_LL1, d_LL2, d_WO), WO_y


def derivatives(x, u, p: IEEESTParams, m):
    """d/dt of (F1_x, F1_y, F2_x1, F2_x2, LL1_x, LL2_x, WO_x) for u = (omega, Pe, Vt)."""
    return _chain(x, u, p, m)[0]


def switched_output(signal, Vt, p, m):
    """Vss: `signal` clipped to [LSMIN, LSMAX], 0 where the terminal voltage Vt lies at or outside
    the output switch's thresholds (low, high) = p.switch (IEEEST, ST2CUT)."""
    low, high = p.switch
    Vss = clip(m, signal, p.LSMIN, p.LSMAX)
    return where(m, Vt >= high, 0.0 * Vss, where(m, Vt <= low, 0.0 * Vss, Vss))


def outputs(x, u, p: IEEESTParams, m):
    """(Vss,): the limited washout output, 0 outside the terminal-voltage switch."""
    return (switched_output(_chain(x, u, p, m)[1], u[2], p, m),)


def equilibrium(u, p: IEEESTParams) -> np.ndarray:
    """The steady state [7] at constant (omega, Pe, Vt): every filter at its input signal."""
    finite_inputs(u, "IEEEST")
    sig = _signal([float(v) for v in u], p)
    return np.array([0.0, sig, 0.0, sig, sig, sig, p.KS * sig])


IEEEST = Component(
    name="ieeest",
    description="IEEEST IEEE stabiliser (PSS/E, ANDES), input modes 1 (speed) and 3 (electrical power)",
    states=(Quantity("F1_x", "pu", "second-order filter, rate"), Quantity("F1_y", "pu", "second-order filter"),
            Quantity("F2_x1", "pu", "second-order lead-lag, rate"), Quantity("F2_x2", "pu", "second-order lead-lag"),
            Quantity("LL1_x", "pu", "first lead-lag state"), Quantity("LL2_x", "pu", "second lead-lag state"),
            Quantity("WO_x", "pu", "washout state")),
    inputs=(Quantity("omega", "pu", "rotor speed", start=1.0, operating_range=(0.95, 1.05), minimum=0.0),
            Quantity("Pe", "pu", "electrical power (machine base)", start=0.7, operating_range=(0.0, 1.2)),
            Quantity("Vt", "pu", "terminal voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0)),
    outputs=(Quantity("Vss", "pu", "stabiliser signal"),),
    params_type=IEEESTParams,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.5),
    ports=Ports(inputs=(Link("rotor_speed", "omega"), Link("electrical_power", "Pe"),
                        Link("terminal_voltage", "Vt")),
                outputs=(Link("stabiliser_signal", "Vss"),)),
)
