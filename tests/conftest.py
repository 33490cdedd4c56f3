"""Small dataset recipes and the SM4 FMUs (surrogate, native and pythonfmu reference), shared by the tests."""
import json
from dataclasses import replace

import pytest

from surrogate.data import generate, preset


def tiny(name="paper", **changes):
    """A few trajectories of a named preset (chunks of 3 unless changed)."""
    changes = {"counts": {"train": 8, "collocation": 4, "val": 3, "test": 3}, "chunk_size": 3, **changes}
    return replace(preset(name), **changes)


def preset_file(path, recipe):
    """Writes a preset as the JSON file `opfmu data --preset FILE.json` reads."""
    path.write_text(json.dumps(recipe.to_dict()))
    return path


@pytest.fixture(scope="session")
def paper_tiny(tmp_path_factory):
    """(recipe, directory) of a tiny paper-preset dataset, generated once."""
    recipe = tiny("paper")
    out = tmp_path_factory.mktemp("paper_tiny")
    generate(recipe, out, seed=7, progress=False)
    return recipe, out


@pytest.fixture(scope="session")
def cosim_tiny(tmp_path_factory):
    """(recipe, directory) of a tiny cosim-preset dataset (2 probes per family), generated once."""
    recipe = tiny("cosim", probes_per_family=2)
    out = tmp_path_factory.mktemp("cosim_tiny")
    generate(recipe, out, seed=3, progress=False)
    return recipe, out


@pytest.fixture(scope="session")
def fmu_path(tmp_path_factory):
    """The surrogate FMU of the shipped operator, built once."""
    from fmu_export.surrogate_fmu import build_surrogate_fmu
    from surrogate.operator import DEFAULT_OPERATOR

    path = tmp_path_factory.mktemp("fmu") / "SM4Surrogate.fmu"
    build_surrogate_fmu(DEFAULT_OPERATOR, path)
    return path


@pytest.fixture(scope="session")
def native_reference_path(tmp_path_factory):
    """The native reference FMU (Dormand-Prince 5(4) in C) of the default machine, built once."""
    from fmu_export.native_reference_fmu import build_native_reference_fmu

    path = tmp_path_factory.mktemp("native_reference") / "SM4Reference.fmu"
    build_native_reference_fmu(path)
    return path


@pytest.fixture(scope="session")
def reference_path(tmp_path_factory):
    """The pythonfmu reference FMU (scipy RK45) of the default machine, built once."""
    from fmu_export.python_reference_fmu import build_reference_fmu

    path = tmp_path_factory.mktemp("reference") / "SM4Reference.fmu"
    build_reference_fmu(path)
    return path


@pytest.fixture(scope="session")
def grid_fmu_cache(tmp_path_factory):
    """The FMU cache of the grid tests (cosim.fmus): each generator's FMUs are built once."""
    return tmp_path_factory.mktemp("grid_fmus")
