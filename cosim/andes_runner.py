"""ANDES' own time-domain simulation of a shipped case as a grid runner (`--fmus andes`): the ANDES
case file the shipped case was converted from (reference_models.grid.andes_case.ANDES_CASES), the
case's own events switched off, the contingency added as ANDES devices (a Fault at the bus from
fault_start to clear_s with the contingency's fault impedance, a Toggle of the tripped Line at
clearing), ANDES' implicit trapezoid at the fixed step h, its result mapped onto a GridResult
(ANDES' rows, every h, and just after each switching, without its rows in the half step up to a
switching time, which hold the state before the switch: rotor angles [rad], speeds [pu, as the
machines' components], field voltages Efd [pu, machine base], bus voltages).

ANDES (GPL-3.0-or-later) is optional: `andes_available()` says whether it imports.
"""
from __future__ import annotations

import importlib.util
import math
import time

import numpy as np

ANDES_MISSING = "--fmus andes needs ANDES: pip install andes==2.0.0"


def andes_available() -> bool:
    """Whether ANDES can be imported here."""
    return importlib.util.find_spec("andes") is not None


class AndesRunner:
    """ANDES' time-domain simulation of the shipped case `case` (its name one of ANDES_CASES) at
    the fixed step `step` [s]."""

    def __init__(self, case, step: float = 0.001):
        from reference_models.grid.andes_case import ANDES_CASES

        if case.name not in ANDES_CASES:
            raise ValueError(f"--fmus andes runs the cases converted from ANDES ({', '.join(ANDES_CASES)}), "
                             f"not {case.name}")
        if not andes_available():
            raise ValueError(ANDES_MISSING)
        self.case, self.step, self.source = case, step, ANDES_CASES[case.name]

    def _system(self, contingency, stop: float):
        import andes

        andes.config_logger(stream_level=40)
        ss = andes.load(andes.get_case(self.source), setup=False, no_output=True, default_config=True)
        number = {idx: int(idx) for idx in ss.Bus.idx.v}
        bus_idx = {n: idx for idx, n in number.items()}
        c = contingency
        if c.fault_bus is not None:
            z = complex(c.fault_impedance)
            ss.add("Fault", {"bus": bus_idx[c.fault_bus], "tf": c.fault_start, "tc": c.clear_s, "rf": z.real,
                             "xf": z.imag})
        if c.trip:
            ss.add("Toggle", {"model": "Line", "dev": self._line(ss, c.trip, number), "t": c.clear_s})
        ss.setup()
        added = (1 if c.fault_bus is not None else 0, 1 if c.trip else 0)
        for model, keep in ((ss.Fault, added[0]), (ss.Toggle, added[1])):
            for i in range(model.n - keep):  # the case's own events: off
                model.u.v[i] = 0
        from reference_models.grid.andes_case import PFLOW_TOLERANCE

        ss.PFlow.config.tol = PFLOW_TOLERANCE
        ss.PFlow.config.max_iter = 50
        if not ss.PFlow.run():
            raise RuntimeError(f"ANDES' power flow of {self.source} does not converge")
        ss.TDS.config.tf = stop
        ss.TDS.config.tstep = self.step
        ss.TDS.config.fixt = 1
        ss.TDS.config.shrinkt = 0
        ss.TDS.config.criteria = 0
        ss.TDS.config.no_tqdm = 1
        return ss, number

    def _line(self, ss, trip, number):
        """ANDES' Line idx of the branch named `trip` (Network.branch's names)."""
        br = self.case.network.branch(trip)
        L = ss.Line
        found = 0
        for i in range(L.n):
            if {number[L.bus1.v[i]], number[L.bus2.v[i]]} == {br.from_bus, br.to_bus} and L.u.v[i] != 0:
                found += 1
                if found == br.parallel:
                    return L.idx.v[i]
        raise ValueError(f"ANDES' {self.source} has no line {br.name}")

    def run(self, contingency, stop: float, stop_at_loss: bool = False):
        """(GridResult, timing dict) of ANDES' run through `contingency` until `stop` [s]."""
        from reference_models.grid.result import GridResult

        started = time.perf_counter()
        ss, number = self._system(contingency, stop)
        ss.TDS.init()
        if not ss.TDS.initialized:
            raise RuntimeError(f"ANDES cannot initialise {self.source}")
        ss.TDS.run()
        total = time.perf_counter() - started
        ts = ss.dae.ts
        t = np.asarray(ts.t, dtype=float)
        if t[-1] < stop - 0.5 * self.step:
            raise RuntimeError(f"ANDES' simulation of {self.case.name} stopped at t = {t[-1]:.4f} s (its Newton "
                               "iteration did not converge; a bolted fault may need --fault-impedance 1e-4)")
        x, y = np.asarray(ts.x), np.asarray(ts.y)
        c = contingency
        switched = [c.fault_start, c.clear_s] if c.fault_bus is not None else [c.clear_s] if c.trip else []
        # ANDES' rows in the half step before a switching time, the one at it included, hold the state
        # before the switch off the regular rows: left out (its next row is just after the switch)
        keep = np.ones(len(t), bool)
        for te in switched:
            keep &= ~((t > te - 0.5 * self.step) & (t < te + 1e-9))
        keep[0] = True
        t, x, y = t[keep], x[keep], y[keep]
        units = self.case.units
        delta = np.full((len(t), len(units)), np.nan)
        omega = np.full_like(delta, np.nan)
        Efd = np.full_like(delta, np.nan)
        where = {(u.bus, u.generator): k for k, u in enumerate(units)}
        for name in ("GENROU", "GENCLS"):
            model = getattr(ss, name)
            for i in range(model.n):
                key = (number[model.bus.v[i]], str(model.gen.v[i]))
                k = where.get(key, where.get((key[0], None)))
                delta[:, k] = x[:, model.delta.a[i]]
                omega[:, k] = x[:, model.omega.a[i]]
                Efd[:, k] = y[:, model.vf.a[i]]
        V = y[:, ss.Bus.v.a] * np.exp(1j * y[:, ss.Bus.a.a])
        order = [list(number.values()).index(b) for b in self.case.buses]
        V = V[:, order]
        gen_cols = [self.case.network.bus_index(u.bus) for u in units]
        V_gen = V[:, gen_cols]
        theta_bus = np.unwrap(np.angle(V), axis=0)
        lost = None
        for i in range(len(t)):
            if np.ptp(delta[i]) >= math.pi:
                lost = float(t[i])
                break
        events = []
        if c.fault_bus is not None:
            events += [(c.fault_start, f"fault at bus {c.fault_bus}"),
                       (c.clear_s, f"fault at bus {c.fault_bus} cleared" + (f", {c.trip} opened" if c.trip else ""))]
        nan = np.full_like(delta, np.nan)
        result = GridResult(time=t, states={"delta": delta, "omega": omega, "Efd": Efd}, Vs=np.abs(V_gen),
                            theta_vs=theta_bus[:, gen_cols], P=nan, Q=nan, V_bus=np.abs(V), theta_bus=theta_bus,
                            stable=lost is None, loss_of_synchronism_s=lost, events=tuple(events),
                            gen_buses=self.case.generator_buses, buses=self.case.buses)
        return result, {"total_s": total, "steps": len(t) - 1}

    def close(self):
        pass
