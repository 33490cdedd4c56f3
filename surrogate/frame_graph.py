"""The window frame inside an operator's ONNX graph (reference_models.drift), and out of it again.

An operator of a component with a drift symmetry learns its windows in their own frame. Its file
still takes and gives physical values (docs/design.md, "The ONNX operator"): the export wraps the network's graph in
nodes, all named `frame/...`, that move x0 and u into the window's frame and the states back
(`wrap_in_frame`), and the file's `frame` metadata holds the numbers. Code that does the frame
itself (Operator.predict with numpy, the FMU in C, so the network's graph keeps its branch-trunk
structure) takes the network's graph back out (`network_graph`). Torch-free.
"""
from __future__ import annotations

import numpy as np

from reference_models.drift import Frame

PREFIX = "frame/"
X0_F, U_F, X_F = PREFIX + "x0_f", PREFIX + "u_f", PREFIX + "x_f"


def wrap_in_frame(proto, frame: Frame, sensor_times: np.ndarray):
    """The graph (x0, u, t) -> x of the network `proto` (which works in the frame) with the frame
    transformation around it: x0_f, u_f from x0, u (drift.to_frame) and x from x_f (drift.from_frame)."""
    import onnx
    from onnx import helper, numpy_helper

    graph = proto.graph
    n_x = graph.input[0].type.tensor_type.shape.dim[1].dim_value
    n_u = graph.input[1].type.tensor_type.shape.dim[2].dim_value
    rename = {"x0": X0_F, "u": U_F, "x": X_F}
    for node in graph.node:
        node.input[:] = [rename.get(i, i) if i in ("x0", "u") else i for i in node.input]
        node.output[:] = [rename.get(o, o) if o == "x" else o for o in node.output]

    nodes = []

    def const(name, value, dtype=np.float32):
        nodes.append(helper.make_node("Constant", [], [PREFIX + name], name=PREFIX + name,
                                      value=numpy_helper.from_array(np.asarray(value, dtype=dtype), PREFIX + name)))
        return PREFIX + name

    def op(kind, inputs, name, **attrs):
        nodes.append(helper.make_node(kind, inputs, [PREFIX + name], name=PREFIX + name, **attrs))
        return PREFIX + name

    angles = np.zeros(n_x, np.float32)
    angles[list(frame.angle_states)] = 1.0
    speed = frame.speed_mask(n_x).astype(np.float32)
    s = np.asarray(sensor_times, dtype=np.float64)
    ramp = s[:, None] * frame.input_ramps(n_u) + frame.input_torques(n_u)  # [S, n_u]: what c multiplies
    u0 = op("Gather", ["u", const("first", 0, np.int64)], "u0", axis=1)  # [N, n_u]
    a = op("Gather", [u0, const("angle_input", frame.angle_inputs[0], np.int64)], "a", axis=1)  # [N]
    if frame.speed_state is None:  # a frame that only turns
        c = op("Mul", [a, const("no_speed", 0.0)], "c")
    else:
        c = op("Gather", ["x0", const("speed_state", frame.speed_state, np.int64)], "speed0", axis=1)  # [N]
    if frame.speed_state is not None and frame.speed_rest:  # a per-unit speed: its offset from rest (drift.frame_speed)
        c = op("Sub", [c, const("speed_rest", frame.speed_rest)], "speed_offset")
    if frame.speed_state is not None and frame.speed_step:  # whole speed steps (drift.frame_speed)
        steps = op("Floor", [op("Add", [op("Mul", [c, const("per_step", 1.0 / frame.speed_step)], "speed_steps"),
                                        const("half_step", 0.5)], "rounded_steps")], "whole_steps")
        c = op("Mul", [steps, const("speed_step", frame.speed_step)], "c")
    if frame.angle_states:
        lead = op("Sub", [op("Gather", ["x0", const("angle_state", frame.angle_states[0], np.int64)], "angle0",
                             axis=1), a], "lead")
        turns = op("Floor", [op("Add", [op("Mul", [lead, const("per_period", 1.0 / frame.period)], "lead_periods"),
                                        const("half", 0.5)], "rounded")], "turns")
        shift = op("Add", [a, op("Mul", [turns, const("period", frame.period)], "whole_periods")], "shift")
    else:
        shift = a
    col, cube = const("axis1", [1], np.int64), const("axes12", [1, 2], np.int64)
    shift_col, c_col = op("Unsqueeze", [shift, col], "shift_col"), op("Unsqueeze", [c, col], "c_col")
    x0_off = op("Add", [op("Mul", [shift_col, const("angles", angles)], "x0_angles"),
                        op("Mul", [c_col, const("speed", speed)], "x0_speed")], "x0_offset")
    nodes.append(helper.make_node("Sub", ["x0", x0_off], [X0_F], name=PREFIX + "x0_to_frame"))
    a_cube, c_cube = op("Unsqueeze", [a, cube], "a_cube"), op("Unsqueeze", [c, cube], "c_cube")
    u_off = op("Add", [op("Mul", [a_cube, const("input_rates", frame.input_rates(n_u))], "u_angles"),
                       op("Mul", [c_cube, const("ramp", ramp)], "u_speed")], "u_offset")
    nodes.append(helper.make_node("Sub", ["u", u_off], [U_F], name=PREFIX + "u_to_frame"))
    head = list(nodes)
    nodes.clear()
    t_col = op("Unsqueeze", ["t", col], "t_col")  # [M, 1]
    turning = op("Add", [op("Mul", [t_col, const("angles_out", angles * np.float32(frame.speed_scale))], "t_angles"),
                         const("speed_out", speed)],
                 "turning")  # [M, n_x]
    x_off = op("Add", [op("Mul", [op("Unsqueeze", [shift, cube], "shift_cube"), const("angles_cube", angles)],
                          "x_angles"), op("Mul", [c_cube, turning], "x_turning")], "x_offset")
    nodes.append(helper.make_node("Add", [X_F, x_off], ["x"], name=PREFIX + "x_from_frame"))
    network = list(graph.node)
    del graph.node[:]
    graph.node.extend(head + network + nodes)
    onnx.checker.check_model(proto)
    return proto


def network_graph(proto):
    """The network's own graph (x0_f, u_f, t) -> x_f of an operator, with inputs and output named
    x0, u, t and x again; the graph itself when it has no frame nodes."""
    import onnx

    if not any(node.name.startswith(PREFIX) for node in proto.graph.node):
        return proto
    inner = onnx.ModelProto()
    inner.CopyFrom(proto)
    graph = inner.graph
    back = {X0_F: "x0", U_F: "u", X_F: "x"}
    kept = [node for node in graph.node if not node.name.startswith(PREFIX)]
    for node in kept:
        node.input[:] = [back.get(i, i) for i in node.input]
        node.output[:] = [back.get(o, o) for o in node.output]
    del graph.node[:]
    graph.node.extend(kept)
    del graph.value_info[:]
    return inner
