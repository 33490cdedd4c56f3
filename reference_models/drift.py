"""The drift symmetry of a component, and the window frame the operators work in.

A machine in a network sees its angles drift (every angle of the network turns with the system's
speed) and its speed drift (with no governors and D = 0 every machine speeds up together during a
fault and keeps the gain). SM4's equations see the rotor angle delta and the bus angle theta_vs
only through delta - theta_vs (2 pi periodic), and the speed omega only through d delta/dt = omega
and the damping torque D omega. So for any constants a and c, with
    delta_f(t) = delta(t) - a - c t,   theta_f(t) = theta_vs(t) - a - c t,
    omega_f(t) = omega(t) - c,         Pm_f(t) = Pm(t) - D c,
(delta_f, omega_f, Ed_p, Eq_p) solves the same equations under (Vs, theta_f, Pm_f, Efd).

An operator therefore works in the frame of its window: a is the first angle input at the window
start (theta_vs(0): theta_f starts at 0), c the speed at the window start, and the angle states are
taken modulo the period nearest to a (delta_f(0) = delta(0) - theta_vs(0) in [-pi, pi)). Where the
speed carries no torque (D = 0) c is the speed itself (omega_f starts at 0) and the frame removes
any speed offset exactly. Where it does (D > 0) the offset is physics, not a symmetry, and c is the
speed rounded to whole steps `speed_step` (2 rad/s for SM4): a machine near rest keeps its speed as
a state (omega_f(0) in [-1, 1) rad/s), which the network learns far better than the same speed
passed on as a torque D c and a ramp of the bus angle (on the paper's families it halves the MSE,
all of it in omega), while a machine whose speed has drifted by 12 rad/s is still brought back
into the envelope. The FMU's unchanged-input path also needs c = 0. What the network sees no
longer depends on the absolute angle or speed, so a machine whose angle has drifted by 30 rad or whose speed has drifted by 12 rad/s is as much inside the
trained envelope as one at rest at theta_vs = 0 (for D = 0; with D > 0 a drifted speed is a torque
D c, which stays an input). The transformation is exact: the operator's error does not change.

A component whose speed is in per unit (GENROU: omega = 1 at synchronous speed, d delta/dt =
2 pi fn (omega - 1)) declares the speed's rest value (`speed_rest`, 1) and the angle rate one speed
unit gives (`speed_scale`, 2 pi fn rad/s: a factor times parameters). The frame speed c is then
taken from the speed's offset from rest (c = omega(0) - 1 where the speed carries no torque, so
omega_f starts at 1), the angles ramp at speed_scale c, and the torque inputs drop by k c. With
the defaults (scale 1, rest 0) this is the frame above, number for number.

A component whose equations turn with the network but read their speed as physics (a sub-system's
frequency relays and droops: reference_models.models.subsystem) has no speed symmetry
(`speed_state` None): its frame only turns (c = 0), which removes any angle offset exactly.

Arrays: x0 [N, n_x], u [N, S, n_u] at window times s [S] (s[0] = 0), x [N, M, n_x] at times t [M].
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Drift:
    """Which states and inputs are angles [rad], which state is their speed (d angle/dt =
    speed_scale (speed - speed_rest)), which inputs carry a torque k c under a speed offset c
    (input index, name of the parameter k), and the period of the equations in the angle
    differences. speed_scale: a number followed by parameter names whose product is the angle rate
    [rad/s] of one speed unit ((1.0,): the speed is in rad/s); speed_rest: the speed at which the
    angles stand still (0 for a deviation, 1 for a per-unit speed)."""

    angle_states: tuple
    angle_inputs: tuple
    speed_state: int | None  # None: the equations have no speed symmetry, the frame only turns (c = 0)
    torque_inputs: tuple = ()
    period: float = 2.0 * math.pi
    speed_step: float = 0.0  # speed units: the frame's speed in whole steps where it carries a torque (0: exact)
    speed_scale: tuple = (1.0,)
    speed_rest: float = 0.0

    def check(self, n_states: int, n_inputs: int) -> None:
        if not self.angle_inputs or not all(0 <= i < n_inputs for i in self.angle_inputs):
            raise ValueError("drift: angle_inputs must name at least one input, by index")
        if not all(0 <= i < n_states for i in self.angle_states) or not (
                self.speed_state is None or 0 <= self.speed_state < n_states):
            raise ValueError("drift: angle_states and speed_state must index states (speed_state None: no speed)")
        if not all(0 <= i < n_inputs for i, _ in self.torque_inputs) or not self.period > 0:
            raise ValueError("drift: torque_inputs must index inputs, and the period be positive")
        if not self.speed_step >= 0:
            raise ValueError("drift: speed_step must be >= 0")
        if not (self.speed_scale and isinstance(self.speed_scale[0], (int, float))
                and all(isinstance(n, str) for n in self.speed_scale[1:])):
            raise ValueError("drift: speed_scale must be a number followed by parameter names")


@dataclass(frozen=True)
class Frame:
    """A drift with the machine's torque coefficients resolved: the numbers the ONNX graph and the
    FMU's C use (`to_dict` is the operator file's `frame` metadata)."""

    angle_states: tuple
    angle_inputs: tuple
    speed_state: int | None  # None: a frame that only turns (c = 0)
    torque: tuple  # (input index, coefficient k): input_f = input - k c
    period: float
    speed_step: float = 0.0  # speed units: c = the start offset rounded to whole steps (0: c = the offset)
    speed_scale: float = 1.0  # rad/s: the angle rate of one speed unit
    speed_rest: float = 0.0  # the speed at which the angles stand still

    def to_dict(self) -> dict:
        """The frame's numbers; scale and rest only where they are not the defaults (1 and 0)."""
        data = {"angle_states": list(self.angle_states), "angle_inputs": list(self.angle_inputs),
                "speed_state": self.speed_state, "torque": [[int(i), float(k)] for i, k in self.torque],
                "period": self.period, "speed_step": self.speed_step}
        if self.speed_scale != 1.0 or self.speed_rest != 0.0:
            data.update(speed_scale=self.speed_scale, speed_rest=self.speed_rest)
        return data

    @classmethod
    def from_dict(cls, data: dict) -> "Frame":
        return cls(tuple(int(i) for i in data["angle_states"]), tuple(int(i) for i in data["angle_inputs"]),
                   None if data["speed_state"] is None else int(data["speed_state"]),
                   tuple((int(i), float(k)) for i, k in data["torque"]),
                   float(data["period"]), float(data.get("speed_step", 0.0)),
                   float(data.get("speed_scale", 1.0)), float(data.get("speed_rest", 0.0)))

    def speed_mask(self, n_states: int) -> np.ndarray:
        """[n_x]: 1 on the speed state (it drops by c in the frame), else 0; all 0 without one."""
        return _mask(n_states, () if self.speed_state is None else (self.speed_state,))

    def input_ramps(self, n_inputs: int) -> np.ndarray:
        """[n_u]: speed_scale for an angle input (what c t turns it by per second), else 0."""
        return self.speed_scale * self.input_rates(n_inputs)

    def input_rates(self, n_inputs: int) -> np.ndarray:
        """[n_u]: 1 for an angle input (it turns with the frame), else 0."""
        rates = np.zeros(n_inputs)
        rates[list(self.angle_inputs)] = 1.0
        return rates

    def input_torques(self, n_inputs: int) -> np.ndarray:
        """[n_u]: k for a torque input (it is lowered by k c in the frame), else 0."""
        torques = np.zeros(n_inputs)
        for i, k in self.torque:
            torques[i] += k
        return torques


def frame_of(drift: Drift, params) -> Frame:
    """The frame numbers of `drift` for the parameters `params` (the torque coefficients' values;
    the speed step only where one of them is nonzero; the speed scale's parameters' values)."""
    torque = tuple((int(i), float(getattr(params, name))) for i, name in drift.torque_inputs)
    step = float(drift.speed_step) if any(k != 0.0 for _, k in torque) else 0.0
    scale = float(drift.speed_scale[0])
    for name in drift.speed_scale[1:]:
        scale *= float(getattr(params, name))
    speed_state = None if drift.speed_state is None else int(drift.speed_state)
    return Frame(tuple(drift.angle_states), tuple(drift.angle_inputs), speed_state, torque,
                 float(drift.period), step, scale, float(drift.speed_rest))


def window_frame(frame: Frame, x0: np.ndarray, u0: np.ndarray):
    """(input shift a [N], state shift [N], speed c [N]) of windows starting at x0 [N, n_x] under
    inputs u0 [N, n_u] (the first sensor values): a = the first angle input; the angle states shift
    by a plus the whole periods that bring them nearest to it; c = the start speed's offset from
    rest (in whole speed steps where the frame has one; 0 where it has no speed state)."""
    a = u0[:, frame.angle_inputs[0]]
    c = np.zeros_like(a) if frame.speed_state is None else frame_speed(frame, x0[:, frame.speed_state])
    lead = x0[:, frame.angle_states[0]] - a if frame.angle_states else np.zeros_like(a)
    return a, a + frame.period * np.floor(lead / frame.period + 0.5), c


def frame_speed(frame: Frame, speed: np.ndarray) -> np.ndarray:
    """The frame's speed c [speed units] for window start speeds `speed` [N]: their offset from
    rest, in whole speed steps where the frame has them."""
    offset = speed - frame.speed_rest if frame.speed_rest else speed
    if frame.speed_step == 0.0:
        return offset
    return frame.speed_step * np.floor(offset / frame.speed_step + 0.5)


def to_frame(frame: Frame, x0: np.ndarray, u: np.ndarray, s: np.ndarray):
    """(x0_f [N, n_x], u_f [N, S, n_u], state shift [N], speed [N]): windows in their own frame."""
    a, shift, c = window_frame(frame, x0, u[:, 0])
    n_x, n_u = x0.shape[-1], u.shape[-1]
    x0_f = x0 - shift[:, None] * _mask(n_x, frame.angle_states) - c[:, None] * frame.speed_mask(n_x)
    u_f = (u - a[:, None, None] * frame.input_rates(n_u)
           - c[:, None, None] * (s[None, :, None] * frame.input_ramps(n_u) + frame.input_torques(n_u)))
    return x0_f, u_f, shift, c


def from_frame(frame: Frame, x_f: np.ndarray, t: np.ndarray, shift: np.ndarray, c: np.ndarray) -> np.ndarray:
    """States x [N, M, n_x] at window times t [M] from x_f [N, M, n_x] in the frame of to_frame."""
    n_x = x_f.shape[-1]
    angles = _mask(n_x, frame.angle_states)
    return (x_f + shift[:, None, None] * angles
            + c[:, None, None] * (t[None, :, None] * frame.speed_scale * angles + frame.speed_mask(n_x)))


def trajectories_to_frame(frame: Frame, x0: np.ndarray, u: np.ndarray, x: np.ndarray, s: np.ndarray):
    """A dataset's windows (x0 [N, n_x], u and x [N, S, .] on the grid s [S]) in their own frames."""
    x0_f, u_f, shift, c = to_frame(frame, x0, u, s)
    n_x = x0.shape[-1]
    angles = _mask(n_x, frame.angle_states)
    x_f = (x - shift[:, None, None] * angles
           - c[:, None, None] * (s[None, :, None] * frame.speed_scale * angles + frame.speed_mask(n_x)))
    return x0_f, u_f, x_f


def _mask(n: int, indices) -> np.ndarray:
    m = np.zeros(n)
    m[list(indices)] = 1.0
    return m
