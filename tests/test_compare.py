"""`opfmu compare` and `opfmu demo`: fmpy runs the surrogate and the reference FMU on the same inputs."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract

from opfmu.compare import ComparisonPlots, CompareError, compare, csv_inputs, plot_comparison, scenario_inputs
from reference_models.scenarios import BUS_SCENARIOS, SCENARIOS, scenario
from reference_models.simulate import simulate
from reference_models.sm4 import SM4, min_voltage_with_equilibrium

from conftest import preset_file, tiny
from test_cli import assert_one_line_error, opfmu

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def extracted(fmu_path, reference_path, tmp_path_factory):
    root = tmp_path_factory.mktemp("extracted")
    return extract(str(fmu_path), unzipdir=str(root / "s")), extract(str(reference_path), unzipdir=str(root / "r"))


@pytest.mark.parametrize("name", SCENARIOS)
def test_every_scenario_starts_the_machine_at_rest_and_is_reproducible_from_its_seed(name):
    s = scenario(name, seed=4, stop_time=10.0)
    x0, (Vs, theta_vs, Pm, Efd) = s.initial_state(), s.inputs(np.array([0.0]))[0]
    # at rest in the frame of its network (drift: turning at s.speed, the damping torque D speed in Pm)
    Pm_f = Pm - s.params.D * s.speed
    u0 = np.array([max(Vs, min_voltage_with_equilibrium(s.params, Pm_f, Efd)), theta_vs, Pm_f, Efd])
    rate = SM4.rhs(x0 - np.array([0.0, s.speed, 0.0, 0.0]), u0, s.params)
    assert np.max(np.abs(rate)) < 1e-8
    assert x0[1] == s.speed and (s.speed != 0) == (name == "drift")
    t = np.linspace(0, 10, 1001)
    np.testing.assert_array_equal(scenario(name, seed=4).inputs(t), s.inputs(t))
    assert not np.array_equal(scenario(name, seed=5).inputs(t), s.inputs(t))


def test_no_scenario_makes_the_machine_slip_a_pole():
    # seed 6 of `step` first drew 0.70 pu held for 50 s: the machine slipped poles after 13 s
    s = scenario("step", seed=6, stop_time=60.0)
    t = np.linspace(0, 60, 1201)
    angle = simulate(s.initial_state(), s.signal, t)[:, 0] - s.inputs(t)[:, 1]
    assert np.abs(angle).max() < np.pi


def test_the_dip_scenario_is_a_fault_that_drops_holds_and_recovers():
    u = scenario("dip", seed=0).inputs(np.arange(0, 10, 0.001))[:, 0]
    assert u.min() < u[0] - 0.05 and abs(u[-1] - u[0]) < 0.06


@pytest.mark.parametrize("name", BUS_SCENARIOS)
def test_bus_scenarios_hold_pm_and_efd_at_their_start_values(name):
    u = scenario(name, seed=2).inputs(np.linspace(0, 10, 1001))
    np.testing.assert_array_equal(u[:, 2:], np.tile(SM4.start_inputs[2:], (len(u), 1)))


def test_the_governor_scenario_steps_and_ramps_pm_every_few_seconds_within_its_levels():
    start, kinds = SM4.start_inputs[2], set()
    for seed in range(4):
        s = scenario("governor", seed=seed)
        pm = s.signal.channels["Pm"]  # a Table: (0, start), then per change (t, before), (t + length, after)
        times, values = np.array(pm.times), np.array(pm.values)
        assert values[0] == start and len(times) >= 5
        change, length = np.abs(np.diff(values[1:])[::2]), np.diff(times[1:])[::2]
        assert np.all((change >= 0.1 * start - 1e-12) & (change <= 0.2 * start + 1e-12))
        assert np.all((length == 0) | ((length >= 0.5) & (length <= 2.0)))
        assert np.all(np.diff(times[2::2]) >= 2.0) and 0.5 <= times[1] <= 2.0
        assert np.all((values >= 0.8 * start - 1e-12) & (values <= 1.1 * start + 1e-12))
        kinds |= {"step" if n == 0 else "ramp" for n in length}
        u = s.inputs(np.linspace(0, 10, 1001))
        assert np.all(u[:, 3] == SM4.start_inputs[3]) and np.mean(np.abs(u[:, 0] - 1.0) <= 0.1) > 0.8
    assert kinds == {"step", "ramp"}


@pytest.mark.parametrize("D", [0.0, 2.0])
def test_the_drift_scenario_is_the_mix_scenario_turned_at_a_constant_speed(D):
    from reference_models.simulate import SolverConfig

    params = SM4.params({"D": D})
    drift, mix = scenario("drift", 3, 5.0, params), scenario("mix", 3, 5.0, params)
    c, t = drift.speed, np.linspace(0, 5, 501)
    assert 1.0 <= abs(c) <= 12.0
    u_drift, u_mix = drift.inputs(t), mix.inputs(t)
    np.testing.assert_allclose(u_drift[:, 1], u_mix[:, 1] + c * t, rtol=1e-12, atol=1e-12)  # up to 60 rad
    np.testing.assert_allclose(u_drift[:, 2], u_mix[:, 2] + D * c, rtol=1e-12, atol=1e-12)  # the damping torque
    np.testing.assert_array_equal(u_drift[:, [0, 3]], u_mix[:, [0, 3]])
    tight = SolverConfig(rtol=1e-10, atol=1e-12)
    x_drift = simulate(drift.initial_state(), drift.signal, t, params, tight)
    x_mix = simulate(mix.initial_state(), mix.signal, t, params, tight)
    turned = x_mix + np.stack([c * t, np.full_like(t, c), 0 * t, 0 * t], axis=1)
    np.testing.assert_allclose(x_drift, turned, rtol=1e-6, atol=1e-6)  # delta up to 60 rad, omega 12 rad/s


def test_comparison_reports_every_output_and_both_timings(extracted):
    inputs = scenario_inputs("slow", 0, 2.0, 0.01)
    result = compare(*extracted, inputs, 2.0, 0.01)
    assert set(result["metrics"]) == {"delta", "omega", "Ed_p", "Eq_p", "Id", "Iq", "I_re", "I_im", "P", "Q",
                                      "rotor_speed"}
    assert len(result["trajectories"]["reference"]["time"]) == 201
    assert result["metrics"]["delta"]["maxae"] < 0.02  # the shipped operator on a slow scenario
    assert all(result[k]["surrogate"] > 0 and result[k]["reference"] > 0 for k in ("wall_s", "do_step_s"))
    assert result["in_envelope"]


def test_reference_run_is_the_held_input_solution_so_the_surrogate_error_is_measured_against_rk45(extracted):
    from scipy.integrate import solve_ivp

    from reference_models.sm4 import rhs

    inputs = scenario_inputs("step", 3, 1.0, 0.05)
    result = compare(*extracted, inputs, 1.0, 0.05)
    x = inputs.x0.copy()
    for u in inputs.values[:-1]:
        x = solve_ivp(lambda _t, y: rhs(y, u), (0, 0.05), x, rtol=1e-11, atol=1e-12, method="DOP853").y[:, -1]
    ref = result["trajectories"]["reference"]
    np.testing.assert_allclose([ref[n][-1] for n in ("delta", "omega", "Ed_p", "Eq_p")], x, atol=1e-6)


def test_csv_inputs_with_a_missing_column_are_refused(tmp_path):
    path = tmp_path / "in.csv"
    path.write_text("time,Vs\n0,1\n1,1\n")
    with pytest.raises(CompareError, match="columns time, Vs, theta_vs"):
        csv_inputs(path)


def test_csv_inputs_without_pm_and_efd_hold_them_at_their_start_values(tmp_path):
    path = tmp_path / "in.csv"
    path.write_text("time,Vs,theta_vs\n0,1,0\n1,0.95,0.1\n")
    inputs = csv_inputs(path)
    np.testing.assert_array_equal(inputs.values, [[1, 0, *SM4.start_inputs[2:]], [0.95, 0.1, *SM4.start_inputs[2:]]])
    np.testing.assert_allclose(inputs.x0, SM4.steady_state(), rtol=0, atol=1e-12)


def test_csv_inputs_with_pm_and_efd_drive_them_and_start_at_rest_under_the_first_row(tmp_path):
    path = tmp_path / "in.csv"
    path.write_text("time,Vs,theta_vs,Pm,Efd\n0,1,0.1,0.6,1.3\n1,1,0.1,0.65,1.2\n")
    inputs = csv_inputs(path)
    np.testing.assert_array_equal(inputs.values, [[1, 0.1, 0.6, 1.3], [1, 0.1, 0.65, 1.2]])
    np.testing.assert_allclose(inputs.x0, SM4.steady_state([1, 0.1, 0.6, 1.3]), rtol=0, atol=1e-12)
    assert inputs.table().dtype.names == ("time", "Vs", "theta_vs", "Pm", "Efd")


def test_csv_inputs_whose_time_goes_back_are_refused(tmp_path):
    path = tmp_path / "in.csv"
    path.write_text("time,Vs,theta_vs\n0,1,0\n0.5,1,0\n0.2,1,0\n")
    with pytest.raises(CompareError, match="never decrease"):
        csv_inputs(path)


def test_compare_command_on_a_csv_writes_plots_and_a_summary(fmu_path, reference_path, tmp_path):
    csv = tmp_path / "fault.csv"
    csv.write_text("time,Vs,theta_vs\n0,1.0,0.0\n0.3,1.0,0.0\n0.3,0.5,0.1\n0.4,0.5,0.1\n0.4,1.0,0.05\n1.5,1.0,0.05\n")
    result = opfmu("compare", "--surrogate", str(fmu_path), "--reference", str(reference_path), "--inputs", str(csv),
                   "--step", "0.01", "--out", str(tmp_path / "out"))
    assert result.returncode == 0, result.stderr
    assert "MaxAE" in result.stdout and "us per step" in result.stdout
    summary = json.loads((tmp_path / "out" / "fault.json").read_text())
    assert summary["stop_time_s"] == 1.5 and summary["metrics"]["omega"]["maxae"] > 0
    for name in ("fault_states.png", "fault_currents_powers.png"):
        assert (tmp_path / "out" / name).stat().st_size > 10_000


def test_compare_command_refuses_a_file_that_is_not_an_fmu(reference_path, tmp_path):
    bogus = tmp_path / "x.fmu"
    bogus.write_text("no zip")
    result = opfmu("compare", "--surrogate", str(bogus), "--reference", str(reference_path), "--scenario", "dip")
    assert_one_line_error(result, "is not an FMU")


def test_compare_command_refuses_a_parameter_the_surrogate_does_not_have(fmu_path, reference_path, tmp_path):
    result = opfmu("compare", "--surrogate", str(fmu_path), "--reference", str(reference_path), "--scenario", "dip",
                   "--param", "no_such=1", "--stop-time", "0.1", "--out", str(tmp_path))
    assert_one_line_error(result, "has no parameter no_such")


def test_compare_command_passes_surrogate_parameters_on(fmu_path, reference_path, tmp_path):
    runs = {}
    for jump in ("0", "0.02"):
        result = opfmu("compare", "--surrogate", str(fmu_path), "--reference", str(reference_path), "--scenario",
                       "step", "--seed", "1", "--param", f"restart_jump={jump}", "--stop-time", "3",
                       "--out", str(tmp_path / jump))
        assert result.returncode == 0, result.stderr
        runs[jump] = json.loads((tmp_path / jump / "step.json").read_text())["metrics"]["omega"]["maxae"]
    assert runs["0"] != runs["0.02"]


def test_compare_command_refuses_a_stop_time_that_is_not_whole_steps(fmu_path, reference_path, tmp_path):
    result = opfmu("compare", "--surrogate", str(fmu_path), "--reference", str(reference_path), "--scenario", "dip",
                   "--stop-time", "1.005", "--step", "0.01", "--out", str(tmp_path))
    assert_one_line_error(result, "not a whole number of steps")


@pytest.mark.slow
def _plotted(t, scale: float, label: str) -> dict:
    """A comparison result with SM4's trajectories of size `scale` (what plot_comparison reads)."""
    def run(offset):
        return {"time": t, **{n: scale * np.sin(t * (i + 1)) + offset for i, n in enumerate(SM4.state_names + SM4.output_names)}}

    inputs = np.column_stack([scale * np.cos(t * (i + 1)) for i in range(len(SM4.input_names))])
    return {"component": SM4, "inputs": label, "step_s": 0.01,
            "trajectories": {"reference": run(0.0), "surrogate": run(scale * 1e-3), "inputs": inputs}}


def test_comparison_figures_drawn_again_with_new_data_equal_figures_drawn_anew(tmp_path):
    from PIL import Image

    t = np.linspace(0.0, 2.0, 201)
    small, large = _plotted(t, 1e-3, "small"), _plotted(t, 250.0, "large")  # other tick labels, other widths
    fresh = plot_comparison(large, tmp_path / "fresh", "large")
    with ComparisonPlots() as plots:
        plot_comparison(small, tmp_path / "again", "small", plots)
        again = plot_comparison(large, tmp_path / "again", "large", plots)
    for a, b in zip(fresh, again):
        assert a.name == b.name and np.array_equal(np.asarray(Image.open(a)), np.asarray(Image.open(b))), a.name


def test_demo_builds_both_fmus_compares_every_scenario_and_writes_the_report(tmp_path):
    result = opfmu("demo", "--out", str(tmp_path), "--stop-time", "2")
    assert result.returncode == 0, result.stderr
    report = (tmp_path / "report.md").read_text()
    assert str(tmp_path / "report.md") in result.stdout
    for name in SCENARIOS:
        assert f"| {name} |" in report
        assert (tmp_path / name / "comparison.json").exists() and (tmp_path / name / f"{name}_states.png").exists()
    assert (tmp_path / "SM4Surrogate.fmu").exists() and (tmp_path / "SM4Reference.fmu").exists()


@pytest.mark.slow
def test_demo_with_train_trains_exports_and_compares_its_own_operator(tmp_path):
    recipe = preset_file(tmp_path / "tiny.json", tiny("quick", probes_per_family=1))
    result = opfmu("demo", "--train", "--preset", str(recipe), "--epochs", "3", "--out", str(tmp_path / "run"),
                   "--stop-time", "1")
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "run" / "operator.onnx").exists() and (tmp_path / "run" / "check" / "metrics.json").exists()
    assert "operator.onnx" in (tmp_path / "run" / "report.md").read_text()


def test_example_script_compares_the_two_fmus_with_plain_fmpy(fmu_path, reference_path, tmp_path):
    result = subprocess.run([sys.executable, str(REPO / "examples" / "compare_with_fmpy.py"), str(fmu_path),
                             str(reference_path), "--plot", str(tmp_path / "example.png")],
                            capture_output=True, text=True, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "max abs error" in result.stdout and (tmp_path / "example.png").exists()
