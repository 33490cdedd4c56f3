"""ONNX export and onnxruntime inference: the contract of docs/design.md, "The ONNX operator"."""
import json
import subprocess
import sys
import warnings

import numpy as np
import onnx
import pytest
import torch

from reference_models.sm4 import SM4
from surrogate.data import generate, load_metadata, load_split
from surrogate.models import OperatorConfig
from surrogate.onnx_export import ExportError, _attach_metadata, _torch_export, export_onnx
from surrogate.operator import EnvelopeWarning, Operator, OperatorInputError
from surrogate.training import TrainConfig, load_model, train

SMALL = OperatorConfig(width=16, depth=2, latent=8)


@pytest.fixture(scope="module", params=["unstacked", "pinn"])
def exported(request, paper_tiny, tmp_path_factory):
    """(run directory, onnx path) of a briefly trained model of each kind."""
    run = tmp_path_factory.mktemp(f"run_{request.param}")
    config = TrainConfig(model=OperatorConfig(**{**SMALL.to_dict(), "arch": request.param}), epochs=3,
                         time_points=20, physics=True)
    train(paper_tiny[1], config, run, progress=False)
    path = run / "model.onnx"
    export_onnx(run, path)
    return run, path


def in_envelope_inputs(meta, n=3):
    """x0 [n, 4] and u [n, S, 4] held at the middle of the envelope, theta_vs at 0 (the envelope is
    in the window frame, where every window starts at theta_vs = 0 and omega = 0: these are in it as given)."""
    box = meta["envelope"]
    x0 = np.array([[np.mean(box["x0"][s]) for s in SM4.state_names]] * n)
    u = np.tile([0.0 if name == "theta_vs" else np.mean(box["u"][name]) for name in SM4.input_names],
                (n, meta["n_points"], 1))
    return x0, u


def test_graph_has_the_contract_inputs_outputs_and_opset(exported):
    model = onnx.load(str(exported[1]))
    dims = lambda v: [d.dim_param or d.dim_value for d in v.type.tensor_type.shape.dim]  # noqa: E731
    assert [(i.name, dims(i)) for i in model.graph.input] == [("x0", ["N", 4]), ("u", ["N", 1001, 4]), ("t", ["M"])]
    assert [(o.name, dims(o)) for o in model.graph.output] == [("x", ["N", "M", 4])]
    assert all(i.type.tensor_type.elem_type == onnx.TensorProto.FLOAT for i in model.graph.input)
    assert max(o.version for o in model.opset_import if o.domain in ("", "ai.onnx")) >= 17


def test_metadata_carries_the_contract_fields(exported, paper_tiny):
    meta = {p.key: p.value for p in onnx.load(str(exported[1])).metadata_props}
    assert meta["component"] == "sm4"
    assert json.loads(meta["state_names"]) == ["delta", "omega", "Ed_p", "Eq_p"]
    assert json.loads(meta["input_names"]) == ["Vs", "theta_vs", "Pm", "Efd"]
    assert float(meta["horizon_s"]) == 1.0 and int(meta["n_sensors"]) == 1001
    assert json.loads(meta["envelope"]) == load_metadata(paper_tiny[1])["envelope"]
    assert json.loads(meta["physics_informed"]) is True
    assert json.loads(meta["training"])["epochs"] == 3
    assert set(json.loads(meta["metrics"])["physical"]) == {"mse", "mae", "maxae"}
    assert meta["opfmu_version"] and json.loads(meta["architecture"])["arch"] in ("unstacked", "pinn")


def test_the_metadata_read_without_the_onnx_package_is_what_onnx_reads_and_a_bad_file_is_refused(exported, tmp_path):
    """surrogate.contract.metadata_of (what the commands that run built FMUs read, through
    onnxruntime) gives every key and value onnx reads; a file that is not a model is a ContractError."""
    from surrogate.contract import ContractError, metadata_of

    assert metadata_of(exported[1]) == {p.key: p.value for p in onnx.load(str(exported[1])).metadata_props}
    garbage = tmp_path / "garbage.onnx"
    garbage.write_bytes(b"not a protobuf" * 10)
    with pytest.raises(ContractError, match="not an ONNX model"):
        metadata_of(garbage)
    with pytest.raises(OSError):
        metadata_of(tmp_path / "absent.onnx")


def test_a_freely_trained_operator_rolls_over_at_its_whole_horizon(exported):
    meta = {p.key: p.value for p in onnx.load(str(exported[1])).metadata_props}
    assert float(meta["rollover_horizon_s"]) == float(meta["horizon_s"])


def test_a_causally_trained_operator_rolls_over_before_its_least_trained_end(paper_tiny, tmp_path):
    from surrogate.training import CAUSAL_ROLLOVER_SHARE

    causal = TrainConfig(model=OperatorConfig(**{**SMALL.to_dict(), "anchored": True}), epochs=2, time_points=20,
                         causal=True)
    train(paper_tiny[1], causal, tmp_path / "causal", progress=False)
    meta = export_onnx(tmp_path / "causal", tmp_path / "causal.onnx")
    assert float(meta["rollover_horizon_s"]) == pytest.approx(CAUSAL_ROLLOVER_SHARE * float(meta["horizon_s"]))


def test_onnxruntime_reproduces_torch_on_the_test_split(exported, paper_tiny):
    data = load_split(paper_tiny[1], "test")
    model = load_model(exported[0])
    with torch.no_grad():
        expected = model(*(torch.as_tensor(data[k], dtype=torch.float32) for k in ("x0", "u", "t"))).numpy()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EnvelopeWarning)
        got = Operator.load(exported[1]).predict(data["x0"], data["u"], data["t"])
    assert np.max(np.abs(got - expected)) <= 1e-5


def test_deeponet_trunk_basis_is_cached_per_time_grid_and_the_pinn_runs_whole(exported, paper_tiny):
    op = Operator.load(exported[1])
    is_pinn = json.loads(op.metadata["architecture"])["arch"] == "pinn"
    assert op.separable is not is_pinn
    x0, u = in_envelope_inputs(load_metadata(paper_tiny[1]))
    t = np.linspace(0, 1, 11)
    first = op.predict(x0, u, t)
    np.testing.assert_array_equal(op.predict(x0, u, t), first)
    op.predict(x0, u, np.linspace(0, 1, 7))
    assert len(op._basis) == (0 if is_pinn else 2)


def test_an_exported_deeponet_head_is_one_product_computed_without_a_session(exported):
    assert Operator.load(exported[1])._head is None


def test_a_graph_with_the_decoding_after_the_product_runs_its_head_as_a_session(exported, paper_tiny, tmp_path):
    model = load_model(exported[0])
    if model.config.arch == "pinn":
        pytest.skip("the PINN has no head")
    unfolded = tmp_path / "unfolded.onnx"
    _torch_export(model, model.n_sensors, SM4.n_states, SM4.n_inputs, unfolded)
    _attach_metadata(unfolded, {p.key: p.value for p in onnx.load(str(exported[1])).metadata_props}, SM4)
    op, reference = Operator.load(unfolded), Operator.load(exported[1])
    x0, u = in_envelope_inputs(load_metadata(paper_tiny[1]))
    t = np.linspace(0, 1, 9)
    assert op.separable and op._head is not None
    np.testing.assert_allclose(op.predict(x0, u, t), reference.predict(x0, u, t), rtol=0, atol=1e-5)


def test_predictions_at_any_query_times_match_the_whole_graph(exported, paper_tiny):
    op = Operator.load(exported[1])
    x0, u = in_envelope_inputs(load_metadata(paper_tiny[1]))
    t = np.array([0.0, 0.0123, 0.5, 1.0], dtype=np.float32)
    whole = op._full.run(["x"], {"x0": x0.astype(np.float32), "u": u.astype(np.float32), "t": t})[0]
    np.testing.assert_allclose(op.predict(x0, u, t), whole, rtol=0, atol=1e-6)


@pytest.mark.parametrize("bad, message", [
    (dict(x0=np.zeros((2, 3))), "x0 must be \\[N, 4\\]"),
    (dict(u=np.zeros((2, 1001, 2))), "u must be \\[N, S, 4\\]"),
    (dict(t=np.array([0.0, 1.5])), "t must lie in \\[0, 1\\]"),
    (dict(t=np.array([np.nan])), "t holds NaN"),
    (dict(u=np.full((2, 1001, 4), np.inf)), "u holds NaN or inf"),
    (dict(x0=np.full((2, 4), np.nan)), "x0 holds NaN"),
])
def test_bad_inputs_are_refused_with_a_clear_message(exported, paper_tiny, bad, message):
    x0, u = in_envelope_inputs(load_metadata(paper_tiny[1]), n=2)
    args = {"x0": x0, "u": u, "t": np.linspace(0, 1, 5), **bad}
    with pytest.raises(OperatorInputError, match=message):
        Operator.load(exported[1]).predict(**args)


def test_inputs_outside_the_envelope_warn_or_raise_when_strict(exported, paper_tiny):
    x0, u = in_envelope_inputs(load_metadata(paper_tiny[1]), n=1)
    u[0, 500:, 0] = 0.3  # a deep voltage dip the paper preset never saw
    op = Operator.load(exported[1])
    with pytest.warns(EnvelopeWarning, match="Vs in \\[0.3"):
        op.predict(x0, u, np.linspace(0, 1, 5))
    with pytest.raises(OperatorInputError, match="outside the training envelope"):
        op.predict(x0, u, np.linspace(0, 1, 5), strict=True)


def test_export_command_writes_the_file_and_reports_metrics(exported, tmp_path):
    out = tmp_path / "op.onnx"
    result = subprocess.run([sys.executable, "-m", "opfmu", "export", str(exported[0]), "-o", str(out)],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert out.exists() and "onnxruntime matches torch" in result.stdout


def test_export_of_a_directory_without_a_model_is_a_one_line_error(tmp_path):
    result = subprocess.run([sys.executable, "-m", "opfmu", "export", str(tmp_path), "-o", str(tmp_path / "x.onnx")],
                            capture_output=True, text=True)
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x.onnx").exists()


@pytest.fixture(scope="module")
def anchored_runs(paper_tiny, cosim_tiny, tmp_path_factory):
    """Four briefly trained anchored causal Unstacked DeepONets: seeds 0 and 1 on the paper dataset,
    seed 2 on the cosim dataset, seed 3 on another cosim dataset."""
    other_cosim = tmp_path_factory.mktemp("other_cosim")
    generate(cosim_tiny[0], other_cosim, seed=4, progress=False)
    runs = []
    for seed, data in ((0, paper_tiny[1]), (1, paper_tiny[1]), (2, cosim_tiny[1]), (3, other_cosim)):
        run = tmp_path_factory.mktemp(f"anchored{seed}")
        config = TrainConfig(model=OperatorConfig(**{**SMALL.to_dict(), "anchored": True}), epochs=2, time_points=20,
                             causal=True, physics=True, seed=seed)
        train(data, config, run, progress=False)
        runs.append(run)
    return runs


def test_an_exported_ensemble_computes_the_mean_of_its_members(anchored_runs, paper_tiny, tmp_path):
    for i, run in enumerate(anchored_runs[:2]):
        export_onnx(run, tmp_path / f"member{i}.onnx")
    meta = export_onnx(anchored_runs[:2], tmp_path / "mean.onnx")
    x0, u = in_envelope_inputs(load_metadata(paper_tiny[1]))
    t = np.linspace(0, 1, 21)
    members = [Operator.load(tmp_path / f"member{i}.onnx").predict(x0, u, t) for i in range(2)]
    np.testing.assert_allclose(Operator.load(tmp_path / "mean.onnx").predict(x0, u, t), (members[0] + members[1]) / 2,
                               rtol=0, atol=1e-5)
    assert json.loads(meta["architecture"])["ensemble"] == 2
    assert [m["seed"] for m in json.loads(meta["training"])["ensemble"]] == [0, 1]


def test_an_ensembles_envelope_is_where_every_member_was_trained(anchored_runs, tmp_path):
    meta = export_onnx(anchored_runs[2:], tmp_path / "mean.onnx")
    boxes = [load_metadata(json.loads((run / "config.json").read_text())["data"]["dir"])["envelope"]
             for run in anchored_runs[2:]]
    assert boxes[0] != boxes[1]
    for group, names in json.loads(meta["envelope"]).items():
        for name, (low, high) in names.items():
            assert low == max(b[group][name][0] for b in boxes) and high == min(b[group][name][1] for b in boxes)


def test_members_trained_on_envelopes_that_do_not_overlap_are_refused(anchored_runs, tmp_path):
    with pytest.raises(ExportError, match="do not overlap in Ed_p"):  # the paper's box holds Ed_p at 0
        export_onnx([anchored_runs[0], anchored_runs[2]], tmp_path / "mean.onnx")
    assert not (tmp_path / "mean.onnx").exists()


def test_export_command_writes_the_mean_of_several_runs(anchored_runs, tmp_path):
    out = tmp_path / "mean.onnx"
    result = subprocess.run([sys.executable, "-m", "opfmu", "export", *map(str, anchored_runs[:2]), "-o", str(out)],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "mean of 2 unstacked operator" in result.stdout and out.exists()


def test_runs_that_cannot_be_averaged_are_a_one_line_error_and_write_nothing(exported, anchored_runs, tmp_path):
    out = tmp_path / "mean.onnx"
    result = subprocess.run([sys.executable, "-m", "opfmu", "export", str(anchored_runs[0]), str(exported[0]),
                             "-o", str(out)], capture_output=True, text=True)
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
    assert "only anchored Unstacked DeepONets" in result.stderr and not out.exists()


def test_shipped_default_operator_loads_and_its_envelope_holds_the_nominal_equilibrium():
    from reference_models.sm4 import steady_state

    op = Operator.default()
    x_eq = steady_state()  # at the start inputs Vs = 1, theta_vs = 0, Pm, Efd
    assert not op.outside_envelope(x_eq[None], np.tile(SM4.start_inputs, (1, op.n_sensors, 1)))
    meta = op.metadata
    assert json.loads(meta["training"])["dataset"]["preset"] == "cosim"
    assert json.loads(meta["metrics"])["physical"]["maxae"] < 0.5


def test_shipped_default_operator_keeps_the_equilibrium_near_rest():
    from reference_models.sm4 import steady_state

    op = Operator.default()
    x_eq = steady_state()  # at the start inputs Vs = 1, theta_vs = 0, Pm, Efd
    x = op.predict(x_eq[None], np.tile(SM4.start_inputs, (1, op.n_sensors, 1)), np.linspace(0, op.horizon, 101))
    assert np.all(np.max(np.abs(x[0] - x_eq), axis=0) < [0.05, 0.05, 0.02, 0.02])


def test_checking_an_operator_against_a_dataset_writes_metrics_and_figures(cosim_tiny, tmp_path):
    from surrogate.report import check_operator

    table = check_operator(Operator.default(), cosim_tiny[1], tmp_path)
    assert "MaxAE" in table and "omega" in table
    saved = json.loads((tmp_path / "metrics.json").read_text())
    assert saved["metrics"]["n_trajectories"] == 3 and saved["metrics"]["physical"]["mse"] < 1e-2
    assert (tmp_path / "trajectories.png").exists() and (tmp_path / "error_over_time.png").exists()
