"""C code for an exported operator, generated from its ONNX graph (no runtime needed).

The graph is specialised to one trajectory and one query time (x0 [1, n_x], u [1, S, n_u], t [1],
with n_x and n_u read from the graph's inputs); shape inference then fixes every tensor's shape, and
each node becomes a loop over fixed sizes. Only an explicit, checked subset of ONNX operators is
supported; any other is refused by name. Weights stay float32 (as exported); arithmetic is in double.

Generated entry point:
    void opfmu_operator(const double x0[n_x], const double u[n_u * OPFMU_N_SENSORS], double t, double x[n_x]);
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

ELEMENTWISE = {"Add": "+", "Sub": "-", "Mul": "*", "Div": "/"}
UNARY = {"Tanh": "opfmu_tanh({})", "Exp": "exp({})", "Neg": "(-{})", "Sqrt": "sqrt({})", "Sin": "sin({})",
         "Cos": "cos({})", "Relu": "({0} > 0.0 ? {0} : 0.0)", "Sigmoid": "(1.0 / (1.0 + exp(-{})))"}
COPIES = {"Flatten", "Reshape", "Unsqueeze", "Squeeze", "Identity"}
SUPPORTED = set(ELEMENTWISE) | set(UNARY) | COPIES | {"Gemm", "MatMul", "Transpose", "Concat", "Constant"}


# the kernel functions are compiled twice on x86-64 with gcc, for AVX2/FMA machines and for any other,
# and the loader picks one at run time (the FMU stays portable; the AVX2 build is about 1.3x faster)
VECTOR = """#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define OPFMU_VECTOR __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define OPFMU_VECTOR
#endif"""

# tanh through one exp: within 3e-16 of libm's tanh and about twice as fast (most of a step's cost is tanh)
TANH = """static double opfmu_tanh(double x)
{
    const double e = exp(-2.0 * fabs(x));
    return copysign((1.0 - e) / (1.0 + e), x);
}"""


class UnsupportedGraph(ValueError):
    """A graph with an operator (or a use of one) outside the supported subset."""


def check_supported(proto) -> None:
    """Raise UnsupportedGraph naming every operator outside SUPPORTED."""
    unknown = sorted({n.op_type for n in proto.graph.node} - SUPPORTED)
    if unknown:
        raise UnsupportedGraph(f"the operator uses ONNX ops the C kernel does not support: {', '.join(unknown)} "
                               f"(supported: {', '.join(sorted(SUPPORTED))})")


def graph_interface(proto) -> tuple:
    """(n_x, n_u, S) of an operator graph: inputs exactly x0 [N, n_x], u [N, S, n_u], t [M] and one
    output x; S is None where the graph leaves it symbolic. UnsupportedGraph otherwise."""
    inputs = {v.name: v for v in proto.graph.input}
    if sorted(inputs) != ["t", "u", "x0"] or [o.name for o in proto.graph.output] != ["x"]:
        raise UnsupportedGraph(f"the graph must take inputs x0, u, t and give output x (it takes "
                               f"{', '.join(sorted(inputs))[:80]} and gives {', '.join(o.name for o in proto.graph.output)[:80]})")

    def dims(name, rank):
        shape = inputs[name].type.tensor_type.shape.dim
        if len(shape) != rank:
            raise UnsupportedGraph(f"graph input {name} must have {rank} dimensions, has {len(shape)}")
        return [d.dim_value if d.HasField("dim_value") else None for d in shape]

    x0, u = dims("x0", 2), dims("u", 3)
    dims("t", 1)
    if not (x0[1] and u[2]):
        raise UnsupportedGraph("graph inputs x0 and u must fix their last dimension (states, input channels)")
    return x0[1], u[2], u[1]


def _specialised(proto, n_sensors: int, n_states: int, n_inputs: int):
    """A copy with concrete input shapes (N = 1, M = 1) and every intermediate shape inferred."""
    import onnx

    proto = onnx.ModelProto.FromString(proto.SerializeToString())
    shapes = {"x0": [1, n_states], "u": [1, n_sensors, n_inputs], "t": [1]}
    for value in proto.graph.input:
        dims = value.type.tensor_type.shape.dim
        for dim, size in zip(dims, shapes[value.name]):
            dim.Clear()
            dim.dim_value = size
    del proto.graph.value_info[:]
    for out in proto.graph.output:
        out.type.tensor_type.ClearField("shape")
    return onnx.shape_inference.infer_shapes(proto, strict_mode=True)


def _shape(value) -> tuple:
    dims = value.type.tensor_type.shape.dim
    if any(not d.HasField("dim_value") for d in dims):
        raise UnsupportedGraph(f"shape of {value.name!r} is not fixed after specialisation")
    return tuple(d.dim_value for d in dims)


def _strides(shape) -> list[int]:
    return [int(np.prod(shape[i + 1:])) for i in range(len(shape))]


def _offset(index: str, out_shape, in_shape) -> str:
    """C expression of the flat index into an input broadcast to out_shape, from the flat output index."""
    in_shape = (1,) * (len(out_shape) - len(in_shape)) + tuple(in_shape)
    out_strides, in_strides = _strides(out_shape), _strides(in_shape)
    terms = []
    for d, (o, i) in enumerate(zip(out_shape, in_shape)):
        if i == 1 or in_strides[d] == 0:
            continue
        coordinate = f"({index} / {out_strides[d]})" if out_strides[d] > 1 else index
        coordinate = f"({coordinate} % {o})" if d > 0 else coordinate
        terms.append(coordinate if in_strides[d] == 1 else f"{coordinate} * {in_strides[d]}")
    return " + ".join(terms) or "0"


def _float_array(name: str, values: np.ndarray) -> str:
    flat = np.asarray(values, dtype=np.float32).ravel()
    body = ",".join(repr(float(v)) + "f" if math.isfinite(v) else "0.0f" for v in flat)
    return f"static const float {name}[{max(flat.size, 1)}] = {{{body or '0.0f'}}};"


@dataclass(frozen=True)
class Kernel:
    """Generated C source; first_layer is the width H of the split point (0 if none); trunk_size and
    coef_size the lengths T and C of the trunk values and coefficients (0 if none; see _trunk_functions);
    n_states and n_inputs the graph's n_x and n_u.

    With a split point, the source also defines
        void opfmu_first_layer(const double x0[n_x], const double u[n_u * S], double z[H]);
        void opfmu_from_first_layer(const double x0[n_x], const double z[H], double t, double x[n_x]);
    where z is the output of the first Gemm fed by the sensors, and the second function finishes the
    evaluation from it (everything but the sensor path), so a caller that tracks z incrementally
    never re-runs the sensor layer.
    """

    source: str
    first_layer: int
    trunk_size: int
    coef_size: int
    n_states: int
    n_inputs: int


def generate_kernel(proto, n_sensors: int) -> Kernel:
    """C source of the operator `proto` (an onnx.ModelProto) for S = n_sensors sensor times; the
    numbers of states and input channels come from the graph (graph_interface)."""
    from onnx import numpy_helper

    check_supported(proto)
    n_x, n_u, graph_sensors = graph_interface(proto)
    if graph_sensors is not None and graph_sensors != n_sensors:
        raise UnsupportedGraph(f"the graph's input u has {graph_sensors} sensor times, not {n_sensors}")
    model = _specialised(proto, n_sensors, n_x, n_u)
    graph = model.graph
    shapes = {v.name: _shape(v) for v in list(graph.input) + list(graph.value_info) + list(graph.output)}
    names, constants, nodes = {}, [], []  # nodes: (node, declaration, code)

    def c_name(tensor: str) -> str:
        return names.setdefault(tensor, f"v{len(names)}")

    # weights a Gemm reads transposed (transB = 1) are stored transposed, so its inner loop reads them
    # contiguously; each such weight must feed that one Gemm only
    uses = {}
    for node in graph.node:
        for i in node.input:
            uses[i] = uses.get(i, 0) + 1
    initializers = {init.name for init in graph.initializer}
    stored_transposed = {n.input[1] for n in graph.node if n.op_type == "Gemm" and n.input[1] in initializers
                         and uses[n.input[1]] == 1 and any(a.name == "transB" and a.i for a in n.attribute)}
    for init in graph.initializer:
        array = numpy_helper.to_array(init)
        if init.name in stored_transposed:
            array = array.T
        shapes[init.name] = array.shape
        if array.dtype.kind == "f":
            constants.append(_float_array(c_name(init.name), array))
    names.update({"x0": "x0", "u": "u", "t": "t_"})

    for node in graph.node:
        op, out = node.op_type, node.output[0]
        attrs = {a.name: a for a in node.attribute}
        if op == "Constant":
            array = numpy_helper.to_array(attrs["value"].t)
            shapes[out] = array.shape
            if array.dtype.kind == "f":
                constants.append(_float_array(c_name(out), array))
            continue
        if op == "Identity" and node.input[0] in initializers:  # the exporter's alias of a shared weight
            names[out] = c_name(node.input[0])
            initializers.add(out)
            continue
        shape = shapes[out]
        size = int(np.prod(shape))
        dst = c_name(out)
        src = [c_name(i) for i in node.input]
        if op in ELEMENTWISE:
            a, b = node.input
            code = (f"    for (int i = 0; i < {size}; ++i) {dst}[i] = {src[0]}[{_offset('i', shape, shapes[a])}] "
                    f"{ELEMENTWISE[op]} {src[1]}[{_offset('i', shape, shapes[b])}];")
        elif op in UNARY:
            code = f"    for (int i = 0; i < {size}; ++i) {dst}[i] = {UNARY[op].format(src[0] + '[i]')};"
        elif op in COPIES:
            code = f"    for (int i = 0; i < {size}; ++i) {dst}[i] = {src[0]}[i];"
        elif op == "Gemm":
            if node.input[1] in stored_transposed:
                attrs = {k: v for k, v in attrs.items() if k != "transB"}
            code = _gemm(node, attrs, src, dst, shapes)
        elif op == "MatMul":
            code = _matmul(node, src, dst, shapes)
        elif op == "Transpose":
            code = _transpose(attrs, src[0], dst, shapes[node.input[0]], shape)
        else:  # Concat
            code = _concat(node, attrs, src, dst, shapes, shape)
        nodes.append((node, f"    double {dst}[{max(size, 1)}];", code))

    result = c_name(graph.output[0].name)
    if int(np.prod(shapes[graph.output[0].name])) != n_x:
        raise UnsupportedGraph(f"the graph's output x has shape {shapes[graph.output[0].name]} for one trajectory "
                               f"and one time, not [1, 1, {n_x}]")
    x0_arg, u_arg = f"const double x0[{n_x}]", f"const double u[{n_u} * OPFMU_N_SENSORS]"
    copy_x = f"    for (int i = 0; i < {n_x}; ++i) x[i] = {result}[i];"
    lines = ["/* Generated by opfmu from an ONNX operator graph; do not edit. */", "#include <math.h>",
             f"#define OPFMU_N_SENSORS {n_sensors}", VECTOR, TANH, *constants, ""]
    lines += _function(f"void opfmu_operator({x0_arg}, {u_arg}, double t, double x[{n_x}])", nodes, copy_x)
    split = _sensor_layer(graph, [n for n, _, _ in nodes])
    if split is None:
        return Kernel("\n".join(lines), 0, 0, 0, n_x, n_u)
    first, _ = split
    width = int(np.prod(shapes[first.output[0]]))
    z = c_name(first.output[0])
    needed = _ancestors({n.output[0]: n for n, _, _ in nodes}, first.output[0])
    head = [entry for entry in nodes if entry[0].output[0] in needed]
    after = _ancestors({n.output[0]: n for n, _, _ in nodes}, graph.output[0].name, cut=first.output[0])
    rest = [entry for entry in nodes if entry[0].output[0] in after and entry[0] is not first]
    lines += _function(f"void opfmu_first_layer({x0_arg}, {u_arg}, double z[{width}])",
                       head, f"    for (int i = 0; i < {width}; ++i) z[i] = {z}[i];")
    lines += _function(f"void opfmu_from_first_layer({x0_arg}, const double z[{width}], double t, double x[{n_x}])",
                       [(None, f"    const double *{z} = z;", "")] + rest, copy_x)
    trunk_size, coef_size, trunk_lines = _trunk_functions(rest, shapes, c_name, z, width, n_x, copy_x)
    return Kernel("\n".join(lines + trunk_lines), width, trunk_size, coef_size, n_x, n_u)


def _trunk_functions(rest, shapes, c_name, z: str, width: int, n_x: int, copy_x: str):
    """(T, C, source lines): the evaluation after the sensor layer split into three parts,
        void opfmu_trunk(double t, double tau[T]);            what depends on t alone
        void opfmu_coefficients(const double x0[n_x], const double z[H], double c[C]);   on x0, z alone
        void opfmu_head(const double c[C], const double tau[T], double x[n_x]);          the rest
    (for a DeepONet: the basis, the coefficients B and their product), so a caller can keep tau per
    query time and evaluate the state at other times from the same coefficients for the price of the
    head. (0, 0, []) when the graph does not split so."""
    producer = {n.output[0]: n for n, _, _ in rest}
    from_t = {"t"}
    for tensor, node in producer.items():  # topological order
        inputs = [i for i in node.input if i]
        if any(i in from_t for i in inputs) and all(i in from_t or (i not in producer and i not in ("x0", "u", z))
                                                     for i in inputs):
            from_t.add(tensor)
    trunk = [entry for entry in rest if entry[0].output[0] in from_t]
    others = [entry for entry in rest if entry[0].output[0] not in from_t]
    boundary = list(dict.fromkeys(i for node, _, _ in others for i in node.input if i in from_t and i != "t"))
    after_tau = set(boundary)
    for node, _, _ in others:
        if any(i in after_tau for i in node.input):
            after_tau.add(node.output[0])
    head = [entry for entry in others if entry[0].output[0] in after_tau]
    coefficients = [entry for entry in others if entry[0].output[0] not in after_tau]
    coef_out = {node.output[0] for node, _, _ in coefficients}
    handed = list(dict.fromkeys(i for node, _, _ in head for i in node.input if i in coef_out))
    if (not trunk or not boundary or not handed or any("t" in node.input for node, _, _ in others)
            or any(i in ("x0", z) for node, _, _ in head for i in node.input)):
        return 0, 0, []

    def packed(tensors, array):
        sizes = [int(np.prod(shapes[b])) for b in tensors]
        offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        copy_out = "\n".join(f"    for (int i = 0; i < {size}; ++i) {array}[{offset} + i] = {c_name(b)}[i];"
                             for b, size, offset in zip(tensors, sizes, offsets))
        views = [(None, f"    const double *{c_name(b)} = {array} + {offset};", "") for b, offset in zip(tensors, offsets)]
        return int(offsets[-1]), copy_out, views

    n_tau, tau_out, tau_views = packed(boundary, "tau")
    n_coef, coef_copy, coef_views = packed(handed, "c")
    lines = _function(f"void opfmu_trunk(double t, double tau[{n_tau}])", trunk, tau_out)
    lines += _function(f"void opfmu_coefficients(const double x0[{n_x}], const double z[{width}], double c[{n_coef}])",
                       [(None, f"    const double *{z} = z;", "")] + coefficients, coef_copy)
    lines += _function(f"void opfmu_head(const double c[{n_coef}], const double tau[{n_tau}], double x[{n_x}])",
                       coef_views + tau_views + head, copy_x)
    return n_tau, n_coef, lines


def _function(signature: str, nodes, tail: str) -> list[str]:
    body = [decl for _, decl, _ in nodes] + [code for _, _, code in nodes if code]
    return ["OPFMU_VECTOR " + signature, "{", "    const double t_[1] = {t};" if "double t," in signature else "", *body, tail, "}", ""]


def _sensor_layer(graph, nodes):
    """(first Gemm fed by the sensors, ids of the nodes on the sensor path before it), when the
    sensors reach the output only through that Gemm; else None."""
    producer = {n.output[0]: n for n in nodes}
    from_u = _dependents(producer, "u", None)
    first = next((n for n in nodes if n.op_type == "Gemm" and n.input[0] in from_u), None)
    if first is None:
        return None
    feeding = _ancestors(producer, first.input[0])
    path = {id(n) for n in nodes if n.output[0] in from_u and n.output[0] in feeding}
    around = _dependents(producer, "u", first.output[0])  # reached from u other than through the Gemm
    if any(i in around for n in nodes if id(n) not in path and n is not first for i in n.input):
        return None
    return first, path


def _dependents(producer: dict, source: str, cut: str | None) -> set:
    """Tensors that depend on `source`, not looking through the tensor `cut`."""
    found = {source}
    for tensor, node in producer.items():  # nodes are in topological order
        if tensor != cut and any(i in found and i != cut for i in node.input):
            found.add(tensor)
    return found


def _ancestors(producer: dict, tensor: str, cut: str | None = None) -> set:
    """`tensor` and every tensor it is computed from, not looking through the tensor `cut`."""
    seen, todo = set(), [tensor]
    while todo:
        t = todo.pop()
        if t not in seen:
            seen.add(t)
            todo += [i for i in producer[t].input if i] if t in producer and t != cut else []
    return seen


def _gemm(node, attrs, src, dst, shapes) -> str:
    """Y = alpha A' B' + beta C as an outer-product accumulation: for each row, Y[r, :] starts at the
    bias and gains alpha A'[r, p] B'[p, :] for p in order. The innermost loop runs over independent
    outputs (no reduction chain), so it vectorises and pipelines; the sum over p keeps its order."""
    alpha = attrs["alpha"].f if "alpha" in attrs else 1.0
    beta = attrs["beta"].f if "beta" in attrs else 1.0
    if not (math.isfinite(alpha) and math.isfinite(beta)):
        raise UnsupportedGraph(f"Gemm {node.name[:40]!r} has a non-finite alpha or beta")
    trans_a = attrs["transA"].i if "transA" in attrs else 0
    trans_b = attrs["transB"].i if "transB" in attrs else 0
    a_shape, b_shape = shapes[node.input[0]], shapes[node.input[1]]
    m, k = (a_shape[1], a_shape[0]) if trans_a else a_shape
    n = b_shape[0] if trans_b else b_shape[1]
    a_index = f"p * {m} + r" if trans_a else f"r * {k} + p"
    b_index = f"c * {k} + p" if trans_b else f"p * {n} + c"
    bias = "0.0"
    if len(node.input) > 2 and node.input[2]:
        bias = f"{beta!r} * {src[2]}[{_offset('(r * %d + c)' % n, (m, n), shapes[node.input[2]])}]"
    return (f"    for (int r = 0; r < {m}; ++r) {{\n"
            f"        double *y = {dst} + r * {n};\n"
            f"        for (int c = 0; c < {n}; ++c) y[c] = {bias};\n"
            f"        for (int p = 0; p < {k}; ++p) {{\n"
            f"            const double a = {alpha!r} * (double){src[0]}[{a_index}];\n"
            f"            for (int c = 0; c < {n}; ++c) y[c] += a * (double){src[1]}[{b_index}];\n"
            f"        }}\n    }}")


def _matmul(node, src, dst, shapes) -> str:
    """Batched A @ B, accumulated row by row as in _gemm."""
    a_shape, b_shape = shapes[node.input[0]], shapes[node.input[1]]
    if len(a_shape) < 2 or len(b_shape) < 2:
        raise UnsupportedGraph("MatMul with a 1-D operand is not supported")
    m, k = a_shape[-2:]
    n = b_shape[-1]
    batch = np.broadcast_shapes(a_shape[:-2], b_shape[:-2])
    n_batch = int(np.prod(batch)) if batch else 1
    a_off = _offset("q", batch, a_shape[:-2]) if batch else "0"
    b_off = _offset("q", batch, b_shape[:-2]) if batch else "0"
    return (f"    for (int q = 0; q < {n_batch}; ++q) for (int r = 0; r < {m}; ++r) {{\n"
            f"        double *y = {dst} + q * {m * n} + r * {n};\n"
            f"        for (int c = 0; c < {n}; ++c) y[c] = 0.0;\n"
            f"        for (int p = 0; p < {k}; ++p) {{\n"
            f"            const double a = (double){src[0]}[({a_off}) * {m * k} + r * {k} + p];\n"
            f"            for (int c = 0; c < {n}; ++c) y[c] += a * (double){src[1]}[({b_off}) * {k * n} + p * {n} + c];\n"
            f"        }}\n    }}")


def _transpose(attrs, src, dst, in_shape, out_shape) -> str:
    perm = list(attrs["perm"].ints) if "perm" in attrs else list(reversed(range(len(in_shape))))
    in_strides, out_strides = _strides(in_shape), _strides(out_shape)
    terms = [f"((i / {out_strides[d]}) % {out_shape[d]}) * {in_strides[perm[d]]}" for d in range(len(out_shape))]
    return f"    for (int i = 0; i < {int(np.prod(out_shape))}; ++i) {dst}[i] = {src}[{' + '.join(terms) or '0'}];"


def _concat(node, attrs, src, dst, shapes, out_shape) -> str:
    axis = attrs["axis"].i % len(out_shape)
    outer = int(np.prod(out_shape[:axis]))
    out_block = int(np.prod(out_shape[axis:]))
    lines, start = [], 0
    for name, tensor in zip(src, node.input):
        block = int(np.prod(shapes[tensor][axis:]))
        lines.append(f"    for (int o = 0; o < {outer}; ++o) for (int j = 0; j < {block}; ++j) "
                     f"{dst}[o * {out_block} + {start} + j] = {name}[o * {block} + j];")
        start += block
    return "\n".join(lines)
