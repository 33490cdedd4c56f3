"""opfmu: physics-informed neural operators of power-system components, shipped as FMI 2.0 FMUs."""

__version__ = "0.1.0"
