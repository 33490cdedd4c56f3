"""A sub-system's operator from its detail to its FMU in one call (issue 35, docs/subsystems.md):
`learn(subsystem, boundary, out)`, what `opfmu operator --subsystem FILE --boundary BUS` runs.

Stages, each resumed where an interrupted call left it (call again with the same arguments):
1. out/data: the windows of the sub-system's detail in host cases (cosim.subsystem_data);
2. out/run: the operator (TRAINING: an anchored Unstacked DeepONet, causal, physics on the states
   whose rates are known: the boundary's frequency measurement and n), resumed from its checkpoint;
3. out/operator.onnx (checked against torch) and out/<NAME>Surrogate.fmu (checked against
   onnxruntime), and the operator registered for the sub-system file's content (`registered`), so
   that `--attach BUS=FILE:surrogate` finds it.
"""
from __future__ import annotations

import hashlib
import shutil
from dataclasses import replace
from pathlib import Path

from surrogate.losses import LossWeights
from surrogate.models import OperatorConfig
from surrogate.training import TrainConfig

from .subsystem_data import Plan, generate

# Ip and Iq are what the FMU takes from the operator; theta_f, theta_w and n it steps exactly
# (their rates are affine: corrections.c), so the data loss weighs them little
TRAINING = TrainConfig(model=OperatorConfig(width=128, depth=3, latent=64, anchored=True, time_taus=(0.01, 0.03, 0.1)),
                       epochs=1500, patience=10**9, time_points=None, causal=True, physics=True,
                       weights=LossWeights(physics_collocation=0.0), state_weights=(0.2, 0.2, 5.0, 5.0, 0.2),
                       checkpoint_every=100)


def operator_registry() -> Path:
    """The folder of registered sub-system operators: <sha256 of the sub-system file>.onnx."""
    from reference_models.grid.andes_case import case_cache_dir

    return case_cache_dir() / "subsystem_operators"


def registered(subsystem) -> Path | None:
    """The operator registered for the sub-system file's content, or None."""
    path = operator_registry() / f"{hashlib.sha256(Path(subsystem).read_bytes()).hexdigest()}.onnx"
    return path if path.is_file() else None


def register(subsystem, operator) -> Path:
    """Keeps a copy of `operator` as the one of the sub-system file's content (atomically)."""
    from reference_models.files import atomic_path

    path = operator_registry() / f"{hashlib.sha256(Path(subsystem).read_bytes()).hexdigest()}.onnx"
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        shutil.copyfile(operator, tmp)
    return path


def learn(subsystem, boundary: int, out, plan: Plan = Plan(), epochs: int | None = None, seed: int = 0,
          workers: int = 1, name: str = "Subsystem", progress: bool = True) -> dict:
    """Runs (or resumes) the stages of the module docstring; returns {"data": dataset metadata,
    "training": TrainResult, "operator": path, "fmu": path, "registered": path}."""
    from fmu_export.surrogate_fmu import build_surrogate_fmu
    from surrogate.onnx_export import export_onnx
    from surrogate.training import train

    out = Path(out)
    meta = generate(subsystem, boundary, out / "data", plan, seed, workers, progress)
    config = replace(TRAINING, seed=seed, epochs=TRAINING.epochs if epochs is None else int(epochs))
    result = train(out / "data", config, out / "run", progress)
    operator = out / "operator.onnx"
    if not operator.exists() or operator.stat().st_mtime < (out / "run" / "result.json").stat().st_mtime:
        export_onnx(out / "run", operator)
    fmu = out / f"{name}Surrogate.fmu"
    if not fmu.exists() or fmu.stat().st_mtime < operator.stat().st_mtime:
        build_surrogate_fmu(operator, fmu, model_name=f"{name}Surrogate")
    return {"data": meta, "training": result, "operator": operator, "fmu": fmu,
            "registered": register(subsystem, operator)}
