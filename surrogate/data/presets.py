"""Dataset presets: how many trajectories, over which window, from which initial states and inputs."""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

from reference_models.simulate import SolverConfig

SPLITS = ("train", "collocation", "val", "test")
LABELED = {"train": True, "collocation": False, "val": True, "test": True}

PAPER_IC_BOX = {"delta": (-2.0, 2.0), "omega": (-1.0, 1.0), "Ed_p": (0.0, 0.0), "Eq_p": (0.9, 1.1)}


@dataclass(frozen=True)
class Preset:
    """A dataset recipe.

    horizon [s] and n_points set the shared grid (sensor times = query times, uniform from 0).
    families: (family name, weight) pairs; each split is split between them by weight.
    ic: "box" samples x0 by Latin hypercube in ic_box [state -> (low, high)] (equal ends: fixed);
        "reachable" draws `reachable_fraction` of x0 from states measured along reference windows
        started at steady states (see surrogate.data.envelope) and the rest by LHS in their bounding box.
    probes_per_family: reference windows per family for the reachable-set measurement.
    chunk_size: trajectories per solve task (the unit of parallel work and of resume).
    component: the component whose trajectories are solved (reference_models.components).
    """

    name: str
    counts: dict
    families: tuple
    horizon: float = 1.0
    n_points: int = 1001
    ic: str = "box"
    ic_box: dict = field(default_factory=lambda: dict(PAPER_IC_BOX))
    reachable_fraction: float = 0.0
    probes_per_family: int = 0
    solver: SolverConfig = SolverConfig()
    chunk_size: int = 50
    component: str = "sm4"

    def to_dict(self) -> dict:
        return asdict(self)


# `jump` windows start at an input change, as the FMU's windows do at a jump (restart_jump)
COSIM_FAMILIES = (
    ("slow", 0.1), ("fast", 0.1), ("step", 0.1), ("dip", 0.15), ("ramp", 0.1),
    ("zoh-slow", 0.05), ("zoh-fast", 0.05), ("zoh-ramp", 0.05), ("mix", 0.1), ("jump", 0.2),
)

PRESETS = {
    "paper": Preset(
        name="paper",
        counts={"train": 1000, "collocation": 1000, "val": 100, "test": 100},
        families=(("slow", 0.5), ("fast", 0.5)),
    ),
    "cosim": Preset(
        name="cosim",
        counts={"train": 4000, "collocation": 2000, "val": 200, "test": 200},
        families=COSIM_FAMILIES,
        ic="reachable",
        reachable_fraction=0.75,
        probes_per_family=100,
    ),
}
PRESETS["quick"] = replace(
    PRESETS["cosim"],
    name="quick",
    counts={"train": 200, "collocation": 200, "val": 40, "test": 40},
    probes_per_family=12,
    chunk_size=20,
)


def preset(name: str) -> Preset:
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"unknown preset {name!r} (known: {', '.join(PRESETS)})") from None


def load_preset(name_or_path: str) -> Preset:
    """A named preset, or one read from a JSON file of Preset fields (missing fields: defaults)."""
    path = Path(name_or_path)
    if not name_or_path.endswith(".json"):
        return preset(name_or_path)
    if not path.exists():
        raise ValueError(f"preset file {path} does not exist")
    try:
        fields_ = json.loads(path.read_text())
        solver = SolverConfig(**fields_.pop("solver", {}))
        fields_["families"] = tuple(tuple(f) for f in fields_["families"])
        loaded = Preset(solver=solver, **fields_)
    except (json.JSONDecodeError, TypeError, KeyError) as exc:
        raise ValueError(f"preset file {path} is not a valid preset: {exc}") from None
    missing = set(SPLITS) - set(loaded.counts)
    if missing:
        raise ValueError(f"preset file {path} gives no count for split(s) {', '.join(sorted(missing))}")
    return loaded
