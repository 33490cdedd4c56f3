"""ANDES' own time-domain simulation of a case as a grid runner (`--fmus andes`): the case file the
case was converted from (`Case.source`: a user's file, with its dyr; for a shipped case its entry of
reference_models.grid.andes_case.ANDES_CASES), with
the case's own events (its Toggle and Fault devices) as the file has them, or switched off where
the contingency leaves them out (Contingency.events empty) or gives others (each added as a Fault or
a Toggle of its line, load or generator's bus devices), the contingency added as ANDES devices
(a Fault at the bus from fault_start to clear_s with the contingency's fault impedance, a Toggle of
the tripped Line at clearing), ANDES' implicit trapezoid at the fixed step h, its result mapped
onto a GridResult as the other runners give it (rows at the multiples of the row spacing, linear between
ANDES' own rows within one topology, and ANDES' first row after each switching: `_on_grid`; the
events as Contingency.topologies names them: rotor angles [rad], speeds [pu, 1 =
synchronous, as the machines' components hold them], the machines' field-voltage inputs [pu,
machine base] in `machine_inputs`, bus voltages, and an inverter's power into its bus, ANDES' Pe, Qe,
as P, Q of its unit [pu, system base]; NaN for what ANDES' result does not give). A unit tripped by an event leaves the stability
check from its trip on.

ANDES (GPL-3.0-or-later) is optional: `andes_available()` says whether it imports.
"""
from __future__ import annotations

import importlib.util
import math
import time

import numpy as np

ANDES_MISSING = "--fmus andes needs ANDES: pip install andes==2.0.0"


REFERENCE_STEP = 1e-3  # s: ANDES' step as a reference (its trapezoid at 1 ms is within 0.07 deg of 0.5 ms)
SWITCH_MARGIN = 1e-4  # s: ANDES steps to each switching time from this far before it
LOSS_LIMIT_DEG = 180.0  # deg: the rotor-angle spread at which ANDES' TDS criteria end a run (stop_at_loss)


def check_contingency(contingency) -> None:
    """ValueError (one line) for a contingency ANDES cannot run: a fault from t <= SWITCH_MARGIN
    (ANDES keeps no state from before it and fails at its clearing)."""
    c = contingency
    if c.fault_bus is not None and c.fault_start <= SWITCH_MARGIN:
        raise ValueError(f"ANDES applies a fault after its first steps: give --fault-start later than "
                         f"{SWITCH_MARGIN:g} s (e.g. 1, as the ANDES cases' own events)")


def andes_available() -> bool:
    """Whether ANDES can be imported here."""
    return importlib.util.find_spec("andes") is not None


def _add_fault(ss, bus, start: float, clear: float, impedance) -> None:
    """An ANDES Fault at the Bus idx `bus` from `start` to `clear` [s] through `impedance` [pu]."""
    z = complex(impedance)
    ss.add("Fault", {"bus": bus, "tf": start, "tc": clear, "rf": z.real, "xf": z.imag})


class AndesRunner:
    """ANDES' time-domain simulation of `case` (converted from a case file, `Case.source`, or a
    shipped case named in ANDES_CASES) at the fixed step `step` [s], its result rows every `rows` [s]
    (default: `step`)."""

    def __init__(self, case, step: float = 0.001, rows: float | None = None):
        from reference_models.grid.andes_case import ANDES_CASES

        if case.source is None and case.name not in ANDES_CASES:
            raise ValueError(f"--fmus andes runs the cases converted from ANDES ({', '.join(ANDES_CASES)}) and case "
                             f"files, not {case.name}")
        if not andes_available():
            raise ValueError(ANDES_MISSING)
        self.case, self.step = case, step
        self.source, self.dyr = case.source if case.source is not None else (ANDES_CASES[case.name], None)
        self.rows = step if rows is None else rows

    def _system(self, contingency, stop: float, stop_at_loss: bool):
        import andes

        from reference_models.grid.andes_case import configure_andes_logging

        configure_andes_logging(andes)  # ANDES' own messages off: a failed run is one line of ours
        path = self.source if self.case.source is not None else andes.get_case(self.source)
        extra = {"addfile": self.dyr} if self.dyr is not None else {}
        ss = andes.load(path, setup=False, no_output=True, default_config=True, **extra)
        number = {idx: int(idx) for idx in ss.Bus.idx.v}
        bus_idx = {n: idx for idx, n in number.items()}
        c = contingency
        own = (ss.Fault.n, ss.Toggle.n)  # the case file's own events come first
        replaced = bool(c.events) and tuple(c.events) != tuple(self.case.events)
        if replaced:  # events the file does not hold: its own switched off below, these added
            for event in c.events:
                self._add_event(ss, event, number, bus_idx)
        if c.fault_bus is not None:
            _add_fault(ss, bus_idx[c.fault_bus], c.fault_start, c.clear_s, c.fault_impedance)
        if c.trip:
            ss.add("Toggle", {"model": "Line", "dev": self._line(ss, c.trip, number), "t": c.clear_s})
        ss.setup()
        if not c.events or replaced:
            for model, n in zip((ss.Fault, ss.Toggle), own):
                for i in range(n):  # the case's own events left out
                    model.u.v[i] = 0
        from reference_models.grid.andes_case import pflow_tolerance

        ss.PFlow.config.tol = pflow_tolerance(ss)
        ss.PFlow.config.max_iter = 50
        if not ss.PFlow.run():
            raise RuntimeError(f"ANDES' power flow of {self.source} does not converge")
        ss.TDS.config.tf = stop
        ss.TDS.config.tstep = self.step
        ss.TDS.config.fixt = 1
        ss.TDS.config.shrinkt = 0
        ss.TDS.config.criteria = int(stop_at_loss)
        ss.TDS.config.ddelta_limit = LOSS_LIMIT_DEG
        ss.TDS.config.no_tqdm = 1
        return ss, number

    def _add_event(self, ss, event, number, bus_idx) -> None:
        """ANDES devices for one case.Event: a Fault, or a Toggle of the Line, PQ load or bus
        devices (machines, converters; a static generator's own where it has none) it switches.
        Each Toggle flips its device, so a sequence of events alternates as Contingency checks."""
        from reference_models.grid.andes_case import bus_devices

        if event.kind == "fault":
            _add_fault(ss, bus_idx[event.bus], event.time, event.clear, event.impedance)
            return
        if event.kind == "branch":
            targets = [("Line", self._line(ss, event.branch, number))]
        elif event.kind == "load":
            targets = [("PQ", idx) for idx in ss.PQ.idx.v if str(idx) == event.name]
        else:
            static, _, device = event.generator.partition("/")
            targets = [(model, idx) for model, _, idx in bus_devices(ss).get(static, [])
                       if not device or str(idx) == device]
            if not targets:  # a static generator without a machine or converter: its own status
                targets = [(model, idx) for model in ("PV", "Slack") for idx in getattr(ss, model).idx.v
                           if str(idx) == static]
        if not targets:
            raise ValueError(f"ANDES' {self.source} has no device for the event {event.kind} "
                             f"{event.branch or event.generator or event.name}")
        for model, idx in targets:
            ss.add("Toggle", {"model": model, "dev": idx, "t": event.time})

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
        """(GridResult, timing dict) of ANDES' run through `contingency` until `stop` [s]. With
        `stop_at_loss`, ANDES' TDS criteria end the run at the first step where the spread of the
        rotor angles of all its synchronous machines exceeds LOSS_LIMIT_DEG: the result then ends
        with ANDES' row of that step (off the row grid), unstable, its loss time that row's time."""
        from reference_models.grid.result import GridResult

        check_contingency(contingency)
        started = time.perf_counter()
        ss, number = self._system(contingency, stop, stop_at_loss)
        ss.TDS.init()
        if not ss.TDS.initialized:
            raise RuntimeError(f"ANDES cannot initialise {self.source}")
        start = np.array(ss.dae.x, dtype=float), np.array(ss.dae.y, dtype=float)  # its rows begin after t = 0
        ss.TDS.run()
        total = time.perf_counter() - started
        ts = ss.dae.ts
        t = np.asarray(ts.t, dtype=float)
        lost_early = stop_at_loss and t[-1] < stop - 0.5 * self.step and bool(ss.TDS.busted) \
            and ss.TDS.check_criteria() is False
        if t[-1] < stop - 0.5 * self.step and not lost_early:
            raise RuntimeError(f"ANDES' simulation of {self.case.name} stopped at t = {t[-1]:.4f} s (its Newton "
                               "iteration did not converge; a bolted fault may need --fault-impedance 1e-4)")
        x, y = np.asarray(ts.x), np.asarray(ts.y)
        if t[0] > 0.0:
            t, x, y = np.r_[0.0, t], np.vstack([start[0], x]), np.vstack([start[1], y])
        from reference_models.grid.andes_case import CONVERTERS, MACHINES, device_generators

        topologies = contingency.topologies(stop)
        units = self.case.units
        g = len(units)
        # (x or y, column) of delta, omega, vf, P, Q per unit (None: not in ANDES' result, NaN)
        cols = [None] * (5 * g)
        where = {(u.bus, u.generator): k for k, u in enumerate(units)}
        named = device_generators(ss)
        for name in MACHINES + CONVERTERS:
            model = getattr(ss, name)
            for i in range(model.n):
                key = (number[model.bus.v[i]], named.get((name, i), str(model.gen.v[i])))
                k = where.get(key, where.get((key[0], None)))
                if k is None:
                    continue
                if name in MACHINES:
                    cols[k], cols[g + k], cols[2 * g + k] = (x, model.delta.a[i]), (x, model.omega.a[i]), \
                        (y, model.vf.a[i])
                elif hasattr(model, "Pe") and hasattr(model, "Qe"):  # an inverter's power into its bus
                    cols[3 * g + k], cols[4 * g + k] = (y, model.Pe.a[i]), (y, model.Qe.a[i])
        order = [list(number.values()).index(b) for b in self.case.buses]
        v_cols, a_cols = np.asarray(ss.Bus.v.a)[order], np.asarray(ss.Bus.a.a)[order]
        table = np.hstack([np.stack([src[:, j] if src is not None else np.full(len(t), np.nan)
                                     for src, j in (c if c is not None else (None, None) for c in cols)], axis=1),
                           y[:, v_cols], y[:, a_cols]])
        end = float(t[-1])
        t_grid, table_grid = self._on_grid(t, table, sorted({tp.start for tp in topologies[1:]}), stop)
        if lost_early and t_grid[-1] < end - 1e-9:
            t_grid, table_grid = np.r_[t_grid, end], np.vstack([table_grid, table[-1:]])
        t, table = t_grid, table_grid
        nb = len(self.case.buses)
        delta, omega, Efd = table[:, :g], table[:, g:2 * g], table[:, 2 * g:3 * g]
        P, Q = table[:, 3 * g:4 * g], table[:, 4 * g:5 * g]
        V = table[:, 5 * g:5 * g + nb] * np.exp(1j * table[:, 5 * g + nb:])
        gen_cols = [self.case.network.bus_index(u.bus) for u in units]
        V_gen = V[:, gen_cols]
        theta_bus = np.unwrap(np.angle(V), axis=0)
        lost = None
        for i in range(len(t)):
            in_service = [k for k in range(len(units)) if k not in
                          [tp for tp in topologies if tp.start <= t[i] + 1e-12][-1].tripped]
            angles = delta[i, in_service]
            angles = angles[np.isfinite(angles)]
            if len(angles) and np.ptp(angles) >= math.pi:
                lost = float(t[i])
                break
        nan = np.full_like(delta, np.nan)
        field = {}
        for k, u in enumerate(units):
            name = u.machine.component.ports.input("field_voltage")
            if name is not None:
                field.setdefault(name, nan.copy())[:, k] = Efd[:, k]
        result = GridResult(time=t, states={"delta": delta, "omega": omega}, rotor_angle=delta, Vs=np.abs(V_gen),
                            theta_vs=theta_bus[:, gen_cols], P=P, Q=Q, V_bus=np.abs(V), theta_bus=theta_bus,
                            stable=lost is None, loss_of_synchronism_s=lost,
                            events=tuple((tp.start, tp.description) for tp in topologies[1:]),
                            gen_buses=self.case.generator_buses, buses=self.case.buses, machine_inputs=field)
        return result, {"total_s": total, "steps": len(t) - 1}

    def _on_grid(self, t, table, switches, stop) -> tuple:
        """ANDES' rows (times t [n], values table [n, m]) as the other runners give theirs: a row at
        every multiple of `rows` up to `stop` (the last one `stop`), linear between ANDES' own
        rows of the same topology (never across a switching), and ANDES' first row after each
        switching at its own time. ANDES steps to a switching time te - 1e-4, te, te + 1e-4 and on
        from there, off the multiples of its step; its rows up to te hold the state before the switch
        (so a multiple at te itself has no row: it is an event time, where runs are not compared)."""
        n = int(math.ceil(stop / self.rows - 1e-9))
        grid = np.minimum(np.arange(n + 1) * self.rows, stop)
        bounds = [0.0] + list(switches) + [math.inf]
        times, rows = [], []
        for a, b in zip(bounds[:-1], bounds[1:]):
            inside = ((t > a + 1e-9) | ((a == 0.0) & (t >= 0.0))) & (t < b - 1e-9)
            ts, part = t[inside], table[inside]
            if not len(ts):
                continue
            if a > 0.0:
                times.append(ts[:1])
                rows.append(part[:1])
            points = grid[(grid >= ts[0] - 1e-9) & (grid <= ts[-1] + 1e-9) & (grid >= a - 1e-9) & (grid < b)]
            points = points[np.abs(points - a) > 1e-9] if a > 0.0 else points
            j = np.clip(np.searchsorted(ts, points), 1, max(len(ts) - 1, 1))
            if len(ts) == 1:
                values = np.repeat(part, len(points), axis=0)
            else:
                w = np.clip((points - ts[j - 1]) / (ts[j] - ts[j - 1]), 0.0, 1.0)[:, None]
                values = (1.0 - w) * part[j - 1] + w * part[j]
            times.append(points)
            rows.append(values)
        t_out, table_out = np.concatenate(times), np.concatenate(rows)
        sort = np.argsort(t_out, kind="stable")
        return t_out[sort], table_out[sort]

    def close(self):
        pass
