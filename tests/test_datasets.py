"""Dataset generation: format, content, determinism, resume, parallel solves."""
import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from reference_models.sm4 import min_voltage_with_equilibrium, rhs, steady_state
from surrogate.data import DatasetError, SPLITS, generate, load_metadata, load_split
from surrogate.data.runner import SolveRunner

from conftest import preset_file, tiny


def test_splits_have_the_documented_arrays_and_shapes(paper_tiny):
    recipe, out = paper_tiny
    for split in SPLITS:
        data = load_split(out, split)
        n, s = recipe.counts[split], recipe.n_points
        assert data["x0"].shape == (n, 4) and data["u"].shape == (n, s, 4) and data["t"].shape == (s,)
        assert data["family"].shape == data["signal"].shape == (n,)
        if split == "collocation":
            assert "x" not in data
        else:
            assert data["x"].shape == (n, s, 4)


def test_time_grid_is_the_paper_grid(paper_tiny):
    t = load_split(paper_tiny[1], "train")["t"]
    assert t.size == 1001 and t[0] == 0.0 and t[-1] == 1.0
    np.testing.assert_allclose(np.diff(t), 1e-3)


def test_trajectories_start_at_x0(paper_tiny):
    data = load_split(paper_tiny[1], "test")
    np.testing.assert_allclose(data["x"][:, 0], data["x0"], rtol=0, atol=1e-12)


def test_trajectories_recompute_independently_from_x0_and_sampled_inputs(paper_tiny):
    data = load_split(paper_tiny[1], "val")
    t = data["t"]
    for x0, u, x in zip(data["x0"], data["u"], data["x"]):
        u_of_t = lambda tt: np.array([np.interp(tt, t, u[:, c]) for c in range(4)])  # noqa: E731
        sol = solve_ivp(lambda tt, y: rhs(y, u_of_t(tt)), (0, 1), x0, method="DOP853", t_eval=t,
                        rtol=1e-10, atol=1e-12, max_step=1e-3)
        np.testing.assert_allclose(sol.y.T, x, rtol=0, atol=1e-4)


def test_paper_initial_states_fill_the_paper_box(paper_tiny):
    x0 = load_split(paper_tiny[1], "train", frame=False)["x0"]
    assert np.all((-2 <= x0[:, 0]) & (x0[:, 0] <= 2) & (-1 <= x0[:, 1]) & (x0[:, 1] <= 1))
    assert np.all(x0[:, 2] == 0) and np.all((0.9 <= x0[:, 3]) & (x0[:, 3] <= 1.1))


def test_paper_splits_are_half_slow_half_fast(paper_tiny):
    family = load_split(paper_tiny[1], "train")["family"]
    assert sorted(family.tolist()) == ["fast"] * 4 + ["slow"] * 4


def test_stored_signal_reproduces_the_stored_inputs(paper_tiny):
    from reference_models.signals import Signal

    data = load_split(paper_tiny[1], "collocation", frame=False)
    for text, u in zip(data["signal"], data["u"]):
        np.testing.assert_array_equal(Signal.from_dict(json.loads(text))(data["t"]), u)


def test_windows_are_read_in_their_own_frame_where_they_solve_the_same_equations(paper_tiny):
    from reference_models.sm4 import SM4

    raw, framed = load_split(paper_tiny[1], "train", frame=False), load_split(paper_tiny[1], "train")
    assert np.all(framed["u"][:, 0, 1] == 0.0)
    assert np.all(np.abs(framed["x0"][:, 0]) <= np.pi)
    c = raw["x0"][:, 1] - framed["x0"][:, 1]  # the frame's speed: whole steps of 2 rad/s (D = 2)
    np.testing.assert_array_equal(c, 2.0 * np.round(c / 2.0))
    assert np.all(np.abs(framed["x0"][:, 1]) <= 1.0)
    np.testing.assert_allclose(framed["u"][..., 2], raw["u"][..., 2] - 2.0 * c[:, None])  # Pm - D c
    np.testing.assert_allclose(framed["x"][..., 1], raw["x"][..., 1] - c[:, None])
    relative = lambda d: d["x"][..., 0] - d["u"][..., 1]  # noqa: E731
    np.testing.assert_allclose(np.cos(relative(framed)), np.cos(relative(raw)), atol=1e-9)
    t = framed["t"]
    mid = slice(1, -1)
    rate = (framed["x"][:, 2:] - framed["x"][:, :-2]) / (t[2] - t[0])
    f = SM4.rhs(framed["x"][:, mid], framed["u"][:, mid], SM4.params())
    assert np.median(np.abs(rate - f)) < 1e-3


def test_metadata_records_preset_seed_envelope_and_versions(paper_tiny):
    meta = load_metadata(paper_tiny[1])
    assert meta["preset"]["name"] == "paper" and meta["seed"] == 7
    assert set(meta["versions"]) >= {"opfmu", "numpy", "scipy", "python"}
    train = load_split(paper_tiny[1], "train")
    assert meta["envelope"]["x0"]["delta"][1] >= train["x0"][:, 0].max()
    assert meta["envelope"]["u"]["Vs"][0] <= train["u"][..., 0].min()


def test_generation_is_deterministic_for_a_seed(paper_tiny, tmp_path):
    recipe, first = paper_tiny
    generate(recipe, tmp_path, seed=7, progress=False)
    for split in SPLITS:
        a, b = load_split(first, split), load_split(tmp_path, split)
        assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)


def test_another_seed_gives_other_data(paper_tiny, tmp_path):
    recipe, first = paper_tiny
    generate(recipe, tmp_path, seed=8, progress=False)
    assert not np.array_equal(load_split(first, "train")["x0"], load_split(tmp_path, "train")["x0"])


def test_a_directory_holding_another_dataset_is_refused(paper_tiny):
    recipe, out = paper_tiny
    with pytest.raises(DatasetError, match="holds a different dataset"):
        generate(recipe, out, seed=99, progress=False)


def test_local_dask_cluster_gives_the_same_data_as_serial_solves(paper_tiny, tmp_path):
    recipe, first = paper_tiny
    generate(recipe, tmp_path, seed=7, runner=SolveRunner(workers=2), progress=False)
    np.testing.assert_array_equal(load_split(tmp_path, "train")["x"], load_split(first, "train")["x"])


@pytest.mark.slow
def test_interrupted_generation_resumes_and_gives_the_same_files(tmp_path):
    recipe = tiny("paper", counts={"train": 40, "collocation": 2, "val": 2, "test": 2}, chunk_size=1)
    spec = preset_file(tmp_path / "preset.json", recipe)
    killed, resumed, fresh = tmp_path / "killed", tmp_path / "resumed", tmp_path / "fresh"
    cmd = [sys.executable, "-m", "opfmu", "data", "--preset", str(spec), "--workers", "0", "--quiet", "--seed", "5"]
    proc = subprocess.Popen(cmd + ["--out", str(killed)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while len(list((killed / ".partial").glob("train-*.npz"))) < 3 and time.monotonic() < deadline:
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not (killed / "train.npz").exists() and not (killed / "metadata.json").exists()
    done_before = len(list((killed / ".partial").glob("train-*.npz")))
    assert 3 <= done_before < 40
    subprocess.run(cmd + ["--out", str(killed)], check=True, stdout=subprocess.DEVNULL)
    generate(recipe, fresh, seed=5, progress=False)
    for split in SPLITS:
        a, b = load_split(killed, split), load_split(fresh, split)
        assert all(np.array_equal(a[k], b[k]) for k in a)
    assert not (killed / ".partial").exists()


def test_cosim_initial_box_contains_the_equilibria_of_the_voltage_range(cosim_tiny):
    meta = load_metadata(cosim_tiny[1])
    box = meta["ic_box"]
    for Vs in (min_voltage_with_equilibrium() + 1e-6, 1.0, 1.2):
        for theta in (-0.5, 0.0, 0.5):
            x = steady_state(Vs, theta)
            for value, name in zip(x, ("delta", "omega", "Ed_p", "Eq_p")):
                assert box[name][0] - 1e-9 <= value <= box[name][1] + 1e-9, (Vs, theta, name)


def test_cosim_reachable_ranges_are_measured_per_family(cosim_tiny):
    recipe, out = cosim_tiny
    reach = load_metadata(out)["reachable"]
    assert set(reach["per_family"]) == {name for name, _ in recipe.families}
    assert reach["probes"] == 2 * len(recipe.families)
    assert reach["all"]["omega"][0] < 0 < reach["all"]["omega"][1]


def test_cosim_splits_mix_the_cosimulation_families(tmp_path):
    from surrogate.data.presets import preset

    names = {n for n, _ in preset("cosim").families}
    assert {"step", "dip", "ramp", "mix"} <= names and any(n.startswith("zoh-") for n in names)


def test_an_existing_dask_scheduler_runs_the_solves(paper_tiny, tmp_path):
    from dask.distributed import LocalCluster

    recipe, first = paper_tiny
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        generate(recipe, tmp_path, seed=7, runner=SolveRunner(0, scheduler=cluster.scheduler_address),
                 progress=False)
    np.testing.assert_array_equal(load_split(tmp_path, "test")["x"], load_split(first, "test")["x"])
