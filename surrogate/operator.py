"""Inference on an exported operator with onnxruntime: `Operator.load(path).predict(x0, u, t)`.

For a DeepONet the graph is split at the product of branch coefficients and trunk basis: branch
(x0, u -> B [N, 4, q]) and trunk (t -> tau^T [q, M]) run as onnxruntime sessions, and the trunk basis,
which depends only on the query times, is cached per time grid. The head of an opfmu export is that
product alone (the decoding is folded into B and tau, see folding.py), so it runs as one float32 GEMM
in numpy, tau [M, q] @ B^T [q, 4 N], whose [M, N, 4] result is returned as the [N, M, 4] view x (no
copy: x.transpose(1, 0, 2) is C-contiguous). Any other head runs as a third session. Repeated
predictions on one grid thus cost a branch evaluation and one matrix product. Graphs without that
product (the PINN) run whole.
"""
from __future__ import annotations

import warnings
from collections import OrderedDict
from pathlib import Path

import numpy as np

from reference_models.drift import from_frame, to_frame

from .contract import ContractError, operator_metadata
from .frame_graph import network_graph

DEFAULT_OPERATOR = Path(__file__).parent / "default" / "sm4_cosim.onnx"


class OperatorInputError(ValueError):
    """Inputs that do not fit the operator (shape, time range, non-finite values, envelope if strict)."""


class EnvelopeWarning(UserWarning):
    """Inputs outside the envelope the operator was trained on: its answer is an extrapolation."""


class Operator:
    """An exported operator of a component. predict(x0 [N, n_x], u [N, S, n_u], t [M]) -> x [N, M, n_x]
    (float32). `state_names`, `input_names`, the `component` and its `params` (the machine it was
    trained for) come from the file's metadata, validated by surrogate.contract.operator_metadata."""

    CACHE_SIZE = 8  # time grids whose trunk basis is kept
    # smaller batches run the branch on one thread: there the hand-off between threads costs more than
    # it saves (measured, one trajectory: 0.031 ms on one thread, 0.068 ms on two)
    SMALL_BATCH = 16

    def __init__(self, path, providers=None, threads: int | None = None):
        import onnx
        import onnxruntime as ort

        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"no operator file at {path}")
        proto = onnx.load(str(path))
        self.path = path
        self.metadata = {p.key: p.value for p in proto.metadata_props}
        try:
            contract = operator_metadata(self.metadata)
        except ContractError as exc:
            raise OperatorInputError(f"{path}: {exc}") from None
        self.horizon, self.n_sensors = contract["horizon_s"], contract["n_sensors"]
        self.rollover_horizon = contract["rollover_horizon_s"]  # s: where a co-simulation starts a new window
        self.envelope = contract["envelope"]
        self.state_names, self.input_names = contract["state_names"], contract["input_names"]
        self.component, self.params = contract["component"], contract["params"]
        self.frame = contract["frame"]
        self.sensor_times = np.linspace(0.0, self.horizon, self.n_sensors)
        proto = network_graph(proto)  # with a frame, it is done here (reference_models.drift)
        n_x = len(self.state_names)
        bounds = ([self.envelope["x0"][n] for n in self.state_names] +
                  [self.envelope["u"][n] for n in self.input_names])
        self._env_min, self._env_max = np.array(bounds).T
        # per-value bounds, widened by 1e-6, for the quick test: x0's, then the inputs per sensor
        self._x_low, self._x_high = self._env_min[:n_x] - 1e-6, self._env_max[:n_x] + 1e-6
        self._u_low = np.tile(self._env_min[n_x:] - 1e-6, self.n_sensors)
        self._u_high = np.tile(self._env_max[n_x:] + 1e-6, self.n_sensors)
        available = ort.get_available_providers()
        providers = providers or [p for p in ("CUDAExecutionProvider", "CPUExecutionProvider") if p in available]

        def session(model, n_threads=threads):
            options = ort.SessionOptions()
            # no spin-waiting after a run: the numpy head follows at once and needs the cores
            options.add_session_config_entry("session.intra_op.allow_spinning", "0")
            if n_threads:
                options.intra_op_num_threads = n_threads
            return ort.InferenceSession(model.SerializeToString(), options, providers=providers)

        self._full = session(proto)
        split = split_branch_trunk(proto)
        self._branch = self._branch_small = self._trunk_session = self._head = None
        if split is not None:
            branch, trunk, head = split
            self._branch, self._branch_small = session(branch), session(branch, threads or 1)
            self._trunk_session = session(trunk)
            self._head = None if is_plain_product(head) else session(head)
        self._basis = OrderedDict()

    @classmethod
    def load(cls, path, providers=None, threads: int | None = None) -> "Operator":
        """The operator in an exported .onnx file (see __init__)."""
        return cls(path, providers, threads)

    @classmethod
    def default(cls, providers=None, threads: int | None = None) -> "Operator":
        """The operator shipped with opfmu (SM4, trained on the `cosim` preset; see default/README.md)."""
        return cls(DEFAULT_OPERATOR, providers, threads)

    @property
    def separable(self) -> bool:
        """True when the trunk basis is cached per time grid (DeepONets)."""
        return self._branch is not None

    def predict(self, x0, u, t, strict: bool = False) -> np.ndarray:
        """States x [N, M, n_x] at times t [M] (s, within [0, horizon]) from x0 [N, n_x] and inputs u [N, S, n_u]
        at the operator's sensor times. Outside the training envelope (in the window frame, see
        reference_models.drift): EnvelopeWarning, or OperatorInputError when strict."""
        x0, u, t, back = self._checked(x0, u, t, strict)  # in the window frame, with the way back
        x = self._network(x0, u, t)
        if back is None:
            return x
        return from_frame(self.frame, x.astype(np.float64), t.astype(np.float64), *back).astype(np.float32)

    def _network(self, x0, u, t) -> np.ndarray:
        """The network's states [N, M, n_x] (in the window frame, if the operator has one)."""
        if self._branch is None:
            return self._full.run(["x"], {"x0": x0, "u": u, "t": t})[0]
        branch = self._branch_small if len(x0) < self.SMALL_BATCH else self._branch
        b = branch.run(None, {"x0": x0, "u": u})[0]  # [N, n_x, q]
        basis = self._trunk(t)  # tau^T [q, M]
        if self._head is None:
            return (b.reshape(-1, b.shape[-1]) @ basis).reshape(len(x0), b.shape[1], len(t)).transpose(0, 2, 1)
        names = [i.name for i in self._head.get_inputs()]
        return self._head.run(["x"], {names[0]: b, names[1]: basis})[0]

    def _trunk(self, t: np.ndarray) -> np.ndarray:
        """The basis tau^T [q, M] at times t, from the cache or the trunk session."""
        key = t.tobytes()
        if key in self._basis:
            self._basis.move_to_end(key)
        else:
            self._basis[key] = self._trunk_session.run(None, {"t": t})[0]
            if len(self._basis) > self.CACHE_SIZE:
                self._basis.popitem(last=False)
        return self._basis[key]

    def _checked(self, x0, u, t, strict: bool):
        given = (np.asarray(x0, dtype=np.float64), np.asarray(u, dtype=np.float64))  # the frame is done in float64
        x0, u, t = (np.ascontiguousarray(a, dtype=np.float32) for a in (x0, u, t))
        n_x, n_u = len(self.state_names), len(self.input_names)
        if x0.ndim != 2 or x0.shape[1] != n_x:
            raise OperatorInputError(f"x0 must be [N, {n_x}] ({', '.join(self.state_names)}), got shape {x0.shape}")
        if u.shape != (x0.shape[0], self.n_sensors, n_u):
            raise OperatorInputError(f"u must be [N, S, {n_u}] = [{x0.shape[0]}, {self.n_sensors}, {n_u}] "
                                     f"({', '.join(self.input_names)} at the sensor times), got shape {u.shape}")
        if t.ndim != 1 or t.size == 0:
            raise OperatorInputError(f"t must be a non-empty 1-D array of times, got shape {t.shape}")
        t_low, t_high = t.min(), t.max()
        if not (0 <= t_low and t_high <= self.horizon * (1 + 1e-6)):  # NaN fails both comparisons
            if not np.isfinite(t).all():
                raise OperatorInputError("t holds NaN or inf")
            raise OperatorInputError(f"t must lie in [0, {self.horizon:g}] s (the horizon), got [{t_low:g}, {t_high:g}]")
        back = None
        if self.frame is not None:
            with np.errstate(invalid="ignore", over="ignore"):  # non-finite inputs are refused just below
                x0_f, u_f, shift, c = to_frame(self.frame, *given, self.sensor_times)
            x0, u, back = x0_f.astype(np.float32), u_f.astype(np.float32), (shift, c)
        # quick test: every value within its bound (NaN compares false); the ranges only when one is not
        flat = u.reshape(len(u), -1)
        x_low, x_high, u_low, u_high = x0.min(0), x0.max(0), flat.min(0), flat.max(0)
        if ((x_low >= self._x_low).all() and (x_high <= self._x_high).all() and (u_low >= self._u_low).all()
                and (u_high <= self._u_high).all()):
            return x0, u, t, back
        for name, a in (("x0", given[0]), ("u", given[1])):  # as given: the frame mixes x0 and u
            if not np.isfinite(a).all():
                raise OperatorInputError(f"{name} holds NaN or inf")
        message = "outside the training envelope: " + "; ".join(self._outside(*self._ranges(x0, u)))
        if strict:
            raise OperatorInputError(message)
        warnings.warn(message, EnvelopeWarning, stacklevel=3)
        return x0, u, t, back

    def in_frame(self, x0: np.ndarray, u: np.ndarray):
        """(x0, u) in the frame of their windows (what the envelope bounds); as given without a frame."""
        if self.frame is None:
            return x0, u
        x0_f, u_f, _, _ = to_frame(self.frame, np.asarray(x0, dtype=np.float64), np.asarray(u, dtype=np.float64),
                                   self.sensor_times)
        return x0_f, u_f

    def outside_envelope(self, x0: np.ndarray, u: np.ndarray) -> list[str]:
        """One line per quantity outside the envelope (in the window frame): its range against the
        trained range."""
        return self._outside(*self._ranges(*self.in_frame(np.asarray(x0), np.asarray(u))))

    @staticmethod
    def _ranges(x0: np.ndarray, u: np.ndarray):
        """(min, max) [n_x + n_u] of the states in x0 and the inputs in u: a reduction over the
        trajectories first (contiguous rows), then over the n_u S interleaved sensor values."""
        n_u = u.shape[-1]
        flat = u.reshape(len(u), -1)
        low, high = flat.min(0), flat.max(0)
        return (np.array([*x0.min(0), *(low[c::n_u].min() for c in range(n_u))]),
                np.array([*x0.max(0), *(high[c::n_u].max() for c in range(n_u))]))

    def _outside(self, low: np.ndarray, high: np.ndarray) -> list[str]:
        outside = (low < self._env_min - 1e-6) | (high > self._env_max + 1e-6)
        if not outside.any():
            return []
        return [f"{name} in [{low[i]:.4g}, {high[i]:.4g}], trained [{self._env_min[i]:.4g}, {self._env_max[i]:.4g}]"
                for i, name in enumerate(self.state_names + self.input_names) if outside[i]]


def split_branch_trunk(proto):
    """(branch, trunk, head) ONNX models of a separable graph, or None.

    The split point is a MatMul whose first operand depends on x0 and u only and whose second on t
    only: branch maps (x0, u) to the first operand, trunk maps t to the second, head maps both to x.
    """
    from onnx.utils import Extractor

    graph = proto.graph
    produced_by = {out: node for node in graph.node for out in node.output}
    memo = {}

    def sources(name):
        if name not in memo:
            if name in {"x0", "u", "t"}:
                memo[name] = {name}
            elif name in produced_by:
                memo[name] = set().union(*[sources(i) for i in produced_by[name].input if i])
            else:
                memo[name] = set()  # initializer or constant
        return memo[name]

    for node in graph.node:
        if node.op_type == "MatMul":
            a, b = node.input
            if sources(a) == {"x0", "u"} and sources(b) == {"t"}:
                extractor = Extractor(_with_value_info(proto, [a, b]))
                return (extractor.extract_model(["x0", "u"], [a]), extractor.extract_model(["t"], [b]),
                        extractor.extract_model([a, b], ["x"]))
    return None


def is_plain_product(head) -> bool:
    """True when the head graph (B [N, 4, q], tau^T [q, M]) -> x is MatMul then a swap of the last two axes."""
    nodes = list(head.graph.node)
    if [n.op_type for n in nodes] != ["MatMul", "Transpose"]:
        return False
    matmul, transpose = nodes
    perm = [list(a.ints) for a in transpose.attribute if a.name == "perm"]
    return (list(matmul.input) == [i.name for i in head.graph.input] and transpose.input[0] == matmul.output[0]
            and perm == [[0, 2, 1]] and transpose.output[0] == head.graph.output[0].name)


def _with_value_info(proto, names):
    """A copy of proto whose graph declares `names` as float tensors of unknown shape (the extractor
    needs a declaration for every cut point; shape inference leaves dynamic ones out)."""
    import onnx

    proto = onnx.shape_inference.infer_shapes(proto)
    declared = {v.name for v in proto.graph.value_info}
    for name in names:
        if name not in declared:
            proto.graph.value_info.append(onnx.helper.make_tensor_value_info(name, onnx.TensorProto.FLOAT, None))
    return proto
