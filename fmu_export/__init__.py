"""FMI 2.0 and 3.0 co-simulation FMUs of opfmu components: the surrogate FMU of an ONNX operator
(surrogate_fmu), the native and pythonfmu reference FMUs (native_reference_fmu,
python_reference_fmu), their C sources and code generation, cross-platform binaries and the
content-keyed build cache."""
