"""Builds the native surrogate FMU of an exported operator (.onnx), for the machine its metadata names.

The operator file's metadata (validated by surrogate.contract.operator_metadata before anything is
generated) names the component and its parameters; from those and the graph, generated at build time:
config.h (sizes, envelope, defaults, component tables, GUID), variables.h (the value references of
the model description, fmu_export.variables), equations.c (the component's right-hand side and
outputs, fmu_export.c_equations), derivatives.c (their exact partial derivatives,
fmu_export.c_derivatives: the directional derivatives), operator_kernel.c (from the ONNX graph) and
sensor_sums.c. The equations hold the trained parameters as literals; the FMU declares them as fixed
parameters and refuses any other value (an operator is trained for one parameter set:
fmu_export.c_parameters, a trained ParameterSpace). With the static sources in c/ (cosimulation.c: the FMI plumbing both versions share,
with fmi2_cs.c or fmi3_cs.c: the FMI 2.0 or 3.0 API over it; model.h: its interface to a model;
window.c: the window-and-sensor engine; frame.c: the window frame; corrections.c;
variables.c: the component's variables; surrogate_variables.c and surrogate_state.h: the
surrogate's own variables and state; linalg.c; self_start.c where the component starts from the load
flow, as its native reference FMU does: fmu_export.self_start) they compile into one binary per platform
(binaries.py), which needs the C runtime only. The host's compiled kernel is checked against
onnxruntime, and the other platforms' binaries against the host's by running them where an emulator
is installed (cross_check.py), before the FMU is written; the .onnx goes into resources/ and the C
sources into sources/. Only numbers, generated identifiers and escaped component names reach the C
sources.
"""
from __future__ import annotations

import ctypes
import hashlib
import math
import re
import shutil
import tempfile
from pathlib import Path

import numpy as np

from surrogate.contract import ContractError, check_scale, drifted, operator_metadata, random_inputs, shortest_rollover
from surrogate.frame_graph import network_graph

from .binaries import PLUMBING, BuildError, check_fmi_version, compile_binaries, compile_c, targets
from .c_derivatives import jacobians_c_source, start_equations_c_source
from .c_equations import c_size, equations_c_source, parameter_space
from .c_parameters import parameters_c_source
from .cross_check import cross_check
from .fmu_archive import write_fmu
from .model_description import model_description
from .onnx_to_c import generate_kernel, hex_literals
from .platforms import host
from .self_start import config_lines as self_start_config, self_start_of
from .self_start import variables as self_start_variables
from .variables import SURROGATE_EXTRAS, SYSTEM_BASE_MVA, fmu_variables, start_inputs, start_state, vr_header

C_DIR = Path(__file__).parent / "c"
# residual above which the FMU warns, for an operator whose metadata names none (the export writes
# each operator's own level, from its test split, as `residual_limit`)
DEFAULT_RESIDUAL_LIMIT = 1.0
# input change (in the input's unit) that starts a new operator window at once
DEFAULT_RESTART_JUMP = 0.02
DEFAULT_REST_RADIUS = 1.0  # default of the parameter rest_radius (corrections.c: the rest correction)
DEFAULT_SLOW_WEIGHT = 1.0  # default of the parameter slow_weight (corrections.c: the slow-mode correction)
DEFAULT_SWING_WEIGHT = 1.0  # default of the parameter swing_weight (corrections.c: the exact affine step)
MODEL_SOURCES = ("cosimulation.c", "window.c", "corrections.c", "frame.c", "variables.c", "surrogate_variables.c",
                 "linalg.c", "self_start.c", "cosimulation.h", "model.h", "surrogate_state.h", "engine.h", "linalg.h")
START_C_FILES = ("self_start.c",)  # where the FMU starts itself from the load flow
# beside the version's plumbing (binaries.PLUMBING) and the operator kernel (compiled once)
C_FILES = ("cosimulation.c", "window.c", "corrections.c", "frame.c", "variables.c", "surrogate_variables.c", "linalg.c",
           "equations.c", "derivatives.c", "sensor_sums.c")
MODEL_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,63}")
C_KEYWORDS = frozenset("auto break case char const continue default do double else enum extern float for goto if "
                       "inline int long register restrict return short signed sizeof static struct switch typedef "
                       "union unsigned void volatile while".split())


# the compiled kernel (double arithmetic on the float32 weights) against onnxruntime (float32
# arithmetic), relative to contract.check_scale: onnxruntime's own rounding through three 128-wide
# layers and 4 x 96 basis products reaches 1.1e-5 of the scale for the WSCC machines' operators
KERNEL_TOLERANCE = 5e-5

def _c_double(value) -> str:
    """A C double literal: shortest round-trip repr of a finite value, or -INFINITY."""
    value = float(value)
    if value == -math.inf:
        return "(-INFINITY)"
    if not math.isfinite(value):
        raise BuildError(f"internal: non-finite value {value!r} for the C sources")
    return repr(value)


def _c_array(values) -> str:
    return "{" + ", ".join(_c_double(v) for v in values) + "}"


def _c_string(text: str) -> str:
    """A C string literal of text; every character outside a small safe set as an octal escape."""
    safe = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_ /.,:=-+()[]{}")  # no ?, \\, ", %
    return '"' + "".join(c if c in safe else "".join(f"\\{b:03o}" for b in c.encode()) for c in text) + '"'


def _c_strings(texts) -> str:
    return "{" + ", ".join(_c_string(t) for t in texts) + "}"


def input_minima(component) -> list[float]:
    """The lowest value each input accepts (the FMU refuses a value below it): the Quantity's
    `minimum`, -inf where it declares none."""
    return [-math.inf if q.minimum is None else float(q.minimum) for q in component.inputs]


def mode_start(n: int) -> list[float]:
    """The start vector of the inverse iteration for the slowest mode: from 1 down to 0.1."""
    return [1.0] if n == 1 else [round(1.0 - 0.9 * i / (n - 1), 12) for i in range(n)]


def component_config(kind: str, model_name: str, guid: str, component, state_header: str, interpolates: bool,
                     x_default, operating_point: dict | None = None, space=None,
                     input_order: int = 1) -> tuple[list, list]:
    """The config.h lines every native FMU of `component` has: (the opening, the closing tables).
    kind names the FMU in the comment; state_header is the model's ModelState header; space: the
    build's ParameterSpace (fmu_export.c_parameters: the parameters' count, defaults and names);
    input_order: the highest order of input derivatives it takes (2: quadratic inputs over a step,
    its ModelState has d2u)."""
    n_x, n_u = component.n_states, component.n_inputs
    opening = [
        f"/* Generated by opfmu: the configuration of one {kind} FMU. */",
        "#ifndef OPFMU_CONFIG_H", "#define OPFMU_CONFIG_H", "#include <math.h>",
        f"#define OPFMU_MODEL_IDENTIFIER {_c_string(model_name)}",
        f"#define OPFMU_GUID {_c_string(guid)}",
        f"#define OPFMU_N_STATES {n_x}",
        f"#define OPFMU_N_INPUTS {n_u}",
        f"#define OPFMU_N_OUTPUTS {len(component.outputs)}",
        f'#define OPFMU_STATE_HEADER "{state_header}" /* the model\'s ModelState */',
        f"#define OPFMU_CAN_INTERPOLATE_INPUTS {int(interpolates)} /* "
        + ("inputs linear over a step where their derivatives are set */" if interpolates
           else "inputs held over a step; no input derivatives */"),
        f"#define OPFMU_INPUT_ORDER {int(input_order)} /* the highest order of input derivatives it takes */",
        f"#define OPFMU_N_PARAMS {space.n} /* the component's parameters */",
        f"#define OPFMU_P_SIZE {space.size} /* the parameter array: the parameters, then the derived ones */",
    ]
    tables = [
        f"static const double OPFMU_DEFAULT_X0[{c_size(n_x)}] = {_c_array(list(x_default) or [0.0])}; /* equilibrium "
        "at the start inputs (none without states: one unused) */",
        f"static const double OPFMU_START_U[{n_u}] = {_c_array(start_inputs(component, operating_point))};",
        f"static const double OPFMU_INPUT_MIN[{n_u}] = {_c_array(input_minima(component))};",
        f"static const char *const OPFMU_INPUT_NAMES[{n_u}] = {_c_strings(component.input_names)};",
        f"static const char *const OPFMU_INPUT_UNITS[{n_u}] = {_c_strings(q.unit for q in component.inputs)};",
        f"static const double OPFMU_PARAM_START[{space.size}] = {_c_array(list(space.values) or [0.0])}; /* the "
        "parameters' defaults (the derived ones: model_derive) */",
        f"static const char *const OPFMU_PARAM_NAMES[{max(space.n, 1)}] = {_c_strings(list(space.names) or [''])};",
    ]
    return opening, tables


def config_header(model_name: str, guid: str, meta: dict, x_default, first_layer: int, kernel, space,
                  self_start=None) -> str:
    """config.h: the FMU's sizes, defaults, envelope and component tables, all numbers or escaped
    names (space: the trained ParameterSpace; self_start: the start from the load flow it solves, or
    None)."""
    component = meta["component"]
    envelope = meta["envelope"]
    n_x, n_u = component.n_states, component.n_inputs
    affine = [int(i) for i in component.affine_states]
    residual_scale = [0.0 if i in component.learned_states else float(s)  # 0: a learned rate, left out
                      for i, s in enumerate(meta["residual_scale"] or [1.0] * n_x)]
    corrections = correction_defaults(component)
    opening, tables = component_config("surrogate", model_name, guid, component, "surrogate_state.h", True, x_default,
                                       meta.get("operating_point"), space)
    lines = opening + [
        f"#define OPFMU_N_SENSORS {int(meta['n_sensors'])}",
        f"#define OPFMU_HORIZON {_c_double(meta['horizon_s'])}",
        f"#define OPFMU_ROLLOVER_HORIZON {_c_double(meta['rollover_horizon_s'])} /* default of the parameter rollover_horizon */",
        f"#define OPFMU_SHORTEST_ROLLOVER {_c_double(shortest_rollover(meta['horizon_s'], meta['n_sensors']))} "
        "/* the least the parameter rollover_horizon takes */",
        f"#define OPFMU_FIRST_LAYER {first_layer} /* width of the sensor layer tracked incrementally; 0: none */",
        f"#define OPFMU_TRUNK_SIZE {kernel.trunk_size if first_layer else 0} /* trunk values kept per sensor time; 0: none */",
        f"#define OPFMU_COEF_SIZE {kernel.coef_size if first_layer else 0} /* coefficients the head multiplies */",
        f"#define OPFMU_RESIDUAL_LIMIT {_c_double(residual_limit(meta))} /* default of the parameter residual_limit */",
        f"#define OPFMU_RESTART_JUMP {_c_double(corrections['restart_jump'])} /* default of the parameter restart_jump */",
        f"#define OPFMU_REST_RADIUS {_c_double(corrections['rest_radius'])} /* default of the parameter rest_radius */",
        f"#define OPFMU_SLOW_WEIGHT {_c_double(corrections['slow_weight'])} /* default of the parameter slow_weight */",
        f"#define OPFMU_SWING_WEIGHT {_c_double(corrections['swing_weight'])} /* default of the parameter swing_weight */",
        f"#define OPFMU_N_AFFINE {len(affine)} /* states whose rate is affine in themselves (exact step) */",
        f"static const int OPFMU_AFFINE_STATES[{max(len(affine), 1)}] = {{{', '.join(map(str, affine or [0]))}}};",
        *tables,
        f"static const double OPFMU_STATE_SCALE[{n_x}] = {_c_array(component.state_scales)}; /* reach of the rest "
        "correction at rest_radius = 1 */",
        f"static const double OPFMU_MODE_START[{n_x}] = {_c_array(mode_start(n_x))};",
        f"static const double OPFMU_ENV_X0_MIN[{n_x}] = {_c_array(envelope['x0'][s][0] for s in component.state_names)};",
        f"static const double OPFMU_ENV_X0_MAX[{n_x}] = {_c_array(envelope['x0'][s][1] for s in component.state_names)};",
        f"static const double OPFMU_ENV_U_MIN[{n_u}] = {_c_array(envelope['u'][s][0] for s in component.input_names)};",
        f"static const double OPFMU_ENV_U_MAX[{n_u}] = {_c_array(envelope['u'][s][1] for s in component.input_names)};",
        f"static const double OPFMU_RESIDUAL_SCALE[{n_x}] = {_c_array(residual_scale)}; /* 0: a learned rate */",
        *frame_config(meta.get("frame"), n_x, n_u),
        *(self_start_config(component, self_start) if self_start else []),
        "#endif", "",
    ]
    return "\n".join(lines)


def frame_config(frame, n_x: int, n_u: int) -> list[str]:
    """config.h lines of the window frame (reference_models.drift.Frame; None: the identity)."""
    rates = frame.input_rates(n_u) if frame else np.zeros(n_u)
    torques = frame.input_torques(n_u) if frame else np.zeros(n_u)
    angles, speed = np.zeros(n_x), np.zeros(n_x)
    if frame:
        angles[list(frame.angle_states)] = 1.0
        speed = frame.speed_mask(n_x)
    return [
        f"#define OPFMU_FRAME {1 if frame else 0} /* the operator works in the frame of its window */",
        f"#define OPFMU_FRAME_ANGLE_INPUT {frame.angle_inputs[0] if frame else 0}",
        f"#define OPFMU_FRAME_SPEED_STATE {-1 if not frame or frame.speed_state is None else frame.speed_state}"
        " /* -1: no speed, the frame only turns */",
        f"#define OPFMU_FRAME_ANGLE_STATE {frame.angle_states[0] if frame and frame.angle_states else -1}",
        f"#define OPFMU_FRAME_PERIOD {_c_double(frame.period if frame else 1.0)}",
        f"#define OPFMU_FRAME_SPEED_STEP {_c_double(frame.speed_step if frame else 0.0)} /* 0: c = the start speed */",
        f"#define OPFMU_FRAME_SPEED_SCALE {_c_double(frame.speed_scale if frame else 1.0)} /* rad/s: angle rate of one speed unit */",
        f"#define OPFMU_FRAME_SPEED_REST {_c_double(frame.speed_rest if frame else 0.0)} /* the speed at which angles stand still */",
        f"static const double OPFMU_FRAME_INPUT_RATES[{n_u}] = {_c_array(rates)}; /* R */",
        f"static const double OPFMU_FRAME_INPUT_TORQUES[{n_u}] = {_c_array(torques)}; /* T */",
        f"static const double OPFMU_FRAME_ANGLES[{n_x}] = {_c_array(angles)}; /* A */",
        f"static const double OPFMU_FRAME_SPEED[{n_x}] = {_c_array(speed)}; /* W */",
    ]


def residual_limit(meta: dict) -> float:
    """The default residual_limit: the operator's own (metadata `residual_limit`, set by the export
    from its test split), else DEFAULT_RESIDUAL_LIMIT."""
    limit = meta.get("residual_limit")
    return DEFAULT_RESIDUAL_LIMIT if limit is None else float(limit)


def rollover_horizon(meta: dict) -> float:
    """The default rollover_horizon [s]: the operator's own (metadata `rollover_horizon_s`, set by the
    export: shorter than the horizon for a causally trained operator), else its whole horizon."""
    return float(meta["rollover_horizon_s"])


def correction_defaults(component) -> dict:
    """Defaults of the parameters of the window's corrections (corrections.c) and restarts. For a
    component whose rates are partly learned (Component.learned_states): the rest and slow-mode
    corrections, which read every state's rate from the right-hand side, are off (0), and so are the
    restarts at an input jump (restart_jump 0): its windows, like those it was trained on, start
    every rollover horizon whatever the input does, and one that starts at a fault's clearing would
    carry the devices' state through their two currents alone (measured: the feeder's largest P
    error on ieee14 9.3 % of its rating, 16.3 % with restarts; docs/results.md). The exact step of
    the affine states stays on."""
    learned = bool(component.learned_states)
    return {"rest_radius": 0.0 if learned else DEFAULT_REST_RADIUS,
            "slow_weight": 0.0 if learned else DEFAULT_SLOW_WEIGHT, "swing_weight": DEFAULT_SWING_WEIGHT,
            "restart_jump": 0.0 if learned else DEFAULT_RESTART_JUMP}


def surrogate_starts(meta: dict) -> dict:
    """Start values of the surrogate FMU's own parameters (SURROGATE_EXTRAS)."""
    return {"rollover_horizon": rollover_horizon(meta), "residual_limit": residual_limit(meta),
            **correction_defaults(meta["component"])}


def check_model_name(model_name) -> str:
    """model_name if it can be the FMU's modelIdentifier (a C identifier of at most 64 ASCII
    characters, no C keyword); BuildError otherwise."""
    if not isinstance(model_name, str) or not MODEL_NAME.fullmatch(model_name) or model_name in C_KEYWORDS:
        raise BuildError(f"model name {str(model_name)[:80]!r} must be a C identifier (letters, digits, _; "
                         "at most 64, not starting with a digit)")
    return model_name


def load_operator(onnx_path: Path):
    """(ModelProto, validated metadata) of an operator file; BuildError for anything unusable."""
    import onnx

    try:
        proto = onnx.load(str(onnx_path))
    except Exception as exc:  # onnx raises several types for unreadable files
        raise BuildError(f"{onnx_path} is not a readable ONNX file ({str(exc)[:200]})") from None
    try:
        meta = operator_metadata(proto)
    except ContractError as exc:
        raise BuildError(f"{onnx_path}: {exc}") from None
    return proto, meta


def default_state(meta: dict, onnx_path: Path) -> np.ndarray:
    """The default initial state: the machine's equilibrium at its inputs' start values (those of the
    operator's operating point, if it has one)."""
    component, params = meta["component"], meta["params"]
    try:
        x = start_state(component, params, meta.get("operating_point"))
    except ValueError as exc:
        raise BuildError(f"{onnx_path}: {exc}") from None
    if not all(math.isfinite(s) and s > 0 for s in component.state_scales):
        raise BuildError(f"the {component.name} component's state_scales must be finite and positive")
    return x


def build_surrogate_fmu(onnx_path, out, model_name: str = "SM4Surrogate", n_check: int = 32, platforms=None,
                        fmi_version: int = 2) -> dict:
    """Write the FMU to `out`. platforms: the binaries it carries (platforms.Platform objects or names;
    None: the host's only); fmi_version: 2 or 3 (the same model code, another plumbing). Binaries of
    other platforms are run here, and compared with the host's, where an emulator is installed.

    Returns {"guid", "max_abs_diff", "size_bytes", "binaries", "checks"} (binaries: {platform:
    {"path", "size_bytes"}}; checks: {platform: what running it found})."""
    onnx_path, out = Path(onnx_path), Path(out)
    check_model_name(model_name)
    version, chosen = check_fmi_version(fmi_version), targets(platforms)
    proto, meta = load_operator(onnx_path)
    component, params = meta["component"], meta["params"]
    x_default = default_state(meta, onnx_path)
    n_sensors = meta["n_sensors"]
    network = network_graph(proto)  # the frame is done by the engine (window.c)
    try:
        kernel = generate_kernel(network, n_sensors)
    except Exception as exc:  # an unsupported or malformed graph, found by the generator or shape inference
        raise BuildError(f"{onnx_path}: cannot generate C for the operator graph ({type(exc).__name__}: "
                         f"{str(exc)[:200]})") from None
    if (kernel.n_states, kernel.n_inputs) != (component.n_states, component.n_inputs):
        raise BuildError(f"{onnx_path}: the graph takes x0 [N, {kernel.n_states}] and u [N, S, {kernel.n_inputs}], "
                         f"but the {component.name} component has {component.n_states} states and "
                         f"{component.n_inputs} inputs")
    space = parameter_space(component, params, trained=True)
    spec = surrogate_self_start(meta, onnx_path)
    variables = surrogate_variables(meta, onnx_path, space)
    equations = ('#include <stdio.h>\n#include "engine.h"\n'
                 + equations_c_source(component, space, linkage="OPFMU_INTERNAL") + "\n"
                 + parameters_c_source(space, linkage="OPFMU_INTERNAL"))
    derivatives = derivatives_source(component, space)

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        src = tmp / "sources"
        src.mkdir()
        for name in (PLUMBING[version], *MODEL_SOURCES):
            shutil.copy(C_DIR / name, src / name)
        guid = _guid(onnx_path, model_name, kernel.source + equations + derivatives, version)
        (src / "operator_kernel.c").write_text(kernel.source)
        (src / "equations.c").write_text(equations)
        (src / "derivatives.c").write_text(derivatives)
        (src / "variables.h").write_text(vr_header(variables, component, self_start=spec))
        first_layer = kernel.first_layer
        suffix = None

        def kernel_object(target):  # the kernel (megabytes of weights) is compiled once per platform
            path = tmp / f"operator_kernel-{target.name}.o"
            return [path if path.exists() else compile_c(path, [src / "operator_kernel.c"], src, "object", target)]

        if first_layer:
            probe = compile_c(tmp / "probe.so", kernel_object(host()), src)
            suffix = sensor_suffix_sums(probe, n_sensors, first_layer, component.n_states, component.n_inputs)
            first_layer = first_layer if suffix is not None else 0
        (src / "sensor_sums.c").write_text(sensor_sums_source(suffix, n_sensors, first_layer, meta.get("frame"),
                                                              meta["horizon_s"]))
        (src / "config.h").write_text(config_header(model_name, guid, meta, x_default, first_layer, kernel, space,
                                                    spec))
        sources = [src / f for f in C_FILES + (START_C_FILES if spec else ())]
        binaries = compile_binaries(tmp, model_name, sources, src, chosen, version, kernel_object)
        worst = check_kernel(binaries[host()], proto, meta, n_check)
        if not worst <= KERNEL_TOLERANCE:
            raise BuildError(f"compiled kernel differs from onnxruntime by {worst:.2e} (> {KERNEL_TOLERANCE:g}); "
                             "FMU not written")
        checks = cross_check(binaries, variables, guid, version, tmp / "check", interpolates=version == 2)
        xml = model_description(model_name, guid, variables,
                                f"{component.description}; PI-DeepONet surrogate evaluated from buffered input sensors",
                                directional_derivatives=True, interpolates_inputs=True, fmi_version=version)
        written = write_fmu(out, tmp, xml, model_name, version, {p: binaries[p] for p in chosen},
                            {"model.onnx": onnx_path}, src)
    return {"guid": guid, "max_abs_diff": worst, "size_bytes": written["size_bytes"], "binaries": written["binaries"],
            "checks": checks}


def surrogate_self_start(meta: dict, onnx_path: Path):
    """The start from the load flow the surrogate FMU of an operator solves (as its component's
    native reference FMU: fmu_export.self_start), None where the component has none."""
    return self_start_of(meta["component"], meta["params"], default_state(meta, Path(onnx_path)),
                         meta.get("operating_point"))


def surrogate_variables(meta: dict, onnx_path: Path, space=None):
    """The surrogate FMU's variable table (fmu_export.variables) for an operator's validated metadata;
    space: its trained ParameterSpace (None: made here). A component with a bus port gets the bus
    port's outputs (the Norton equivalent at the surrogate's state, P and Q at the bus) on the system
    base its trained parameters name (`Sb`; 100 MVA where they name none); one that starts from the
    load flow, its start variables (surrogate_self_start)."""
    component, params = meta["component"], meta["params"]
    space = space or parameter_space(component, params, trained=True)
    spec = surrogate_self_start(meta, onnx_path)
    base = float(getattr(params, "Sb", SYSTEM_BASE_MVA))
    return fmu_variables(component, params, default_state(meta, Path(onnx_path)), SURROGATE_EXTRAS,
                         surrogate_starts(meta), meta.get("operating_point"), bus_outputs=True, base_mva=base,
                         space=space, self_start=spec and self_start_variables(spec, component))


def derivatives_source(component, space) -> str:
    """derivatives.c of a native FMU: the component's exact partial derivatives (forward-mode tracing
    of its one definition, fmu_export.c_derivatives) at the parameters of the build's ParameterSpace
    `space`, behind model.h's component_rhs_jacobian and component_output_jacobian; where the
    component has start equations of its own, them and their Jacobian (model_start_equations,
    component_start_jacobian: c/self_start.c solves them)."""
    n_x, n_u, n_y = component.n_states, component.n_inputs, len(component.outputs)
    return ('#include "model.h"\n' + jacobians_c_source(component, space) + "\n"
            + start_equations_c_source(component, space) +
            f"void component_rhs_jacobian(const double x[{c_size(n_x)}], const double u[{n_u}], const double p[], "
            f"double J[{c_size(n_x) * (n_x + n_u)}])\n"
            "{\n    model_derivatives_jacobian(x, u, p, J);\n}\n\n"
            f"void component_output_jacobian(const double x[{c_size(n_x)}], const double u[{n_u}], const double p[], "
            f"double J[{n_y * (n_x + n_u)}])\n"
            "{\n    model_outputs_jacobian(x, u, p, J);\n}\n")


def _guid(onnx_path: Path, model_name: str, generated: str, version: int = 2) -> str:
    """A GUID (FMI 3.0: instantiation token) that changes with everything compiled into the binary:
    operator, name, FMI version and C sources."""
    digest = hashlib.sha256(onnx_path.read_bytes() + model_name.encode() + generated.encode()
                            + (b"" if version == 2 else b"\0fmi3"))
    for name in (PLUMBING[version], *MODEL_SOURCES):
        digest.update((C_DIR / name).read_bytes())
    h = digest.hexdigest()
    return f"{{{h[:8]}-{h[8:12]}-{h[12:16]}-{h[16:20]}-{h[20:32]}}}"


def sensor_suffix_sums(library: Path, n_sensors: int, width: int, n_states: int, n_inputs: int):
    """Suffix sums [S + 1, n_u, H] over sensor slots of d z / d u, the sensor layer's response to each
    slot, so that z(x0, u) = z(x0, 0) + sum_k (suffix[k] - suffix[k + 1]) . u_k; None when z is not
    affine in u with a slope independent of x0 (then the FMU evaluates the whole kernel each step)."""
    lib = ctypes.CDLL(str(library))
    p = ctypes.POINTER(ctypes.c_double)
    u = np.zeros(n_inputs * n_sensors)
    z = np.zeros(width)

    def first_layer(x0, u_):
        lib.opfmu_first_layer(x0.ctypes.data_as(p), u_.ctypes.data_as(p), z.ctypes.data_as(p))
        return z.copy()

    x0 = np.zeros(n_states)
    base = first_layer(x0, u)
    slope = np.empty((n_inputs * n_sensors, width))
    for i in range(n_inputs * n_sensors):
        u[i] = 1.0
        slope[i] = first_layer(x0, u) - base
        u[i] = 0.0
    rng = np.random.default_rng(0)
    for _ in range(3):  # affine, with a slope that does not depend on x0
        x_r, u_r = rng.uniform(-1, 2, n_states), rng.uniform(-1, 2, n_inputs * n_sensors)
        predicted = first_layer(x_r, np.zeros_like(u_r)) + u_r @ slope
        if not np.allclose(first_layer(x_r, u_r), predicted, rtol=1e-9, atol=1e-9):
            return None
    per_slot = slope.reshape(n_sensors, n_inputs, width)
    suffix = np.zeros((n_sensors + 1, n_inputs, width))
    suffix[:-1] = np.cumsum(per_slot[::-1], axis=0)[::-1]
    return suffix


def ramp_suffix_sums(suffix, frame, horizon: float) -> np.ndarray:
    """[S + 1, H]: sum over slots j >= k of s_j R . slope_j, with slope_j = suffix[j] - suffix[j + 1]
    and R the frame's input ramps (its angle inputs' rate per speed unit; zeros without a frame): how
    the frame's ramp reaches z."""
    n_sensors, n_inputs, width = suffix.shape[0] - 1, suffix.shape[1], suffix.shape[2]
    if frame is None:
        return np.zeros((n_sensors + 1, width))
    per_slot = np.einsum("jch,c->jh", suffix[:-1] - suffix[1:], frame.input_ramps(n_inputs))
    s = np.linspace(0.0, horizon, n_sensors)
    ramp = np.zeros((n_sensors + 1, width))
    ramp[:-1] = np.cumsum((s[:, None] * per_slot)[::-1], axis=0)[::-1]
    return ramp


def time_suffix_sums(suffix, horizon: float) -> np.ndarray:
    """[S + 1, n_u, H]: sum over slots j >= k of s_j slope_j, per input, with slope_j = suffix[j] -
    suffix[j + 1] and s_j slot j's window time: how an input ramping over a step (its derivative
    set, fmi2SetRealInputDerivatives) reaches z."""
    n_sensors = suffix.shape[0] - 1
    s = np.linspace(0.0, horizon, n_sensors)
    weighted = np.zeros_like(suffix)
    weighted[:-1] = np.cumsum((s[:, None, None] * (suffix[:-1] - suffix[1:]))[::-1], axis=0)[::-1]
    return weighted


def _c_table(name: str, values: np.ndarray) -> str:
    if not np.all(np.isfinite(values)):
        raise BuildError("the operator's sensor layer has non-finite weights")
    literals = hex_literals(values)
    body = ",\n".join(",".join(literals[i:i + 8]) for i in range(0, len(literals), 8))
    return f"OPFMU_INTERNAL const double {name}[{values.size}] = {{\n{body}}};\n"


def sensor_sums_source(suffix, n_sensors: int, width: int, frame=None, horizon: float = 1.0) -> str:
    """C definitions of OPFMU_SENSOR_SUFFIX [(S + 1) * n_u * H], OPFMU_RAMP_SUFFIX [(S + 1) * H] and
    OPFMU_TIME_SUFFIX [(S + 1) * n_u * H] (one zero each when there is no split)."""
    split = suffix is not None and width
    values = suffix.ravel() if split else np.zeros(1)
    ramp = ramp_suffix_sums(suffix, frame, horizon).ravel() if split else np.zeros(1)
    timed = time_suffix_sums(suffix, horizon).ravel() if split else np.zeros(1)
    return ("/* Generated by opfmu: suffix sums over sensor slots of the sensor layer's slope. */\n"
            '#include "model.h"\n' + _c_table("OPFMU_SENSOR_SUFFIX", values) + _c_table("OPFMU_RAMP_SUFFIX", ramp)
            + _c_table("OPFMU_TIME_SUFFIX", timed))


def check_kernel(binary: Path, proto, meta: dict, n: int, seed: int = 0) -> float:
    """Max abs difference against onnxruntime of the compiled kernel (inside the FMU binary) on the
    network's graph and, for an operator with a frame, of the kernel with the engine's frame on the
    whole graph, under inputs turned by random angles (up to 30 rad) and speeds (angle rates up to 12 rad/s);
    relative to contract.check_scale, as the export's check (onnxruntime computes in float32)."""
    import onnxruntime as ort

    n_sensors, horizon = meta["n_sensors"], meta["horizon_s"]
    t_grid = np.linspace(0.0, horizon, n_sensors)
    rng = np.random.default_rng(seed)
    x0, u, t = random_inputs(meta["envelope"], t_grid, n, rng)
    t = t[:: max(1, len(t) // 9)]
    library = ctypes.CDLL(str(binary))
    cases = [(network_graph(proto), library.opfmu_operator, x0, u)]
    if meta.get("frame") is not None:
        cases.append((proto, library.opfmu_framed_operator,
                      *drifted(meta["frame"], x0, u, t_grid, rng.uniform(-30, 30, n),
                               rng.uniform(-12, 12, n) / meta["frame"].speed_scale)))
    worst = 0.0
    for graph, fn, x0_, u_ in cases:
        try:
            expected = ort.InferenceSession(graph.SerializeToString(), providers=["CPUExecutionProvider"]).run(
                ["x"], {"x0": x0_, "u": u_, "t": t})[0]
        except Exception as exc:  # onnxruntime's own errors for graphs it cannot load or run
            raise BuildError(f"onnxruntime cannot run the operator ({str(exc)[:200]})") from None
        double_p = ctypes.POINTER(ctypes.c_double)
        fn.argtypes = [double_p, double_p, ctypes.c_double, double_p]
        out = np.zeros(x0_.shape[1])
        for i in range(n):
            xi, ui = np.ascontiguousarray(x0_[i], np.float64), np.ascontiguousarray(u_[i], np.float64)
            for j, tj in enumerate(t):
                fn(xi.ctypes.data_as(double_p), ui.ctypes.data_as(double_p), float(tj), out.ctypes.data_as(double_p))
                worst = max(worst, float(np.max(np.abs(out - expected[i, j]) / check_scale(meta, expected[i, j]))))
    return worst
