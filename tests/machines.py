"""Machines the tests run, read from the data files the project ships."""
import json

from reference_models.grid.case import DATA_DIR


def wscc9_machine(k: int) -> dict:
    """SM4 parameters of WSCC 9-bus generator k (1-3; Anderson & Fouad, Sauer-Pai two-axis data, 100 MVA,
    60 Hz: Wb = 376.99 rad/s) from reference_models/grid/data/wscc9_gen<k>.json, as name: value."""
    return json.loads((DATA_DIR / f"wscc9_gen{k}.json").read_text(encoding="utf-8"))
