"""The C kernel generated from an operator's ONNX graph computes what onnxruntime computes."""
import ctypes
import json
import subprocess

import numpy as np
import onnx
import onnxruntime as ort
import pytest
from onnx import TensorProto, helper

from fmu_export.onnx_to_c import UnsupportedGraph, generate_kernel, graph_interface
from surrogate.models import OperatorConfig
from surrogate.contract import random_inputs
from surrogate.frame_graph import network_graph
from surrogate.onnx_export import export_onnx
from surrogate.training import TrainConfig, train

DOUBLE_P = ctypes.POINTER(ctypes.c_double)


# per kind: (width of the sensor layer, trunk values, coefficients)
SIZES = {"unstacked": (16, 9, 36), "stacked-n": (16, 9, 36), "pinn": (16, 16, 16), "anchored": (16, 9, 36),
         "ensemble": (32, 17, 68)}


@pytest.fixture(scope="module", params=list(SIZES))
def kernel(request, paper_tiny, tmp_path_factory):
    """(onnx path of the network, compiled kernel library, envelope) for a briefly trained model of each
    architecture (anchored: an anchored Unstacked DeepONet; ensemble: the mean of two). The kernel is
    the network inside the file's frame nodes (surrogate.frame_graph), as the FMU builder compiles it:
    its inputs are in the window frame, where the envelope is."""
    run = tmp_path_factory.mktemp(f"c_{request.param}")
    arch, anchored = (request.param, False) if request.param in ("unstacked", "stacked-n", "pinn") else ("unstacked", True)
    runs = [run / f"member{seed}" for seed in range(2 if request.param == "ensemble" else 1)]
    for seed, member in enumerate(runs):
        config = TrainConfig(model=OperatorConfig(arch=arch, width=16, depth=2, latent=8, anchored=anchored), epochs=3,
                             time_points=20, seed=seed)
        train(paper_tiny[1], config, member, progress=False)
    meta = export_onnx(runs, run / "op.onnx")
    path = run / "network.onnx"
    onnx.save(network_graph(onnx.load(str(run / "op.onnx"))), str(path))
    source = run / "kernel.c"
    kernel = generate_kernel(onnx.load(str(path)), 1001)
    # every architecture's sensors enter through one dense layer; the DeepONets' trunk values are the
    # basis and the constant, their coefficients B_aug [4, p + 1]
    assert (kernel.first_layer, kernel.trunk_size, kernel.coef_size) == SIZES[request.param]
    source.write_text(kernel.source)
    library = run / "libkernel.so"
    subprocess.run(["gcc", "-O2", "-Wall", "-Werror", "-shared", "-fPIC", str(source), "-o", str(library), "-lm"],
                   check=True)
    return path, ctypes.CDLL(str(library)), json.loads(meta["envelope"])


def test_kernel_matches_onnxruntime_on_random_in_envelope_inputs(kernel):
    path, lib, envelope = kernel
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    x0, u, t = random_inputs(envelope, np.linspace(0, 1, 1001), 16, np.random.default_rng(3))
    expected = session.run(["x"], {"x0": x0, "u": u, "t": t})[0]
    for n in range(len(x0)):
        x0_n, u_n = np.ascontiguousarray(x0[n], np.float64), np.ascontiguousarray(u[n], np.float64)
        for m in (0, 1, 500, len(t) - 1):
            out = np.zeros(4)
            lib.opfmu_operator(x0_n.ctypes.data_as(DOUBLE_P), u_n.ctypes.data_as(DOUBLE_P), ctypes.c_double(t[m]),
                               out.ctypes.data_as(DOUBLE_P))
            np.testing.assert_allclose(out, expected[n, m], rtol=0, atol=1e-5)


def test_evaluation_split_at_the_sensor_layer_equals_the_whole_kernel(kernel):
    _, lib, envelope = kernel
    x0, u, _ = random_inputs(envelope, np.linspace(0, 1, 1001), 4, np.random.default_rng(5))
    for n in range(len(x0)):
        x0_n, u_n = np.ascontiguousarray(x0[n], np.float64), np.ascontiguousarray(u[n], np.float64)
        whole, split, z = np.zeros(4), np.zeros(4), np.zeros(256)  # z: room for any sensor layer
        lib.opfmu_operator(x0_n.ctypes.data_as(DOUBLE_P), u_n.ctypes.data_as(DOUBLE_P), ctypes.c_double(0.37),
                           whole.ctypes.data_as(DOUBLE_P))
        lib.opfmu_first_layer(x0_n.ctypes.data_as(DOUBLE_P), u_n.ctypes.data_as(DOUBLE_P), z.ctypes.data_as(DOUBLE_P))
        lib.opfmu_from_first_layer(x0_n.ctypes.data_as(DOUBLE_P), z.ctypes.data_as(DOUBLE_P), ctypes.c_double(0.37),
                                   split.ctypes.data_as(DOUBLE_P))
        np.testing.assert_array_equal(split, whole)


def test_evaluation_from_coefficients_and_a_kept_trunk_equals_the_whole_kernel(kernel):
    _, lib, envelope = kernel
    x0, u, _ = random_inputs(envelope, np.linspace(0, 1, 1001), 3, np.random.default_rng(6))
    tau = np.zeros(256)  # room for any kind's trunk values
    lib.opfmu_trunk(ctypes.c_double(0.61), tau.ctypes.data_as(DOUBLE_P))
    for n in range(len(x0)):
        x0_n, u_n = np.ascontiguousarray(x0[n], np.float64), np.ascontiguousarray(u[n], np.float64)
        whole, split, z = np.zeros(4), np.zeros(4), np.zeros(256)  # z: room for any sensor layer
        lib.opfmu_operator(x0_n.ctypes.data_as(DOUBLE_P), u_n.ctypes.data_as(DOUBLE_P), ctypes.c_double(0.61),
                           whole.ctypes.data_as(DOUBLE_P))
        lib.opfmu_first_layer(x0_n.ctypes.data_as(DOUBLE_P), u_n.ctypes.data_as(DOUBLE_P), z.ctypes.data_as(DOUBLE_P))
        c = np.zeros(256)  # room for any kind's coefficients
        lib.opfmu_coefficients(x0_n.ctypes.data_as(DOUBLE_P), z.ctypes.data_as(DOUBLE_P), c.ctypes.data_as(DOUBLE_P))
        lib.opfmu_head(c.ctypes.data_as(DOUBLE_P), tau.ctypes.data_as(DOUBLE_P), split.ctypes.data_as(DOUBLE_P))
        np.testing.assert_array_equal(split, whole)


def test_graph_with_an_unsupported_op_is_refused_naming_it():
    graph = helper.make_graph(
        [helper.make_node("Softmax", ["x0"], ["y"]), helper.make_node("Erf", ["y"], ["x"])], "g",
        [helper.make_tensor_value_info("x0", TensorProto.FLOAT, [1, 4])],
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 4])])
    with pytest.raises(UnsupportedGraph, match="does not support: Erf, Softmax"):
        generate_kernel(helper.make_model(graph), 1001)


def branch_trunk_graph(name: str, branch: list, init: list, n_x: int, n_u: int, n_sensors: int):
    """x [N, M, n_x] = branch [N, n_x] * sin(Gemm(t, Wt)): the `branch` nodes map xu = [x0, flat u] to
    "branch"; init holds their weights, Wt [1, n_x] and the axes ax0, ax1."""
    nodes = [helper.make_node("Flatten", ["u"], ["uf"], axis=1),
             helper.make_node("Concat", ["x0", "uf"], ["xu"], axis=1),
             *branch,
             helper.make_node("Unsqueeze", ["t", "ax1"], ["tc"]),
             helper.make_node("Gemm", ["tc", "Wt"], ["tg"]),
             helper.make_node("Sin", ["tg"], ["trunk"]),
             helper.make_node("Unsqueeze", ["branch", "ax1"], ["b3"]),
             helper.make_node("Unsqueeze", ["trunk", "ax0"], ["t3"]),
             helper.make_node("Mul", ["b3", "t3"], ["x"])]
    graph = helper.make_graph(nodes, name, [
        helper.make_tensor_value_info("x0", TensorProto.FLOAT, ["N", n_x]),
        helper.make_tensor_value_info("u", TensorProto.FLOAT, ["N", n_sensors, n_u]),
        helper.make_tensor_value_info("t", TensorProto.FLOAT, ["M"])],
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, ["N", "M", n_x])], init)
    return helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])


def small_operator(n_x: int, n_u: int, n_sensors: int):
    """A hand-made operator graph of other sizes: x [N, M, n_x] = tanh(Gemm([x0, u])) * sin(Gemm(t))."""
    rng = np.random.default_rng(0)
    width = n_x + n_u * n_sensors
    init = [helper.make_tensor("W", TensorProto.FLOAT, [width, n_x], rng.normal(size=width * n_x).tolist()),
            helper.make_tensor("b", TensorProto.FLOAT, [n_x], rng.normal(size=n_x).tolist()),
            helper.make_tensor("Wt", TensorProto.FLOAT, [1, n_x], rng.normal(size=n_x).tolist()),
            helper.make_tensor("ax1", TensorProto.INT64, [1], [1]), helper.make_tensor("ax0", TensorProto.INT64, [1], [0])]
    branch = [helper.make_node("Gemm", ["xu", "W", "b"], ["g"]), helper.make_node("Tanh", ["g"], ["branch"])]
    return branch_trunk_graph("small", branch, init, n_x, n_u, n_sensors)


def test_kernel_takes_the_number_of_states_and_inputs_from_the_graph(tmp_path):
    n_x, n_u, n_sensors = 3, 1, 11
    proto = small_operator(n_x, n_u, n_sensors)
    kernel = generate_kernel(proto, n_sensors)
    assert (kernel.n_states, kernel.n_inputs) == (n_x, n_u)
    assert "void opfmu_operator(const double x0[3], const double u[1 * OPFMU_N_SENSORS], double t, double x[3])" \
        in kernel.source
    source, library = tmp_path / "kernel.c", tmp_path / "libkernel.so"
    source.write_text(kernel.source)
    subprocess.run(["gcc", "-O2", "-Wall", "-Werror", "-shared", "-fPIC", str(source), "-o", str(library), "-lm"],
                   check=True)
    lib = ctypes.CDLL(str(library))
    rng = np.random.default_rng(1)
    x0 = rng.uniform(-1, 1, (5, n_x)).astype(np.float32)
    u = rng.uniform(-1, 1, (5, n_sensors, n_u)).astype(np.float32)
    t = np.array([0.0, 0.3, 1.0], np.float32)
    expected = ort.InferenceSession(proto.SerializeToString(), providers=["CPUExecutionProvider"]).run(
        ["x"], {"x0": x0, "u": u, "t": t})[0]
    for n in range(len(x0)):
        x0_n, u_n = np.ascontiguousarray(x0[n], np.float64), np.ascontiguousarray(u[n], np.float64)
        for m, tm in enumerate(t):
            out = np.zeros(n_x)
            lib.opfmu_operator(x0_n.ctypes.data_as(DOUBLE_P), u_n.ctypes.data_as(DOUBLE_P), ctypes.c_double(tm),
                               out.ctypes.data_as(DOUBLE_P))
            np.testing.assert_allclose(out, expected[n, m], rtol=0, atol=1e-5)


def test_graph_interface_is_read_from_the_inputs_and_refused_when_it_is_not_the_contract():
    assert graph_interface(small_operator(3, 1, 11)) == (3, 1, 11)
    renamed = small_operator(3, 1, 11)
    renamed.graph.input[0].name = "state"
    with pytest.raises(UnsupportedGraph, match="must take inputs x0, u, t"):
        generate_kernel(renamed, 11)
    with pytest.raises(UnsupportedGraph, match="has 11 sensor times, not 12"):
        generate_kernel(small_operator(3, 1, 11), 12)


def _compiled(tmp_path, source: str, portable: bool):
    """The kernel source compiled as the tests compile it; portable: without the AVX2/FMA loops."""
    path, library = tmp_path / f"kernel{int(portable)}.c", tmp_path / f"libkernel{int(portable)}.so"
    path.write_text(source)
    subprocess.run(["gcc", "-O2", "-Wall", "-Werror", *(["-DOPFMU_X86=0"] if portable else []), "-shared", "-fPIC",
                    str(path), "-o", str(library), "-lm"], check=True)
    return ctypes.CDLL(str(library))


def _evaluate(lib, x0, u, t, n_x):
    out = np.zeros((len(x0), len(t), n_x))
    for n in range(len(x0)):
        x0_n, u_n = np.ascontiguousarray(x0[n], np.float64), np.ascontiguousarray(u[n], np.float64)
        for m, tm in enumerate(t):
            lib.opfmu_operator(x0_n.ctypes.data_as(DOUBLE_P), u_n.ctypes.data_as(DOUBLE_P), ctypes.c_double(tm),
                               out[n, m].ctypes.data_as(DOUBLE_P))
    return out


def layered_operator(n_x: int, n_u: int, n_sensors: int, hidden: int, alpha: float, beta: float, trans_a: bool):
    """x = tanh(Gemm2(tanh(Gemm1([x0, u])))) * sin(Gemm(t)), with Gemm1 (the sensor layer) taking
    alpha, beta and transA as given and Gemm2 reading its weights transposed (transB = 1)."""
    rng = np.random.default_rng(2)
    width = n_x + n_u * n_sensors
    init = [helper.make_tensor("W1", TensorProto.FLOAT, [width, hidden], rng.normal(size=width * hidden).tolist()),
            helper.make_tensor("b1", TensorProto.FLOAT, [hidden], rng.normal(size=hidden).tolist()),
            helper.make_tensor("W2", TensorProto.FLOAT, [n_x, hidden], (rng.normal(size=n_x * hidden) / 8).tolist()),
            helper.make_tensor("b2", TensorProto.FLOAT, [n_x], rng.normal(size=n_x).tolist()),
            helper.make_tensor("Wt", TensorProto.FLOAT, [1, n_x], rng.normal(size=n_x).tolist()),
            helper.make_tensor("ax1", TensorProto.INT64, [1], [1]), helper.make_tensor("ax0", TensorProto.INT64, [1], [0])]
    first = ([helper.make_node("Transpose", ["xu"], ["xuT"]),
              helper.make_node("Gemm", ["xuT", "W1", "b1"], ["g"], alpha=alpha, beta=beta, transA=1)] if trans_a else
             [helper.make_node("Gemm", ["xu", "W1", "b1"], ["g"], alpha=alpha, beta=beta)])
    branch = [*first, helper.make_node("Tanh", ["g"], ["h"]),
              helper.make_node("Gemm", ["h", "W2", "b2"], ["g2"], transB=1), helper.make_node("Tanh", ["g2"], ["branch"])]
    return branch_trunk_graph("layered", branch, init, n_x, n_u, n_sensors)


@pytest.mark.parametrize("portable", [False, True], ids=["avx2", "portable"])
@pytest.mark.parametrize("n_x, hidden, alpha, beta, trans_a", [(37, 70, 1.0, 1.0, False), (3, 16, 0.5, 2.0, True)])
def test_gemm_weights_in_panels_match_onnxruntime_with_zero_sensors(tmp_path, portable, n_x, hidden, alpha, beta,
                                                                    trans_a):
    # widths 70 and 37: whole panels of 32 outputs and a narrower last one; the sensor layer skips the
    # sensors that are exactly zero (at a window start all of them are)
    n_u, n_sensors = 2, 11
    proto = layered_operator(n_x, n_u, n_sensors, hidden, alpha, beta, trans_a)
    source = generate_kernel(proto, n_sensors).source
    assert ("opfmu_product_sparse(" in source) and ("opfmu_product(" in source)
    lib = _compiled(tmp_path, source, portable)
    rng = np.random.default_rng(4)
    x0 = rng.uniform(-1, 1, (4, n_x)).astype(np.float32)
    u = rng.uniform(-1, 1, (4, n_sensors, n_u)).astype(np.float32)
    u[1] = 0.0
    u[2, ::2] = 0.0
    x0[3, ::3] = 0.0
    t = np.array([0.0, 0.3, 1.0], np.float32)
    expected = ort.InferenceSession(proto.SerializeToString(), providers=["CPUExecutionProvider"]).run(
        ["x"], {"x0": x0, "u": u, "t": t})[0]
    np.testing.assert_allclose(_evaluate(lib, x0, u, t, n_x), expected, rtol=0, atol=1e-5)


def tanh_operator(n_x: int):
    """x = tanh(x0) (u and t unused)."""
    graph = helper.make_graph([helper.make_node("Tanh", ["x0"], ["x"])], "tanh", [
        helper.make_tensor_value_info("x0", TensorProto.FLOAT, ["N", n_x]),
        helper.make_tensor_value_info("u", TensorProto.FLOAT, ["N", 3, 1]),
        helper.make_tensor_value_info("t", TensorProto.FLOAT, ["M"])],
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, ["N", n_x])])
    return helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])


@pytest.mark.parametrize("portable", [False, True], ids=["avx2", "portable"])
def test_tanh_is_within_4e16_of_numpys_and_keeps_zeros_infinities_and_nan(tmp_path, portable):
    n_x = 7  # one vector of 4 and a tail of 3
    lib = _compiled(tmp_path, generate_kernel(tanh_operator(n_x), 3).source, portable)
    rng = np.random.default_rng(8)
    x = np.concatenate([rng.uniform(-30, 30, 7000), rng.uniform(-2, 2, 7000), rng.normal(size=7000) * 1e-6,
                        np.ldexp(rng.uniform(-1, 1, 7000), rng.integers(-1070, 0, 7000)),
                        [0.0, -0.0, np.inf, -np.inf, 19.0, 20.0, -20.0, 40.0, 1e300, -1e300, 5e-324, np.nan, 0.5, -0.5]])
    x = np.concatenate([x, np.zeros(-len(x) % n_x)])
    out, u = np.zeros(n_x), np.zeros(3)
    got = np.empty_like(x)
    for i in range(0, len(x), n_x):
        x0 = np.ascontiguousarray(x[i:i + n_x])
        lib.opfmu_operator(x0.ctypes.data_as(DOUBLE_P), u.ctypes.data_as(DOUBLE_P), ctypes.c_double(0.0),
                           out.ctypes.data_as(DOUBLE_P))
        got[i:i + n_x] = out
    finite = ~np.isnan(x)
    assert np.abs(got[finite] - np.tanh(x[finite])).max() <= 4e-16
    assert np.isnan(got[~finite]).all()
    assert np.array_equal(np.signbit(got[finite]), np.signbit(x[finite]))  # tanh(-0) = -0
    assert np.array_equal(got[np.isinf(x)], np.sign(x[np.isinf(x)]))
