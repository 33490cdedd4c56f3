"""HYGOVDB: HYGOV with a dead band on its speed input (ANDES HYGOVDB), as ANDES 2.0.0 computes it.

States, inputs, outputs, equations and bases: HYGOV's (hygov.py), with the governor's speed signal
sig the continuous dead band of wd = omega - wref0 (ANDES' DeadBand1, centre 0):

    sig = wd - dbU where wd > dbU,  wd - dbL where wd < dbL,  else 0

(dbL = dbU = 0, ANDES' defaults: sig = wd, HYGOV). The damping term of Pm keeps wd itself.
ANDES 2.0.0's HYGOVDB has no gate-flow table (PSS/E's GV/PGV points are commented out of its
data): its gate and flow enter the turbine as HYGOV's.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..blocks import dead_band
from .hygov import HYGOVParams, hydro_governor


@dataclass(frozen=True)
class HYGOVDBParams(HYGOVParams):
    """HYGOV's data and the dead band dbL <= 0 <= dbU [pu speed]."""

    dbL: float = 0.0
    dbU: float = 0.0

    def check(self) -> None:
        super().check()
        self.require("dbL", -1.0 <= self.dbL <= 0.0, "lie in [-1, 0] pu")
        self.require("dbU", 0.0 <= self.dbU <= 1.0, "lie in [0, 1] pu")


HYGOVDB = hydro_governor("hygovdb", "HYGOVDB hydro turbine-governor with a speed dead band (ANDES 2.0.0)",
                         HYGOVDBParams, lambda wd, p, m: dead_band(m, wd, p.dbL, p.dbU))
