"""Reusable control blocks of the standard dynamic models, written against a math namespace `m`.

Every function here takes and returns values of the namespace the equations run on (the `math`
module with Python floats, numpy arrays, torch tensors, or the C tracers of fmu_export), using only
+ - * /, `m.sqrt` and `reference_models.piecewise.where` for conditions, so one definition serves
scipy, autograd and code generation. Parameters (gains, time constants, limits) are Python floats:
a block decides on them in Python (a time constant of 0 gives another equation, not a conditional).

A block with a state returns `(derivative, output)`. A block whose time constant is 0 keeps its
state (so a component's state vector is fixed whatever its data): the derivative is then 0 (the
state is held, unused) and the output is what the block degenerates to (a lag or lead-lag with
T = 0: its input times the gain), as ANDES treats a zero time constant.

Limits (ANDES' terms, andes.core.discrete and andes.core.block):
* windup limiter (`clip`): the output is the input clipped to [low, high]; nothing is held;
* non-windup (anti-windup) limit (`non_windup`, `lag_non_windup`, `integrator_non_windup`): the
  state itself stays within [low, high]: at a limit while its unlimited derivative pushes outward,
  the derivative is 0; it leaves as soon as the derivative turns back.
* the reset of a non-windup limit (`non_windup_reset`, `lag_non_windup_reset`,
  `integrator_non_windup_reset`; ANDES' AntiWindup.check_eq): a state at or beyond its upper limit
  while its unlimited derivative is >= 0 is placed on the limit, likewise at the lower limit with a
  derivative <= 0. A component's `reset` is written with these, and integrators apply it where they
  (re)start (component.py): a state beyond a constant limit (a start value, a numerical overshoot,
  a limit crossed between two restarts) returns onto it, and a state under a limit that moves with
  an input (`non_windup_between`) follows the limit when it moves inward. The standard models'
  limits are all constant (IEEEX1's too, as ANDES 2.0.0 computes it: models/ieeex1.py).

Saturation: `quadratic_saturation` (GENROU's S(x) = B (x - A)^2 / x above A, ANDES' ExcQuadSat
coefficients from two points; ANDES 2.0.0 uses it for every exciter here, never ExcExpSat).
`rectifier_loading`: ESST3A's FEX(IN).
"""
from __future__ import annotations

import math

from .piecewise import where

NO_LIMIT = 1e6  # pu: a limit this large (or larger) in magnitude is no limit (no conditional is generated)


def _lower(low: float) -> float:
    return low if low > -NO_LIMIT else -math.inf


def _upper(high: float) -> float:
    return high if high < NO_LIMIT else math.inf


def clip(m, x, low: float, high: float):
    """Windup limiter: x clipped to [low, high] (a limit beyond NO_LIMIT is absent)."""
    low, high = _lower(low), _upper(high)
    if high < math.inf:
        x = where(m, x >= high, high + 0.0 * x, x)
    if low > -math.inf:
        x = where(m, x <= low, low + 0.0 * x, x)
    return x


def clip_between(m, x, low, high):
    """x clipped to [low, high] where the limits are values of the namespace (e.g. ones that move
    with an input): high where x >= high, else low where x <= low, else x."""
    return where(m, x >= high, high, where(m, x <= low, low, x))


def non_windup(m, rate, x, low: float, high: float):
    """The derivative of a state x under a non-windup limit [low, high]: `rate` (the unlimited
    derivative), 0 where x is at or beyond high while rate > 0, or at or beyond low while rate < 0."""
    low, high = _lower(low), _upper(high)
    if high < math.inf:
        rate = where(m, x >= high, where(m, rate > 0.0, 0.0 * rate, rate), rate)
    if low > -math.inf:
        rate = where(m, x <= low, where(m, rate < 0.0, 0.0 * rate, rate), rate)
    return rate


def non_windup_between(m, rate, x, low, high):
    """`non_windup` with limits that are values of the namespace (e.g. proportional to an input)."""
    rate = where(m, x >= high, where(m, rate > 0.0, 0.0 * rate, rate), rate)
    return where(m, x <= low, where(m, rate < 0.0, 0.0 * rate, rate), rate)


def non_windup_reset(m, rate, x, low, high):
    """The state x after the reset of its non-windup limit [low, high] (ANDES' AntiWindup): high
    where x >= high while the unlimited derivative `rate` >= 0, low where x <= low while rate <= 0,
    else x. A limit is a Python float (beyond NO_LIMIT: absent) or a value of the namespace (a limit
    that moves with an input)."""
    if isinstance(high, (int, float)):
        high = _upper(high)
        if high < math.inf:
            x = where(m, x >= high, where(m, rate >= 0.0, high + 0.0 * x, x), x)
    else:
        x = where(m, x >= high, where(m, rate >= 0.0, high, x), x)
    if isinstance(low, (int, float)):
        low = _lower(low)
        if low > -math.inf:
            x = where(m, x <= low, where(m, rate <= 0.0, low + 0.0 * x, x), x)
    else:
        x = where(m, x <= low, where(m, rate <= 0.0, low, x), x)
    return x


def lag(m, u, x, K: float, T: float):
    """First-order lag K / (1 + s T): (dx/dt, y). T > 0: T dx/dt = K u - x, y = x. T = 0: the
    state is held (dx/dt = 0) and y = K u."""
    if T > 0:
        return (K * u - x) / T, x
    return 0.0 * x, K * u


def lag_non_windup(m, u, x, K: float, T: float, low: float, high: float):
    """Lag K / (1 + s T) with a non-windup limit [low, high] on its state (ANDES' LagAntiWindup):
    (dx/dt, y = x). T = 0: the state is held and y = K u clipped to [low, high]."""
    if T > 0:
        return non_windup(m, (K * u - x) / T, x, low, high), x
    return 0.0 * x, clip(m, K * u, low, high)


def lag_non_windup_reset(m, u, x, K: float, T: float, low: float, high: float):
    """The state of `lag_non_windup` after its limit's reset (`non_windup_reset`); T = 0: x (held,
    unused)."""
    if T > 0:
        return non_windup_reset(m, (K * u - x) / T, x, low, high)
    return x


def integrator_non_windup(m, u, x, K: float, T: float, low: float, high: float):
    """Integrator K / (s T) with a non-windup limit [low, high] (ANDES' IntegratorAntiWindup):
    (dx/dt, y = x)."""
    return non_windup(m, K * u / T, x, low, high), x


def integrator_non_windup_reset(m, u, x, K: float, T: float, low: float, high: float):
    """The state of `integrator_non_windup` after its limit's reset (`non_windup_reset`)."""
    return non_windup_reset(m, K * u / T, x, low, high)


def lead_lag(m, u, x, K: float, T1: float, T2: float):
    """Lead-lag K (1 + s T1) / (1 + s T2) (ANDES' LeadLag with zero_out): (dx/dt, y).
    T2 > 0: T2 dx/dt = u - x, y = K (T1 / T2 (u - x) + x). T2 = 0: the state is held
    (dx/dt = 0) and y = K u (the block is a gain)."""
    if T2 > 0:
        return (u - x) / T2, K * (T1 / T2 * (u - x) + x)
    return 0.0 * x, K * u


def washout(m, u, x, K: float, T: float):
    """Washout s K / (1 + s T) (ANDES' Washout): (dx/dt, y); T dx/dt = u - x, y = K (u - x) / T.
    T must be > 0."""
    return (u - x) / T, K * (u - x) / T


def washout_or_lag(m, u, x, K: float, T: float):
    """ANDES' WashoutOrLag: a washout s K / (1 + s T) for K > 0; for K = 0 the lag 1 / (1 + s T)
    (y = x). T must be > 0."""
    if K > 0:
        return washout(m, u, x, K, T)
    return (u - x) / T, x


def lag_second_order(m, u, x, y, K: float, T1: float, T2: float):
    """Second-order lag K / (1 + s T1 + s^2 T2) (ANDES' Lag2ndOrd): (dx/dt, dy/dt, y) with
    T2 dx/dt = K u - y - T1 x, dy/dt = x. T2 = 0 < T1: the first-order lag T1 dy/dt = K u - y,
    x held; T1 = T2 = 0: both states held, output K u."""
    if T2 > 0:
        return (K * u - y - T1 * x) / T2, x, y
    if T1 > 0:
        return 0.0 * x, (K * u - y) / T1, y
    return 0.0 * x, 0.0 * y, K * u


def lead_lag_second_order(m, u, x1, x2, T1: float, T2: float, T3: float, T4: float):
    """Second-order lead-lag (1 + s T3 + s^2 T4) / (1 + s T1 + s^2 T2) (ANDES' LeadLag2ndOrd with
    zero_out): (dx1/dt, dx2/dt, y) with T2 dx1/dt = u - x2 - T1 x1, dx2/dt = x1,
    T2 y = T2 x2 + T2 T3 x1 + T4 (u - x2 - T1 x1). T2 = 0: both states held, y = u."""
    if T2 > 0:
        rest = u - x2 - T1 * x1
        return rest / T2, x1, x2 + T3 * x1 + T4 / T2 * rest
    return 0.0 * x1, 0.0 * x2, u


def quadratic_saturation_coefficients(E1: float, SE1: float, E2: float, SE2: float) -> tuple:
    """(A, B) of the quadratic saturation S(x) = B (x - A)^2 / x through S(E1) = SE1, S(E2) = SE2
    (ANDES' ExcQuadSat): a = sqrt(SE1 E1 / (SE2 E2)), A = E2 - (E1 - E2) / (a - 1),
    B = SE2 E2 (a - 1)^2 / (E1 - E2)^2. SE2 = 0 or SE1 = 0: no saturation (B = 0)."""
    if SE2 == 0:
        E2, SE2 = E2 + 2.0, SE2 + 2.0
    a = math.sqrt(SE1 * E1 / (SE2 * E2)) if SE1 * E1 / (SE2 * E2) > 0 else 0.0
    A = E2 - (E1 - E2) / (a - 1.0)
    B = SE2 * E2 * (a - 1.0) ** 2 / (E1 - E2) ** 2 if a != 0 else 0.0
    return A, B


def quadratic_saturation_product(m, x, A: float, B: float):
    """S(x) x = B (x - A)^2 where x >= A, else 0 [pu] (the saturation times its argument)."""
    if B == 0:
        return 0.0 * x
    return where(m, x >= A, B * (x - A) * (x - A), 0.0 * x)


def rectifier_loading(m, IN):
    """ESST3A's rectifier loading factor FEX(IN) (IEEE 421.5 / ANDES' Piecewise): 1 for IN <= 0,
    1 - 0.577 IN up to 0.433, sqrt(0.75 - IN^2) up to 0.75, 1.732 (1 - IN) up to 1, 0 beyond."""
    # the root of |0.75 - IN^2|: the same on its piece (0 <= IN <= 0.75, where it is at least 0.1875),
    # and defined elsewhere whatever branch a solver has locked (IN < -0.866 in a transient with a
    # negative exciter voltage, IN > 0.866)
    square = 0.75 - IN * IN
    root = m.sqrt(m.sqrt(square * square))
    return where(m, IN <= 0.0, 1.0 + 0.0 * IN,
                 where(m, IN <= 0.433, 1.0 - 0.577 * IN,
                       where(m, IN <= 0.75, root,
                             where(m, IN <= 1.0, 1.732 * (1.0 - IN), 0.0 * IN))))


def low_value_gate(m, u1, u2):
    """ANDES' LVGate: the smaller of u1 and u2 (u2 where they are equal)."""
    return where(m, u1 < u2, u1, u2)


def dead_band(m, u, low: float, high: float):
    """Continuous dead band (ANDES' DeadBand1, centre 0): 0 for low <= u <= high, u - high above
    the band, u - low below it."""
    return where(m, u > high, u - high, where(m, u < low, u - low, 0.0 * u))


def step_dead_band(m, u, low: float, high: float):
    """Dead band that passes its input unshifted outside the band: u where u > high or u < low,
    else 0 (the output steps at the band's edges; ANDES' DeadBand as `u (1 - zi)`)."""
    return where(m, u > high, u, where(m, u < low, u, 0.0 * u))


def rate_limited_non_windup(m, rate, x, rate_low, rate_high, low: float, high: float):
    """The derivative of a state x under a rate limit [rate_low, rate_high] (values of the
    namespace, e.g. moving with a signal) and a non-windup limit [low, high] (ANDES'
    AntiWindupRate): `rate` clipped to the rate limits, then `non_windup`."""
    return non_windup(m, clip_between(m, rate, rate_low, rate_high), x, low, high)


def rate_limited_non_windup_reset(m, rate, x, rate_low, rate_high, low: float, high: float):
    """The state of `rate_limited_non_windup` after its limit's reset (`non_windup_reset` at the
    rate-limited derivative)."""
    return non_windup_reset(m, clip_between(m, rate, rate_low, rate_high), x, low, high)


def pid_tracking(m, u, xi, xd, kp: float, ki: float, kd: float, Td: float, ks: float, low: float, high: float):
    """PID controller kp + ki / s + s kd / (1 + s Td) with a windup limiter [low, high] on its output
    and tracking anti-windup (ANDES' PIDTrackAW): (dxi/dt, dxd/dt, y) with
    Td dxd/dt = u - xd (the derivative's washout), ys = kp u + xi + kd (u - xd) / Td,
    y = ys clipped to [low, high], dxi/dt = ki (u - ks (ys - y)): the clipped excess, times the
    tracking gain ks, is fed back to the integrator. Nothing is reset. Td must be > 0."""
    d_xd, derivative = washout(m, u, xd, kd, Td)
    ys = kp * u + xi + derivative
    y = clip(m, ys, low, high)
    return ki * (u - ks * (ys - y)), d_xd, y


def pi_tracking(m, u, xi, kp: float, ki: float, ks: float, low, high):
    """PI controller kp + ki / s with a windup limiter [low, high] on its output and tracking
    anti-windup (ANDES' PITrackAW): (dxi/dt, y) with ys = kp u + xi, y = ys clipped to [low, high],
    dxi/dt = ki (u - ks (ys - y)). The limits are Python floats or values of the namespace (limits
    that move with a signal). Nothing is reset."""
    ys = kp * u + xi
    low = low + 0.0 * ys if isinstance(low, (int, float)) else low
    high = high + 0.0 * ys if isinstance(high, (int, float)) else high
    y = clip_between(m, ys, low, high)
    return ki * (u - ks * (ys - y)), y


def lag_rate(m, u, x, K: float, T: float, rate_low: float, rate_high: float):
    """Lag K / (1 + s T) with a rate limit (ANDES' LagRate): (dx/dt, y = x) with
    T dx/dt = K u - x clipped to [rate_low, rate_high]: the limits bound T dx/dt, as ANDES' RateLimiter
    clips the equation's value before its time constant divides it. T must be > 0."""
    return clip(m, K * u - x, rate_low, rate_high) / T, x


def piecewise_linear(m, u, points: tuple, values: tuple):
    """The piecewise-linear characteristic through (points[k], values[k]) (points non-decreasing),
    flat beyond its ends: values[0] for u <= points[0], values[-1] above points[-1] (ANDES'
    Piecewise with linear pieces: REECA1's VDL1, VDL2). A piece of zero width is never taken."""
    y = values[-1] + 0.0 * u
    for k in range(len(points) - 1, 0, -1):
        if points[k] > points[k - 1]:
            slope = (values[k] - values[k - 1]) / (points[k] - points[k - 1])
            y = where(m, u <= points[k], values[k - 1] + slope * (u - points[k - 1]), y)
    return where(m, u <= points[0], values[0] + 0.0 * u, y)


def power(m, x, a: float):
    """x ** a for x > 0 and an exponent a decided in Python (a load's voltage or frequency exponent):
    a whole or half-whole a by products, divisions and m.sqrt, so it traces into C; any other a as
    m.exp(a m.log(x)), for the namespaces that have a logarithm (math, numpy, torch; the C tracers
    have none)."""
    whole = math.floor(a)
    if 2.0 * a != math.floor(2.0 * a):
        return m.exp(a * m.log(x))
    y = m.sqrt(x) if a != whole else 1.0 + 0.0 * x
    for _ in range(int(abs(whole))):
        y = y * x if whole > 0 else y / x
    return y


def bus_frequency(m, theta, theta_f, theta_w, Tf: float, Tw: float, fn: float):
    """A bus-frequency measurement (ANDES' BusFreq) as a device's own states: (d theta_f/dt,
    d theta_w/dt, f [pu]). The bus angle theta [rad] through the lag 1 / (1 + s Tf) (state theta_f;
    Tf = 0: held, theta passes), then the washout s K / (1 + s Tw), K = 1 / (2 pi fn) (state theta_w):
    f = 1 + K (theta_f - theta_w) / Tw. Both states are angles of the network frame (ANDES' L_y and
    WO_x plus the load flow's angle theta0). Tw must be > 0."""
    d_f, filtered = lag(m, theta, theta_f, 1.0, Tf)
    d_w, deviation = washout(m, filtered, theta_w, 1.0 / (2.0 * math.pi * fn), Tw)
    return d_f, d_w, 1.0 + deviation


def lags_of_ramp(x, w, u0, u1, h: float, Tf: float, Tw: float) -> tuple:
    """(x(h), w(h)) of Tf dx/dt = u - x, Tw dw/dt = x - w from (x, w), u linear from u0 to u1 over h
    (a BusFreq's lag and washout states). Linear in (x, w, u0, u1): floats, or arrays of the
    coefficients of one linear combination (subsystem.measured_frequency_map).
    x = r + A e^{-tau/Tf} with the ramp r = u0 - s Tf + s tau (s the slope), A = x - u0 + s Tf; w is
    the lag of r plus the exact response to the exponential (Tf = 0: x follows u)."""
    s = (u1 - u0) / h if h > 0 else 0.0
    if Tf <= 0.0:
        return u1, lag_of_ramp(w, u0, u1, h, Tw)
    A = x - u0 + s * Tf
    r0, r1 = u0 - s * Tf, u1 - s * Tf
    x_end = r1 + A * math.exp(-h / Tf)
    if abs(Tf - Tw) <= 1e-12 * Tw:  # equal time constants: the resonant term A tau / T e^{-tau/T}
        return x_end, lag_of_ramp(w, r0, r1, h, Tw) + A * h / Tw * math.exp(-h / Tw)
    C = A * Tf / (Tf - Tw)
    return x_end, lag_of_ramp(w - C, r0, r1, h, Tw) + C * math.exp(-h / Tf)


def lag_of_ramp(x, u0, u1, h: float, T: float):
    """x(h) of T dx/dt = u - x from x, u linear from u0 to u1 over h (T = 0: x follows u)."""
    if T <= 0.0:
        return u1
    e = math.exp(-h / T)
    slope = (u1 - u0) / h if h > 0 else 0.0
    return u1 - slope * T + (x - u0 + slope * T) * e


def lag_non_windup_between(m, u, x, K: float, T: float, low, high):
    """`lag_non_windup` with limits that are values of the namespace (e.g. proportional to an input):
    (dx/dt, y = x). T = 0: the state is held and y = K u clipped to [low, high] (its reset:
    `lag_non_windup_reset`, which takes such limits). A limit may also be a Python float."""
    if T > 0:
        return non_windup_between(m, (K * u - x) / T, x, low, high), x
    y = K * u
    return 0.0 * x, clip_between(m, y, low + 0.0 * y, high + 0.0 * y)


def sqrt_positive_part(m, x):
    """sqrt(max(x, 0)) with no condition: max(x, 0) as (x + |x|) / 2, |x| = m.sqrt(x x) (for x > 0
    bit for bit x: sqrt(x x) is |x| exactly in binary floating point). Under a `where(m, x > 0, ...)`
    the branch that takes sqrt(x) needs it: a guard `m.sqrt(where(m, x > 0, x, 1))` is a condition
    too, locked with the branch it guards by the integrators that lock branches between switchings
    (fmu_export.c_equations, Model Exchange), so past x = 0 the locked branch would take the root of
    a negative number (NaN) where this continues it as 0, the other branch's value there."""
    return m.sqrt(0.5 * (x + m.sqrt(x * x)))
