"""The ONNX operator contract that needs no torch: the export tolerance, in-envelope test inputs and
the validated metadata of an operator file (`operator_metadata`; `metadata_of` reads it without the
onnx package).

Used by the export (against torch), by inference and by the FMU builder (the compiled kernel against
onnxruntime), which must not import torch.
"""
from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from reference_models.messages import one_line

# The largest difference allowed between onnxruntime and torch at export, relative to check_scale
# (the build's check of the compiled kernel has its own, fmu_export.surrogate_fmu.KERNEL_TOLERANCE). Both
# round to float32, in different orders: a DeepONet's answer is a sum of basis terms that can be
# 100 times the answer itself, and its first layer a dot product over thousands of sensor values,
# so rounding differences scale with the terms, not with the answer (up to 2.1e-5 measured on the
# WSCC machine operators, whose speeds swing by 10 rad/s within a window).
TOLERANCE = 5e-5


def random_inputs(envelope: dict, t_grid: np.ndarray, n: int, rng: np.random.Generator):
    """In-envelope test inputs: x0 [n, n_x] uniform in the box; u [n, S, n_u] ramps between two
    random levels per channel plus a random-amplitude sine, clipped to the box; t [M]: the grid and
    random times. The envelope's groups `x0` and `u` map names to [low, high] in the operator's order."""
    lo_x, hi_x = np.array(list(envelope["x0"].values()), dtype=float).T
    lo_u, hi_u = np.array(list(envelope["u"].values()), dtype=float).T
    n_x, n_u = lo_x.size, lo_u.size
    x0 = rng.uniform(lo_x, hi_x, (n, n_x))
    frac = t_grid / t_grid[-1]
    a, b = rng.uniform(lo_u, hi_u, (n, n_u)), rng.uniform(lo_u, hi_u, (n, n_u))
    wiggle = (0.1 * (hi_u - lo_u) * rng.uniform(0, 1, (n, 1, n_u))
              * np.sin(2 * np.pi * rng.uniform(1, 8, (n, 1, n_u)) * frac[None, :, None]))
    u = np.clip(a[:, None] + (b - a)[:, None] * frac[None, :, None] + wiggle, lo_u, hi_u)
    t = np.sort(np.concatenate([t_grid, rng.uniform(0, t_grid[-1], 37)]))
    return x0.astype(np.float32), u.astype(np.float32), t.astype(np.float32)


def drifted(frame, x0_f: np.ndarray, u_f: np.ndarray, s: np.ndarray, a: np.ndarray, c: np.ndarray):
    """(x0 [n, n_x], u [n, S, n_u]) float32: windows given in their frame (x0_f, u_f at window times
    s [S]) turned by angles a [n] and speeds c [n], the inverse of reference_models.drift.to_frame."""
    n_x, n_u = x0_f.shape[-1], u_f.shape[-1]
    angles, speed = np.zeros(n_x), frame.speed_mask(n_x)
    angles[list(frame.angle_states)] = 1.0
    x0 = x0_f + a[:, None] * angles + c[:, None] * speed
    u = (u_f + a[:, None, None] * frame.input_rates(n_u)
         + c[:, None, None] * (s[None, :, None] * frame.input_ramps(n_u) + frame.input_torques(n_u)))
    return x0.astype(np.float32), u.astype(np.float32)


# ---------------------------------------------------------------------------------------------------
# The metadata of an operator file, validated: every value a consumer (the FMU builder, inference)
# uses is parsed here, typed, range-checked and bounded before anything is generated from it.

MAX_METADATA_CHARS = 8_000_000  # per value (sensor_times_s of the largest S is about 2.5 MB)
MAX_NAMES = 256
N_SENSORS_RANGE = (2, 100_000)
ROLLOVER_MIN_INTERVALS = 10  # sensor intervals: the shortest window a surrogate FMU rolls over at
MAX_HORIZON_S = 1000.0
REQUIRED_KEYS = ("component", "params", "state_names", "input_names", "horizon_s", "n_sensors", "envelope")


class ContractError(ValueError):
    """Operator metadata that breaks the contract (docs/design.md, "The ONNX operator"); the message is one line."""


def metadata_of(path) -> dict:
    """{key: value} of the metadata strings of the ONNX file at `path`, read through onnxruntime's
    session (graph optimisations off: nothing is run or compiled), which loads in a tenth of the time
    the onnx package takes to import (its ml_dtypes extension: about 1 s). For the commands that run
    built FMUs and only need what the operator was trained for; whoever compiles the graph reads it
    with onnx. OSError where the file cannot be read, ContractError where it is not an ONNX model."""
    import onnxruntime as ort

    options = ort.SessionOptions()
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_DISABLE_ALL
    options.log_severity_level = 3  # its warnings are about running the graph, which this does not
    data = Path(path).read_bytes()
    try:
        session = ort.InferenceSession(data, options, providers=["CPUExecutionProvider"])
    except Exception as exc:  # onnxruntime raises its own types for files that are not models
        raise ContractError(f"not an ONNX model onnxruntime loads ({one_line(exc)[:160]})") from None
    return dict(session.get_modelmeta().custom_metadata_map)


def operator_metadata(source) -> dict:
    """The validated metadata of an operator: `source` is an onnx.ModelProto (its metadata_props)
    or a mapping of key to string value. Returns

        component           the Component (reference_models.components) named by `component`
        params              its parameters from `params` (a JSON object; the rest default)
        state_names, input_names   tuples, equal to the component's
        horizon_s           float in (0, MAX_HORIZON_S]
        n_sensors           int in N_SENSORS_RANGE
        sensor_times_s      tuple of n_sensors uniform times from 0 to horizon_s, or None if absent
        envelope            {"x0": {state: (lo, hi)}, "u": {input: (lo, hi)}} in the component's order
        residual_scale      tuple of n_x finite positive numbers, or None if absent
        state_scale         tuple of n_x finite positive numbers (each state's standard deviation in
                            training, what the checks measure differences against), or None
        residual_limit      finite number >= 0, or None if absent or null
        rollover_horizon_s  float in [the shortest rollover, horizon_s] (default horizon_s)
        operating_point     {input name: value} the FMUs start their inputs at (a machine's Pm and Efd
                            from its load flow), or None: the component's start values
        frame               the window frame (reference_models.drift.Frame) of a component with a drift
                            symmetry, which must be that of the component and parameters (its speed
                            step the operator's own: 0 in files made before it existed); else None
        raw                 the metadata strings as read

    Raises ContractError naming the key and what is wrong with it."""
    from reference_models.component import ParameterError
    from reference_models.components import component as lookup

    raw = _raw_metadata(source)
    missing = [k for k in REQUIRED_KEYS if k not in raw]
    if missing:
        raise ContractError(f"not an opfmu operator: its metadata lacks {', '.join(missing)}")
    try:
        comp = lookup(raw["component"])
    except ValueError as exc:
        raise ContractError(f"metadata component: {exc}") from None
    try:
        params = comp.params(_json(raw, "params"))
    except ParameterError as exc:
        raise ContractError(f"metadata params: {one_line(exc)}") from None
    except OverflowError:  # an integer beyond the range of a float
        raise ContractError("metadata params: a parameter is too large for a floating-point number") from None
    for key, expected in (("state_names", comp.state_names), ("input_names", comp.input_names)):
        names = _json(raw, key)
        if not (isinstance(names, list) and tuple(names) == expected):
            raise ContractError(f"metadata {key} {_show(names)} differ from the {comp.name} component's "
                                f"{list(expected)}")
    horizon = _number(raw, "horizon_s", _json(raw, "horizon_s"))
    if not 0.0 < horizon <= MAX_HORIZON_S:
        raise ContractError(f"metadata horizon_s = {horizon!r} must lie in (0, {MAX_HORIZON_S:g}] s")
    n_sensors = _json(raw, "n_sensors")
    low, high = N_SENSORS_RANGE
    if isinstance(n_sensors, float) and n_sensors.is_integer() and abs(n_sensors) < 2 ** 53:
        n_sensors = int(n_sensors)
    if isinstance(n_sensors, bool) or not isinstance(n_sensors, int) or not low <= n_sensors <= high:
        raise ContractError(f"metadata n_sensors = {_show(n_sensors)} must be an integer in [{low}, {high}]")
    return {
        "component": comp, "params": params, "state_names": comp.state_names, "input_names": comp.input_names,
        "horizon_s": horizon, "n_sensors": n_sensors,
        "sensor_times_s": _sensor_times(raw, n_sensors, horizon),
        "envelope": _envelope(raw, comp),
        "residual_scale": _residual_scale(raw, comp.n_states),
        "state_scale": _residual_scale(raw, comp.n_states, "state_scale"),
        "residual_limit": _residual_limit(raw),
        "rollover_horizon_s": _rollover(raw, horizon, n_sensors),
        "frame": _frame(raw, comp, params),
        "operating_point": _operating_point(raw, comp),
        "raw": raw,
    }


def _raw_metadata(source) -> dict:
    """{key: value} of string metadata; ContractError for duplicate keys, non-strings, oversize values."""
    from collections.abc import Mapping

    if isinstance(source, Mapping):
        pairs = list(source.items())
    elif hasattr(source, "metadata_props"):
        pairs = [(p.key, p.value) for p in source.metadata_props]
    else:
        raise ContractError(f"operator metadata must be an ONNX model or a mapping, got {type(source).__name__}")
    raw = {}
    for key, value in pairs:
        if not isinstance(key, str) or not isinstance(value, str):
            raise ContractError(f"metadata entry {_show(key)} must map a string to a string")
        if key in raw:
            raise ContractError(f"metadata key {_show(key)} appears more than once")
        if len(value) > MAX_METADATA_CHARS:
            raise ContractError(f"metadata {_show(key)} is longer than {MAX_METADATA_CHARS} characters")
        raw[key] = value
    return raw


def _refuse_constant(name: str):
    raise ValueError(f"{name} is not a number the metadata may hold")


def _json(raw: dict, key: str):
    """The JSON value of metadata `key` (NaN and Infinity refused)."""
    try:
        return json.loads(raw[key], parse_constant=_refuse_constant)
    except (ValueError, RecursionError) as exc:
        raise ContractError(f"metadata {key} is not valid JSON ({one_line(exc)[:100]}): {_show(raw[key])}") from None


def _number(raw: dict, key: str, value, what: str = "") -> float:
    """value as a finite float, or ContractError naming the key."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ContractError(f"metadata {key}{what} = {_show(value)} must be a number")
    try:
        number = float(value)
    except OverflowError:
        number = math.inf
    if not math.isfinite(number):
        raise ContractError(f"metadata {key}{what} = {_show(value)} must be a finite number")
    return number


def _sensor_times(raw: dict, n_sensors: int, horizon: float):
    if "sensor_times_s" not in raw:
        return None
    times = _json(raw, "sensor_times_s")
    if not isinstance(times, list) or len(times) != n_sensors:
        raise ContractError(f"metadata sensor_times_s must be a list of n_sensors = {n_sensors} times")
    times = tuple(_number(raw, "sensor_times_s", t, f"[{i}]") for i, t in enumerate(times))
    uniform = np.linspace(0.0, horizon, n_sensors)
    if np.max(np.abs(np.asarray(times) - uniform)) > 1e-6 * horizon:
        raise ContractError(f"metadata sensor_times_s must be {n_sensors} uniformly spaced times from 0 to "
                            f"horizon_s = {horizon!r} s")
    return times


def _bounds(raw: dict, where: str, value) -> tuple:
    if not (isinstance(value, list) and len(value) == 2):
        raise ContractError(f"metadata envelope {where} = {_show(value)} must be [low, high]")
    low, high = (_number(raw, "envelope", v, f" {where}") for v in value)
    if not low <= high:
        raise ContractError(f"metadata envelope {where} = [{low!r}, {high!r}] has low > high")
    return low, high


def _envelope(raw: dict, comp) -> dict:
    envelope = _json(raw, "envelope")
    if not isinstance(envelope, dict):
        raise ContractError(f"metadata envelope must be a JSON object with groups x0 and u, got {_show(envelope)}")
    out = {}
    for group, names in (("x0", comp.state_names), ("u", comp.input_names)):
        box = envelope.get(group)
        if not isinstance(box, dict) or sorted(box) != sorted(names):
            shown = _show(sorted(box)) if isinstance(box, dict) else _show(box)
            raise ContractError(f"metadata envelope {group} must give [low, high] for exactly {', '.join(names)} "
                                f"(the {comp.name} component's), got {shown}")
        out[group] = {name: _bounds(raw, f"{group}.{name}", box[name]) for name in names}
    return out


def _residual_scale(raw: dict, n_states: int, key: str = "residual_scale"):
    if key not in raw:
        return None
    scale = _json(raw, key)
    if not isinstance(scale, list) or len(scale) != n_states:
        raise ContractError(f"metadata {key} must be a list of {n_states} numbers, one per state")
    scale = tuple(_number(raw, key, s, f"[{i}]") for i, s in enumerate(scale))
    if not all(s > 0.0 for s in scale):
        raise ContractError(f"metadata {key} {list(scale)} must hold positive numbers")
    return scale


def check_scale(meta_or_scale, x: np.ndarray) -> np.ndarray:
    """What a difference in x [..., n_x] is measured against in the export's and the build's checks:
    max(1, |x|, the state's spread in training): float32 keeps about 7 digits of each (a machine in
    a network swings its speed by 10 rad/s within a window and turns its angle by 36 rad)."""
    spread = meta_or_scale.get("state_scale") if isinstance(meta_or_scale, dict) else meta_or_scale
    spread = np.ones(x.shape[-1]) if spread is None else np.asarray(spread, dtype=float)
    return np.maximum(np.maximum(1.0, np.abs(x)), spread)


def _residual_limit(raw: dict):
    if "residual_limit" not in raw:
        return None
    limit = _json(raw, "residual_limit")
    if limit is None:
        return None
    limit = _number(raw, "residual_limit", limit)
    if limit < 0.0:
        raise ContractError(f"metadata residual_limit = {limit!r} must be >= 0")
    return limit


def shortest_rollover(horizon: float, n_sensors: int) -> float:
    """The shortest window [s] a surrogate FMU rolls over at: 10 sensor intervals, or the whole
    horizon where it has fewer (the least its parameter rollover_horizon takes: OPFMU_SHORTEST_ROLLOVER)."""
    return min(ROLLOVER_MIN_INTERVALS * horizon / (n_sensors - 1), horizon)


def _rollover(raw: dict, horizon: float, n_sensors: int) -> float:
    if "rollover_horizon_s" not in raw:
        return horizon
    rollover = _number(raw, "rollover_horizon_s", _json(raw, "rollover_horizon_s"))
    low = shortest_rollover(horizon, n_sensors)
    if not low * (1.0 - 1e-9) <= rollover <= horizon:
        raise ContractError(f"metadata rollover_horizon_s = {rollover!r} must lie in [{low!r}, horizon_s = {horizon!r}] "
                            f"(at least {ROLLOVER_MIN_INTERVALS} sensor intervals, where the horizon has them)")
    return rollover


def _operating_point(raw: dict, comp):
    if "operating_point" not in raw:
        return None
    point = _json(raw, "operating_point")
    if not isinstance(point, dict) or not all(k in comp.input_names for k in point):
        raise ContractError(f"metadata operating_point {_show(raw['operating_point'])} must map inputs of "
                            f"{comp.name} ({', '.join(comp.input_names)}) to numbers")
    return {k: _number(raw, "operating_point", v, f" {k}") for k, v in point.items()}


def _frame(raw: dict, comp, params):
    from reference_models.drift import Frame, frame_of

    if comp.drift is None:
        return None
    if "frame" not in raw:
        raise ContractError(f"metadata has no frame: the operator was made before {comp.name} operators worked in "
                            "the frame of their window (opfmu < 0.3); retrain it")
    expected = frame_of(comp.drift, params)
    try:
        frame = Frame.from_dict(_json(raw, "frame"))
    except (KeyError, TypeError, ValueError, AttributeError):
        raise ContractError(f"metadata frame {_show(raw['frame'])} is not a frame") from None
    # the speed step is the operator's choice (every frame speed is exact, by the symmetry), the rest is the component's
    if not (math.isfinite(frame.speed_step) and frame.speed_step >= 0):
        raise ContractError(f"metadata frame speed_step {_show(frame.speed_step)} must be a finite number >= 0")
    if replace(frame, speed_step=expected.speed_step) != expected:
        raise ContractError(f"metadata frame {_show(raw['frame'])} is not the frame of the {comp.name} component "
                            f"with these params ({_show(json.dumps(expected.to_dict()))})")
    return frame


def _show(value) -> str:
    """A short one-line rendering of a (possibly hostile) value for a message."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


