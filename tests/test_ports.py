"""Ports on the component definition: declared in every FMU's model description, read back as declared."""
import re
import zipfile
from pathlib import Path

import pytest

from fmu_export.model_description import validation_problems
from fmu_export.native_reference_fmu import build_native_reference_fmu
from fmu_export.variables import fmu_ports
from reference_models.ieee1 import IEEE1
from reference_models.ports import PortError, ports_of_fmu
from reference_models.sm4 import SM4


@pytest.mark.parametrize("fmi_version", [2, 3])
@pytest.mark.parametrize("component", [SM4, IEEE1], ids=lambda c: c.name)
def test_a_native_reference_fmu_declares_its_components_ports_and_still_validates(component, fmi_version, tmp_path):
    path = tmp_path / f"{component.name}.fmu"
    build_native_reference_fmu(path, f"{component.name.upper()}Reference", component, fmi_version=fmi_version)
    assert ports_of_fmu(path) == fmu_ports(component)  # the component's, with the bus port's outputs
    assert validation_problems(path) == []


def test_the_surrogate_fmu_declares_the_machines_ports_with_the_norton_port(fmu_path, tmp_path):
    from fmu_export.variables import fmu_ports

    assert ports_of_fmu(fmu_path) == fmu_ports(SM4)  # SM4's, its bus port with the Norton and power outputs
    assert ports_of_fmu(fmu_path).bus.norton and ports_of_fmu(fmu_path).bus.base_mva == 100.0
    with zipfile.ZipFile(fmu_path) as archive:
        archive.extractall(tmp_path)
    assert ports_of_fmu(tmp_path) == fmu_ports(SM4)  # an extracted FMU reads the same


def test_the_pythonfmu_reference_fmu_declares_the_machines_ports(reference_path):
    assert ports_of_fmu(reference_path) == SM4.ports


def test_an_fmu_without_a_readable_model_description_is_refused_in_one_line(tmp_path):
    for path, reason in ((tmp_path / "none.fmu", "No such file"), (tmp_path / "text.fmu", "not a zip file")):
        if path.name == "text.fmu":
            path.write_text("not an FMU")
        with pytest.raises(PortError, match=reason) as caught:
            ports_of_fmu(path)
        assert "\n" not in str(caught.value)


@pytest.mark.parametrize("damage, says", [("corrupt", r"binaries/linux64/SM4Reference.so: invalid ELF header"),
                                          ("missing", r"binaries/linux64/SM4Reference.so is missing")])
def test_compare_refuses_an_fmu_whose_binary_is_corrupt_or_missing_in_one_line(tmp_path, damage, says):
    from fmpy import extract

    from opfmu.compare import OUTPUTS, CompareError, scenario_inputs, simulate

    path = tmp_path / "SM4Reference.fmu"
    build_native_reference_fmu(path, platforms=None)
    directory = Path(extract(str(path), unzipdir=str(tmp_path / "x")))
    binary = directory / "binaries" / "linux64" / "SM4Reference.so"
    if damage == "corrupt":
        binary.write_bytes(b"\x7fELX" + bytes(range(256)) * 4)
    else:
        binary.unlink()
    inputs = scenario_inputs("step", 0, 0.1, 0.01)
    with pytest.raises(CompareError) as caught:
        simulate(directory, inputs, 0.1, 0.01, OUTPUTS, role="the reference")
    message = str(caught.value)
    assert re.fullmatch(f"the reference FMU SM4Reference cannot be loaded: {says}", message), message
    assert str(tmp_path) not in message  # no temporary path


@pytest.mark.parametrize("damage", ["corrupt", "missing"])
def test_the_compare_command_says_in_one_line_which_fmu_cannot_be_loaded(fmu_path, tmp_path, damage):
    from test_cli import assert_one_line_error, opfmu

    built = tmp_path / "built.fmu"
    build_native_reference_fmu(built, platforms=None)
    damaged = tmp_path / "Damaged.fmu"
    with zipfile.ZipFile(built) as source, zipfile.ZipFile(damaged, "w") as target:
        for info in source.infolist():
            if info.filename == "binaries/linux64/SM4Reference.so":
                if damage == "missing":
                    continue
                target.writestr(info, b"\x7fELX" + bytes(range(256)) * 4)
            else:
                target.writestr(info, source.read(info))
    done = opfmu("compare", "--surrogate", str(fmu_path), "--reference", str(damaged), "--scenario", "step",
                 "--stop-time", "1", "--out", str(tmp_path / "out"))
    reason = "invalid ELF header" if damage == "corrupt" else "is missing"
    assert_one_line_error(done, "the reference FMU SM4Reference cannot be loaded: binaries/linux64/SM4Reference.so",
                          reason)
    assert done.stdout == "" and not (tmp_path / "out").exists()


def test_a_machine_on_a_bus_is_found_by_its_ports_and_a_component_without_them_is_refused():
    from reference_models.ports import MachineInputs, machine_inputs

    assert machine_inputs(SM4) == MachineInputs("Vs", "theta_vs", "Pm", "Efd")
    with pytest.raises(PortError, match="'ieee1' is no machine on a bus"):
        machine_inputs(IEEE1)


def test_every_family_gives_the_machines_inputs_in_its_order():
    import numpy as np

    from reference_models.families import BASE_FAMILIES, COMPONENT

    for fam in BASE_FAMILIES.values():
        signal = fam.sample(np.full((1, fam.dim), 0.5), 1.0)[0]
        assert signal.names == COMPONENT.input_names, fam.name


def test_init_start_values_meet_where_the_ports_link_the_machine_and_the_exciter():
    from opfmu.init_command import start_values

    result = start_values(1.025, 0.16, 1.63, 0.0665, SM4.params(), IEEE1.params())
    machine, exciter, point = result["machine"], result["exciter"], result["operating_point"]
    magnitude, angle = SM4.ports.bus.voltage
    assert (machine[magnitude], machine[angle]) == (1.025, 0.16)
    # the exciter's field output starts where the machine's field input starts; it sees the terminal voltage
    assert exciter[IEEE1.ports.output("field_voltage") + "0"] == machine[SM4.ports.input("field_voltage")]
    assert exciter[IEEE1.ports.input("terminal_voltage")] == point["Vt"]
    assert list(machine)[-SM4.n_inputs:] == list(SM4.input_names)
    assert list(exciter)[-IEEE1.n_inputs:] == list(IEEE1.input_names)
