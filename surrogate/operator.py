"""Inference on an exported operator with onnxruntime: `Operator.load(path).predict(x0, u, t)`.

For a DeepONet the graph is split at the product of branch coefficients and trunk basis into
three sessions: branch (x0, u -> B), trunk (t -> tau) and head (B, tau -> x). The trunk basis depends
only on the query times, so it is cached per time grid: repeated predictions on one grid cost a
branch evaluation and the small head. Graphs without that product (the PINN) run whole.
"""
from __future__ import annotations

import json
import warnings
from collections import OrderedDict
from pathlib import Path

import numpy as np

from reference_models.sm4 import INPUT_NAMES, STATE_NAMES


DEFAULT_OPERATOR = Path(__file__).parent / "default" / "sm4_cosim.onnx"


class OperatorInputError(ValueError):
    """Inputs that do not fit the operator (shape, time range, non-finite values, envelope if strict)."""


class EnvelopeWarning(UserWarning):
    """Inputs outside the envelope the operator was trained on: its answer is an extrapolation."""


class Operator:
    """An exported SM4 operator. predict(x0 [N, 4], u [N, S, 2], t [M]) -> x [N, M, 4] (float32)."""

    CACHE_SIZE = 8  # time grids whose trunk basis is kept
    # batches at least this large run the whole graph: there the trunk is a negligible part and the
    # split graph's extra session costs more than it saves (measured: 1000 trajectories, 113 ms split
    # against 57 ms whole; 10 trajectories, 1.0 ms split against 1.3 ms whole)
    SPLIT_BELOW = 100

    def __init__(self, path, providers=None, threads: int | None = None):
        import onnx
        import onnxruntime as ort

        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"no operator file at {path}")
        proto = onnx.load(str(path))
        self.path = path
        self.metadata = {p.key: p.value for p in proto.metadata_props}
        missing = {"horizon_s", "n_sensors", "envelope"} - set(self.metadata)
        if missing:
            raise OperatorInputError(f"{path} is not an opfmu operator (metadata lacks {', '.join(sorted(missing))})")
        self.horizon = float(self.metadata["horizon_s"])
        self.n_sensors = int(self.metadata["n_sensors"])
        self.envelope = json.loads(self.metadata["envelope"])
        bounds = [self.envelope["x0"][n] for n in STATE_NAMES] + [self.envelope["u"][n] for n in INPUT_NAMES]
        self._env_min, self._env_max = np.array(bounds).T
        options = ort.SessionOptions()
        if threads:
            options.intra_op_num_threads = threads
        available = ort.get_available_providers()
        providers = providers or [p for p in ("CUDAExecutionProvider", "CPUExecutionProvider") if p in available]
        session = lambda model: ort.InferenceSession(model.SerializeToString(), options, providers=providers)  # noqa: E731
        self._full = session(proto)
        split = split_branch_trunk(proto)
        self._parts = None if split is None else tuple(session(part) for part in split)
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
        return self._parts is not None

    def predict(self, x0, u, t, strict: bool = False) -> np.ndarray:
        """States x [N, M, 4] at times t [M] (s, within [0, horizon]) from x0 [N, 4] and inputs u [N, S, 2]
        at the operator's sensor times. Outside the training envelope: EnvelopeWarning, or
        OperatorInputError when strict."""
        x0, u, t = self._checked(x0, u, t, strict)
        if self._parts is None or len(x0) >= self.SPLIT_BELOW:
            return self._full.run(["x"], {"x0": x0, "u": u, "t": t})[0]
        branch, trunk, head = self._parts
        b = branch.run(None, {"x0": x0, "u": u})[0]
        return head.run(["x"], {head.get_inputs()[0].name: b, head.get_inputs()[1].name: self._trunk(trunk, t)})[0]

    def _trunk(self, trunk, t: np.ndarray) -> np.ndarray:
        key = t.tobytes()
        if key in self._basis:
            self._basis.move_to_end(key)
        else:
            self._basis[key] = trunk.run(None, {"t": t})[0]
            if len(self._basis) > self.CACHE_SIZE:
                self._basis.popitem(last=False)
        return self._basis[key]

    def _checked(self, x0, u, t, strict: bool):
        x0, u, t = (np.ascontiguousarray(a, dtype=np.float32) for a in (x0, u, t))
        if x0.ndim != 2 or x0.shape[1] != 4:
            raise OperatorInputError(f"x0 must be [N, 4] ({', '.join(STATE_NAMES)}), got shape {x0.shape}")
        if u.shape != (x0.shape[0], self.n_sensors, 2):
            raise OperatorInputError(f"u must be [N, S, 2] = [{x0.shape[0]}, {self.n_sensors}, 2] "
                                     f"({', '.join(INPUT_NAMES)} at the sensor times), got shape {u.shape}")
        if t.ndim != 1 or t.size == 0:
            raise OperatorInputError(f"t must be a non-empty 1-D array of times, got shape {t.shape}")
        low, high = self._ranges(x0, u)
        for name, a in (("x0", np.concatenate([low[:4], high[:4]])), ("u", np.concatenate([low[4:], high[4:]])), ("t", t)):
            if not np.all(np.isfinite(a)):  # NaN and inf propagate into the ranges
                raise OperatorInputError(f"{name} holds NaN or inf")
        if t.min() < 0 or t.max() > self.horizon * (1 + 1e-6):
            raise OperatorInputError(f"t must lie in [0, {self.horizon:g}] s (the horizon), got [{t.min():g}, {t.max():g}]")
        outside = self._outside(low, high)
        if outside:
            message = "outside the training envelope: " + "; ".join(outside)
            if strict:
                raise OperatorInputError(message)
            warnings.warn(message, EnvelopeWarning, stacklevel=3)
        return x0, u, t

    def outside_envelope(self, x0: np.ndarray, u: np.ndarray) -> list[str]:
        """One line per quantity outside the envelope: its range against the trained range."""
        return self._outside(*self._ranges(np.asarray(x0), np.asarray(u)))

    @staticmethod
    def _ranges(x0: np.ndarray, u: np.ndarray):
        """(min, max) [6] of the four states in x0 and the two inputs in u (per-channel strided
        reductions: a reduction over axis 0 of a [N*S, 2] array is an order of magnitude slower)."""
        columns = [x0[:, i] for i in range(4)] + [u[..., c] for c in range(2)]
        return np.array([c.min() for c in columns]), np.array([c.max() for c in columns])

    def _outside(self, low: np.ndarray, high: np.ndarray) -> list[str]:
        outside = (low < self._env_min - 1e-6) | (high > self._env_max + 1e-6)
        return [f"{name} in [{low[i]:.4g}, {high[i]:.4g}], trained [{self._env_min[i]:.4g}, {self._env_max[i]:.4g}]"
                for i, name in enumerate(STATE_NAMES + INPUT_NAMES) if outside[i]]


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
