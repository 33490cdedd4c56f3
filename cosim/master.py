"""The grid co-simulation master: one machine FMU and one exciter FMU per generator, coupled through
the network, which is solved at every communication point.

Coupling, over each communication step [t0, t1] (h = t1 - t0):

1. The bus voltages V(t0) are known (the network solved at t0), and an end guess V(t1): extrapolated
   linearly from the last two communication points, or held after an event.
2. Each exciter gets its terminal voltage Vt = |V + (Re + jXep) I| linear from Vt(t0) to the guess
   Vt(t1) and steps; its field voltage Efd(t1) comes back. Each machine gets its bus voltage (Vs,
   theta_vs) linear from V(t0) to the guess V(t1) and Efd linear from Efd(t0) to Efd(t1), and steps.
   "Linear" is fmi2SetRealInputDerivatives where the FMU can interpolate its inputs; an FMU that
   cannot gets the mean of the start and end values held over the step (the midpoint rule: the same
   second order in h for what the step integrates).
3. The network is solved at t1 with the machines' new states: each machine's bus current is
   I(V) (outputs I_re, I_im), and Y_red V = I(V) at the generator buses is solved by Newton with the
   FMUs' directional derivatives dI/d(Vs, theta_vs) (central differences for an FMU without them).
   SM4's current is affine in V for given states, so one Newton step solves it; the next confirms.
4. If V(t1) moved by more than `tolerance` from the guess, the FMUs are set back to t0
   (fmi2SetFMUstate) and the step is done again from 2 with V(t1) as the guess: at most `passes`
   passes. Converged, the inputs over the step are linear between two consistent network solutions:
   the coupling error is second order in h (held voltages are first order: degrees of rotor angle
   at h = 10 ms after a fault; see docs/grid.md for the measured numbers).

Events (a fault, its clearing, a branch opening: reference_models.grid.contingency) happen at
communication points: the step before an event is shortened to end there. At an event time the
network is solved twice: in the old topology (the end of the step before) and in the new one (the
start of the step after; the inputs jump there). The row recorded at an event time is the one after.

The master runs on fmpy's FMU2Slave (slave.py). Every FMU is rewound to its initial state between
runs (fmi2SetFMUstate), so one master serves the many runs of a critical-clearing-time bisection.
"""
from __future__ import annotations

import cmath
import math
import time
from dataclasses import dataclass, field

import numpy as np

from reference_models.grid import wscc9
from reference_models.grid.contingency import Contingency
from reference_models.grid.monolithic import GridResult, WSCC9, system
from reference_models.ieee1 import IEEE1
from reference_models.sm4 import SM4

from .fmu import CouplingError, Slave

MACHINE_INPUTS = ("Vs", "theta_vs", "Pm", "Efd")
MACHINE_OUTPUTS = ("delta", "omega", "Ed_p", "Eq_p", "I_re", "I_im")
EXCITER_INPUTS = ("Vt", "Vref")
EXCITER_OUTPUTS = ("Efd", "RF", "VR")
_I = (4, 5)  # rows of I_re, I_im in MACHINE_OUTPUTS


COUPLINGS = ("iterated", "extrapolated", "held")


@dataclass(frozen=True)
class MasterSettings:
    """step [s]: the communication step; coupling: `iterated` (inputs linear to a consistent end,
    the step redone up to `passes` times), `extrapolated` (inputs linear to the end guess, one
    pass) or `held` (the inputs at the step's start held over it, one pass: what a plain master
    does); passes: the most passes of an iterated step; tolerance [pu]: the change of the end
    voltages below which a step is consistent; newton_tolerance [pu]: the network's current
    mismatch that ends Newton; stop_at_loss: end a run when two rotor angles are pi apart (a
    critical-clearing-time run needs no more)."""

    step: float = 0.01
    coupling: str = "iterated"
    passes: int = 3
    tolerance: float = 1e-6
    newton_tolerance: float = 1e-10
    newton_iterations: int = 20
    stop_at_loss: bool = False

    def __post_init__(self):
        if not (isinstance(self.step, (int, float)) and math.isfinite(self.step) and 1e-5 <= self.step <= 1.0):
            raise ValueError(f"the communication step must be a time from 1e-5 to 1 s, got {self.step!r}")
        if self.coupling not in COUPLINGS:
            raise ValueError(f"coupling must be one of {', '.join(COUPLINGS)}, got {self.coupling!r}")
        if not (isinstance(self.passes, int) and 1 <= self.passes <= 20):
            raise ValueError(f"passes must be an integer from 1 to 20, got {self.passes!r}")
        if not (self.tolerance > 0 and self.newton_tolerance > 0):
            raise ValueError("tolerances must be positive")


@dataclass
class Timing:
    """Where a run's wall time went [s]: FMU steps (inputs, derivatives, fmi2DoStep), network solves
    (Newton with the FMUs' outputs and derivatives), rollback (fmi2Get/SetFMUstate), the rest
    (`overhead`: the master's own bookkeeping); counts of steps, passes and Newton iterations."""

    total_s: float = 0.0
    fmu_step_s: float = 0.0
    network_s: float = 0.0
    rollback_s: float = 0.0
    steps: int = 0
    passes: int = 0
    newton_iterations: int = 0

    @property
    def overhead_s(self) -> float:
        return self.total_s - self.fmu_step_s - self.network_s - self.rollback_s

    def to_dict(self) -> dict:
        return {"total_s": self.total_s, "fmu_step_s": self.fmu_step_s, "network_s": self.network_s,
                "rollback_s": self.rollback_s, "overhead_s": self.overhead_s, "steps": self.steps,
                "passes": self.passes, "newton_iterations": self.newton_iterations}


@dataclass
class CosimResult:
    """A co-simulation run: `result` (monolithic.GridResult, one row per communication point), its
    `timing`, per generator the FMU kind and what the FMUs logged (status, message), and the
    master's notes on how it coupled them."""

    result: GridResult
    timing: Timing
    kinds: tuple
    messages: dict = field(default_factory=dict)
    notes: tuple = ()


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


class GridMaster:
    """The master over the FMUs of every generator of `grid` (monolithic.WSCC9: network, load flow,
    start values); files: cosim.fmus.GeneratorFiles per generator, in GENERATOR_BUSES order.
    Use as a context manager, or call close()."""

    def __init__(self, files, grid: WSCC9 | None = None, settings: MasterSettings = MasterSettings()):
        self.grid = grid if grid is not None else system()
        self.settings = settings
        self.files = tuple(files)
        if [f.bus for f in self.files] != list(wscc9.GENERATOR_BUSES):
            raise CouplingError(f"one FMU pair per generator bus {wscc9.GENERATOR_BUSES} is needed")
        self.kinds = tuple(f.kind for f in self.files)
        self.machines, self.exciters = [], []
        self._networks = {}
        self._Z = [complex(p.Re, p.Xep) for p in self.grid.machines]  # behind which Vt is measured
        try:
            for k, f in enumerate(self.files):
                x0 = self.grid.x0
                ms, es = x0[self.grid.machine_slice(k)], x0[self.grid.exciter_slice(k)]
                op = self.grid.flow.generator(f.bus)
                start = {f"{n}0": float(v) for n, v in zip(SM4.state_names, ms)}
                start.update(Vs=op["V"], theta_vs=op["theta"], Pm=float(self.grid.Pm[k]), Efd=float(self.grid.Efd0[k]))
                self.machines.append(Slave(f.machine, f"machine at bus {f.bus}", MACHINE_INPUTS, MACHINE_OUTPUTS, start))
                start = {f"{n}0": float(v) for n, v in zip(IEEE1.state_names, es)}
                start.update(Vt=op["V"], Vref=float(self.grid.Vref[k]))
                self.exciters.append(Slave(f.exciter, f"exciter at bus {f.bus}", EXCITER_INPUTS, EXCITER_OUTPUTS, start))
        except BaseException:
            self.close()
            raise
        self.rolls_back = all(s.rolls_back for s in self.machines + self.exciters)
        self.notes = ()
        if not self.rolls_back and settings.coupling == "iterated" and settings.passes > 1:
            names = ", ".join(s.model_name for s in self.machines + self.exciters if not s.rolls_back)
            self.notes = (f"{names} cannot restore an FMU state: steps are not iterated (one pass, inputs "
                          "linear to the extrapolated end voltage)",)
        self._Pm = [float(p) for p in self.grid.Pm]
        self._runs = 0

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self) -> None:
        for s in self.machines + self.exciters:
            s.close()
        self.machines, self.exciters = [], []

    def network(self, topology):
        key = (topology.fault_bus, topology.open)
        if key not in self._networks:
            self._networks[key] = self.grid.network(topology.fault_bus, self._fault_impedance, topology.open)
        return self._networks[key]

    def _solve(self, network, V, Efd, theta_ref, timing: Timing):
        """The generator-bus voltages [3] (complex) at which the machines' currents I(V) and the
        network agree, Newton from V; the machines are left at those inputs. Returns (V, I, theta,
        the machines' states [3, 4] as their outputs read them)."""
        started = time.perf_counter()
        s = self.settings
        n = len(self.machines)
        v = np.empty(2 * n)
        v[0::2], v[1::2] = V.real, V.imag
        Y = network.Y_real
        i_vec = np.empty(2 * n)
        theta = np.empty(n)
        states = np.empty((n, 4))
        for iteration in range(s.newton_iterations + 1):
            values = v.tolist()
            for k, m in enumerate(self.machines):
                re, im = values[2 * k], values[2 * k + 1]
                theta[k] = theta_ref[k] + _wrap(math.atan2(im, re) - theta_ref[k])
                m.set_inputs((math.hypot(re, im), theta[k], self._Pm[k], Efd[k]))
                out = m.outputs()
                states[k] = out[:4]
                i_vec[2 * k], i_vec[2 * k + 1] = out[4], out[5]
            F = Y @ v - i_vec
            mismatch = max(map(abs, F.tolist()))
            if mismatch < s.newton_tolerance or iteration == s.newton_iterations:
                break
            M = Y.copy()
            for k, m in enumerate(self.machines):
                re, im = values[2 * k], values[2 * k + 1]
                Vs = math.hypot(re, im)
                c, sn = re / Vs, im / Vs
                (a, b), (d, e) = m.output_jacobian(_I, (0, 1))  # d(I_re, I_im) / d(Vs, theta_vs)
                # chain rule with d(Vs, theta) / d(V_re, V_im) = [[c, sn], [-sn / Vs, c / Vs]]
                r = 2 * k
                M[r, r] -= a * c - b * sn / Vs
                M[r, r + 1] -= a * sn + b * c / Vs
                M[r + 1, r] -= d * c - e * sn / Vs
                M[r + 1, r + 1] -= d * sn + e * c / Vs
            v -= np.linalg.solve(M, F)
            timing.newton_iterations += 1
        if not mismatch < max(s.newton_tolerance, 1e-8):
            raise CouplingError(f"the network solve did not converge (current mismatch {mismatch:.3g} pu)")
        timing.network_s += time.perf_counter() - started
        return v[0::2] + 1j * v[1::2], i_vec[0::2] + 1j * i_vec[1::2], theta, states

    def _terminal(self, V, I):
        return np.array([abs(V[k] + self._Z[k] * I[k]) for k in range(len(V))])

    def _step(self, t0, h, V0, theta0, Vt0, Efd0, V1, theta1, Vt1, timing):
        """One pass over [t0, t0 + h] with the inputs linear from (V0, Vt0, Efd0) to (V1, Vt1) and
        Efd to the exciters' new values (held at the start values with coupling "held"); returns
        the exciters' outputs (Efd, RF, VR) at t0 + h [3, 3]."""
        started = time.perf_counter()
        n = len(self.machines)
        exciter = np.empty((n, len(EXCITER_OUTPUTS)))
        held = self.settings.coupling == "held"
        for k in range(n):
            e, m = self.exciters[k], self.machines[k]
            Vref = self.grid.Vref[k]
            if held:
                e.set_inputs((Vt0[k], Vref))
                if e.interpolates:
                    e.set_input_derivatives((0.0, 0.0))
            elif e.interpolates:
                e.set_inputs((Vt0[k], Vref))
                e.set_input_derivatives(((Vt1[k] - Vt0[k]) / h, 0.0))
            else:
                e.set_inputs((0.5 * (Vt0[k] + Vt1[k]), Vref))
            e.step(t0, h)
            exciter[k] = e.outputs()
            Vs0, Vs1 = abs(V0[k]), abs(V1[k])
            Pm = self.grid.Pm[k]
            if held:
                m.set_inputs((Vs0, theta0[k], Pm, Efd0[k]))
                if m.interpolates:
                    m.set_input_derivatives((0.0, 0.0, 0.0, 0.0))
            elif m.interpolates:
                m.set_inputs((Vs0, theta0[k], Pm, Efd0[k]))
                m.set_input_derivatives(((Vs1 - Vs0) / h, (theta1[k] - theta0[k]) / h, 0.0, (exciter[k, 0] - Efd0[k]) / h))
            else:
                m.set_inputs((0.5 * (Vs0 + Vs1), 0.5 * (theta0[k] + theta1[k]), Pm, 0.5 * (Efd0[k] + exciter[k, 0])))
            m.step(t0, h)
        timing.fmu_step_s += time.perf_counter() - started
        return exciter

    def run(self, contingency: Contingency, stop: float = 5.0) -> CosimResult:
        """The system from its load-flow equilibrium through `contingency` until `stop` [s]."""
        if not (isinstance(stop, (int, float)) and math.isfinite(stop) and stop > 0):
            raise ValueError(f"stop must be a positive time, got {stop!r}")
        s = self.settings
        timing = Timing()
        started = time.perf_counter()
        if self._runs:
            for slave in self.machines + self.exciters:
                slave.rewind()
        self._runs += 1
        self._fault_impedance = contingency.fault_impedance
        topologies = contingency.topologies(stop)
        n_steps = int(math.ceil(stop / s.step - 1e-9))
        grid_points = [min(k * s.step, stop) for k in range(n_steps + 1)]
        points = sorted(set(grid_points) | {tp.start for tp in topologies[1:]})
        points = [p for i, p in enumerate(points) if i == 0 or p - points[i - 1] > 1e-9]  # no sliver steps
        change_at = {}
        for tp in topologies[1:]:
            nearest = min(points, key=lambda p: abs(p - tp.start))
            change_at[nearest] = tp
        topology = topologies[0]
        n = len(self.machines)
        state = [m.outputs() for m in self.machines]
        theta_ref = np.array([float(x[0]) for x in state])  # continuous angles near the rotor angles
        V = self.grid.flow.V_complex[[wscc9.bus_index(b) for b in wscc9.GENERATOR_BUSES]].copy()
        Efd = np.array(self.grid.Efd0, dtype=float)
        V, I, theta, machine = self._solve(self.network(topology), V, Efd, theta_ref, timing)
        exciter = np.array([e.outputs() for e in self.exciters])
        rows = []
        lost = None
        V_prev, h_prev = None, None
        rows.append(self._row(0.0, V, I, theta, machine, exciter))
        for j in range(1, len(points)):
            t0, t1 = points[j - 1], points[j]
            h = t1 - t0
            Vt0 = self._terminal(V, I)
            if V_prev is not None and s.coupling != "held":
                V1 = V + (V - V_prev) * (h / h_prev)
            else:
                V1 = V.copy()
            theta1 = np.array([theta[k] + _wrap(cmath.phase(V1[k]) - theta[k]) for k in range(n)])
            I1 = I
            saved = None
            passes = s.passes if s.coupling == "iterated" else 1
            if passes > 1 and self.rolls_back:
                t_save = time.perf_counter()
                saved = [slave.save() for slave in self.machines + self.exciters]
                timing.rollback_s += time.perf_counter() - t_save
            try:
                for p in range(passes if saved is not None else 1):
                    if p > 0:
                        t_save = time.perf_counter()
                        for slave, snap in zip(self.machines + self.exciters, saved):
                            slave.restore(snap)
                        timing.rollback_s += time.perf_counter() - t_save
                    Vt1 = self._terminal(V1, I1)
                    exciter = self._step(t0, h, V, theta, Vt0, Efd, V1, theta1, Vt1, timing)
                    Efd1 = exciter[:, 0].copy()
                    timing.passes += 1
                    new_V, I1, new_theta, machine = self._solve(self.network(topology), V1, Efd1, theta1, timing)
                    change = float(np.max(np.abs(new_V - V1)))
                    V1, theta1 = new_V, new_theta
                    if change < s.tolerance:
                        break
            finally:
                if saved is not None:
                    for slave, snap in zip(self.machines + self.exciters, saved):
                        slave.free(snap)
            timing.steps += 1
            V_prev, h_prev = V, h
            V, I, theta, Efd = V1, I1, theta1, Efd1
            if t1 in change_at:
                topology = change_at[t1]
                V, I, theta, machine = self._solve(self.network(topology), V, Efd, theta, timing)
                V_prev = None  # no extrapolation across the jump
            rows.append(self._row(t1, V, I, theta, machine, exciter))
            if lost is None:
                lost = _loss_time(rows)
                if lost is not None and s.stop_at_loss:
                    break
        timing.total_s = time.perf_counter() - started
        result = self._result(rows, topologies, lost)
        messages = {f.bus: list(m.messages) + list(e.messages)
                    for f, m, e in zip(self.files, self.machines, self.exciters)}
        return CosimResult(result=result, timing=timing, kinds=self.kinds, messages=messages, notes=self.notes)

    @staticmethod
    def _row(t, V, I, theta, machine, exciter) -> dict:
        return {"time": t, "machine": machine, "exciter": exciter, "V": V.copy(), "I": I.copy(), "theta": theta.copy()}

    def _result(self, rows, topologies, lost) -> GridResult:
        time_ = np.array([r["time"] for r in rows])
        machine = np.stack([r["machine"] for r in rows])  # [n, 3, 4]
        exciter = np.stack([r["exciter"] for r in rows])  # [n, 3, 3]
        V_gen = np.stack([r["V"] for r in rows])
        I_gen = np.stack([r["I"] for r in rows])
        S = V_gen * np.conj(I_gen)
        # bus voltages: the recovery of the topology in force at each row
        V_bus = np.empty((len(rows), len(wscc9.BUSES)), dtype=complex)
        for i, t in enumerate(time_):
            tp = [tp for tp in topologies if tp.start <= t + 1e-12][-1]
            V_bus[i] = self.network(tp).recovery @ V_gen[i]
        theta_vs = np.stack([r["theta"] for r in rows])
        theta_bus = np.unwrap(np.angle(V_bus), axis=0)
        gen_rows = [wscc9.bus_index(b) for b in wscc9.GENERATOR_BUSES]
        theta_bus[:, gen_rows] = theta_vs
        return GridResult(time=time_, delta=machine[:, :, 0], omega=machine[:, :, 1], Ed_p=machine[:, :, 2],
                          Eq_p=machine[:, :, 3], Efd=exciter[:, :, 0], RF=exciter[:, :, 1], VR=exciter[:, :, 2],
                          Vs=np.abs(V_gen), theta_vs=theta_vs, P=S.real, Q=S.imag, V_bus=np.abs(V_bus),
                          theta_bus=theta_bus, Pm=np.array(self.grid.Pm), Vref=np.array(self.grid.Vref),
                          stable=lost is None, loss_of_synchronism_s=lost,
                          events=tuple((tp.start, tp.description) for tp in topologies[1:]), exciters=True)


def _loss_time(rows) -> float | None:
    """The time two rotor angles first got pi apart, linear between the last two rows; None if not."""
    def spread(row):
        d = row["machine"][:, 0]
        return float(np.max(d) - np.min(d))

    now = spread(rows[-1])
    if now <= math.pi:
        return None
    if len(rows) < 2:
        return rows[-1]["time"]
    before = spread(rows[-2])
    t0, t1 = rows[-2]["time"], rows[-1]["time"]
    return t0 + (t1 - t0) * (math.pi - before) / (now - before) if now > before else t1
