"""modelDescription.xml of opfmu's FMUs (FMI 2.0 co-simulation), written with ElementTree.

Variables come from variables.py; ModelStructure gives every output's dependencies (the states
depend on no input within a step, a derived output directly on the inputs its equation reads),
with indices as 1-based positions in ModelVariables.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET

from reference_models.version import __version__

from .variables import Variable


# SI base-unit exponents of the units components use; a unit not listed is declared without them
BASE_UNITS = {"rad": {"rad": "1"}, "rad/s": {"rad": "1", "s": "-1"}, "s": {"s": "1"}, "pu": {},
              "Hz": {"s": "-1"}, "1/s": {"s": "-1"}}


def unit_names(variables: list[Variable]) -> list[str]:
    """The units the variables use, in order of first use (pu, dimensionless, declared all the same)."""
    return list(dict.fromkeys(v.unit for v in variables if v.unit))


def model_description(model_name: str, guid: str, variables: list[Variable], description: str,
                      stop_time: float = 10.0, step: float = 0.01, directional_derivatives: bool = False,
                      interpolates_inputs: bool = False) -> bytes:
    """The XML document (UTF-8 bytes). directional_derivatives: the FMU provides
    fmi2GetDirectionalDerivative (providesDirectionalDerivative); interpolates_inputs: it takes
    first input derivatives with fmi2SetRealInputDerivatives, the inputs linear over a step
    (canInterpolateInputs)."""
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": model_name, "guid": guid, "description": description,
        "generationTool": f"opfmu {__version__}", "variableNamingConvention": "flat",
        "numberOfEventIndicators": "0"})
    capabilities = {"modelIdentifier": model_name, "canHandleVariableCommunicationStepSize": "true"}
    if interpolates_inputs:
        capabilities["canInterpolateInputs"] = "true"
    capabilities.update(canGetAndSetFMUstate="true", canSerializeFMUstate="true",
                        canNotUseMemoryManagementFunctions="true")
    if directional_derivatives:
        capabilities["providesDirectionalDerivative"] = "true"
    ET.SubElement(root, "CoSimulation", capabilities)
    units = ET.SubElement(root, "UnitDefinitions")
    for name in unit_names(variables):
        unit = ET.SubElement(units, "Unit", {"name": name})
        if name in BASE_UNITS:
            ET.SubElement(unit, "BaseUnit", BASE_UNITS[name])
    categories = ET.SubElement(root, "LogCategories")
    for name, text in (("logStatusWarning", "warnings: inputs or states outside the trained envelope"),
                       ("logStatusError", "errors: invalid calls and values"), ("logAll", "everything")):
        ET.SubElement(categories, "Category", {"name": name, "description": text})
    ET.SubElement(root, "DefaultExperiment", {"startTime": "0", "stopTime": repr(stop_time), "stepSize": repr(step)})
    mv = ET.SubElement(root, "ModelVariables")
    for v in variables:
        attrs = {"name": v.name, "valueReference": str(v.vr), "causality": v.causality, "description": v.description}
        if v.causality == "parameter":
            attrs.update(variability="fixed", initial="exact")
        elif v.causality == "input":
            attrs["variability"] = "continuous" if v.kind == "Real" else "discrete"
        else:
            attrs.update(variability="continuous" if v.kind == "Real" else "discrete", initial="calculated")
        sv = ET.SubElement(mv, "ScalarVariable", attrs)
        type_attrs = {"unit": v.unit} if v.unit and v.unit != "pu" else {}
        if v.start is not None:
            type_attrs["start"] = repr(float(v.start))
        ET.SubElement(sv, v.kind, type_attrs)
    structure = ET.SubElement(root, "ModelStructure")
    index = {v.name: i + 1 for i, v in enumerate(variables)}
    outputs = [v for v in variables if v.causality == "output"]
    out_el = ET.SubElement(structure, "Outputs")
    for v in outputs:
        ET.SubElement(out_el, "Unknown", {"index": str(index[v.name]),
                                          "dependencies": " ".join(str(index[n]) for n in v.dependencies)})
    init_el = ET.SubElement(structure, "InitialUnknowns")
    parameters = [str(index[v.name]) for v in variables if v.causality == "parameter"]
    for v in outputs:
        deps = [str(index[n]) for n in v.dependencies] + parameters
        ET.SubElement(init_el, "Unknown", {"index": str(index[v.name]), "dependencies": " ".join(deps)})
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def validation_problems(fmu) -> list[str]:
    """What fmpy's validator finds wrong with an FMU file (empty: nothing)."""
    from fmpy.validation import validate_fmu

    return list(validate_fmu(str(fmu)))
