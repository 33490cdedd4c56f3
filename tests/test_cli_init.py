"""`opfmu init`: start values keyed by the FMU variable names, from flags or a load-flow file; the
FMUs started with them stay at rest; user mistakes are one line with exit code 2."""
import json
import math
import subprocess
import sys

import numpy as np
import pytest
from fmpy import simulate_fmu

from opfmu.cli import main
from opfmu.init_command import load_flow_points, start_values
from reference_models.ieee1 import IEEE1
from reference_models.sm4 import SM4

GEN2 = {"H": 6.4, "D": 0.0, "Xd": 0.8958, "Xd_p": 0.1198, "Xq": 0.8645, "Xq_p": 0.1969, "Td0_p": 6.0,
        "Tq0_p": 0.535, "Xep": 0.0, "Re": 0.0, "Rs": 0.0}
POINT = ["--V", "1.025", "--theta-deg", "9.28", "--P", "1.63", "--Q", "0.0665"]


@pytest.fixture
def gen2(tmp_path):
    path = tmp_path / "gen2.json"
    path.write_text(json.dumps(GEN2))
    return path


def run(capsys, *args):
    code = main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


def one_line_error(capsys, *args):
    code, out, err = run(capsys, *args)
    assert code == 2 and out == "", (code, out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    return lines[0]


def test_json_gives_both_fmus_start_values_by_their_variable_names(capsys, gen2):
    code, out, _ = run(capsys, "init", "--machine", str(gen2), *POINT, "--json")
    assert code == 0
    result = json.loads(out)
    assert list(result["machine"]) == ["delta0", "omega0", "Ed_p0", "Eq_p0", "Vs", "theta_vs", "Pm", "Efd"]
    assert list(result["exciter"]) == ["Efd0", "RF0", "VR0", "Vt", "Vref"]
    m, e = result["machine"], result["exciter"]
    assert math.degrees(m["delta0"]) == pytest.approx(61.099, abs=1e-3) and m["omega0"] == 0.0
    assert m["Efd"] == pytest.approx(1.7893, abs=1e-4) and m["Pm"] == pytest.approx(1.63, rel=1e-12)
    assert e["Efd0"] == m["Efd"] and e["Vt"] == pytest.approx(1.025, rel=1e-15)
    assert e["Vref"] == pytest.approx(1.1201, abs=1e-4)
    assert result["operating_point"]["stable_at_constant_field"] is True


def test_the_table_lists_the_same_values_readably(capsys, gen2):
    code, out, _ = run(capsys, "init", "--machine", str(gen2), *POINT)
    assert code == 0
    for name in ("delta0", "Ed_p0", "Eq_p0", "theta_vs", "Pm", "Efd0", "RF0", "VR0", "Vref"):
        assert f"    {name} " in out
    assert "61.0992 deg" in out and "1.789303968" in out and "1.120102687" in out


def test_no_exciter_gives_the_machine_alone_and_an_angle_in_rad_is_accepted(capsys, gen2):
    code, out, _ = run(capsys, "init", "--machine", str(gen2), "--V", "1.025", "--theta", str(math.radians(9.28)),
                       "--P", "1.63", "--Q", "0.0665", "--no-exciter", "--json")
    assert code == 0 and "exciter" not in json.loads(out)
    assert json.loads(out)["machine"]["Efd"] == pytest.approx(1.7893, abs=1e-4)


def test_a_load_flow_file_starts_every_generator_with_its_own_machine_and_exciter(capsys, tmp_path, gen2):
    flow = tmp_path / "flow.json"
    flow.write_text(json.dumps({"case": "wscc9", "generators": [
        {"bus": 1, "V": 1.04, "theta_deg": 0.0, "P": 0.7164, "Q": 0.2705,
         "machine": {"params": {"H": 23.64, "D": 0.0, "Xd": 0.146, "Xd_p": 0.0608, "Xq": 0.0969, "Xq_p": 0.0969,
                                "Td0_p": 8.96, "Tq0_p": 0.31, "Xep": 0.0}}},
        {"name": "G2", "V": 1.025, "theta": math.radians(9.28), "P": 1.63, "Q": 0.0665,
         "machine": {"component": "sm4", "file": gen2.name}, "exciter": {"component": "ieee1", "params": {"KA": 25}}},
        {"bus": 3, "V": 1.025, "theta_deg": 4.665, "P": 0.85, "Q": -0.1086, "machine": gen2.name, "exciter": None},
    ]}))
    code, out, _ = run(capsys, "init", "--load-flow", str(flow), "--json")
    assert code == 0
    g1, g2, g3 = json.loads(out)["generators"]
    assert [g["name"] for g in (g1, g2, g3)] == ["bus 1", "G2", "bus 3"]
    assert g1["machine"]["Efd"] == pytest.approx(1.0821, abs=1e-4) and g1["exciter"]["Vref"] == pytest.approx(1.0952,
                                                                                                               abs=1e-4)
    assert g2["machine"]["Efd"] == pytest.approx(1.7893, abs=1e-4)
    assert g2["exciter"]["Vref"] == pytest.approx(1.025 + g2["exciter"]["VR0"] / 25, rel=1e-15)  # its own KA
    assert "exciter" not in g3
    code, table, _ = run(capsys, "init", "--load-flow", str(flow))
    assert code == 0 and table.count("machine FMU") == 3 and table.count("exciter FMU") == 2 and "G2: bus V" in table


def test_the_fmus_started_with_these_values_stay_at_rest(tmp_path, native_reference_path):
    from fmu_export.native_reference_fmu import build_native_reference_fmu

    exciter_path = tmp_path / "IEEE1Reference.fmu"
    build_native_reference_fmu(exciter_path, "IEEE1Reference", IEEE1)
    result = start_values(1.0, 0.2, 0.7048, 0.2, SM4.params(), IEEE1.params())  # the default machine, Xep = 0.1
    assert result["exciter"]["Vt"] != pytest.approx(1.0, abs=1e-3)  # the terminal voltage, behind Xep
    for path, values, states in ((native_reference_path, result["machine"], SM4.state_names),
                                 (exciter_path, result["exciter"], IEEE1.state_names)):
        run_ = simulate_fmu(str(path), start_values=values, stop_time=2.0, output_interval=0.5, output=list(states))
        x = np.array([list(row)[1:] for row in run_])
        np.testing.assert_allclose(x, np.tile([values[f"{n}0"] for n in states], (len(x), 1)), rtol=0, atol=1e-12)


@pytest.mark.parametrize("args, says", [
    (["--V", "1", "--P", "1", "--Q", "0"], "needs --theta-deg/--theta"),
    (["--V", "1", "--theta", "0", "--P", "1"], "needs --Q"),
    (["--V", "1", "--theta", "0", "--P", "1", "--Q", "zero"], "argument --Q: invalid float value: 'zero'"),
    (["--V", "nan", "--theta", "0", "--P", "1", "--Q", "0"], "V must be a finite number"),
    (["--V", "-1", "--theta", "0", "--P", "1", "--Q", "0"], "bus voltage V = -1 pu lies outside its physical range"),
    (["--V", "1e-300", "--theta", "0", "--P", "1", "--Q", "0"], "V = 1e-300 pu lies outside its physical range "
                                                                  "[0.5, 1.5] pu"),
    (["--V", "1", "--theta", "0", "--P", "1e300", "--Q", "0"], "P = 1e+300 pu lies outside its physical range "
                                                                 "[-10, 10] pu"),
    (["--V", "1", "--theta", "0", "--P", "100", "--Q", "0"], "P = 100 pu lies outside its physical range [-10, 10] pu"),
    # within the ranges, but the WSCC exciter's saturation would need VR = 4748 pu for this field
    (["--V", "1", "--theta", "0", "--P", "5", "--Q", "2"], "regulator output VR = 4747.71 pu the exciter needs to hold "
                                                            "Efd = 7.69754 pu lies outside its physical range"),
    (["--V", "1", "--theta", "0", "--theta-deg", "0", "--P", "1", "--Q", "0"], "not allowed with argument"),
    (["--V", "1", "--theta", "0", "--P", "1", "--Q", "0", "--load-flow", "f.json"], "drop --V, --P, --Q"),
    (["--V", "1", "--theta", "0", "--P", "1", "--Q", "0", "--exciter", "e.json", "--no-exciter"], "not allowed"),
    (["--V", "1", "--theta", "0", "--P", "1", "--Q", "0", "--machine", "/nonexistent/m.json"], "cannot read machine file"),
    # the regulator cannot hold this field voltage within its limits
    (["--V", "1", "--theta", "0", "--P", "0.7", "--Q", "0.5", "--exciter", "LIMITED"], "beyond the regulator limit VRmax"),
])
def test_mistakes_in_the_flags_are_one_line_errors(capsys, tmp_path, args, says):
    limited = tmp_path / "limited.json"
    limited.write_text(json.dumps({"VRmax": 1.0}))
    line = one_line_error(capsys, "init", *[str(limited) if a == "LIMITED" else a for a in args])
    assert says in line, line


HOSTILE = {
    "not json": ("{V: 1", "cannot read load-flow file"),
    "NaN": ('{"V": NaN, "theta": 0, "P": 1, "Q": 0}', "NaN is not a number this file may hold"),
    "deep": ("[" * 100000 + "]" * 100000, "cannot read load-flow file"),
    "not utf-8": (b"\xff\xfe{", "cannot read load-flow file"),
    "a number": ("3", "needs a generator"),
    "empty list": ("[]", "needs a generator"),
    "a string entry": ('["G1"]', "generator 1: must be an object"),
    "typo": ('{"V": 1, "Theta_deg": 0, "P": 1, "Q": 0}', "unknown key(s) 'Theta_deg'"),
    "both angles": ('{"V": 1, "theta": 0, "theta_deg": 0, "P": 1, "Q": 0}', "one of theta_deg or theta"),
    "missing P": ('{"V": 1, "theta": 0, "Q": 0}', "(missing P)"),
    "bool": ('{"V": true, "theta": 0, "P": 1, "Q": 0}', "V must be a finite number"),
    "string number": ('{"V": "1", "theta": 0, "P": 1, "Q": 0}', "V must be a finite number"),
    "huge": ('{"V": 1e999, "theta": 0, "P": 1, "Q": 0}', "V must be a finite number"),
    "huge int": ('{"V": 1' + "0" * 400 + ', "theta": 0, "P": 1, "Q": 0}', "V must be a finite number"),
    "zero voltage": ('{"name": "G9", "V": 0, "theta": 0, "P": 1, "Q": 0}', "G9: the bus voltage V = 0 pu lies outside"),
    "machine list": ('{"V": 1, "theta": 0, "P": 1, "Q": 0, "machine": [1]}', "machine: must be a file name or"),
    "machine missing": ('{"V": 1, "theta": 0, "P": 1, "Q": 0, "machine": "none.json"}', "cannot read machine file"),
    "bad parameter": ('{"V": 1, "theta": 0, "P": 1, "Q": 0, "machine": {"params": {"H": -1}}}', "parameter H = -1.0"),
    "wrong component": ('{"V": 1, "theta": 0, "P": 1, "Q": 0, "exciter": {"component": "sm4", "params": {}}}',
                        "component must be 'ieee1'"),
    "file and params": ('{"V": 1, "theta": 0, "P": 1, "Q": 0, "machine": {"file": "m.json", "params": {}}}',
                        "give one of file or params"),
    "control characters": ('{"name": "G\\n\\u001b[2J", "V": -1, "theta": 0, "P": 1, "Q": 0}', "G??[2J: the bus"),
    "generators not a list": ('{"generators": {"V": 1}}', "needs a generator"),
    "unknown top key": ('{"generators": [], "gens": 1}', "unknown key(s) 'gens'"),
}


@pytest.mark.parametrize("content, says", list(HOSTILE.values()), ids=list(HOSTILE))
def test_a_malformed_or_hostile_load_flow_file_is_a_one_line_error(capsys, tmp_path, content, says):
    flow = tmp_path / "flow.json"
    (flow.write_bytes if isinstance(content, bytes) else flow.write_text)(content)
    line = one_line_error(capsys, "init", "--load-flow", str(flow))
    assert says in line, line


def test_a_load_flow_file_too_large_or_absent_is_a_one_line_error(capsys, tmp_path):
    big = tmp_path / "big.json"
    big.write_text(" " * (1024 * 1024 + 1))
    assert "larger than 1048576 bytes" in one_line_error(capsys, "init", "--load-flow", str(big))
    assert "No such file or directory" in one_line_error(capsys, "init", "--load-flow", str(tmp_path / "none.json"))


def test_load_flow_points_apply_the_defaults_to_generators_that_name_no_machine(tmp_path):
    flow = tmp_path / "flow.json"
    flow.write_text('[{"V": 1.0, "theta_deg": 10, "P": 0.5, "Q": 0.1}]')
    machine = SM4.params({"H": 4.0})
    [(name, V, theta, P, Q, m, e)] = load_flow_points(flow, machine, None)
    assert (name, V, P, Q, m, e) == ("generator 1", 1.0, 0.5, 0.1, machine, None)
    assert theta == pytest.approx(math.radians(10), rel=1e-15)


def test_a_point_past_the_peak_of_the_power_angle_curve_is_marked(capsys):
    # the default machine underexcited, absorbing reactive power: rotor angle 92 deg
    result = start_values(1.0, 0.0, 1.0, -0.8, SM4.params(), None)
    assert result["operating_point"]["stable_at_constant_field"] is False
    assert start_values(1.0, 0.0, 1.0, -0.5, SM4.params(), None)["operating_point"]["stable_at_constant_field"]
    code, out, _ = run(capsys, "init", "--V", "1", "--theta", "0", "--P", "1", "--Q", "-0.8", "--no-exciter")
    assert code == 0 and "past the peak" in out


def test_the_installed_command_ends_a_mistake_without_a_traceback():
    result = subprocess.run([sys.executable, "-m", "opfmu", "init", "--V", "1", "--theta", "0", "--P", "1", "--Q",
                             "inf"], capture_output=True, text=True)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert result.stderr.strip() == "error: init: Q must be a finite number, got inf"
