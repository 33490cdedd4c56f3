"""A black box from another tool (issue 35): an FMU of a sub-system whose model description declares
no opfmu bus port, read through --bus-port with the units its model description gives (angles in deg,
powers in MW drawn from the bus), refused in one line where the spec does not fit it."""
import math
import re
import subprocess
import sys
import zipfile

import numpy as np
import pytest

# A third-party exponential-recovery load as a pythonfmu slave: it draws P0 Vf^2 [MW] and Q0 Vm^2
# [Mvar], Vf the voltage through a first-order lag (T), stepped exactly with Vm held over a step
BOX_SOURCE = '''
import math
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class ThirdPartyLoad(Fmi2Slave):
    description = "an aggregated load another tool exported"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.Vm, self.Va, self.Vf = 1.0, 0.0, 1.0
        self.P0, self.Q0, self.T = 12.0, 3.0, 0.05
        self.register_variable(Real("Vm", causality=Fmi2Causality.input))
        self.register_variable(Real("Va", causality=Fmi2Causality.input))
        self.register_variable(Real("Pload", causality=Fmi2Causality.output, getter=lambda: self.P0 * self.Vf ** 2))
        self.register_variable(Real("Qload", causality=Fmi2Causality.output, getter=lambda: self.Q0 * self.Vm ** 2))

    def exit_initialization_mode(self):
        self.Vf = self.Vm

    def do_step(self, current_time, step_size):
        self.Vf = self.Vm + (self.Vf - self.Vm) * math.exp(-step_size / self.T)
        return True
'''
P0_MW, Q0_MVAR, T_S = 12.0, 3.0, 0.05
UNITS = {"Vm": "pu", "Va": "deg", "Pload": "MW", "Qload": "Mvar"}
SPEC = "V=Vm,theta=Va,P=-Pload,Q=-Qload"


def opfmu(argv) -> tuple:
    """(exit code, stdout, stderr) of `python -m opfmu argv`."""
    done = subprocess.run([sys.executable, "-m", "opfmu", *argv], capture_output=True, text=True)
    return done.returncode, done.stdout, done.stderr


def _with_units(fmu, units: dict) -> None:
    """Gives the variables of the FMU file `fmu` the units `units` ({name: unit}) in its model
    description, each defined in its UnitDefinitions, as a tool that declares units writes them."""
    with zipfile.ZipFile(fmu) as z:
        files = {n: z.read(n) for n in z.namelist()}
    text = files["modelDescription.xml"].decode()
    for name, unit in units.items():
        text = re.sub(rf'(<ScalarVariable name="{name}"[^>]*>\s*<Real)', rf'\1 unit="{unit}"', text)
    definitions = "".join(f'<Unit name="{u}"/>' for u in sorted(set(units.values())))
    # in the schema's order: after the interfaces, before the type definitions, log categories, ...
    text = re.sub(r"(<(?:TypeDefinitions|LogCategories|DefaultExperiment|VendorAnnotations|ModelVariables)\b)",
                  f"<UnitDefinitions>{definitions}</UnitDefinitions>\\1", text, count=1)
    files["modelDescription.xml"] = text.encode()
    with zipfile.ZipFile(fmu, "w") as z:
        for n, data in files.items():
            z.writestr(n, data)


@pytest.fixture(scope="module")
def third_party_box(tmp_path_factory):
    # built by pythonfmu's command in a Python of its own: in this one, a pythonfmu FMU loaded by an
    # earlier test may have put the copy of pythonfmu from its resources (without binaries) first
    folder = tmp_path_factory.mktemp("third_party")
    script = folder / "third_party_load.py"
    script.write_text(BOX_SOURCE)
    subprocess.run([sys.executable, "-m", "pythonfmu", "build", "-f", str(script), "-d", str(folder)], check=True,
                   capture_output=True)
    fmu = folder / "ThirdPartyLoad.fmu"
    _with_units(fmu, UNITS)
    return fmu


def test_a_box_that_gives_the_power_it_draws_in_mw_is_read_as_the_current_it_injects(third_party_box):
    from cosim.black_box_data import own_rest, replay

    rest = own_rest(third_party_box, SPEC, 100.0)
    S0 = -complex(P0_MW, Q0_MVAR) / 100.0  # pu into the bus at 1 pu
    assert rest["V_own"] == 1.0
    assert complex(rest["Ip_own"], -rest["Iq_own"]).conjugate() == pytest.approx(S0, abs=1e-12)
    t = np.arange(31) * 0.01
    V, theta = np.where(t < 0.1, 1.0, 0.8), np.full_like(t, 0.3)
    current = replay(third_party_box, t, V, theta, spec=SPEC, base_mva=100.0)
    # from 0.1 s the box holds 0.8 pu: its lagged voltage falls to it with T, exactly
    Vf = np.where(t < 0.1, 1.0, 0.8 + 0.2 * np.exp(-(t - 0.1) / T_S))
    S = -(P0_MW * Vf ** 2 + 1j * Q0_MVAR * V ** 2) / 100.0
    expected = np.conj(S / (V * np.exp(1j * theta)))  # the angle given to the box in degrees
    assert np.max(np.abs(current - expected)) < 1e-9 * np.max(np.abs(expected))


@pytest.mark.parametrize("spec, says", [
    (None, "declares no bus port .* --bus-port V=NAME.*inputs: Vm, Va; outputs: Pload, Qload"),
    ("V=Vm,theta=Va,P=-Pload,Q=-Qmissing", "Q=Qmissing: ThirdPartyLoad has no Real output 'Qmissing'"),
    ("V=Pload,theta=Va,P=-Pload,Q=-Qload", "V=Pload: ThirdPartyLoad has no Real input 'Pload'"),
    ("V=Vm,theta=Va,I_re=Pload,I_im=Qload", "I_re=Pload: its unit 'MW': a current must be in pu"),
    ("V=Vm,theta=Va,P=Pload", "names V and theta, and either I_re and I_im or P and Q"),
])
def test_a_box_without_a_bus_port_or_with_a_spec_that_does_not_fit_it_is_refused_saying_why(
        third_party_box, spec, says):
    from cosim.black_box_data import own_rest
    from surrogate.data import DatasetError

    with pytest.raises(DatasetError, match=says):
        own_rest(third_party_box, spec)


def test_a_power_box_at_a_bolted_boundary_has_no_current_to_give():
    from cosim.black_box_data import POWER_FLOOR_PU, BoxPort

    port = BoxPort("Vm", "Va", ("P", "Q"), "power")
    assert port.current(1.0, 0.0, (0.1, 0.05)) == pytest.approx(complex(0.1, -0.05))
    with pytest.raises(ValueError, match="its current is undefined"):
        port.current(0.5 * POWER_FLOOR_PU, 0.0, (0.0, 0.0))


@pytest.mark.parametrize("extra, says", [
    (["--bus-port", "V=Vm,theta=Va,P=Pload"], "--bus-port 'V=Vm,theta=Va,P=Pload': it names V and theta"),
    (["--bus-port", "V=-Vm,theta=Va,P=P,Q=Q"], "V and theta are inputs: no sign"),
    (["--bus-port", "V=Vm,theta=Va,P=P,Q=Q,X=Y"], "'X=Y': each part is KEY=NAME once"),
])
def test_a_malformed_bus_port_is_one_line_and_exit_2_before_the_box_is_opened(tmp_path, extra, says):
    (tmp_path / "box.fmu").write_bytes(b"not read: refused before")
    code, out, err = opfmu(["operator", "--subsystem", str(tmp_path / "box.fmu"), "--rating", "20", *extra,
                            "--out", str(tmp_path / "out")])
    assert code == 2 and out == "" and err.count("\n") == 1 and says in err, err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("argv, says", [
    (["--machine", "m.json", "--bus-port", "V=a,theta=b,P=c,Q=d"], "--bus-port: for a sub-system"),
    (["--machine", "m.json", "--rating", "5", "--boundary", "3"], "--boundary, --rating: for a sub-system"),
    (["--machine", "m.json", "--members", "2", "--frequency-features"], "--members, --frequency-features: for a sub-system"),
])
def test_sub_system_options_given_for_a_machine_are_refused(tmp_path, argv, says):
    code, out, err = opfmu(["operator", *argv, "--out", str(tmp_path / "out")])
    assert code == 2 and out == "" and says in err, err


@pytest.mark.andes
@pytest.mark.parametrize("memory", [False, True])
def test_the_dataset_of_a_third_party_box_comes_from_the_host_voltages_replayed_into_it(third_party_box, tmp_path,
                                                                                       memory):
    from cosim.black_box_data import generate_black_box
    from cosim.subsystem_data import Plan

    plan = Plan(hosts=("ieee14",), buses=1, runs=7, stop=1.0, trips=0.0, memory=memory)  # a run in each split
    meta = generate_black_box(third_party_box, tmp_path / "data", 20.0, plan, seed=3, progress=False,
                              bus_port_spec=SPEC)
    assert meta["source"] == {"kind": "black box", "fmu": third_party_box.name, "bus_port": SPEC}
    assert meta["component"] == ("subsystem_mem" if memory else "subsystem")  # a box has a memory as a case has
    assert meta["failed_runs"] == [] and sum(meta["counts"].values()) > 0
    assert meta["params"]["Ip_own"] == pytest.approx(-P0_MW / 100.0, rel=1e-12)
    assert math.isclose(meta["params"]["V_own"], 1.0)
