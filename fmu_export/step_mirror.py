"""The surrogate FMU's step semantics in Python: what its C (fmu_export/c/: the window, the
corrections) does per step, with the operator's network evaluated by onnxruntime
(surrogate.operator.Operator).

Tests compare the compiled FMU with this mirror step by step; benchmarks use it to evaluate the
operator "as the FMU does" without the FMU. It follows the C where the C is generic: the sizes of the
component (n_x states, n_u inputs), its window frame (the operator's `frame`, a
reference_models.drift.Frame, or None: the identity), its affine states (`component.affine_states`:
the exact swing step for SM4's omega) and its state scales (`component.state_scales`: the reach of the
rest correction at rest_radius = 1). The machine's parameters are the operator's (metadata `params`),
else the component's defaults, as the FMU's generated equations are.

The window frame (reference_models/drift.py): the state stays raw; the network sees the window in its
frame. A window starting at time t_w from state x_w under the input u_w (the input the FMU holds
then: at a rollover, that of the step that just ended; at initialisation, the start values or what
the master set in initialization mode) has a = u_w's first angle input, c = x_w's speed state (its offset from rest) and
shift = a + period floor((x_w's first angle state - a) / period + 1/2). In the frame, inputs at window
time tau are u - a R - c (R s tau + T) and states x - (shift + c s tau) A - c W (R: 1 for angle inputs, T:
the torque coefficients, e.g. D on SM4's Pm, A: 1 for angle states, W: 1 for the speed state, s: the
frame's speed scale, 1 for SM4's rad/s, 2 pi fn for a per-unit speed whose c is its offset from 1).

Per communication step (h, u) [s, u in the component's input units] (docs/fmu.md, "A step"), with the
inputs' derivatives du over it (fmi2SetRealInputDerivatives; 0: held), u(s) = u + du (s - t):

* an input change above restart_jump (in any input's unit) starts a new window at once, from the
  state reached, with every sensor slot at the new input: the step's u against the value the
  previous step ended at, u + du h of that step; a held angle input (du = 0 over the previous step)
  is compared after removing c R times the time since the last input was set, the turn of the frame;
* the step is cut at the window's end (rollover_horizon; the input there starts the new window,
  and its ramp goes on in it); each piece, from window time tau0 to tau, writes into the sensor
  slots from the current time on (slot k at window time s_k = k dt, dt = horizon / (n_sensors - 1))
  the input in the frame, u(min(s_k, tau)) - a R - c (R min(s_k, tau) + T): it ramps along its
  derivatives and with the turning frame until tau and holds that value after it (earlier slots keep
  what earlier steps wrote), and evaluates the network from the window's start state in the frame at
  tau; the state is the network's answer x_f + (shift + c tau) A + c W;
* rest correction (rest_radius > 0, operators whose FMU kernel splits branch and trunk), in the
  frame: each window subtracts w (G(x_rest, level held) - x_rest) from x_f, level the input held over
  the window's first step in the frame at tau = 0, x_rest its equilibrium (Newton from the window's
  start state in the frame), w = 1 - max_i |x_window_f,i - x_rest_i| / (rest_radius * state_scale_i)
  when positive;
* slow-mode correction (slow_weight > 0), on raw states and inputs: the slowest real mode of the
  right-hand side's Jacobian at the window start (inverse iteration, left and right eigenvectors l, r
  with l . r = 1); the slow coordinate l . x follows the trapezoid integral of l . f(x, u) over the
  window (u at each piece's start and end), and the state moves along r by slow_weight times its miss;
* exact affine step (swing_weight > 0), on raw states and inputs: each affine state x_i (dx_i/dt =
  g(x) - k x_i) is integrated exactly over the piece from its value at the piece's start, g linear in
  time between its values at the piece's start and end states (and inputs), and x_i moves
  swing_weight of the way to that solution, in the component's order (each end state reading the
  affine states before it as already moved);
* at the window's end a new window starts from the state there, under the input there.

The rest correction and the slow mode of a window take the input at its first step's start.

The diagnostics (residual, in_envelope, warnings) are not mirrored.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from reference_models.component import Component
from reference_models.drift import window_frame

TIME_EPS = 1e-9  # s: times closer than this are the same time (TIME_EPS in the C)
SETTINGS = ("rollover_horizon", "restart_jump", "rest_radius", "slow_weight", "swing_weight")


def fmu_settings(model_description) -> dict:
    """{setting: default} of a surrogate FMU: the start values of its parameters named in SETTINGS,
    from an fmpy ModelDescription (fmpy.read_model_description). Pass them on to StepMirror.run."""
    starts = {v.name: v.start for v in model_description.modelVariables}
    missing = [name for name in SETTINGS if starts.get(name) is None]
    if missing:
        raise ValueError(f"the model description has no parameter {', '.join(missing)} (not a surrogate FMU?)")
    return {name: float(starts[name]) for name in SETTINGS}


def jacobian(f, x, u) -> np.ndarray:
    """d f / d x [n_x, n_x] at state x [n_x] under input u [n_u], by central differences with steps
    1e-6 max(1, |x_j|) (as the C)."""
    x = np.asarray(x, dtype=float)
    J = np.empty((x.size, x.size))
    for j in range(x.size):
        d = 1e-6 * max(1.0, abs(x[j]))
        hi, lo = x.copy(), x.copy()
        hi[j] += d
        lo[j] -= d
        J[:, j] = (f(hi, u) - f(lo, u)) / (2.0 * d)
    return J


def lu_factor(A):
    """(F, perm) LU factors of A [n, n] with partial pivoting (row i of F is row perm[i] of A), or None
    when a pivot is below 1e-14 in magnitude (as the C)."""
    F, n = np.array(A, dtype=float), len(A)
    perm = np.arange(n)
    for c in range(n):
        pivot = c + int(np.argmax(np.abs(F[c:, c])))
        if not abs(F[pivot, c]) >= 1e-14:
            return None
        if pivot != c:
            F[[c, pivot]] = F[[pivot, c]]
            perm[[c, pivot]] = perm[[pivot, c]]
        F[c + 1:, c] /= F[c, c]
        F[c + 1:, c + 1:] -= np.outer(F[c + 1:, c], F[c, c + 1:])
    return F, perm


def lu_solve(factors, b) -> np.ndarray:
    """A^-1 b [n] from lu_factor's factors."""
    F, perm = factors
    x = np.asarray(b, dtype=float)[perm].copy()
    for i in range(len(x)):
        x[i] -= F[i, :i] @ x[:i]
    for i in reversed(range(len(x))):
        x[i] = (x[i] - F[i, i + 1:] @ x[i + 1:]) / F[i, i]
    return x


def equilibrium(f, x, u, iterations: int = 30):
    """The equilibrium [n_x] under the held input u nearest x (Newton on f from x, finite-difference
    Jacobian), or None when Newton does not reach sum |f| < 1e-12 within `iterations` (as the C)."""
    rest = np.array(x, dtype=float)
    for _ in range(iterations):
        rate = f(rest, u)
        norm = np.abs(rate).sum()
        if not np.isfinite(norm):
            return None
        if norm < 1e-12:
            return rest
        factors = lu_factor(jacobian(f, rest, u))
        if factors is None:
            return None
        rest = rest - lu_solve(factors, rate)
    return None


def slowest_mode(A, factors, iterations: int = 60):
    """The eigenvector [n] of A's eigenvalue of least magnitude by inverse iteration with A's LU
    factors (start from 1 down to 0.1, as the C's OPFMU_MODE_START; scaled by the largest entry,
    signed), or None unless it converged:
    |A v - lambda v| <= 1e-6 |lambda|, which needs that eigenvalue real and clearly the smallest."""
    n = len(A)
    v = np.array([1.0] if n == 1 else [round(1.0 - 0.9 * i / (n - 1), 12) for i in range(n)])
    for _ in range(iterations):
        w = lu_solve(factors, v)
        big = int(np.argmax(np.abs(w)))
        if not np.isfinite(w[big]) or w[big] == 0.0:
            return None
        v = w / w[big]
    Av = A @ v
    eigenvalue = (v @ Av) / (v @ v)
    return v if np.max(np.abs(Av - eigenvalue * v)) <= 1e-6 * abs(eigenvalue) else None


def slow_mode(f, x, u):
    """(l, r): left and right eigenvectors [n_x] (l . r = 1) of the slowest mode of f's Jacobian at
    (x, u), or None where the C finds none (no converged real slowest mode, or l . r ~ 0)."""
    J = jacobian(f, x, u)
    right_factors, left_factors = lu_factor(J), lu_factor(J.T)
    if right_factors is None or left_factors is None:
        return None
    r, l = slowest_mode(J, right_factors), slowest_mode(J.T, left_factors)
    if r is None or l is None:
        return None
    overlap = l @ r
    if not abs(overlap) > 1e-9:
        return None
    return l / overlap, r


def affine_drive(f, i: int, x, u) -> tuple[float, float]:
    """(g, k) of an affine state i, dx_i/dt = g - k x_i, at state x [n_x] under input u: k = -d f_i / d x_i
    by central differences (the piece it is on, for a piecewise affine state), g = f_i + k x_i."""
    x = np.array(x, dtype=float)
    d = 1e-6 * max(1.0, abs(x[i]))
    hi, lo = x.copy(), x.copy()
    hi[i] += d
    lo[i] -= d
    k = (f(lo, u)[i] - f(hi, u)[i]) / (2.0 * d)
    return f(x, u)[i] + k * x[i], k


def affine_step(value_start: float, g_start: float, g_end: float, k: float, h: float) -> float:
    """x_i after a step of h [s] from value_start, solving dx_i/dt = g - k x_i exactly for g linear in
    time from g_start to g_end (the trapezoid rule, also exact, where |k h| <= 1e-8)."""
    if not abs(k * h) > 1e-8:
        return value_start + 0.5 * h * (g_start + g_end)
    reach = -np.expm1(-k * h) / k  # integral of exp(-k (h - s)) over the step
    return np.exp(-k * h) * value_start + g_start * reach + (g_end - g_start) * (h - reach) / (k * h)


class StepMirror:
    """The surrogate FMU's steps for one operator, in Python.

    operator: a surrogate.operator.Operator or the path of an exported .onnx; component and params:
    default the machine its metadata names. The window frame is the operator's (`operator.frame`, as
    the FMU's config.h has it from the same metadata; None: the identity).
    """

    def __init__(self, operator, component: Component | None = None, params=None):
        if isinstance(operator, (str, Path)):
            from surrogate.operator import Operator

            operator = Operator.load(operator)
        self.operator = operator
        meta = operator.metadata
        self.component = component or operator.component
        self.params = operator.params if params is None else params
        self.n_sensors, self.horizon = operator.n_sensors, float(operator.horizon)
        self.sensor_dt = self.horizon / (self.n_sensors - 1)
        self.slot_times = np.arange(self.n_sensors) * self.sensor_dt  # s_k = k SENSOR_DT, as the C
        self.default_rollover = float(meta.get("rollover_horizon_s", self.horizon))
        self.rest_scale = np.asarray(self.component.state_scales, dtype=float)
        n_x, n_u = self.component.n_states, self.component.n_inputs
        self.frame = frame = getattr(operator, "frame", None)
        # the frame tables of config.h: R (angle inputs), T (torque inputs), A (angle states), W (speed)
        self.rates = frame.input_rates(n_u) if frame else np.zeros(n_u)
        self.scale = frame.speed_scale if frame else 1.0  # rad/s: the angle rate of one speed unit
        self.torques = frame.input_torques(n_u) if frame else np.zeros(n_u)
        self.angles, self.speed = np.zeros(n_x), np.zeros(n_x)
        if frame:
            self.angles[list(frame.angle_states)] = 1.0
            self.speed = frame.speed_mask(n_x)

    def f(self, x, u) -> np.ndarray:
        """The component's right-hand side dx/dt [n_x] at state x [n_x] under input u [n_u]."""
        return np.asarray(self.component.rhs(np.asarray(x, float), np.asarray(u, float), self.params), dtype=float)

    def window_frame(self, x, u) -> tuple[float, float, float]:
        """(a, shift, c) of a window starting at state x [n_x] under input u [n_u]
        (reference_models.drift.window_frame; zeros without a frame)."""
        if self.frame is None:
            return 0.0, 0.0, 0.0
        a, shift, c = window_frame(self.frame, np.asarray(x, float)[None], np.asarray(u, float)[None])
        return float(a[0]), float(shift[0]), float(c[0])

    def input_in_frame(self, window: dict, u, tau) -> np.ndarray:
        """u [n_u] at window time tau [s] (a number, or [k, 1] for k slots) in the window's frame:
        u - a R - c (R tau + T)."""
        return u - window["a"] * self.rates - window["c"] * (self.rates * self.scale * tau + self.torques)

    def network(self, x0_f, sensors_f, tau: float) -> np.ndarray:
        """The operator's network [n_x] at window time tau [s] from x0_f [n_x] and the sensor buffer
        [n_sensors, n_u], both in the window frame, and its answer in the frame (float32 evaluation
        by onnxruntime, the file's network graph without its frame nodes, as the FMU's kernel).

        Operator._network, not Operator.predict: predict takes physical values and takes the frame
        from their first sensor slot, while the FMU's frame is the window's (from the input it started
        with, which need not be the input of its first slot) and its slots hold held-then-ramped
        values; and the frame is done here in float64 before the cast to float32, as the C does it in
        double (predict casts physical angles of tens of rad first). No envelope check: the FMU flags
        that instead (not mirrored)."""
        x = self.operator._network(np.asarray(x0_f, np.float32)[None], np.ascontiguousarray(sensors_f, np.float32)[None],
                                   np.array([tau], np.float32))
        return x[0, 0].astype(float)

    def rest_correction(self, x_window_f, level, rest_radius: float):
        """(weight, x_rest) of a window starting at x_window_f [n_x] (in its frame) whose first step
        holds the input `level` [n_u] (in the frame at window time 0): x_rest the equilibrium of
        `level` held, in the frame (a machine turning with it); None where the correction does not
        apply (off, no equilibrium, too far from rest, or an operator the FMU evaluates whole)."""
        if not (rest_radius > 0 and self.operator.separable):
            return None
        rest = equilibrium(self.f, x_window_f, level)
        if rest is None:
            return None
        distance = np.max(np.abs(np.asarray(x_window_f, float) - rest) / (rest_radius * self.rest_scale))
        return (1.0 - distance, rest) if distance < 1.0 else None

    def start_window(self, time: float, x, u) -> dict:
        """A window starting at `time` from state x [n_x] under input u [n_u] (the FMU's start_window):
        its frame, its start state in the frame, every slot at u's level in the frame."""
        a, shift, c = self.window_frame(x, u)
        window = {"t": time, "x": np.array(x, dtype=float), "a": a, "shift": shift, "c": c, "corrections": None}
        window["x_f"] = window["x"] - shift * self.angles - c * self.speed
        window["sensors"] = np.tile(self.input_in_frame(window, u, 0.0), (self.n_sensors, 1))
        return window

    def run(self, x0, steps, rollover_horizon: float | None = None, restart_jump: float = 0.0,
            rest_radius: float = 0.0, slow_weight: float = 0.0, swing_weight: float = 0.0,
            u_init=None, derivatives=None) -> np.ndarray:
        """States [len(steps), n_x] at the end of each communication step (h, u_1, ..., u_n_u), from x0
        [n_x] at t = 0, with the FMU's settings (names and meanings of its parameters; default: the
        bare operator, windows of the operator's rollover horizon). fmu_settings(md) gives a surrogate
        FMU's defaults. u_init [n_u]: the inputs the FMU holds when it is initialised, which give the
        first window its frame: its start values (default), or what the master set in initialization
        mode (fmpy's simulate_fmu sets the first input row there). derivatives [len(steps), n_u]: the
        inputs' first derivatives over each step, as set by fmi2SetRealInputDerivatives (default:
        all 0, the inputs held)."""
        n_u = self.component.n_inputs
        horizon = float(rollover_horizon or self.default_rollover)
        steps = [(float(s[0]), np.asarray(s[1:], dtype=float)) for s in steps]
        if any(u.shape != (n_u,) for _, u in steps):
            raise ValueError(f"each step is (h, {', '.join(self.component.input_names)})")
        rates = np.zeros((len(steps), n_u)) if derivatives is None else np.asarray(derivatives, dtype=float)
        if rates.shape != (len(steps), n_u):
            raise ValueError(f"derivatives must be [{len(steps)}, {n_u}]: one row of input derivatives per step")
        u_init = np.asarray(self.component.start_inputs if u_init is None else u_init, dtype=float)
        if u_init.shape != (n_u,):
            raise ValueError(f"u_init must hold {n_u} inputs ({', '.join(self.component.input_names)})")
        t, x = 0.0, np.array(x0, dtype=float)
        window = self.start_window(0.0, x, u_init)
        last_u, input_time = u_init, 0.0  # the input written last and the time the last step started
        end_u, end_du = u_init, np.zeros(n_u)  # the inputs the last step ended at, their derivatives over it
        out = []
        for (h, u_step), du in zip(steps, rates):
            if restart_jump > 0 and t > window["t"] + TIME_EPS:
                turned = np.where(end_du != 0, 0.0, window["c"] * self.rates * self.scale * (t - input_time))  # a held angle
                if np.max(np.abs(u_step - end_u - turned)) > restart_jump:  # turning with the frame is no jump
                    window = self.start_window(t, x, u_step)
            if t < window["t"] + TIME_EPS and not np.array_equal(u_step, last_u):
                window = self.start_window(t, x, u_step)  # a window not run yet takes its first step's input
                last_u = u_step
            input_time, step_start, stop = t, t, t + h
            u, u_stop = u_step, np.where(du != 0, u_step + du * h, u_step)  # u: the input at t
            while t < stop - TIME_EPS:
                end = min(stop, window["t"] + horizon)
                # the input at the piece's end (bit for bit the step's where du = 0)
                u_end = u_stop if end >= stop else np.where(du != 0, u_step + du * (end - step_start), u_step)
                first = min(max(int(np.ceil((t - window["t"]) / self.sensor_dt - 1e-6)), 0), self.n_sensors)
                if window["corrections"] is None:  # for the input at the start of the window's first step
                    level = self.input_in_frame(window, u, 0.0)
                    window["corrections"] = {
                        "rest": self.rest_correction(window["x_f"], level, rest_radius),
                        "rest_sensors": np.tile(level, (self.n_sensors, 1)),
                        "slow": slow_mode(self.f, window["x"], u) if slow_weight > 0 else None,
                        "slow_integral": 0.0}
                fix = window["corrections"]
                slow = fix["slow"]
                rate_start = slow[0] @ self.f(x, u) if slow else 0.0
                x_start = x.copy()
                drives = {i: affine_drive(self.f, i, x, u) for i in self.component.affine_states} \
                    if swing_weight > 0 else {}
                tau0, tau = t - window["t"], min(end - window["t"], self.horizon)
                # slots from the current time on: u in the frame, ramping along du and with the frame until
                # tau, then held
                s = np.minimum(self.slot_times[first:], tau)[:, None]
                ramp = np.where(du != 0, u + du * (s - tau0), u)
                window["sensors"][first:] = self.input_in_frame(window, ramp, s)
                x_f = self.network(window["x_f"], window["sensors"], tau)
                if fix["rest"] is not None:
                    weight, rest = fix["rest"]
                    x_f = x_f - weight * (self.network(rest, fix["rest_sensors"], tau) - rest)
                x = x_f + (window["shift"] + window["c"] * self.scale * tau) * self.angles + window["c"] * self.speed
                if slow:
                    l, r = slow
                    fix["slow_integral"] += 0.5 * (end - t) * (rate_start + l @ self.f(x, u_end))
                    x = x + slow_weight * (l @ window["x"] + fix["slow_integral"] - l @ x) * r
                for i, (g_start, k) in drives.items():  # k is the start's, so g at the end is f_i + k x_i;
                    g_end = self.f(x, u_end)[i] + k * x[i]  # in order, each reading the exact ones before it
                    x[i] += swing_weight * (affine_step(x_start[i], g_start, g_end, k, end - t) - x[i])
                last_u, t, u = u, end, u_end
                if not np.all(np.isfinite(x)):
                    raise FloatingPointError(f"t = {t:.6g} s: the operator returned a non-finite state")
                if t >= window["t"] + horizon - TIME_EPS:
                    window = self.start_window(t, x, u)
                    last_u = u
            t = stop
            end_u, end_du = u_stop, du
            out.append(x.copy())
        return np.array(out).reshape(len(steps), self.component.n_states)
