"""Hand-made operators for the FMU tests: small ONNX graphs with a shipped operator's metadata and
frame whose answer does not split into trunk and coefficients, so the FMU's kernel takes its other
paths (it tracks the sensor layer's output, or keeps the sensor buffer and evaluates the whole
network)."""
import numpy as np
import onnx
from onnx import TensorProto, helper

from surrogate.frame_graph import wrap_in_frame
from surrogate.operator import Operator


def operator_without_trunk(source_path, path, name: str, squash: bool = False) -> None:
    """Writes to `path` the operator x = x0 + t sum_i(b_i / 10) b, b = tanh(W [x0, v] + c), with v the
    sensors (the FMU then has OPFMU_TRUNK_SIZE 0: it tracks the sensor layer's output) or, with
    squash, tanh of them (not affine: OPFMU_FIRST_LAYER 0, the FMU keeps the sensor buffer and
    evaluates the whole network); metadata and frame of the operator at `source_path`."""
    source = Operator.load(source_path)
    n_x, n_u, n_sensors = 4, 4, source.n_sensors
    rng = np.random.default_rng(0)
    width = n_x + n_u * n_sensors
    init = [helper.make_tensor("W", TensorProto.FLOAT, [width, n_x], (0.01 * rng.normal(size=width * n_x)).tolist()),
            helper.make_tensor("c", TensorProto.FLOAT, [n_x], (0.1 * rng.normal(size=n_x)).tolist()),
            helper.make_tensor("tenth", TensorProto.FLOAT, [n_x, 1], [0.1] * n_x),
            helper.make_tensor("ax1", TensorProto.INT64, [1], [1]), helper.make_tensor("ax2", TensorProto.INT64, [1], [2])]
    sensors = [helper.make_node("Flatten", ["u"], ["uf"], axis=1)]
    if squash:
        sensors += [helper.make_node("Tanh", ["uf"], ["us"])]
    nodes = sensors + [
        helper.make_node("Concat", ["x0", "us" if squash else "uf"], ["xu"], axis=1),
        helper.make_node("Gemm", ["xu", "W", "c"], ["g"]), helper.make_node("Tanh", ["g"], ["b"]),
        helper.make_node("MatMul", ["b", "tenth"], ["s"]), helper.make_node("Mul", ["s", "t"], ["st"]),
        helper.make_node("Unsqueeze", ["st", "ax2"], ["st3"]), helper.make_node("Unsqueeze", ["b", "ax1"], ["b3"]),
        helper.make_node("Mul", ["st3", "b3"], ["p"]), helper.make_node("Unsqueeze", ["x0", "ax1"], ["x03"]),
        helper.make_node("Add", ["p", "x03"], ["x"])]
    graph = helper.make_graph(nodes, name, [
        helper.make_tensor_value_info("x0", TensorProto.FLOAT, ["N", n_x]),
        helper.make_tensor_value_info("u", TensorProto.FLOAT, ["N", n_sensors, n_u]),
        helper.make_tensor_value_info("t", TensorProto.FLOAT, ["M"])],
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, ["N", "M", n_x])], init)
    proto = wrap_in_frame(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)]), source.frame,
                          source.sensor_times)
    for key, value in source.metadata.items():
        proto.metadata_props.append(onnx.StringStringEntryProto(key=key, value=value))
    onnx.save(proto, str(path))
