"""Labeled and collocation datasets of reference trajectories (see datasets.py for the format)."""
from .datasets import DatasetError, generate, load_metadata, load_split, machine_of, time_grid
from .presets import PRESETS, SPLITS, Preset, preset

__all__ = ["DatasetError", "generate", "load_metadata", "load_split", "machine_of", "time_grid", "PRESETS", "SPLITS",
           "Preset", "preset"]
