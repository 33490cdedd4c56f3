"""Dataset presets: how many trajectories, over which window, from which initial states and inputs."""
from __future__ import annotations

import json
import math
from dataclasses import MISSING, asdict, dataclass, field, fields, replace
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
    levels: {input name: (low, high)}: the level ranges the families draw each input from (a
        machine's dispatch and field voltages); inputs not named keep their operating range.
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
    levels: dict = field(default_factory=dict)

    def __post_init__(self):
        from reference_models.components import component
        from reference_models.families import family

        def whole(value, low, high):
            return isinstance(value, int) and not isinstance(value, bool) and low <= value <= high

        if not isinstance(self.counts, dict) or not all(whole(self.counts.get(s, -1), 0, 10**6) for s in SPLITS):
            raise ValueError(f"preset {self.name!r}: counts must give every split ({', '.join(SPLITS)}) "
                             "a whole number in [0, 1000000]")
        if not self.families or not all(isinstance(f, (tuple, list)) and len(f) == 2 for f in self.families):
            raise ValueError(f"preset {self.name!r}: families must be (name, weight) pairs")
        for name, weight in self.families:
            family(str(name))  # ValueError naming the known families
            if not (isinstance(weight, (int, float)) and weight >= 0):
                raise ValueError(f"preset {self.name!r}: family {name!r} needs a weight >= 0")
        if not (isinstance(self.horizon, (int, float)) and 0 < self.horizon <= 1000):
            raise ValueError(f"preset {self.name!r}: horizon must lie in (0, 1000] s")
        if not whole(self.n_points, 2, 100_000) or not whole(self.chunk_size, 1, 10**6):
            raise ValueError(f"preset {self.name!r}: n_points must lie in [2, 100000] and chunk_size be >= 1")
        if self.ic not in ("box", "reachable") or not (0 <= self.reachable_fraction <= 1):
            raise ValueError(f"preset {self.name!r}: ic must be box or reachable, reachable_fraction in [0, 1]")
        if not whole(self.probes_per_family, 1 if self.ic == "reachable" else 0, 10**5):
            raise ValueError(f"preset {self.name!r}: probes_per_family must be a whole number (>= 1 when "
                             "ic is reachable)")

        try:
            model = component(str(self.component))
            model.require_states()  # the trajectories of states are what a dataset holds
        except ValueError as exc:
            raise ValueError(f"preset {self.name!r}: {exc}") from None
        inputs = model.input_names
        if not isinstance(self.levels, dict):
            raise ValueError(f"preset {self.name!r}: levels must map input names to (low, high)")
        for name, pair in self.levels.items():
            ok = (isinstance(pair, (tuple, list)) and len(pair) == 2
                  and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in pair)
                  and pair[0] <= pair[1])
            if name not in inputs or not ok:
                raise ValueError(f"preset {self.name!r}: levels must map inputs of {self.component} "
                                 f"({', '.join(inputs)}) to (low, high) with low <= high, got {str(name)[:40]!r}")
        object.__setattr__(self, "levels", {k: tuple(float(v) for v in p) for k, p in self.levels.items()})

    def to_dict(self) -> dict:
        return asdict(self)


# `jump` windows start at an input change, as the FMU's windows do at a jump (restart_jump); the
# control families move Pm and Efd, `drift` is a faulted bus of a drifting network under a ZOH master
COSIM_FAMILIES = (
    ("slow", 0.06), ("fast", 0.06), ("step", 0.06), ("dip", 0.08), ("ramp", 0.06),
    ("zoh-slow", 0.03), ("zoh-fast", 0.03), ("zoh-ramp", 0.03), ("mix", 0.07), ("jump", 0.14),
    ("governor", 0.07), ("exciter", 0.1), ("zoh-exciter", 0.04), ("avr", 0.05), ("drift", 0.06),
    ("zoh-governor", 0.02),
)
# the paper's machine at its operating point (Table I): the Table II setting
PAPER_LEVELS = {"Pm": (0.7048, 0.7048), "Efd": (1.08, 1.08)}

PRESETS = {
    "paper": Preset(
        name="paper",
        counts={"train": 1000, "collocation": 1000, "val": 100, "test": 100},
        families=(("slow", 0.5), ("fast", 0.5)),
        levels=PAPER_LEVELS,
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
        if not isinstance(fields_, dict):
            raise ValueError("it must be a JSON object of Preset fields")
        unknown = sorted(set(fields_) - {f.name for f in fields(Preset)})
        missing = [f.name for f in fields(Preset) if f.default is MISSING and f.default_factory is MISSING
                   and f.name not in fields_]
        if unknown or missing:
            raise ValueError(f"unknown field {unknown[0][:60]!r}" if unknown else f"it lacks the field {missing[0]!r}")
        if not isinstance(fields_.get("solver", {}), dict):
            raise ValueError("solver must be a JSON object of SolverConfig fields")
        solver = SolverConfig(**fields_.pop("solver", {}))
        fields_["families"] = tuple(tuple(f) for f in fields_["families"])
        fields_["levels"] = {k: tuple(v) for k, v in fields_.get("levels", {}).items()}
        return Preset(solver=solver, **fields_)
    except (ValueError, TypeError, KeyError, AttributeError, RecursionError, OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"preset file {path} is not a valid preset: {' '.join(str(exc).split())[:300]}") from None
