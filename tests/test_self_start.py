"""Native reference FMUs start themselves from the load flow: given a bus device's V_lf, theta_lf,
P_lf, Q_lf (and a controller's `<output>_init`, the value the device it drives solved), the FMU
solves its states and the inputs its initialisation solves (Pm, Efd, Vref, Pref) in C, to the start
reference_models.grid.case computes in Python; the solved inputs are calculated parameters and the
inputs' values while left unconnected; a host that chains them machine -> controllers gets the
same unit start; a start that has none is refused with fmi2Error and the reason, not a crash."""
from __future__ import annotations

import json

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

from cosim.export import export_case
from fmu_export.build_cache import cached_native_reference_fmu
from fmu_export.self_start import describe, self_start_of
from reference_models.components import COMPONENTS
from reference_models.grid.case import shipped_case


def close(a, b, rel=1e-9) -> bool:
    return abs(a - b) <= rel * max(1.0, abs(a), abs(b))


class Instance:
    """One FMU instance driven through fmpy alone, as a third-party master would (FMI 2.0 or 3.0)."""

    def __init__(self, path, name="device"):
        self.md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.causality = {v.name: v.causality for v in self.md.modelVariables}
        self.messages = []
        kw = dict(guid=self.md.guid, unzipDirectory=extract(str(path)),
                  modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.v3 = self.md.fmiVersion.startswith("3")
        if self.v3:
            self.fmu = FMU3Slave(**kw)
            self.fmu.instantiate(logMessage=lambda env, status, category, message: self.messages.append(message))
        else:
            self.fmu = FMU2Slave(**kw)
            self.fmu.instantiate()
            self.fmu.setupExperiment(startTime=0.0)

    def set(self, values: dict) -> None:
        names = list(values)
        refs, numbers = [self.vr[n] for n in names], [float(values[n]) for n in names]
        (self.fmu.setFloat64 if self.v3 else self.fmu.setReal)(refs, numbers)

    def get(self, names) -> list:
        return list((self.fmu.getFloat64 if self.v3 else self.fmu.getReal)([self.vr[n] for n in names]))

    def enter(self) -> None:
        if self.v3:
            self.fmu.enterInitializationMode(startTime=0.0)
        else:
            self.fmu.enterInitializationMode()


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """{case: (folder, case.json)} for shipped cases whose units cover GENROU, GENCLS, EXDC2, EXST1,
    ESST3A, IEEEX1, TGOV1 and TGOV1N."""
    out = {}
    for name in ("kundur", "ieee14", "npcc"):
        folder = tmp_path_factory.mktemp(name)
        out[name] = folder, json.loads(export_case(shipped_case(name), folder).read_text())
    return out


@pytest.mark.parametrize("case", ["kundur", "ieee14", "npcc"])
def test_each_device_solves_the_start_the_case_computes_from_its_start_parameters(exported, case):
    folder, description = exported[case]
    started = 0
    for d in description["devices"]:
        if "self_start" not in d:
            continue
        fmu = Instance(folder / d["fmu"], d["id"])
        fmu.set(d["parameters"] | d["self_start"]["parameters"])
        solved = [n for n in fmu.vr if fmu.causality[n] == "calculatedParameter"]
        # the inputs it does not solve, as the host's network and devices give them; not the bus voltage
        given = {n: v for n, v in d["start"]["inputs"].items() if f"{n}_init" not in solved
                 and d["inputs"][n] != {"bus": "magnitude"} and d["inputs"][n] != {"bus": "angle"}}
        fmu.set(given)
        fmu.enter()
        fmu.fmu.exitInitializationMode()
        states = d["start"]["states"]
        got = dict(zip(states, fmu.get(list(states))))
        inert = describe_inert(d)
        for name, value in states.items():
            if name not in inert:
                assert close(got[name], value), (d["id"], name, got[name], value)
        for name in solved:
            (value,) = fmu.get([name])
            assert close(value, d["start"]["inputs"][name[:-len("_init")]]), (d["id"], name)
            assert fmu.get([name[:-len("_init")]]) == [value]  # the input, left unconnected, takes it
        started += 1
    assert started >= 3


def describe_inert(d) -> set:
    """The names of the states a device's FMU holds and reads nowhere (not part of the comparison)."""
    component = COMPONENTS[d["component"]]
    params = component.params(d["parameters"])
    x = [d["start"]["states"][n] for n in component.state_names]
    u = [d["start"]["inputs"][n] for n in component.input_names]
    spec, _ = describe(component, params, x, u)
    return {component.state_names[i] for i in spec.anchor.inert} if spec else set()


def test_a_host_that_chains_calculated_parameters_starts_a_unit_from_the_load_flow_alone(exported):
    """Machine first (its load flow only), then each controller's <output>_init read from the machine's
    calculated parameter as case.json's `from` says, its inputs from the machine's outputs."""
    folder, description = exported["ieee14"]
    devices = {d["id"]: d for d in description["devices"]}
    unit = [d for d in description["devices"] if d["unit"] == devices["1/machine"]["unit"]]
    assert [d["role"] for d in unit][:3] == ["machine", "exciter", "governor"]
    fmus = {d["id"]: Instance(folder / d["fmu"], d["id"]) for d in unit}
    machine = fmus[unit[0]["id"]]
    machine.set(unit[0]["parameters"] | unit[0]["self_start"]["parameters"])
    machine.enter()
    for d in unit[1:]:
        fmu = fmus[d["id"]]
        fmu.set(d["parameters"])
        for name, source in d["self_start"]["from"].items():
            fmu.set({name: fmus[source["device"]].get([source["parameter"]])[0]})
        for name, source in d["inputs"].items():
            if "device" in source:
                fmu.set({name: fmus[source["device"]].get([source["output"]])[0]})
            elif "held" in source:
                fmu.set({name: source["held"]})
        fmu.enter()
    for d in unit:
        fmus[d["id"]].fmu.exitInitializationMode()
        got = fmus[d["id"]].get(list(d["start"]["states"]))
        for (name, value), mine in zip(d["start"]["states"].items(), got):
            assert close(mine, value), (d["id"], name)
    # at rest: a second of steps with the links passed moves nothing
    before = {d["id"]: fmus[d["id"]].get(list(d["start"]["states"])) for d in unit}
    for k in range(100):
        for d in unit:
            fmus[d["id"]].fmu.doStep(currentCommunicationPoint=0.01 * k, communicationStepSize=0.01)
    for d in unit:
        after = fmus[d["id"]].get(list(d["start"]["states"]))
        assert all(close(a, b, 1e-9) for a, b in zip(after, before[d["id"]])), d["id"]


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_a_machine_starts_at_a_load_flow_point_far_from_its_default(fmi_version):
    """GENROU at -2.5 rad and an underexcited point: the continuation from the anchor gets there."""
    genrou = COMPONENTS["genrou"]
    path = cached_native_reference_fmu("GENROUReference", genrou, fmi_version=fmi_version)
    fmu = Instance(path)
    point = {"V_lf": 0.96, "theta_lf": -2.5, "P_lf": 0.9, "Q_lf": -0.25}
    fmu.set(point)
    fmu.enter()
    fmu.fmu.exitInitializationMode()
    x0, inputs = genrou.start({"V0": 0.96, "theta0": -2.5, "P0": 0.9, "Q0": -0.25, "Vs": 0.96, "theta_vs": -2.5},
                              genrou.params())
    for mine, value in zip(fmu.get(list(genrou.state_names)), x0):
        assert close(mine, value)
    assert close(fmu.get(["Pm_init"])[0], inputs["Pm"]) and close(fmu.get(["Efd_init"])[0], inputs["Efd"])
    p, q = fmu.get(["P_bus", "Q_bus"])
    assert close(p, 0.9) and close(q, -0.25)  # it delivers the load flow's power


def test_a_start_that_has_no_rest_is_refused_with_the_reason():
    """EXAC1 asked for Efd = 50 pu: its regulator would sit beyond VRMAX = 8 pu (Python refuses it too)."""
    exac1 = COMPONENTS["exac1"]
    given = dict(zip(exac1.input_names, exac1.start_inputs)) | {"Efd": 50.0}
    with pytest.raises(ValueError, match="outside"):
        exac1.start(given, exac1.params())
    path = cached_native_reference_fmu("EXAC1Reference", exac1, fmi_version=3)
    fmu = Instance(path)
    fmu.set({"Efd_init": 50.0})
    fmu.enter()
    with pytest.raises(Exception):
        fmu.fmu.exitInitializationMode()
    text = [m.decode() if isinstance(m, bytes) else m for m in fmu.messages]
    assert any("no rest at the start asked for (Efd_init = 50)" in m for m in text), text


def test_components_whose_references_follow_relations_of_their_own_get_no_self_start():
    """REECA1 solves four references from two delivered currents: its FMU declares no start variables."""
    reeca1 = COMPONENTS["reeca1"]
    params = reeca1.params()
    x = reeca1.steady_state(reeca1.start_inputs, params)
    assert self_start_of(reeca1, params, x) is None
    spec, why = describe(reeca1, params, x, reeca1.start_inputs)
    assert spec is None and "Pref, Qref, Vref, pfaref" in why
    assert self_start_of(COMPONENTS["genrou"], COMPONENTS["genrou"].params(),
                         COMPONENTS["genrou"].steady_state(None, COMPONENTS["genrou"].params())).solves == ("Pm", "Efd")


def test_an_initial_state_the_importer_sets_wins_over_the_start_parameters():
    """As opfmu's master and the VeraGrid host do; a host that sets every declared start value as
    well (the start parameters at their defaults) starts there too."""
    genrou = COMPONENTS["genrou"]
    path = cached_native_reference_fmu("GENROUReference", genrou)
    declared = {v.name: float(v.start) for v in read_model_description(str(path)).modelVariables
                if v.causality == "parameter" and v.start is not None}
    x = np.array(genrou.steady_state(None, genrou.params())) * 1.01
    fmu = Instance(path)
    fmu.set(declared | {f"{n}0": v for n, v in zip(genrou.state_names, x)})
    fmu.enter()
    fmu.fmu.exitInitializationMode()
    assert fmu.get(list(genrou.state_names)) == list(x)


def test_a_host_that_sets_only_parameters_starts_as_built():
    """No start parameter off its default: the built start, whatever the parameters (a host that
    changes a limit and starts as it always did)."""
    genrou = COMPONENTS["genrou"]
    path = cached_native_reference_fmu("GENROUReference", genrou)
    fmu = Instance(path)
    fmu.set({"xd": 2.1, "M": 9.0})
    fmu.enter()
    fmu.fmu.exitInitializationMode()
    assert fmu.get(list(genrou.state_names)) == list(genrou.steady_state(None, genrou.params()))


@pytest.mark.parametrize("device", ["1/machine", "3/machine"])
def test_fmpys_simulate_fmu_of_a_machine_given_only_its_load_flow_stays_there(exported, device):
    """Nothing but the device's parameters and its load flow: the bus voltage left unset takes V_lf,
    theta_lf, and Pm and Efd, left unconnected, their solved values."""
    from fmpy import simulate_fmu

    folder, description = exported["kundur"]
    d = next(e for e in description["devices"] if e["id"] == device)
    result = simulate_fmu(str(folder / d["fmu"]), start_values=d["parameters"] | d["self_start"]["parameters"],
                          stop_time=2.0, output_interval=0.1, output=list(d["start"]["states"]) + ["P_bus", "Q_bus"])
    for name, value in d["start"]["states"].items():
        assert np.max(np.abs(result[name] - value)) <= 1e-9 * max(1.0, abs(value)), name
    assert np.max(np.abs(result["P_bus"] - d["load_flow"]["P"])) <= 1e-9 * max(1.0, abs(d["load_flow"]["P"]))
    assert np.max(np.abs(result["Q_bus"] - d["load_flow"]["Q"])) <= 1e-9 * max(1.0, abs(d["load_flow"]["Q"]))


SELF_STARTING = sorted(name for name, c in COMPONENTS.items()  # a learned component's surrogate: test_subsystem_operator
                       if not c.learned_states and self_start_of(c, c.params(), c.steady_state(c.start_inputs, c.params())) is not None)


@pytest.mark.parametrize("name", SELF_STARTING)
def test_every_model_that_starts_itself_solves_the_start_its_initialisation_gives(name):
    """At a load flow or delivered values 5 % and (a bus device) 0.3 rad off the built ones, against
    Component.start; held states that nothing reads aside."""
    component = COMPONENTS[name]
    params = component.params()
    u = np.array(component.start_inputs)
    x = component.steady_state(u, params)
    spec = self_start_of(component, params, x)
    path = cached_native_reference_fmu(f"{name.upper()}Reference", component)
    fmu = Instance(path)
    given = dict(zip(component.input_names, u))
    asked = {}
    if spec.load_flow:
        V, theta, P, Q = spec.flow_defaults
        asked = {"V_lf": V * 1.02, "theta_lf": theta + 0.3, "P_lf": P * 1.05, "Q_lf": Q * 1.05 + 0.01}
        bus = component.ports.bus
        given.update({"V0": asked["V_lf"], "theta0": asked["theta_lf"], "P0": asked["P_lf"], "Q0": asked["Q_lf"],
                      bus.voltage[0]: asked["V_lf"], bus.voltage[1]: asked["theta_lf"]})
    for delivered, value in zip(spec.delivers, spec.deliver_defaults):
        asked[f"{delivered}_init"] = value * 1.05 + 0.01
        given[delivered] = asked[f"{delivered}_init"]
    fmu.set(asked)
    fmu.enter()
    fmu.fmu.exitInitializationMode()
    x0, inputs = component.start(given, params)
    for i, (mine, value) in enumerate(zip(fmu.get(list(component.state_names)), x0)):
        if i not in spec.anchor.inert:
            assert close(mine, value), (component.state_names[i], mine, value)
    for solved in spec.solves:
        assert close(fmu.get([f"{solved}_init"])[0], inputs[solved]), solved


def test_under_model_exchange_a_machine_given_only_its_load_flow_stays_there(exported):
    from fmpy import simulate_fmu

    folder, description = exported["kundur"]
    d = next(e for e in description["devices"] if e["id"] == "2/machine")
    result = simulate_fmu(str(folder / d["fmu"]), fmi_type="ModelExchange", solver="CVode", relative_tolerance=1e-10,
                          start_values=d["parameters"] | d["self_start"]["parameters"], stop_time=1.0,
                          output_interval=0.1, output=list(d["start"]["states"]))
    for name, value in d["start"]["states"].items():
        assert np.max(np.abs(result[name] - value)) <= 1e-8 * max(1.0, abs(value)), name
