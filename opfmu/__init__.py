"""opfmu: physics-informed neural operators of power-system components, shipped as FMI 2.0 and 3.0
co-simulation FMUs; this package is the command line."""
from reference_models.version import __version__

__all__ = ["__version__"]
