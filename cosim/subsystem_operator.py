"""A sub-system's operator from its detail to its FMU in one call (issue 35, docs/subsystems.md):
`learn(subsystem, boundary, out)`, what `opfmu operator --subsystem FILE --boundary BUS` runs.

Stages, each resumed where an interrupted call left it (call again with the same arguments):
1. out/data: the windows of the sub-system's detail in host cases (cosim.subsystem_data), or of a
   black box's replies to host voltages (an FMU with the bus port: cosim.black_box_data);
2. out/run (and out/run_2, ... for a mean of several): the operator (TRAINING: an anchored Unstacked
   DeepONet, causal, physics on the states whose rates are known: the boundary's frequency
   measurement and n; where asked, reading that measurement at every sensor), resumed from its
   checkpoint;
3. out/operator.onnx (checked against torch; several runs: their mean) and
   out/<NAME>Surrogate.fmu (checked against onnxruntime), and the operator registered for the
   sub-system file's content (cosim.subsystem_surrogate), so that `--attach BUS=FILE:surrogate` finds it.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from reference_models.models.subsystem import MEMORY_STATES, UNIT_FREQUENCY_STATE
from surrogate.losses import LossWeights
from surrogate.models import OperatorConfig
from surrogate.training import TrainConfig

from .subsystem_data import Plan, generate
from .subsystem_surrogate import register

# Ip and Iq are what the FMU takes from the operator; theta_f, theta_w and n it steps exactly
# (their rates are affine: corrections.c), so the data loss weighs them little; a plant controller's
# carried states (subsystem_pc) only feed the next window, so they weigh less than the currents; a
# memory's lags (subsystem_mem) are stepped exactly from the input alone and weigh as theta_f; the
# devices' measured frequency (subsystem_uf) only feeds the next window and spikes at every switching:
# at the controller's weight it took capacity from the currents (docs/results.md), so it weighs as theta_f
TRAINING = TrainConfig(model=OperatorConfig(width=128, depth=3, latent=96, anchored=True, time_taus=(0.01, 0.03, 0.1)),
                       epochs=2000, patience=10**9, time_points=None, causal=True, physics=True,
                       weights=LossWeights(physics_collocation=0.0), state_weights=(0.2, 0.2, 5.0, 5.0, 0.2),
                       checkpoint_every=100)
CARRIED_WEIGHT = 1.0  # the data loss' weight of each carried controller state
MEMORY_WEIGHT = 0.2  # and of each of a memory's lags
UNIT_FREQUENCY_WEIGHT = 0.2  # and of the devices' measured frequency
MEMBERS = 1  # operators trained per sub-system and exported as their mean


def training_config(state_names, seed: int, epochs: int | None, features: bool = False,
                    rollover_share: float = 0.0) -> TrainConfig:
    """TRAINING for a sub-system component of the states `state_names` (its carried states after
    the boundary's five weighing CARRIED_WEIGHT, a memory's lags MEMORY_WEIGHT, the devices' measured
    frequency UNIT_FREQUENCY_WEIGHT); features: the branch also reads the boundary's measured
    frequency at every sensor (the component's window features, surrogate/models.py); rollover_share:
    TrainConfig's (windows that start from the operator's own rollover)."""
    weight = {**{q.name: MEMORY_WEIGHT for q in MEMORY_STATES}, UNIT_FREQUENCY_STATE.name: UNIT_FREQUENCY_WEIGHT}
    weights = TRAINING.state_weights + tuple(weight.get(name, CARRIED_WEIGHT)
                                             for name in state_names[len(TRAINING.state_weights):])
    return replace(TRAINING, seed=seed, epochs=TRAINING.epochs if epochs is None else int(epochs),
                   state_weights=weights, model=replace(TRAINING.model, features=features),
                   rollover_share=float(rollover_share))


def learn(subsystem, boundary: int | None, out, plan: Plan = Plan(), epochs: int | None = None, seed: int = 0,
          workers: int = 1, name: str = "Subsystem", progress: bool = True, rating_mva: float | None = None,
          bus_port: str | None = None, members: int = MEMBERS, features: bool = False,
          rollover_share: float = 0.0) -> dict:
    """Runs (or resumes) the stages of the module docstring; returns {"data": dataset metadata,
    "training": [TrainResult per member], "operator": path, "fmu": path, "registered": path}. A
    sub-system given as an FMU (.fmu: a black box, cosim.black_box_data) takes its rating rating_mva
    [MVA], no boundary, and where its model description declares no bus port, `bus_port`
    (black_box_data.bus_port). members: operators trained on the data with seeds seed, seed + 1, ...
    (out/run, out/run_2, ...), exported as their mean (surrogate.ensemble) where more than one;
    features: they read the boundary's measured frequency, rollover_share: windows that start from
    their own rollover (training_config)."""
    from fmu_export.surrogate_fmu import build_surrogate_fmu
    from surrogate.onnx_export import export_onnx
    from surrogate.training import train

    out = Path(out)
    if Path(subsystem).suffix.lower() == ".fmu":
        from .black_box_data import generate_black_box

        meta = generate_black_box(subsystem, out / "data", rating_mva, plan, seed, workers, progress, bus_port)
    else:
        meta = generate(subsystem, boundary, out / "data", plan, seed, workers, progress)
    runs = [out / "run"] + [out / f"run_{k}" for k in range(2, members + 1)]
    results = [train(out / "data", training_config(meta["state_names"], seed + k, epochs, features, rollover_share),
                     run, progress)
               for k, run in enumerate(runs)]
    operator = out / "operator.onnx"
    trained = max((run / "result.json").stat().st_mtime for run in runs)
    if not operator.exists() or operator.stat().st_mtime < trained:
        export_onnx(runs if members > 1 else runs[0], operator)
    fmu = out / f"{name}Surrogate.fmu"
    if not fmu.exists() or fmu.stat().st_mtime < operator.stat().st_mtime:
        build_surrogate_fmu(operator, fmu, model_name=f"{name}Surrogate")
    return {"data": meta, "training": results, "operator": operator, "fmu": fmu,
            "registered": register(subsystem, operator)}
