"""Operator datasets, networks, physics losses, training, evaluation and ONNX export/inference.

`from surrogate import Operator` gives inference on an exported operator file; importing it loads
neither torch nor the training code.
"""
from .operator import Operator

__all__ = ["Operator"]
