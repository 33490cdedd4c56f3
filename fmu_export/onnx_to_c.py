"""C code for an exported operator, generated from its ONNX graph (no runtime needed).

The graph is specialised to one trajectory and one query time (x0 [1, n_x], u [1, S, n_u], t [1],
with n_x and n_u read from the graph's inputs); shape inference then fixes every tensor's shape, and
each node becomes a loop over fixed sizes. Only an explicit, checked subset of ONNX operators is
supported; any other is refused by name. Weights stay float32 (as exported); arithmetic is in double.
A Gemm's weights are stored in the order its product reads them, and the products and tanh, most of
the cost, have AVX2/FMA versions that x86-64 CPUs with those instructions take (DISPATCH).

Generated entry point:
    void opfmu_operator(const double x0[n_x], const double u[n_u * OPFMU_N_SENSORS], double t, double x[n_x]);
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

ELEMENTWISE = {"Add": "+", "Sub": "-", "Mul": "*", "Div": "/"}
UNARY = {"Exp": "exp({})", "Neg": "(-{})", "Sqrt": "sqrt({})", "Sin": "sin({})",
         "Cos": "cos({})", "Relu": "({0} > 0.0 ? {0} : 0.0)", "Sigmoid": "(1.0 / (1.0 + exp(-{})))"}
COPIES = {"Flatten", "Reshape", "Unsqueeze", "Squeeze", "Identity"}
SUPPORTED = set(ELEMENTWISE) | set(UNARY) | COPIES | {"Tanh", "Gemm", "MatMul", "Transpose", "Concat", "Constant"}
# output columns a Gemm accumulates at once from its weights stored in panels (_gemm, PRODUCT): 32
# doubles are 8 AVX2 registers, as many independent sums as two FMA pipes of latency 4 keep busy (and
# half of the 16 registers, so none is spilled)
PANEL = 32


# The kernel functions are compiled twice on x86-64 with gcc, for AVX2/FMA machines and for any other,
# and the loader picks one at run time (the FMU stays portable). Windows has no such loader (ifunc):
# there they are compiled once, for any x86-64.
VECTOR = """#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#if defined(_WIN32)
#define OPFMU_VECTOR
#else
#define OPFMU_VECTOR __attribute__((target_clones("arch=x86-64-v3", "default")))
#endif
#ifndef OPFMU_X86 /* -DOPFMU_X86=0 builds the portable loops alone */
#define OPFMU_X86 1
#endif
#else
#undef OPFMU_X86
#define OPFMU_VECTOR
#define OPFMU_X86 0
#endif"""

# The two loops that are most of a step, the weight products of the Gemms and tanh, are in addition
# written out in AVX2/FMA instructions, taken on x86-64 CPUs that have them (decided once, when the
# binary loads): gcc's own vectorisation of the plain product converts float32 weights through extra
# shuffles and spills a sum (about twice as slow), and it does not vectorise tanh's exp at all. Any other
# CPU runs the plain loops, whose results differ from the vector ones in the last bits (the products
# unfused, tanh through libm's exp).
DISPATCH = """#if OPFMU_X86
#include <immintrin.h>
static int opfmu_avx2; /* the CPU has AVX2 and FMA */
__attribute__((constructor)) static void opfmu_pick(void)
{
    __builtin_cpu_init();
    opfmu_avx2 = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
}
#endif"""

# tanh through one exp (libm's): within 3e-16 of libm's tanh and about twice as fast. The AVX2 version
# computes exp(-2 |x|) = 2^k exp(r) with k = round(-2 |x| / ln 2), |r| <= ln 2 / 2, and exp(r) by its
# Taylor polynomial of degree 13 (truncation below 5e-18): within 4e-16 of libm's tanh, and it keeps
# tanh(+-0) = +-0, tanh(+-inf) = +-1 and NaN.
TANH = """static double opfmu_tanh(double x)
{
    const double e = exp(-2.0 * fabs(x));
    return copysign((1.0 - e) / (1.0 + e), x);
}

#if OPFMU_X86
__attribute__((target("avx2,fma"))) static inline __m256d opfmu_tanh4(__m256d x)
{
    const __m256d sign = _mm256_set1_pd(-0.0), one = _mm256_set1_pd(1.0);
    /* y = -2 |x|, at least -40 (a NaN stays); below -40 exp(y) < 2^-54 and the quotient is 1 either way */
    const __m256d y = _mm256_max_pd(_mm256_set1_pd(-40.0), _mm256_mul_pd(_mm256_set1_pd(-2.0),
                                                                          _mm256_andnot_pd(sign, x)));
    /* k = y / ln 2 rounded, also held in the low bits of `shifted`; r = y - k ln 2 in two parts */
    const __m256d shifted = _mm256_fmadd_pd(y, _mm256_set1_pd(0x1.71547652b82fep0), _mm256_set1_pd(0x1.8p52));
    const __m256d k = _mm256_sub_pd(shifted, _mm256_set1_pd(0x1.8p52));
    const __m256d r = _mm256_fnmadd_pd(k, _mm256_set1_pd(0x1.abc9e3b39803fp-56),
                                       _mm256_fnmadd_pd(k, _mm256_set1_pd(0x1.62e42fefa39efp-1), y));
    /* exp(r): sum of r^i / i! for i <= 13, by Estrin's scheme */
    const __m256d r2 = _mm256_mul_pd(r, r), r4 = _mm256_mul_pd(r2, r2), r8 = _mm256_mul_pd(r4, r4);
    const __m256d q0 = _mm256_add_pd(r, one);
    const __m256d q1 = _mm256_fmadd_pd(r, _mm256_set1_pd(1.0 / 6), _mm256_set1_pd(1.0 / 2));
    const __m256d q2 = _mm256_fmadd_pd(r, _mm256_set1_pd(1.0 / 120), _mm256_set1_pd(1.0 / 24));
    const __m256d q3 = _mm256_fmadd_pd(r, _mm256_set1_pd(1.0 / 5040), _mm256_set1_pd(1.0 / 720));
    const __m256d q4 = _mm256_fmadd_pd(r, _mm256_set1_pd(1.0 / 362880), _mm256_set1_pd(1.0 / 40320));
    const __m256d q5 = _mm256_fmadd_pd(r, _mm256_set1_pd(1.0 / 39916800), _mm256_set1_pd(1.0 / 3628800));
    const __m256d q6 = _mm256_fmadd_pd(r, _mm256_set1_pd(1.0 / 6227020800), _mm256_set1_pd(1.0 / 479001600));
    const __m256d s0 = _mm256_fmadd_pd(r2, q1, q0), s1 = _mm256_fmadd_pd(r2, q3, q2), s2 = _mm256_fmadd_pd(r2, q5, q4);
    const __m256d p = _mm256_fmadd_pd(r8, _mm256_fmadd_pd(r4, q6, s2), _mm256_fmadd_pd(r4, s1, s0));
    /* 2^k from the bits of k + 1023 */
    const __m256i bits = _mm256_add_epi64(_mm256_castpd_si256(shifted), _mm256_set1_epi64x(1023 - 0x4338000000000000LL));
    const __m256d e = _mm256_mul_pd(p, _mm256_castsi256_pd(_mm256_slli_epi64(bits, 52)));
    const __m256d q = _mm256_div_pd(_mm256_sub_pd(one, e), _mm256_add_pd(one, e));
    return _mm256_or_pd(q, _mm256_and_pd(sign, x)); /* q >= 0: with x's sign */
}

__attribute__((target("avx2,fma"))) static void opfmu_tanh_avx2(int n, const double *x, double *y)
{
    int i = 0;
    for (; i + 4 <= n; i += 4) _mm256_storeu_pd(y + i, opfmu_tanh4(_mm256_loadu_pd(x + i)));
    if (i < n) { /* the last 1-3 values, by the same formula */
        double in[4] = {0.0, 0.0, 0.0, 0.0}, out[4];
        for (int j = 0; i + j < n; ++j) in[j] = x[i + j];
        _mm256_storeu_pd(out, opfmu_tanh4(_mm256_loadu_pd(in)));
        for (int j = 0; i + j < n; ++j) y[i + j] = out[j];
    }
}
#endif

/* y[i] = tanh(x[i]), i < n */
static void opfmu_tanh_array(int n, const double *x, double *y)
{
#if OPFMU_X86
    if (opfmu_avx2) {
        opfmu_tanh_avx2(n, x, y);
        return;
    }
#endif
    for (int i = 0; i < n; ++i) y[i] = opfmu_tanh(x[i]);
}"""

# The weight product of a Gemm's row, y[c] += sum over p in order of x[p] W[p, c] for its n outputs,
# with W [k, n] stored in panels of OPFMU_PANEL columns (each [k, width] row-major, _panels) and y
# holding the bias: each panel's sums stay in registers over the whole of p while its weights stream
# by contiguously. The AVX2 version converts 4 float32 weights and fuses their multiply-add at a time.
# The sensor layer's product (opfmu_product_sparse) skips the inputs that are exactly zero, which adds
# nothing but the sign of a zero sum: a window's start evaluates it with every sensor at zero, for the
# part of its output that comes from the start state and the bias (4 of 2006 inputs for SM4).
PANEL_PLAIN = """#define OPFMU_PANEL {panel}
static inline void opfmu_panel(int k, int width, const float *restrict w, const double *restrict x,
                               double *restrict y, int skip_zeros)
{{
    double acc[OPFMU_PANEL];
    for (int j = 0; j < width; ++j) acc[j] = y[j];
    for (int p = 0; p < k; ++p) {{
        const double a = x[p];
        if (skip_zeros && a == 0.0) continue;
        for (int j = 0; j < width; ++j) acc[j] += a * (double)w[p * width + j];
    }}
    for (int j = 0; j < width; ++j) y[j] = acc[j];
}}"""
PRODUCT_AVX2 = """__attribute__((target("avx2,fma"))) static void opfmu_{name}_avx2(int k, int n, const float *restrict w,
                                                                    const double *restrict x, double *restrict y)
{{
    int c = 0;{inputs}
    for (; c + OPFMU_PANEL <= n; c += OPFMU_PANEL) {{
        const float *panel = w + c * k;
{load}
        for ({loop}) {{{pick}
            const __m256d a = _mm256_set1_pd(x[p]);
            const float *v = panel + p * OPFMU_PANEL;
{step}
        }}
{store}
    }}
    if (c < n) opfmu_panel(k, n - c, w + c * k, x, y + c, {skip_zeros}); /* the narrower last panel */
}}"""
PRODUCT = """static void opfmu_{name}(int k, int n, const float *w, const double *x, double *y)
{{
#if OPFMU_X86
    if (opfmu_avx2) {{
        opfmu_{name}_avx2(k, n, w, x, y);
        return;
    }}
#endif
    int c = 0;
    for (; c + OPFMU_PANEL <= n; c += OPFMU_PANEL) opfmu_panel(k, OPFMU_PANEL, w + c * k, x, y + c, {skip_zeros});
    if (c < n) opfmu_panel(k, n - c, w + c * k, x, y + c, {skip_zeros});
}}"""


def _product_source(names) -> str:
    """PANEL_PLAIN and, for each of the names used ("product", "product_sparse"), its AVX2 version
    (PANEL / 4 sums of 4 in named registers) and its dispatch."""
    vectors = range(PANEL // 4)
    load = "\n".join(f"        __m256d s{i} = _mm256_loadu_pd(y + c + {4 * i});" for i in vectors)
    step = "\n".join(f"            s{i} = _mm256_fmadd_pd(a, _mm256_cvtps_pd(_mm_loadu_ps(v + {4 * i})), s{i});"
                     for i in vectors)
    store = "\n".join(f"        _mm256_storeu_pd(y + c + {4 * i}, s{i});" for i in vectors)
    parts, x86 = [PANEL_PLAIN.format(panel=PANEL)], []
    for name in sorted(names):
        sparse = int(name == "product_sparse")
        if sparse:  # the inputs that are not zero, listed once for all panels
            inputs = "\n    int nonzero[k], m = 0;\n    for (int p = 0; p < k; ++p)\n        if (x[p] != 0.0) nonzero[m++] = p;"
            loop, pick = "int i = 0; i < m; ++i", "\n            const int p = nonzero[i];"
        else:
            inputs, loop, pick = "", "int p = 0; p < k; ++p", ""
        x86.append(PRODUCT_AVX2.format(name=name, load=load, step=step, store=store, inputs=inputs, loop=loop,
                                       pick=pick, skip_zeros=sparse))
        parts.append(PRODUCT.format(name=name, skip_zeros=sparse))
    return "\n\n".join(parts[:1] + ["#if OPFMU_X86", *x86, "#endif"] + parts[1:])


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


TRAILING_ZEROS = re.compile(r"\.?0*p")


def hex_literals(values) -> list[str]:
    """C99 hexadecimal floating literals of finite doubles, exact, with no trailing zeros: the
    compiler reads them without decimal conversion (the weights and tables are megabytes of them)."""
    text = " ".join(map(float.hex, np.asarray(values, dtype=np.float64).ravel().tolist()))
    return TRAILING_ZEROS.sub("p", text).split(" ") if text else []


def _float_array(name: str, values: np.ndarray) -> str:
    flat = np.asarray(values, dtype=np.float32).ravel()
    body = ",".join(x + "f" for x in hex_literals(np.where(np.isfinite(flat), flat, 0.0)))
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

    # the weights B [k, n] of a Gemm (B' read transposed where transB = 1) are stored in panels of
    # PANEL output columns, each panel [k, PANEL] contiguous in the order the Gemm reads it (see
    # _gemm); each such weight must be a 2-D initializer that feeds that one Gemm only
    uses = {}
    for node in graph.node:
        for i in node.input:
            uses[i] = uses.get(i, 0) + 1
    initializers = {init.name for init in graph.initializer}
    stored_panels = {n.input[1]: any(a.name == "transB" and a.i for a in n.attribute) for n in graph.node
                     if n.op_type == "Gemm" and n.input[1] in initializers and uses[n.input[1]] == 1}
    for init in graph.initializer:
        array = numpy_helper.to_array(init)
        shapes[init.name] = array.shape
        if init.name in stored_panels:
            if array.ndim != 2:
                raise UnsupportedGraph(f"Gemm weight {init.name[:40]!r} is not a matrix")
            array = _panels(array.T if stored_panels[init.name] else array)
        if array.dtype.kind == "f":
            constants.append(_float_array(c_name(init.name), array))
    float_tensors = set(initializers)  # stored as float arrays (with the Constant nodes' values, below)
    sensor_fed = {"u"}  # tensors computed from the sensors before any Gemm
    for node in graph.node:
        if node.op_type != "Gemm" and any(i in sensor_fed for i in node.input):
            sensor_fed.add(node.output[0])
    products = set()  # the product functions the Gemms call
    names.update({"x0": "x0", "u": "u", "t": "t_"})

    for node in graph.node:
        op, out = node.op_type, node.output[0]
        attrs = {a.name: a for a in node.attribute}
        if op == "Constant":
            array = numpy_helper.to_array(attrs["value"].t)
            shapes[out] = array.shape
            if array.dtype.kind == "f":
                constants.append(_float_array(c_name(out), array))
            float_tensors.add(out)
            continue
        if op == "Identity" and node.input[0] in initializers:  # the exporter's alias of a shared weight
            names[out] = c_name(node.input[0])
            initializers.add(out)
            float_tensors.add(out)
            continue
        shape = shapes[out]
        size = int(np.prod(shape))
        dst = c_name(out)
        src = [c_name(i) for i in node.input]
        if op in ELEMENTWISE:
            a, b = node.input
            code = (f"    for (int i = 0; i < {size}; ++i) {dst}[i] = {src[0]}[{_offset('i', shape, shapes[a])}] "
                    f"{ELEMENTWISE[op]} {src[1]}[{_offset('i', shape, shapes[b])}];")
        elif op == "Tanh":
            code = f"    opfmu_tanh_array({size}, {src[0]}, {dst});"
        elif op in UNARY:
            code = f"    for (int i = 0; i < {size}; ++i) {dst}[i] = {UNARY[op].format(src[0] + '[i]')};"
        elif op in COPIES:
            if node.input[0] not in float_tensors:  # the same values in the same order: a view, no copy
                nodes.append((node, f"    const double *{dst} = {src[0]};", ""))
                continue
            code = f"    for (int i = 0; i < {size}; ++i) {dst}[i] = {src[0]}[i];"
        elif op == "Gemm":
            panels, sparse = node.input[1] in stored_panels, node.input[0] in sensor_fed
            if panels:
                products.add("product_sparse" if sparse else "product")
            code = _gemm(node, attrs, src, dst, shapes, panels, node.input[0] in float_tensors, sparse)
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
    uses_tanh = any(n.op_type == "Tanh" for n in graph.node)
    lines = ["/* Generated by opfmu from an ONNX operator graph; do not edit. */", "#include <math.h>",
             f"#define OPFMU_N_SENSORS {n_sensors}", VECTOR, *([DISPATCH] if uses_tanh or products else []),
             *([TANH] if uses_tanh else []), *([_product_source(products)] if products else []), *constants, ""]
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
    uses_t = "double t," in signature and any(re.search(r"\bt_\b", line) for line in body)
    return ["OPFMU_VECTOR " + signature, "{", "    const double t_[1] = {t};" if uses_t else "", *body, tail, "}", ""]


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


def _panels(weights: np.ndarray) -> np.ndarray:
    """B [k, n] as its column panels B[:, j:j + PANEL] (the last one narrower where PANEL does not
    divide n), each row-major, one after the other: the order _gemm reads them in."""
    return np.concatenate([weights[:, j:j + PANEL].ravel() for j in range(0, weights.shape[1], PANEL)]
                          or [weights.ravel()])


def _gemm(node, attrs, src, dst, shapes, panels: bool = False, a_float: bool = False, sparse: bool = False) -> str:
    """Y = alpha A' B' + beta C. Each output starts at its bias and gains alpha A'[r, p] B'[p, c] for
    p in order (in both forms below). With B a weight stored in panels (_panels), each row is one call
    of opfmu_product (PANEL_PLAIN, PRODUCT), which keeps the sums in registers while the weights stream by;
    otherwise (B computed in the graph) Y[r, :] is accumulated in place, p by p. a_float: A is a float
    array of the kernel (a constant) rather than a double one; sparse: the product skips zero inputs
    (opfmu_product_sparse, for the sensor layer)."""
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

    def bias(column: str) -> str:
        if len(node.input) > 2 and node.input[2]:
            return f"{beta!r} * {src[2]}[{_offset(f'(r * {n} + {column})', (m, n), shapes[node.input[2]])}]"
        return "0.0"

    if not panels:
        b_index = f"c * {k} + p" if trans_b else f"p * {n} + c"
        return (f"    for (int r = 0; r < {m}; ++r) {{\n"
                f"        double *y = {dst} + r * {n};\n"
                f"        for (int c = 0; c < {n}; ++c) y[c] = {bias('c')};\n"
                f"        for (int p = 0; p < {k}; ++p) {{\n"
                f"            const double a = {alpha!r} * (double){src[0]}[{a_index}];\n"
                f"            for (int c = 0; c < {n}; ++c) y[c] += a * (double){src[1]}[{b_index}];\n"
                f"        }}\n    }}")
    if alpha == 1.0 and not trans_a and not a_float:  # the row itself (1.0 * a == a)
        row, scaled = f"{src[0]} + r * {k}", ""
    else:
        row = "a"
        scaled = (f"        double a[{k}];\n"
                  f"        for (int p = 0; p < {k}; ++p) a[p] = {alpha!r} * (double){src[0]}[{a_index}];\n")
    return (f"    for (int r = 0; r < {m}; ++r) {{\n"
            f"        double *y = {dst} + r * {n};\n"
            f"        for (int c = 0; c < {n}; ++c) y[c] = {bias('c')};\n"
            f"{scaled}"
            f"        opfmu_product{'_sparse' if sparse else ''}({k}, {n}, {src[1]}, {row}, y);\n"
            f"    }}")


def _matmul(node, src, dst, shapes) -> str:
    """Batched A @ B, accumulated row by row as in _gemm (over independent outputs c), or, for B a
    column (n = 1), over the independent rows r: each sum runs over p in order either way."""
    a_shape, b_shape = shapes[node.input[0]], shapes[node.input[1]]
    if len(a_shape) < 2 or len(b_shape) < 2:
        raise UnsupportedGraph("MatMul with a 1-D operand is not supported")
    m, k = a_shape[-2:]
    n = b_shape[-1]
    batch = np.broadcast_shapes(a_shape[:-2], b_shape[:-2])
    n_batch = int(np.prod(batch)) if batch else 1
    a_off = _offset("q", batch, a_shape[:-2]) if batch else "0"
    b_off = _offset("q", batch, b_shape[:-2]) if batch else "0"
    if n == 1:  # a matrix times a vector (a DeepONet's head): the rows' sums interleaved, each in order
        return (f"    for (int q = 0; q < {n_batch}; ++q) {{\n"
                f"        double *y = {dst} + q * {m};\n"
                f"        for (int r = 0; r < {m}; ++r) y[r] = 0.0;\n"
                f"        for (int p = 0; p < {k}; ++p) {{\n"
                f"            const double b = (double){src[1]}[({b_off}) * {k} + p];\n"
                f"            for (int r = 0; r < {m}; ++r) y[r] += (double){src[0]}[({a_off}) * {m * k} + r * {k} + p] * b;\n"
                f"        }}\n    }}")
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
