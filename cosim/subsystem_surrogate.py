"""A sub-system run as its surrogate FMU (issue 35, docs/subsystems.md): the operators registered for
sub-system files (`registered`, `register`) and a case with one attached as its operator's device
(`surrogate_in`). What `opfmu grid run --attach BUS=FILE:surrogate` needs, apart from the learning
(cosim.subsystem_operator), so that a run imports neither torch nor the onnx package.
"""
from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

# the operators of the shipped sub-systems (`feeder`, `plant`): <name>-<first 16 hex digits of the
# sha256 of the sub-system file>.onnx
SHIPPED = Path(__file__).resolve().parents[1] / "surrogate" / "default" / "subsystems"


def operator_registry() -> Path:
    """The folder of the operators registered (`register`, which cosim.subsystem_operator.learn
    calls): <sha256 of the sub-system file>.onnx."""
    from reference_models.grid.andes_case import case_cache_dir

    return case_cache_dir() / "subsystem_operators"


def registered(subsystem) -> Path | None:
    """The operator for the sub-system file's content: one `learn` registered, else a shipped one,
    else None."""
    digest = hashlib.sha256(Path(subsystem).read_bytes()).hexdigest()
    path = operator_registry() / f"{digest}.onnx"
    if path.is_file():
        return path
    return next(iter(sorted(SHIPPED.glob(f"*-{digest[:16]}.onnx"))), None)


def register(subsystem, operator) -> Path:
    """Keeps a copy of `operator` as the one of the sub-system file's content (atomically)."""
    from reference_models.files import atomic_path

    path = operator_registry() / f"{hashlib.sha256(Path(subsystem).read_bytes()).hexdigest()}.onnx"
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        shutil.copyfile(operator, tmp)
    return path


def surrogate_in(case, bus: int, subsystem):
    """`case` (with the sub-system file `subsystem` attached at its bus `bus`) with that sub-system
    run as its surrogate FMU: one `subsystem` device at `bus` whose operator is the one registered
    for the file (boundary.with_equivalent); CouplingError where none is."""
    from reference_models.grid.boundary import with_equivalent
    from reference_models.grid.case import Device
    from surrogate.contract import ContractError, metadata_of, operator_metadata

    from .fmu import CouplingError

    operator = registered(subsystem)
    if operator is None:
        raise CouplingError(f"no operator is registered for the sub-system {Path(subsystem).name}: learn one with "
                            f"opfmu operator --subsystem {subsystem} --boundary BUS --out DIR")
    try:
        meta = operator_metadata(metadata_of(operator))
    except (ContractError, OSError, ValueError) as exc:
        raise CouplingError(f"the operator registered for {Path(subsystem).name} ({operator}) is not usable: {exc}") from None
    device = Device("subsystem", meta["component"], meta["params"])
    return with_equivalent(case, bus, device, {"kind": "surrogate", "operator": str(operator)})
