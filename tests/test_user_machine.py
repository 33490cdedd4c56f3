"""A user's own machine end to end: machine file -> data -> train -> export -> both FMUs -> compare.

The machine (WSCC generator 3's two-axis data, D = 0, no external reactance) is not Table I's, so
every place that still used the default machine would show here: the datasets' solves, the
operator's metadata, the FMUs' equations, default initial state and derived outputs.
"""
import json
import subprocess
import sys

import numpy as np
import onnx
import pytest
from fmpy import extract, read_model_description
from scipy.integrate import solve_ivp

from reference_models.scenarios import scenario
from reference_models.sm4 import SM4
from surrogate.data import load_metadata, load_split

from conftest import preset_file, tiny
from cosim.fmu import FMU as Slave
from machines import wscc9_machine

MACHINE = wscc9_machine(3)  # WSCC generator 3 as shipped


def opfmu(*args):
    return subprocess.run([sys.executable, "-m", "opfmu", *map(str, args)], capture_output=True, text=True)


@pytest.fixture(scope="module")
def user_run(tmp_path_factory):
    """(directory, params): the user's machine through data, train, export and both FMU builds."""
    root = tmp_path_factory.mktemp("user_machine")
    (root / "machine.json").write_text(json.dumps(MACHINE))
    recipe = preset_file(root / "preset.json", tiny("quick", probes_per_family=1))
    steps = [("data", "--preset", recipe, "--machine", root / "machine.json", "--out", root / "data", "--workers", 0,
              "--quiet"),
             ("train", "--data", root / "data", "--out", root / "train", "--epochs", 3, "--quiet"),
             ("export", root / "train", "-o", root / "m.onnx"),
             ("build-fmu", root / "m.onnx", "-o", root / "M.fmu"),
             ("build-reference-fmu", "--operator", root / "m.onnx", "-o", root / "R.fmu")]
    for step in steps:
        done = opfmu(*step)
        assert done.returncode == 0, f"opfmu {step[0]} failed: {done.stderr}"
    return root, SM4.params(MACHINE)


def test_the_dataset_is_solved_for_the_users_machine(user_run):
    root, params = user_run
    assert load_metadata(root / "data")["params"] == params.to_dict()
    train = load_split(root / "data", "train")
    x, u, t = train["x"][0], train["u"][0], train["t"]
    rate = np.gradient(x, t, axis=0)[100:900]
    own, default = SM4.rhs(x, u, params)[100:900], SM4.rhs(x, u, SM4.params())[100:900]
    assert np.abs(rate - own).max() < 0.05 * np.abs(rate - default).max()


def test_the_operator_file_names_the_machine_it_was_trained_for(user_run):
    root, params = user_run
    meta = {p.key: p.value for p in onnx.load(str(root / "m.onnx")).metadata_props}
    assert meta["component"] == "sm4" and json.loads(meta["params"]) == params.to_dict()


@pytest.mark.parametrize("fmu", ["M.fmu", "R.fmu"])
def test_both_fmus_start_at_the_users_machines_equilibrium(user_run, fmu):
    root, params = user_run
    starts = {v.name: float(v.start) for v in read_model_description(str(root / fmu)).modelVariables
              if v.name.endswith("0") and v.start is not None}
    own, default = SM4.steady_state(None, params), SM4.steady_state()
    np.testing.assert_allclose([starts[f"{s}0"] for s in SM4.state_names], own, rtol=0, atol=1e-12)
    assert np.abs(own - default).max() > 0.05


@pytest.mark.parametrize("fmu", ["M.fmu", "R.fmu"])
def test_derived_outputs_follow_the_users_machines_equations(user_run, tmp_path, fmu):
    root, params = user_run
    directory = extract(str(root / fmu), unzipdir=str(tmp_path / "x"))
    x0 = SM4.steady_state(None, params) + np.array([0.1, 0.0, 0.02, -0.03])
    slave = Slave((directory, read_model_description(directory)), **dict(zip(
        [f"{s}0" for s in SM4.state_names], x0)))
    u = np.array([0.95, 0.1, 0.6, 1.3])
    slave.set(**dict(zip(SM4.input_names, u)))
    got = slave.get(*SM4.output_names)
    slave.close()
    np.testing.assert_allclose(got, SM4.output_values(x0, u, params), rtol=0, atol=1e-12)


def test_the_reference_fmu_agrees_with_an_independent_solve_for_the_users_machine(user_run, tmp_path):
    root, params = user_run
    directory = extract(str(root / "R.fmu"), unzipdir=str(tmp_path / "r"))
    x0 = SM4.steady_state(None, params)
    slave = Slave((directory, read_model_description(directory)))
    states = [slave.step(0.01, Vs=0.9, theta_vs=0.05, Pm=0.6, Efd=1.2) for _ in range(50)]
    slave.close()
    exact = solve_ivp(lambda _t, x: SM4.rhs(x, np.array([0.9, 0.05, 0.6, 1.2]), params), (0, 0.5), x0, method="DOP853",
                      rtol=1e-11, atol=1e-12, t_eval=[0.5]).y[:, -1]
    np.testing.assert_allclose(states[-1], exact, rtol=0, atol=1e-6)


def test_compare_runs_the_users_fmus_from_that_machines_rest(user_run):
    root, _ = user_run
    done = opfmu("compare", "--surrogate", root / "M.fmu", "--reference", root / "R.fmu", "--scenario", "step",
                 "--stop-time", 1, "--out", root / "cmp")
    assert done.returncode == 0, done.stderr
    start = scenario("step", 0, 1.0, SM4.params(MACHINE)).initial_state()
    assert json.loads((root / "cmp" / "step.json").read_text())["x0"] == pytest.approx(start.tolist(), abs=1e-12)
    assert np.abs(start - scenario("step", 0, 1.0).initial_state()).max() > 0.05


def test_compare_refuses_fmus_of_two_different_machines(user_run, tmp_path):
    root, _ = user_run
    assert opfmu("build-reference-fmu", "-o", tmp_path / "Default.fmu", "--platforms", "linux64").returncode == 0
    done = opfmu("compare", "--surrogate", root / "M.fmu", "--reference", tmp_path / "Default.fmu", "--scenario",
                 "step", "--stop-time", 1, "--out", tmp_path / "cmp")
    assert done.returncode == 2 and "different machines" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("content, says", [
    ('{"H": -1}', "parameter H"),
    ('{"Hx": 3}', "unknown sm4 parameter"),
    ('{"D": "0"}', "parameter D"),
    ('[1, 2]', "JSON object"),
    ('{"H": NaN}', "cannot read machine file"),
    ('{"H": 1e400}', "parameter H"),
    ('{"H": 1' + '0' * 400 + '}', "parameter H"),
    ('{"Xd_p": 2.0}', "not exceed Xd"),
    ('{"H": 1e-9}', "parameter H = 1e-09 must lie in [0.1, 1000] s"),
    ('{"H": 1e308, "D": 1e308}', "parameter H = 1e+308 must lie in [0.1, 1000] s"),
    ('{"Pm": 0.7}', "unknown sm4 parameter(s) 'Pm'"),  # an input, not a parameter
    ("not json", "cannot read machine file"),
])
def test_a_bad_machine_file_is_one_line_and_exit_code_2(tmp_path, content, says):
    (tmp_path / "m.json").write_text(content)
    done = opfmu("data", "--preset", "quick", "--machine", tmp_path / "m.json", "--out", tmp_path / "d")
    assert done.returncode == 2 and says in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and "Traceback" not in done.stderr
    assert not (tmp_path / "d").exists()


@pytest.mark.parametrize("content", ['{"H": 1e-9}', '{"H": 1e308, "D": 1e308}'])
def test_operator_refuses_a_machine_outside_the_physical_ranges_before_any_work(tmp_path, content):
    (tmp_path / "m.json").write_text(content)
    done = opfmu("operator", "--machine", tmp_path / "m.json", "--out", tmp_path / "run")
    assert done.returncode == 2 and "parameter H = " in done.stderr and "must lie in [0.1, 1000] s" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and done.stdout == ""
    assert not (tmp_path / "run").exists()
