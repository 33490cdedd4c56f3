"""opfmu: physics-informed neural operators of power-system components, shipped as FMI 2.0 FMUs."""
from reference_models.version import __version__

__all__ = ["__version__"]
