"""modelDescription.xml of opfmu's FMUs (FMI 2.0 or 3.0 co-simulation), written with ElementTree.

Variables come from variables.py; ModelStructure gives every output's dependencies (the states
depend on no input within a step, a derived output directly on the inputs its equation reads):
in FMI 2.0 as 1-based positions in ModelVariables, in FMI 3.0 as value references (unique across
types there: variables.fmi3_value_references), with the independent variable `time` FMI 3.0 requires.
The component's ports (reference_models.ports), which the variable table carries, are declared as a
<Ports> element: in FMI 2.0 under <VendorAnnotations><Tool name="opfmu">, between DefaultExperiment
and ModelVariables as the schema orders them; in FMI 3.0 under <Annotations><Annotation
type="org.opfmu.ports">, the last element of the document.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET

from reference_models.ports import FMI3_ANNOTATION_TYPE, TOOL_NAME
from reference_models.version import __version__

from .variables import TIME, Variable, VariableTable, fmi3_value_references


# SI base-unit exponents (and factor) of the units components use; a unit not listed is declared
# without them. pu and 1 are dimensionless.
BASE_UNITS = {"rad": {"rad": "1"}, "rad/s": {"rad": "1", "s": "-1"}, "s": {"s": "1"}, "pu": {}, "1": {},
              "Hz": {"s": "-1"}, "1/s": {"s": "-1"}, "deg": {"rad": "1", "factor": repr(math.pi / 180.0)},
              # the rates of the states (Model Exchange's derivatives: variables.rate_unit)
              "pu/s": {"s": "-1"}, "rad/s2": {"rad": "1", "s": "-2"},
              "deg/s": {"rad": "1", "s": "-1", "factor": repr(math.pi / 180.0)}}
DIMENSIONLESS = ("", "-")  # how a variable without a unit may say so: declared as the unit "1"


def unit_of(v: Variable) -> str | None:
    """The unit a Real variable declares (every one declares one: "1" where it has none), None for another type."""
    if v.kind != "Real":
        return None
    return "1" if v.unit in DIMENSIONLESS else v.unit


def unit_names(variables: list[Variable]) -> list[str]:
    """The units the Real variables declare, in order of first use."""
    return list(dict.fromkeys(unit_of(v) for v in variables if v.kind == "Real"))


LOG_CATEGORIES = (("logStatusWarning", "warnings: inputs or states outside the trained envelope"),
                  ("logStatusError", "errors: invalid calls and values"), ("logAll", "everything"))


def model_description(model_name: str, guid: str, variables: list[Variable], description: str,
                      stop_time: float = 10.0, step: float = 0.01, directional_derivatives: bool = False,
                      interpolates_inputs: bool = False, fmi_version: int = 2, model_exchange: bool = False) -> bytes:
    """The XML document (UTF-8 bytes) of an FMI `fmi_version` (2 or 3) co-simulation FMU with
    `variables` (a VariableTable declares its component's ports; a plain list declares none).
    directional_derivatives: the FMU provides the outputs' derivatives with respect to the inputs
    (FMI 2.0 fmi2GetDirectionalDerivative; FMI 3.0 also fmi3GetAdjointDerivative); interpolates_inputs:
    it takes first input derivatives with fmi2SetRealInputDerivatives, the inputs linear over a step
    (canInterpolateInputs; FMI 3.0 has no such call, its inputs are held over a step).
    model_exchange: the FMU also offers Model Exchange (same model identifier), with the state
    derivatives and event indicators of `variables` (variables.exchange_variables)."""
    if fmi_version == 3:
        return _fmi3_document(model_name, guid, variables, description, stop_time, step, directional_derivatives,
                              model_exchange)
    if fmi_version != 2:
        raise ValueError(f"FMI version {fmi_version!r}: 2 or 3")
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": model_name, "guid": guid, "description": description,
        "generationTool": f"opfmu {__version__}", "variableNamingConvention": "flat",
        "numberOfEventIndicators": str(len(_indicators(variables)) if model_exchange else 0)})
    if model_exchange:  # before CoSimulation, as the schema orders them; fmi2CompletedIntegratorStep is called
        ET.SubElement(root, "ModelExchange", {  # (completedIntegratorStepNotNeeded: false, the default)
            "modelIdentifier": model_name, "canGetAndSetFMUstate": "true",
            "canSerializeFMUstate": "true", "canNotUseMemoryManagementFunctions": "true"})
    capabilities = {"modelIdentifier": model_name, "canHandleVariableCommunicationStepSize": "true"}
    if interpolates_inputs:
        capabilities["canInterpolateInputs"] = "true"
    capabilities.update(canGetAndSetFMUstate="true", canSerializeFMUstate="true",
                        canNotUseMemoryManagementFunctions="true")
    if directional_derivatives:
        capabilities["providesDirectionalDerivative"] = "true"
    ET.SubElement(root, "CoSimulation", capabilities)
    _units_categories_experiment(root, variables, stop_time, step)
    if isinstance(variables, VariableTable):
        ET.SubElement(ET.SubElement(root, "VendorAnnotations"), "Tool", {"name": TOOL_NAME}).append(
            variables.ports.element())
    mv = ET.SubElement(root, "ModelVariables")
    index = {v.name: i + 1 for i, v in enumerate(variables)}
    for v in variables:
        sv = ET.SubElement(mv, "ScalarVariable", {"name": v.name, "valueReference": str(v.vr),
                                                 "causality": v.causality, "description": v.description,
                                                 **_variability(v)})
        type_attrs = {"unit": unit_of(v)} if v.kind == "Real" else {}
        type_attrs.update(_bounds(v))
        if v.start is not None:
            type_attrs["start"] = repr(float(v.start))
        if v.derivative_of is not None:
            type_attrs["derivative"] = str(index[v.derivative_of])
        ET.SubElement(sv, v.kind, type_attrs)
    structure = ET.SubElement(root, "ModelStructure")
    _structure(structure, variables, index, "Outputs", "InitialUnknowns", "Unknown", "index", model_exchange)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _fmi3_document(model_name: str, guid: str, variables: list[Variable], description: str, stop_time: float,
                   step: float, directional_derivatives: bool, model_exchange: bool) -> bytes:
    """modelDescription.xml of FMI 3.0 co-simulation: Float64 and Boolean variables, `time` as the
    independent variable, no event mode, variable communication steps, FMU state, and (if
    directional_derivatives) directional and adjoint derivatives; with model_exchange also Model
    Exchange."""
    refs = fmi3_value_references(variables)
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "3.0", "modelName": model_name, "instantiationToken": guid, "description": description,
        "generationTool": f"opfmu {__version__}", "variableNamingConvention": "flat"})
    if model_exchange:  # the schema orders ModelExchange before CoSimulation
        ET.SubElement(root, "ModelExchange", {
            "modelIdentifier": model_name, "needsCompletedIntegratorStep": "true", "canGetAndSetFMUState": "true",
            "canSerializeFMUState": "true"})
    flags = "true" if directional_derivatives else "false"
    ET.SubElement(root, "CoSimulation", {
        "modelIdentifier": model_name, "canGetAndSetFMUState": "true", "canSerializeFMUState": "true",
        "providesDirectionalDerivatives": flags, "providesAdjointDerivatives": flags,
        "canHandleVariableCommunicationStepSize": "true", "hasEventMode": "false"})
    _units_categories_experiment(root, variables, stop_time, step)
    mv = ET.SubElement(root, "ModelVariables")
    ET.SubElement(mv, "Float64", {"name": TIME, "valueReference": str(refs[TIME]), "causality": "independent",
                                  "variability": "continuous", "description": "simulation time", "unit": "s"})
    for v in variables:
        attrs = {"name": v.name, "valueReference": str(refs[v.name]), "causality": v.causality,
                 "description": v.description, **_variability(v)}
        if v.kind == "Real":
            attrs["unit"] = unit_of(v)
            attrs.update(_bounds(v))
        if v.start is not None:
            attrs["start"] = repr(float(v.start)) if v.kind == "Real" else ("true" if v.start else "false")
        if v.derivative_of is not None:
            attrs["derivative"] = str(refs[v.derivative_of])
        ET.SubElement(mv, "Float64" if v.kind == "Real" else v.kind, attrs)
    structure = ET.SubElement(root, "ModelStructure")
    _structure(structure, variables, refs, "Output", "InitialUnknown", None, "valueReference", model_exchange)
    if model_exchange:
        for v in _indicators(variables):
            ET.SubElement(structure, "EventIndicator", {"valueReference": str(refs[v.name])})
    if isinstance(variables, VariableTable):
        ET.SubElement(ET.SubElement(root, "Annotations"), "Annotation", {"type": FMI3_ANNOTATION_TYPE}).append(
            variables.ports.element())
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _bounds(v: Variable) -> dict:
    """min and max of a variable with a declared range (the same attributes in FMI 2.0 and 3.0)."""
    return {name: repr(float(value)) for name, value in (("min", v.minimum), ("max", v.maximum)) if value is not None}


def _variability(v: Variable) -> dict:
    """variability and initial of a variable (the same in FMI 2.0 and 3.0)."""
    if v.causality == "parameter":
        return {"variability": "fixed", "initial": "exact"}
    if v.causality == "calculatedParameter":
        return {"variability": "fixed", "initial": "calculated"}
    variability = "continuous" if v.kind == "Real" else "discrete"
    if v.causality == "input":
        return {"variability": variability}
    return {"variability": variability, "initial": "calculated"}


def _units_categories_experiment(root, variables: list[Variable], stop_time: float, step: float) -> None:
    units = ET.SubElement(root, "UnitDefinitions")
    for name in unit_names(variables) + (["s"] if root.get("fmiVersion") == "3.0" else []):
        if units.find(f"Unit[@name='{name}']") is not None:
            continue
        unit = ET.SubElement(units, "Unit", {"name": name})
        if name in BASE_UNITS:
            ET.SubElement(unit, "BaseUnit", BASE_UNITS[name])
    categories = ET.SubElement(root, "LogCategories")
    for name, text in LOG_CATEGORIES:
        ET.SubElement(categories, "Category", {"name": name, "description": text})
    ET.SubElement(root, "DefaultExperiment", {"startTime": "0", "stopTime": repr(stop_time), "stepSize": repr(step)})


def _indicators(variables: list[Variable]) -> list[Variable]:
    """The event indicators of a table with Model Exchange's variables (variables.exchange_variables)."""
    return [v for v in variables if v.causality == "local" and v.derivative_of is None]


def _structure(structure, variables: list[Variable], key: dict, outputs_tag: str, initial_tag: str, item_tag,
               attribute: str, model_exchange: bool = False) -> None:
    """ModelStructure: each output with its direct dependencies on inputs, with model_exchange each
    state derivative (depending on the states and inputs: no dependencies attribute), then each
    output, state derivative and calculated parameter as an initial unknown (an output or calculated
    parameter depending on those inputs and every parameter). FMI 2.0 groups the items (<Outputs><Unknown index=...>), FMI 3.0 lists them
    (<Output valueReference=...>); `key` gives the number an item and a dependency are named by."""
    outputs = [v for v in variables if v.causality == "output"]
    derivatives = [v for v in variables if v.derivative_of is not None] if model_exchange else []
    calculated = [v for v in variables if v.causality == "calculatedParameter"]
    parameters = [str(key[v.name]) for v in variables if v.causality == "parameter"]
    fmi3 = item_tag is None
    groups = [(outputs_tag, outputs, [])]
    if derivatives:
        groups.append(("ContinuousStateDerivative" if fmi3 else "Derivatives", derivatives, None))
    groups.append((initial_tag, sorted(outputs + derivatives + calculated, key=lambda v: key[v.name]), parameters))
    for tag, items, extra in groups:
        parent = structure if fmi3 else ET.SubElement(structure, tag)
        for v in items:
            attrs = {attribute: str(key[v.name])}
            if v.derivative_of is None and extra is not None:
                attrs["dependencies"] = " ".join([str(key[n]) for n in v.dependencies] + extra)
            ET.SubElement(parent, item_tag or tag, attrs)


def validation_problems(fmu) -> list[str]:
    """What fmpy's validator finds wrong with an FMU file (empty: nothing)."""
    from fmpy.validation import validate_fmu

    return list(validate_fmu(str(fmu)))
