"""Checks a command makes before any work, so that a refusal is its only output: the files and
folders it will write, the JSON objects it reads, the fields of a configuration. Each raises the
command line's UserError with one line naming the path or field."""
from __future__ import annotations

import json
import math
import os
from pathlib import Path

from opfmu.errors import UserError
from reference_models.messages import explain

MAX_COUNT = 10**9  # largest seed, epoch count or other count a flag or config file may give


def output_file(path) -> Path:
    """`path` as a file the command may write (its folder is made when it is written); UserError,
    before any work, when it is a folder, lies under a file, or its folder cannot be written."""
    path = Path(path)
    if path.is_dir():
        raise UserError(f"{path} is a folder, not a file to write")
    _writable_folder(path.parent, f"cannot write {path}")
    return path


def output_folder(path) -> Path:
    """`path` as a folder the command may create or fill; UserError, before any work, when it is a
    file, lies under a file or cannot be written."""
    if isinstance(path, str) and not path.strip():
        raise UserError("--out must name a folder (an empty name would be the current folder)")
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UserError(f"{path} is a file, not a folder")
    _writable_folder(path, f"cannot write into {path}")
    return path


def _writable_folder(folder: Path, what: str) -> None:
    """UserError `what: reason` unless `folder`, or the nearest of its parents that exists, is a
    folder this process may write into."""
    existing = folder
    while not existing.exists() and existing != existing.parent:
        if existing.is_symlink():
            raise UserError(f"{what}: {existing} is a broken link")
        existing = existing.parent
    if not existing.is_dir():
        raise UserError(f"{what}: {existing} is not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise UserError(f"{what}: permission denied on {existing}")


def json_object_file(path, what: str) -> dict:
    """The JSON object in file `path` (at most 1 MB); UserError naming `what` and the file otherwise."""
    path = Path(path)
    try:
        if path.stat().st_size > 1_000_000:
            raise UserError(f"{what} {path} is larger than 1 MB")
        data = json.loads(path.read_text(encoding="utf-8"), parse_constant=_no_constant)
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
        reason = explain(exc)
        raise UserError(f"cannot read {what} {path}: {reason}") from None
    if not isinstance(data, dict):
        raise UserError(f"{what} {path} must be a JSON object, got {_json_type(data)}")
    return data


def _no_constant(name):
    raise ValueError(f"{name} is not a number JSON allows")


def check_fields(data: dict, cls, where: str) -> None:
    """UserError unless every key of `data` is a field of dataclass `cls` and its value has the JSON
    type of that field's default (a number for a float, an integer in [-MAX_COUNT, MAX_COUNT] for an
    int, a list for a tuple; anything where the default is None)."""
    from dataclasses import MISSING, fields

    known = {f.name: f for f in fields(cls)}
    for key, value in data.items():
        if key not in known:
            raise UserError(f"{where}: unknown field {str(key)[:60]!r} (known: {', '.join(known)})")
        f = known[key]
        default = f.default if f.default is not MISSING else (f.default_factory() if f.default_factory is not MISSING
                                                               else None)
        expected = _expected_type(default)
        if expected is None or isinstance(default, dict):
            continue
        good = {"a boolean": isinstance(value, bool),
                "an integer": isinstance(value, int) and not isinstance(value, bool) and abs(value) <= MAX_COUNT,
                "a finite number": isinstance(value, (int, float)) and not isinstance(value, bool)
                and math.isfinite(value),
                "a string": isinstance(value, str),
                "a list": isinstance(value, list)}[expected]
        if not good:
            raise UserError(f"{where}: {key} must be {expected}, got {_json_type(value)}")


def _expected_type(default):
    for kind, name in ((bool, "a boolean"), (int, "an integer"), (float, "a finite number"), (str, "a string"),
                       ((tuple, list), "a list")):
        if isinstance(default, kind):
            return name
    return None


def _json_type(value) -> str:
    if isinstance(value, bool):
        return "a boolean"
    for kind, name in ((dict, "an object"), (list, "a list"), (str, "a string"), (int, "an integer"),
                       (float, "a number")):
        if isinstance(value, kind):
            return name if kind is not int or abs(value) <= MAX_COUNT else "an integer out of range"
    return "null"
