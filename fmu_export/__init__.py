"""FMI 2.0 co-simulation export of opfmu operators (C sources, code generation, builder)."""
