"""The opfmu version: recorded in datasets, operator files and FMUs."""

__version__ = "0.3.0"
