"""modelDescription.xml of the SM4 FMUs (FMI 2.0 co-simulation), written with ElementTree.

Variables follow DESIGN section 5; ModelStructure gives every output's dependencies (the states
depend on no input within a step, the derived outputs and the residual directly on Vs, theta_vs),
with indices as 1-based positions in ModelVariables.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

from opfmu import __version__


@dataclass(frozen=True)
class Variable:
    name: str
    vr: int
    causality: str            # input | output | parameter
    description: str
    unit: str = ""
    start: float | None = None
    kind: str = "Real"        # Real | Boolean
    direct_inputs: bool = False  # output depending directly on the inputs within a step


def sm4_variables(x_start, horizon: float | None, surrogate: bool, extra: tuple = (),
                  residual_limit: float | None = None, restart_jump: float | None = None,
                  rest_radius: float | None = None, slow_weight: float | None = None,
                  swing_weight: float | None = None) -> list[Variable]:
    """The variable list; x_start [4] are the default initial-state parameters, horizon the default
    rollover horizon and residual_limit the default warning level (surrogate only); extra: further
    (parameter) variables of the reference FMU."""
    names = [("Vs", "bus voltage magnitude", "pu"), ("theta_vs", "bus voltage angle", "rad")]
    states = [("delta", "rotor angle", "rad"), ("omega", "rotor speed deviation", "rad/s"),
              ("Ed_p", "d-axis transient voltage", "pu"), ("Eq_p", "q-axis transient voltage", "pu")]
    derived = [("Id", "d-axis stator current", "pu"), ("Iq", "q-axis stator current", "pu"),
               ("I_re", "bus current, real part (network frame)", "pu"),
               ("I_im", "bus current, imaginary part (network frame)", "pu"),
               ("P", "active power into the bus", "pu"), ("Q", "reactive power into the bus", "pu")]
    out = [Variable(n, i, "input", d, u, start) for i, ((n, d, u), start) in enumerate(zip(names, (1.0, 0.0)))]
    out += [Variable(n, 2 + i, "output", f"{d} at the communication point", u) for i, (n, d, u) in enumerate(states)]
    out += [Variable(n, 6 + i, "output", d, u, direct_inputs=True) for i, (n, d, u) in enumerate(derived)]
    out += [Variable(f"{n}0", 12 + i, "parameter", f"initial {d}", u, float(x_start[i])) for i, (n, d, u) in enumerate(states)]
    if surrogate:
        out.append(Variable("residual", 16, "output", "RMS of the operator's physics residual, per state scaled",
                            direct_inputs=True))
        out.append(Variable("rollover_horizon", 17, "parameter", "operator window length (at most the trained horizon)",
                            "s", horizon))
        out.append(Variable("in_envelope", 0, "output", "false once an input or window start state left the "
                            "trained envelope", kind="Boolean"))
        out.append(Variable("residual_limit", 18, "parameter", "residual above which a warning is logged once per "
                            "excursion (0: no check)", start=residual_limit))
        out.append(Variable("restart_jump", 19, "parameter", "an input change larger than this (pu, rad) starts a "
                            "new operator window at once (0: only at the rollover horizon)", start=restart_jump))
        out.append(Variable("rest_radius", 20, "parameter", "reach of the rest correction, which removes the "
                            "operator's error at the equilibrium of the held input (0: off)", start=rest_radius))
        out.append(Variable("slow_weight", 21, "parameter", "weight in [0, 1] of the slow-mode correction, which "
                            "integrates the slowest mode from the physics (0: off)", start=slow_weight))
        out.append(Variable("swing_weight", 22, "parameter", "weight in [0, 1] of the exact swing step, which "
                            "integrates omega from the swing equation over each step (0: the operator's omega)",
                            start=swing_weight))
    out += list(extra)
    return out


def model_description(model_name: str, guid: str, variables: list[Variable], description: str,
                      stop_time: float = 10.0, step: float = 0.01) -> bytes:
    """The XML document (UTF-8 bytes)."""
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": model_name, "guid": guid, "description": description,
        "generationTool": f"opfmu {__version__}", "variableNamingConvention": "flat",
        "numberOfEventIndicators": "0"})
    ET.SubElement(root, "CoSimulation", {
        "modelIdentifier": model_name, "canHandleVariableCommunicationStepSize": "true",
        "canGetAndSetFMUstate": "true", "canSerializeFMUstate": "true",
        "canNotUseMemoryManagementFunctions": "true"})
    units = ET.SubElement(root, "UnitDefinitions")
    for name, base in (("rad", {"rad": "1"}), ("rad/s", {"rad": "1", "s": "-1"}), ("s", {"s": "1"}), ("pu", {})):
        ET.SubElement(ET.SubElement(units, "Unit", {"name": name}), "BaseUnit", base)
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
    inputs = " ".join(str(index[n]) for n in ("Vs", "theta_vs"))
    outputs = [v for v in variables if v.causality == "output"]
    out_el = ET.SubElement(structure, "Outputs")
    for v in outputs:
        ET.SubElement(out_el, "Unknown", {"index": str(index[v.name]), "dependencies": inputs if v.direct_inputs else ""})
    init_el = ET.SubElement(structure, "InitialUnknowns")
    parameters = " ".join(str(index[v.name]) for v in variables if v.causality == "parameter")
    for v in outputs:
        deps = f"{inputs} {parameters}" if v.direct_inputs else parameters
        ET.SubElement(init_el, "Unknown", {"index": str(index[v.name]), "dependencies": deps})
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)
