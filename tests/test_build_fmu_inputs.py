"""`opfmu build-fmu` on operator files it must refuse, and on the machine an operator file names.

Each hostile file is the shipped operator with its metadata rewritten; every refusal is exit code 2
with one line on stderr, before anything is generated or compiled."""
import json
import subprocess
import sys

import numpy as np
import onnx
import pytest
from fmpy import extract, read_model_description

from cosim.fmu import FMU as Slave
from hand_made import operator_without_trunk
from machines import wscc9_machine
from opfmu.cli import main
from reference_models.drift import frame_of
from reference_models.sm4 import SM4, SM4Params
from surrogate.operator import DEFAULT_OPERATOR

INJECTION = '"); system("rm -rf /"); //'
UNDAMPED = wscc9_machine(3)  # WSCC generator 3 as shipped: D = 0, no external reactance, 60 Hz


@pytest.fixture(scope="module")
def shipped():
    return onnx.load(str(DEFAULT_OPERATOR))


def rewritten(shipped, path, changes=None, drop=(), duplicate=None):
    """The shipped operator with metadata keys set (changes), removed (drop) or given twice."""
    proto = onnx.ModelProto()
    proto.CopyFrom(shipped)
    meta = {p.key: p.value for p in proto.metadata_props if p.key not in drop}
    meta.update(changes or {})
    del proto.metadata_props[:]
    for key, value in meta.items():
        proto.metadata_props.add(key=key, value=value)
    if duplicate:
        proto.metadata_props.add(key=duplicate[0], value=duplicate[1])
    onnx.save(proto, str(path))
    return path


def refused(capsys, tmp_path, path, *extra):
    """The one-line error of build-fmu on `path` (asserting exit code 2, no traceback, no FMU)."""
    out = tmp_path / "out.fmu"
    code = main(["build-fmu", str(path), "-o", str(out), *extra])
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:"), err
    assert "Traceback" not in err and not out.exists()
    return lines[0]


def meta_of(shipped, key):
    return json.loads({p.key: p.value for p in shipped.metadata_props}[key])


CASES = {
    "all metadata removed": (lambda s: {}, "ALL", "metadata lacks component"),
    "params removed": (lambda s: {}, ("params",), "metadata lacks params"),
    "unknown component": (lambda s: {"component": INJECTION}, (), "unknown component"),
    "code as a state name": (lambda s: {"state_names": json.dumps(["delta", INJECTION, "Ed_p", "Eq_p"])}, (),
                             "state_names"),
    "inputs in another order": (lambda s: {"input_names": json.dumps(["theta_vs", "Vs", "Pm", "Efd"])}, (),
                                "input_names"),
    "the two inputs of the first operators": (lambda s: {"input_names": json.dumps(["Vs", "theta_vs"])}, (),
                                              "input_names"),
    "code as n_sensors": (lambda s: {"n_sensors": INJECTION}, (), "n_sensors is not valid JSON"),
    "n_sensors 1e8": (lambda s: {"n_sensors": "1e8"}, (), "n_sensors = 100000000 must be an integer in"),
    "n_sensors abc": (lambda s: {"n_sensors": "abc"}, (), "n_sensors is not valid JSON"),
    "n_sensors unlike the graph": (lambda s: {"n_sensors": "1000", "sensor_times_s": json.dumps(
        list(np.linspace(0, 1, 1000)))}, (), "1001 sensor times, not 1000"),
    "horizon 1e400": (lambda s: {"horizon_s": "1e400"}, (), "horizon_s = inf must be a finite number"),
    "horizon NaN": (lambda s: {"horizon_s": "NaN"}, (), "horizon_s is not valid JSON"),
    "horizon negative": (lambda s: {"horizon_s": "-1"}, (), "horizon_s = -1.0 must lie in"),
    "params with an unknown key": (lambda s: {"params": json.dumps({**SM4Params().to_dict(), INJECTION: 1})}, (),
                                   "unknown sm4 parameter"),
    "params H = -1": (lambda s: {"params": json.dumps({"H": -1})}, (), "parameter H = -1.0 must be > 0"),
    "params H huge": (lambda s: {"params": '{"H": ' + "9" * 400 + "}"}, (), "metadata params"),
    "params not an object": (lambda s: {"params": "[1, 2]"}, (), "must be a JSON object"),
    "Pm as a parameter": (lambda s: {"params": json.dumps({**SM4Params().to_dict(), "Pm": 0.7})}, (),
                          "unknown sm4 parameter(s) 'Pm'"),
    # behind a 2 pu line the machine cannot deliver the start Pm at the start Efd
    "machine without equilibrium": (lambda s: {"params": json.dumps({"Xep": 2.0})}, (), "no stable equilibrium"),
    "frame removed": (lambda s: {}, ("frame",), "metadata has no frame"),
    "frame of another machine": (lambda s: {"frame": json.dumps(frame_of(SM4.drift, SM4Params(D=0.5)).to_dict())}, (),
                                 "is not the frame of the sm4 component"),
    "frame with code": (lambda s: {"frame": json.dumps({"angle_states": INJECTION})}, (), "is not a frame"),
    "envelope with wrong names": (lambda s: {"envelope": json.dumps(
        {"x0": {INJECTION: [0, 1], "omega": [0, 1], "Ed_p": [0, 1], "Eq_p": [0, 1]},
         "u": {"Vs": [0, 1], "theta_vs": [0, 1]}})}, (), "envelope x0 must give [low, high] for exactly"),
    "envelope low above high": (lambda s: {"envelope": json.dumps(
        {**meta_of(s, "envelope"), "u": {**meta_of(s, "envelope")["u"], "Vs": [1.2, 0.2]}})}, (), "has low > high"),
    "envelope with code as a bound": (lambda s: {"envelope": json.dumps(
        {**meta_of(s, "envelope"), "u": {**meta_of(s, "envelope")["u"], "Pm": [INJECTION, 1.0]}})}, (),
        "must be a number"),
    "envelope without Pm and Efd": (lambda s: {"envelope": json.dumps(
        {**meta_of(s, "envelope"), "u": {"Vs": [0.7, 1.2], "theta_vs": [-0.5, 0.5]}})}, (),
        "envelope u must give [low, high] for exactly"),
    "residual_scale with code": (lambda s: {"residual_scale": json.dumps([1, 1, INJECTION, 1])}, (),
                                 "residual_scale[2]"),
    "residual_scale negative": (lambda s: {"residual_scale": "[1, -1, 1, 1]"}, (), "positive numbers"),
    "residual_scale too short": (lambda s: {"residual_scale": "[1, 1]"}, (), "list of 4 numbers"),
    "residual_limit text": (lambda s: {"residual_limit": json.dumps(INJECTION)}, (), "residual_limit"),
    "rollover beyond the horizon": (lambda s: {"rollover_horizon_s": "2.0"}, (), "rollover_horizon_s = 2.0"),
    "rollover shorter than ten sensor intervals": (
        lambda s: {"rollover_horizon_s": repr(5 * float(meta_of(s, "horizon_s")) / (int(meta_of(s, "n_sensors")) - 1))},
        (), "at least 10 sensor intervals"),
    "deeply nested JSON": (lambda s: {"envelope": "[" * 100000 + "]" * 100000}, (), "envelope is not valid JSON"),
}


@pytest.mark.platform_tools  # one line whichever platforms' compilers are installed
@pytest.mark.parametrize("case", list(CASES))
def test_a_hostile_or_malformed_operator_file_is_one_line_error(shipped, tmp_path, capsys, case):
    changes, drop, expected = CASES[case]
    if drop == "ALL":
        drop = [p.key for p in shipped.metadata_props]
    path = rewritten(shipped, tmp_path / "op.onnx", changes(shipped), drop)
    assert expected in refused(capsys, tmp_path, path)


@pytest.mark.platform_tools
def test_a_key_given_twice_is_refused(shipped, tmp_path, capsys):
    path = rewritten(shipped, tmp_path / "op.onnx", duplicate=("component", "sm4"))
    assert "appears more than once" in refused(capsys, tmp_path, path)


@pytest.mark.platform_tools
@pytest.mark.parametrize("name", [INJECTION, "1abc", "int", "Ω", "a" * 65])
def test_a_model_name_that_is_not_a_c_identifier_is_refused(tmp_path, capsys, name):
    assert "must be a C identifier" in refused(capsys, tmp_path, DEFAULT_OPERATOR, "--name", name)


@pytest.mark.platform_tools
def test_the_refusal_reaches_the_shell_as_one_line(shipped, tmp_path):
    path = rewritten(shipped, tmp_path / "op.onnx", {"horizon_s": "1e400", "component": INJECTION})
    result = subprocess.run([sys.executable, "-m", "opfmu", "build-fmu", str(path), "-o", str(tmp_path / "x.fmu")],
                            capture_output=True, text=True)
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
    assert result.stderr.startswith("error:") and "Traceback" not in result.stderr


def test_build_fmu_runs_without_torch(tmp_path):
    small = tmp_path / "small.onnx"
    operator_without_trunk(DEFAULT_OPERATOR, small, "small")
    script = f"""
import importlib.abc, sys
class NoTorch(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == "torch" or name.startswith("torch."):
            raise ImportError("torch is blocked in this test")
sys.meta_path.insert(0, NoTorch())
from fmu_export.surrogate_fmu import build_surrogate_fmu
build_surrogate_fmu({str(small)!r}, {str(tmp_path / 'x.fmu')!r}, n_check=4)
assert "torch" not in sys.modules
"""
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr[-2000:]
    assert (tmp_path / "x.fmu").exists()


@pytest.fixture(scope="module")
def undamped_fmu(tmp_path_factory):
    """The FMU of a shipped operator (wscc9_gen2.onnx: 201 sensors, a fifth of the size of the default
    one) relabelled for another undamped machine (D = 0, other reactances), at the component's start
    inputs (no operating point): its network wrapped in that machine's frame (no damping torque), as
    an export for it would; from the run's build cache."""
    from fmu_export.build_cache import cached_surrogate_fmu
    from surrogate.frame_graph import network_graph, wrap_in_frame

    source = onnx.load(str(DEFAULT_OPERATOR.parent / "wscc9_gen2.onnx"))
    path = tmp_path_factory.mktemp("undamped") / "op.onnx"
    frame = frame_of(SM4.drift, SM4Params(**UNDAMPED))
    horizon, n_sensors = meta_of(source, "horizon_s"), meta_of(source, "n_sensors")
    relabelled = wrap_in_frame(network_graph(source), frame, np.linspace(0.0, horizon, n_sensors))
    rewritten(relabelled, path, {"params": json.dumps(UNDAMPED), "frame": json.dumps(frame.to_dict())},
              drop=("operating_point",))
    return cached_surrogate_fmu(path, "Undamped", n_check=4)


def test_the_fmu_is_built_for_the_machine_its_operator_file_names(undamped_fmu):
    params = SM4Params(**UNDAMPED)
    md = read_model_description(str(undamped_fmu))
    starts = {v.name: float(v.start) for v in md.modelVariables if v.start is not None}
    expected = SM4.steady_state(SM4.start_inputs, params)
    np.testing.assert_array_equal([starts[f"{n}0"] for n in SM4.state_names], expected)
    assert expected[0] != pytest.approx(SM4.steady_state()[0], abs=1e-3)  # not the default machine's
    assert starts["H"] == 3.01 and starts["D"] == 0.0  # the machine's parameters, fixed to the trained ones


def test_an_undamped_machine_stays_at_rest_and_steps_through_a_dip_with_every_correction(undamped_fmu):
    unzipped = extract(str(undamped_fmu)), read_model_description(str(undamped_fmu))
    rest = SM4.steady_state(SM4.start_inputs, SM4Params(**UNDAMPED))
    slave = Slave(unzipped)
    at_rest = np.array([slave.step(0.01) for _ in range(100)])
    dip = np.array([slave.step(0.01, 0.8, 0.05) for _ in range(20)] + [slave.step(0.01) for _ in range(50)])
    slave.close()
    np.testing.assert_allclose(at_rest, np.tile(rest, (100, 1)), rtol=0, atol=1e-6)
    assert np.all(np.isfinite(dip)) and np.abs(dip - rest).max() > 1e-3
