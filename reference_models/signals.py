"""Time-varying inputs u(t) of a component, one closed-form channel per input.

Every channel is a closed-form function of time, so
the solver and the sensors see exactly the same signal, and lists its breakpoints (times where the
value or its slope jumps) so the solver can integrate piece by piece without stepping over them.
Channels take a float (the solver's hot path, plain `math`) or an array of times.
Signals serialise to plain dicts (stored with each dataset trajectory) and back.
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, fields

import numpy as np


def _ops(t):
    """The math module for a float time (fast scalar path), numpy for arrays."""
    return math if isinstance(t, float) else np


@dataclass(frozen=True)
class FirstOrder:
    """dy/dt = -k (y - y_ref) + A sin(w t), y(0) = y0 (paper eq. ode1); k, w in 1/s and rad/s."""

    y0: float
    k: float
    A: float
    w: float
    y_ref: float

    def __call__(self, t):
        m = _ops(t)
        kw2 = self.k**2 + self.w**2
        transient = (self.y0 - self.y_ref + self.A * self.w / kw2) * m.exp(-self.k * t)
        forced = self.A * (self.k * m.sin(self.w * t) - self.w * m.cos(self.w * t)) / kw2
        return self.y_ref + transient + forced

    def breakpoints(self):
        return ()


@dataclass(frozen=True)
class SecondOrder:
    """y'' + 2 zeta wn y' + wn^2 (y - y_ref) = 0, y(0) = y0, y'(0) = dy0 (paper eq. ode2, zeta < 1)."""

    y0: float
    dy0: float
    zeta: float
    wn: float
    y_ref: float

    def __call__(self, t):
        m = _ops(t)
        wd = self.wn * math.sqrt(1.0 - self.zeta**2)
        c1 = self.y0 - self.y_ref
        c2 = (self.dy0 + self.zeta * self.wn * c1) / wd
        return self.y_ref + m.exp(-self.zeta * self.wn * t) * (c1 * m.cos(wd * t) + c2 * m.sin(wd * t))

    def breakpoints(self):
        return ()


@dataclass(frozen=True)
class Piecewise:
    """Piecewise-constant level: values[i] on [times[i-1], times[i]) with times ascending."""

    values: tuple
    times: tuple

    def __call__(self, t):
        if isinstance(t, float):
            return float(self.values[bisect.bisect_right(self.times, t)])
        index = np.searchsorted(np.asarray(self.times), t, side="right")
        return np.asarray(self.values, dtype=float)[index]

    def breakpoints(self):
        return tuple(self.times)


@dataclass(frozen=True)
class Ramp:
    """y0 until t_start, linear to y1 at t_end, y1 after."""

    y0: float
    y1: float
    t_start: float
    t_end: float

    def __call__(self, t):
        frac = np.clip((t - self.t_start) / (self.t_end - self.t_start), 0.0, 1.0)
        return self.y0 + (self.y1 - self.y0) * float(frac) if isinstance(t, float) else (
            self.y0 + (self.y1 - self.y0) * frac
        )

    def breakpoints(self):
        return (self.t_start, self.t_end)


@dataclass(frozen=True)
class Dip:
    """Fault: y0 until t_fault, y_fault for `duration`, then recovery to y_post with time constant tau
    (tau = 0: instant)."""

    y0: float
    y_fault: float
    t_fault: float
    duration: float
    y_post: float
    tau: float

    def __call__(self, t):
        if isinstance(t, float):
            return float(self(np.array(t)))
        t_clear = self.t_fault + self.duration
        since = np.maximum(t - t_clear, 0.0)
        decay = np.exp(-since / self.tau) if self.tau > 0 else np.zeros_like(since)
        recovery = self.y_post + (self.y_fault - self.y_post) * decay
        return np.where(t < self.t_fault, self.y0, np.where(t < t_clear, self.y_fault, recovery))

    def breakpoints(self):
        return (self.t_fault, self.t_fault + self.duration)


@dataclass(frozen=True)
class Forcing:
    """An exciter's field voltage through a fault: y0 until t_fault, then rising towards `ceiling`
    with time constant tau_rise [s] for `duration`, then returning from where it got to towards
    y_post with time constant tau_return [s]."""

    y0: float
    ceiling: float
    t_fault: float
    duration: float
    tau_rise: float
    y_post: float
    tau_return: float

    def __call__(self, t):
        if isinstance(t, float):
            return float(self(np.array(t)))
        t_clear = self.t_fault + self.duration
        rise = self.y0 + (self.ceiling - self.y0) * -np.expm1(-np.clip(t - self.t_fault, 0.0, self.duration) / self.tau_rise)
        at_clear = self.y0 + (self.ceiling - self.y0) * -math.expm1(-self.duration / self.tau_rise)
        back = self.y_post + (at_clear - self.y_post) * np.exp(-np.maximum(t - t_clear, 0.0) / self.tau_return)
        return np.where(t < t_clear, rise, back)

    def breakpoints(self):
        return (self.t_fault, self.t_fault + self.duration)


@dataclass(frozen=True)
class Sawtooth:
    """y0 - rate (t - period floor(t / period)): an angle that a zero-order-hold master advances by
    rate * period every period [s], seen from a frame turning at `rate` [rad/s] (the drift of a
    network delivered at communication step `period`)."""

    y0: float
    rate: float
    period: float

    def __call__(self, t):
        m = _ops(t)
        return self.y0 - self.rate * (t - self.period * m.floor(t / self.period + 1e-9))

    def breakpoints(self):
        return ()

    def breakpoints_until(self, horizon: float):
        return tuple(np.arange(1, int(math.ceil(horizon / self.period)) + 1) * self.period)


@dataclass(frozen=True)
class Table:
    """Piecewise linear through (times[i], values[i]), times ascending; a time given twice is a jump
    (the second value holds from it on). Constant before the first and after the last time."""

    times: tuple
    values: tuple

    def __call__(self, t):
        if isinstance(t, float):  # the solver's hot path: plain Python
            times, values = self.times, self.values
            i = min(max(bisect.bisect_right(times, t) - 1, 0), len(times) - 1)
            j = min(i + 1, len(times) - 1)
            span = times[j] - times[i]
            frac = min(max((t - times[i]) / span, 0.0), 1.0) if span > 0 else 0.0
            return values[i] + frac * (values[j] - values[i])
        times, values = np.asarray(self.times, dtype=float), np.asarray(self.values, dtype=float)
        t = np.asarray(t, dtype=float)
        i = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 1)
        j = np.minimum(i + 1, len(times) - 1)
        span = times[j] - times[i]
        frac = np.where(span > 0, (t - times[i]) / np.where(span > 0, span, 1.0), 0.0)
        return values[i] + np.clip(frac, 0.0, 1.0) * (values[j] - values[i])

    def breakpoints(self):
        """Every tabulated time: the slope changes at each."""
        return tuple(dict.fromkeys(self.times))


CHANNELS = {cls.__name__: cls for cls in (FirstOrder, SecondOrder, Piecewise, Ramp, Dip, Forcing, Sawtooth, Table)}


@dataclass(frozen=True)
class Signal:
    """u(t): one channel per input, by input name in the component's order (SM4: Vs, theta_vs, Pm, Efd);
    optionally held piecewise constant every `hold` seconds (ZOH). x0: the state the signal's source
    had the component in at t = 0 (a signal recorded from a closed loop, families.NETWORK), else None."""

    channels: dict
    hold: float = 0.0
    x0: tuple | None = None

    @property
    def names(self) -> tuple:
        return tuple(self.channels)

    def __call__(self, t):
        """u at times t [...] -> [..., C] (t scalar -> [C])."""
        t = self.sample_time(np.asarray(t, dtype=float))
        return np.stack([c(t) for c in self.channels.values()], axis=-1)

    def at(self, t: float) -> tuple:
        """The C input values at one time t [s] as floats: the solver's fast path."""
        t = float(self.sample_time(t))
        return tuple(c(t) for c in self.channels.values())

    def sample_time(self, t):
        """The time whose value is seen at t: t itself, or under ZOH the last sample instant k*hold
        (the small offset keeps k*hold itself in slot k despite rounding)."""
        if self.hold > 0:
            return np.floor(t / self.hold + 1e-9) * self.hold
        return t

    def breakpoints(self, horizon: float) -> np.ndarray:
        """Sorted times in (0, horizon) where u jumps or kinks [s]."""
        if self.hold > 0:
            points = np.arange(1, int(math.ceil(horizon / self.hold)) + 1) * self.hold
        else:
            points = np.array([b for c in self.channels.values()
                               for b in (c.breakpoints_until(horizon) if hasattr(c, "breakpoints_until")
                                         else c.breakpoints())], dtype=float)
        return np.unique(points[(points > 0) & (points < horizon)])

    def to_dict(self) -> dict:
        """{input name: {"kind": channel class, its fields...}, ..., "hold": seconds}."""
        def channel(c):
            return {"kind": type(c).__name__, **{f.name: getattr(c, f.name) for f in fields(c)}}

        extra = {} if self.x0 is None else {"x0": list(self.x0)}
        return {**{name: channel(c) for name, c in self.channels.items()}, "hold": self.hold, **extra}

    @classmethod
    def from_dict(cls, data: dict) -> "Signal":
        def channel(d):
            d = dict(d)
            kind = CHANNELS[d.pop("kind")]
            return kind(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})

        x0 = data.get("x0")
        return cls({name: channel(d) for name, d in data.items() if name not in ("hold", "x0")},
                   float(data.get("hold", 0.0)), None if x0 is None else tuple(float(v) for v in x0))


def held(signal: Signal, hold: float) -> Signal:
    """The same signal sampled and held every `hold` seconds (zero-order hold, as a co-simulation
    master with communication step `hold` delivers it)."""
    return Signal(signal.channels, hold, signal.x0)
