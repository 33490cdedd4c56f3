"""Hostile and careless command lines: each refusal is one line on stderr with exit code 2, decided
before any work (nothing written, nothing else printed), naming the file or field; a Ctrl-C is one
"interrupted" line, which says "rerun to resume" only where a rerun resumes."""
import json
import time

import pytest

from opfmu.cli import build_parser, interrupted_message, main

from conftest import interrupt_and_wait, opfmu_process, preset_file, tiny

MACHINE = {"H": 3.01, "D": 2.0}


def refusal(capsys, *argv) -> str:
    """The one line `opfmu argv` is refused with (asserting exit code 2 and nothing on stdout)."""
    code = main([str(a) for a in argv])
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert code == 2, captured.err
    assert len(lines) == 1 and lines[0].startswith("error:"), captured.err
    assert captured.out == ""
    return lines[0]


@pytest.fixture
def files(tmp_path):
    """A file, a folder and a usable machine file to aim commands at."""
    (tmp_path / "a_file").write_text("x")
    (tmp_path / "a_folder").mkdir()
    (tmp_path / "machine.json").write_text(json.dumps(MACHINE))
    return tmp_path


def written(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return path


OUTPUT_FOLDER_COMMANDS = {
    "data": lambda d, out: ["data", "--preset", "quick", "--workers", "0", "--out", out],
    "train": lambda d, out: ["train", "--data", d / "a_folder", "--out", out],
    "evaluate": lambda d, out: ["evaluate", d / "a_folder", "--data", d / "a_folder", "--out", out],
    "operator": lambda d, out: ["operator", "--machine", d / "machine.json", "--out", out],
    "demo": lambda d, out: ["demo", "--out", out],
}
OUTPUT_FILE_COMMANDS = {
    "export": lambda d, out: ["export", d / "a_folder", "-o", out],
    "build-fmu": lambda d, out: ["build-fmu", "-o", out],
    "build-reference-fmu": lambda d, out: ["build-reference-fmu", "-o", out],
}


@pytest.mark.parametrize("command", list(OUTPUT_FOLDER_COMMANDS))
def test_an_output_folder_that_is_a_file_or_lies_under_one_is_refused_before_any_work(files, capsys, command):
    argv = OUTPUT_FOLDER_COMMANDS[command]
    assert "is a file, not a folder" in refusal(capsys, *argv(files, files / "a_file"))
    assert "a_file is not a folder" in refusal(capsys, *argv(files, files / "a_file" / "run"))
    assert sorted(p.name for p in files.iterdir()) == ["a_file", "a_folder", "machine.json"]


@pytest.mark.parametrize("command", list(OUTPUT_FILE_COMMANDS))
def test_an_output_file_that_is_a_folder_or_lies_under_a_file_is_refused_before_any_work(files, capsys, command):
    argv = OUTPUT_FILE_COMMANDS[command]
    assert "is a folder, not a file to write" in refusal(capsys, *argv(files, files / "a_folder"))
    assert "a_file is not a folder" in refusal(capsys, *argv(files, files / "a_file" / "x.out"))
    assert list((files / "a_folder").iterdir()) == []


TRAINING_CONFIGS = {
    "a list": ("[1, 2]", "must be a JSON object, got a list"),
    "empty": ("", "cannot read training config"),
    "an unknown field": ('{"epoch": 10}', "unknown field 'epoch'"),
    "model as a list": ('{"model": [1]}', "model must be a JSON object of OperatorConfig fields"),
    "model with an unknown field": ('{"model": {"widht": 3}}', "model: unknown field 'widht'"),
    "lr as text": ('{"lr": "fast"}', "lr must be a finite number, got a string"),
    "epochs as a float": ('{"epochs": 1e300}', "epochs must be an integer, got a number"),
    "epochs beyond any run": ('{"epochs": 10000000000000}', "epochs must be an integer, got an integer out of range"),
    "physics as text": ('{"physics": "yes"}', "physics must be a boolean"),
    "weights as a number": ('{"weights": 3}', "weights must be a JSON object of LossWeights fields"),
    "NaN": ('{"lr": NaN}', "NaN is not a number JSON allows"),
    "a negative rate": ('{"lr": -1}', "learning rate must be a finite number > 0"),
}


@pytest.mark.parametrize("case", list(TRAINING_CONFIGS))
def test_a_training_config_that_is_not_an_object_of_known_typed_fields_names_the_file_and_field(
        tmp_path, capsys, paper_tiny, case):
    text, expected = TRAINING_CONFIGS[case]
    config = written(tmp_path, "config.json", text)
    line = refusal(capsys, "train", "--data", paper_tiny[1], "--out", tmp_path / "run", "--config", config)
    assert expected in line and "Traceback" not in line
    assert not (tmp_path / "run").exists()


def test_a_training_config_that_is_a_folder_is_one_line(tmp_path, capsys, paper_tiny):
    line = refusal(capsys, "train", "--data", paper_tiny[1], "--out", tmp_path / "run", "--config", tmp_path)
    assert line == f"error: cannot read training config {tmp_path}: Is a directory"


@pytest.mark.parametrize("flags, expected", [
    (["--threads", "0"], "--threads must be >= 1"),
    (["--epochs", "0"], "epochs in [1, 1000000000]"),
    (["--seed", "-1"], "seed must lie in [0, 1000000000]"),
    (["--lr", "nan"], "learning rate must be a finite number > 0, got nan"),
])
def test_training_flags_out_of_range_are_refused(tmp_path, capsys, paper_tiny, flags, expected):
    assert expected in refusal(capsys, "train", "--data", paper_tiny[1], "--out", tmp_path / "run", *flags)


@pytest.mark.parametrize("metadata, expected", [
    ("[1]", "metadata.json must be a JSON object"),
    ("{", "metadata.json is not readable JSON"),
    ("", "metadata.json is not readable JSON"),
])
def test_a_dataset_whose_metadata_is_not_a_json_object_is_named_by_every_command_that_reads_it(
        tmp_path, capsys, metadata, expected):
    (tmp_path / "ds").mkdir()
    (tmp_path / "ds" / "metadata.json").write_text(metadata)
    spec = preset_file(tmp_path / "p.json", tiny("paper"))
    for argv in (["train", "--data", tmp_path / "ds", "--out", tmp_path / "run"],
                 ["data", "--preset", spec, "--out", tmp_path / "ds", "--workers", "0"]):
        line = refusal(capsys, *argv)
        assert expected in line and str(tmp_path / "ds" / "metadata.json") in line


@pytest.mark.parametrize("text, expected", [
    ("[1, 2]", "it must be a JSON object of Preset fields"),
    ('{"counts": {"train": 1}}', "it lacks the field 'name'"),
    ('{"name": "x", "counts": {"train": 1}, "families": [], "sizes": 3}', "unknown field 'sizes'"),
    ('{"name": "x", "counts": {"train": 1}, "families": [], "solver": [1]}', "solver must be a JSON object"),
])
def test_a_preset_file_of_the_wrong_shape_names_the_file_and_what_is_expected(tmp_path, capsys, text, expected):
    spec = written(tmp_path, "preset.json", text)
    line = refusal(capsys, "data", "--preset", spec, "--out", tmp_path / "d", "--workers", "0")
    assert f"preset file {spec} is not a valid preset: {expected}" in line


def test_a_dataset_seed_out_of_range_is_refused(tmp_path, capsys):
    for seed in ("-1", str(10**30)):
        assert "--seed must lie in" in refusal(capsys, "data", "--preset", "quick", "--seed", seed,
                                               "--out", tmp_path / "d")
    assert not (tmp_path / "d").exists()


@pytest.mark.parametrize("extra, expected", [
    (["--pm", "nan", "1"], "--pm LOW HIGH needs finite numbers"),
    (["--efd", "1", "inf"], "--efd LOW HIGH needs finite numbers"),
    (["--vs", "-1", "1"], "--vs LOW must be >= 0"),
    (["--pm", "0", "1e300"], "no operating point at Pm = 5e+299 pu"),
    (["--operating-point", "1e300", "1"], "no operating point at Pm = 1e+300 pu"),
    (["--operating-point", "nan", "1"], "--operating-point PM EFD must be finite numbers"),
    (["--seed", "-5"], "--seed must lie in"),
    (["--threads", "0"], "--threads be >= 1"),
    (["--windows", str(10**12)], "--windows in [4, 1000000]"),
])
def test_operator_levels_and_counts_without_a_meaning_are_refused_before_any_work(files, capsys, extra, expected):
    out = files / "run"
    assert expected in refusal(capsys, "operator", "--machine", files / "machine.json", "--out", out, *extra)
    assert not out.exists()


def test_build_reference_fmu_names_a_missing_operator_file(tmp_path, capsys):
    for path in (tmp_path, tmp_path / "none.onnx"):
        assert refusal(capsys, "build-reference-fmu", "--operator", path, "-o", tmp_path / "r.fmu") == \
            f"error: no operator file at {path}"


def test_a_refused_build_prints_no_platform_note(tmp_path, capsys):
    """Whatever cross compilers this machine lacks, the refusal of a bad request is the only line."""
    machine = written(tmp_path, "m.json", json.dumps({"H": -1}))
    assert "H" in refusal(capsys, "build-reference-fmu", "--machine", machine, "-o", tmp_path / "r.fmu")
    assert "C identifier" in refusal(capsys, "build-fmu", "--name", "1x", "-o", tmp_path / "s.fmu")


@pytest.mark.parametrize("argv, expected", [
    (["data", "--out", "d"], "interrupted: rerun the same command to resume"),
    (["train", "--data", "d", "--out", "r"], "interrupted: rerun the same command to resume"),
    (["operator", "--machine", "m.json", "--out", "o"], "interrupted: rerun the same command to resume"),
    (["demo", "--train"], "interrupted: rerun the same command to resume"),
    (["demo"], "interrupted"),
    (["build-fmu"], "interrupted"),
    (["export", "r", "-o", "x.onnx"], "interrupted"),
    (["compare", "--surrogate", "s", "--reference", "r", "--scenario", "dip"], "interrupted"),
])
def test_an_interrupt_offers_a_rerun_only_where_a_rerun_resumes(argv, expected):
    assert interrupted_message(build_parser().parse_args(argv)) == expected


def interrupted_run(out, argv):
    """(exit code, stderr) of `opfmu argv` sent Ctrl-C (SIGINT to its process group, as a terminal
    does) once a first solved chunk appears under `out`; at most 300 s for that, 120 s to stop."""
    process = opfmu_process(argv)
    deadline = time.monotonic() + 300
    while process.poll() is None and time.monotonic() < deadline and not any(out.glob("**/.partial/*-0*.npz")):
        time.sleep(0.05)
    assert process.poll() is None, process.stderr.read()
    return interrupt_and_wait(process, 120)


def test_ctrl_c_while_dask_workers_solve_is_one_line_and_keeps_the_finished_chunks(tmp_path):
    spec = preset_file(tmp_path / "p.json", tiny("paper", counts={"train": 4000, "collocation": 4, "val": 3,
                                                                   "test": 3}, chunk_size=2))
    code, err = interrupted_run(tmp_path / "d", ["data", "--preset", spec, "--out", tmp_path / "d",
                                                 "--workers", "2", "--quiet"])
    assert code == 130 and err.strip().splitlines() == ["interrupted: rerun the same command to resume"], err
    assert list((tmp_path / "d" / ".partial").glob("train-*.npz"))  # what the rerun resumes from


def test_operator_into_a_folder_holding_another_dataset_or_run_is_refused_before_any_work(files, capsys):
    out = files / "run"
    (out / "data").mkdir(parents=True)
    (out / "data" / "metadata.json").write_text(json.dumps({"fingerprint": "another"}))
    argv = ["operator", "--machine", files / "machine.json", "--out", out]
    assert "holds the dataset of another machine, recipe or seed" in refusal(capsys, *argv)
    (out / "data" / "metadata.json").unlink()
    (out / "run").mkdir()
    (out / "run" / "checkpoint.pt").write_bytes(b"")
    (out / "run" / "config.json").write_text("[]")
    assert "run/config.json is not a JSON object" in refusal(capsys, *argv)
    (out / "run" / "config.json").write_text(json.dumps({"train": {"lr": 1.0}, "data": {}}))
    assert "holds a training run with other settings" in refusal(capsys, *argv)
    assert sorted(p.name for p in (out / "run").iterdir()) == ["checkpoint.pt", "config.json"]


def test_a_scheduler_that_is_not_an_address_is_one_line(tmp_path, capsys):
    spec = preset_file(tmp_path / "p.json", tiny("paper"))
    line = refusal(capsys, "data", "--preset", spec, "--out", tmp_path / "d", "--scheduler", "no address")
    assert line.startswith("error: --scheduler 'no address'")
    line = refusal(capsys, "data", "--preset", spec, "--out", tmp_path / "d", "--scheduler", "http://localhost:1")
    assert "a dask scheduler address is tcp://HOST:PORT" in line
    assert not (tmp_path / "d").exists()


def test_more_data_workers_than_cores_is_one_line(tmp_path, capsys):
    spec = preset_file(tmp_path / "p.json", tiny("paper"))
    line = refusal(capsys, "data", "--preset", spec, "--out", tmp_path / "d", "--workers", "100000")
    assert line.startswith("error: --workers must lie in [0, ")


def damaged_copy(source, target, damage):
    import shutil

    shutil.copytree(source, target)
    damage(target)
    return target


@pytest.mark.parametrize("damage, expected", [
    (lambda d: (d / "train.npz").write_bytes(b"not an archive"), "train.npz is not a readable split"),
    (lambda d: __import__("numpy").savez(d / "train.npz", y=[1.0]), "train.npz lacks the arrays x0, u, t, x"),
    (lambda d: (d / "metadata.json").write_text(json.dumps({**json.loads((d / "metadata.json").read_text()),
                                                            "horizon_s": "1 s"})), "horizon_s must be a number > 0"),
    (lambda d: (d / "metadata.json").write_text(json.dumps({**json.loads((d / "metadata.json").read_text()),
                                                            "envelope": "all"})), "envelope must be"),
])
def test_a_damaged_dataset_names_the_file_and_what_it_lacks(tmp_path, capsys, paper_tiny, damage, expected):
    data = damaged_copy(paper_tiny[1], tmp_path / "ds", damage)
    assert expected in refusal(capsys, "train", "--data", data, "--out", tmp_path / "run", "--epochs", "1", "--quiet")


@pytest.fixture(scope="module")
def trained_run(tmp_path_factory, paper_tiny):
    out = tmp_path_factory.mktemp("trained") / "run"
    assert main(["train", "--data", str(paper_tiny[1]), "--out", str(out), "--epochs", "2", "--quiet"]) == 0
    return out


def test_a_damaged_checkpoint_or_model_file_is_named(tmp_path, capsys, paper_tiny, trained_run):
    run = damaged_copy(trained_run, tmp_path / "run", lambda d: (d / "checkpoint.pt").write_bytes(b"x"))
    line = refusal(capsys, "train", "--data", paper_tiny[1], "--out", run, "--epochs", "3", "--quiet")
    assert f"{run / 'checkpoint.pt'} is not a readable checkpoint" in line
    (run / "model.pt").write_bytes(b"x")
    for argv in (["evaluate", run, "--data", paper_tiny[1], "--out", tmp_path / "e"],
                 ["export", run, "-o", tmp_path / "x.onnx"]):
        assert f"{run / 'model.pt'} is not a readable model file" in refusal(capsys, *argv)


@pytest.mark.parametrize("config, expected", [
    ("[1]", "must be a JSON object, got a list"),
    ('{"train": {}, "data": []}', "must hold the objects train and data"),
])
def test_export_of_a_run_whose_config_is_not_what_train_writes_is_refused(tmp_path, capsys, trained_run, config,
                                                                           expected):
    run = damaged_copy(trained_run, tmp_path / "run", lambda d: (d / "config.json").write_text(config))
    assert expected in refusal(capsys, "export", run, "-o", tmp_path / "x.onnx")
    assert not (tmp_path / "x.onnx").exists()


@pytest.fixture
def look_alike_fmus(tmp_path):
    """Two zip files with the entries `compare` looks for first: enough for what it refuses before opening them."""
    import zipfile

    paths = []
    for name in ("S.fmu", "R.fmu"):
        with zipfile.ZipFile(tmp_path / name, "w") as archive:
            archive.writestr("modelDescription.xml", "<fmiModelDescription/>")
            archive.writestr("resources/model.onnx", b"")
        paths.append(tmp_path / name)
    return paths


@pytest.mark.parametrize("extra, expected", [
    (["--scenario", "dip", "--step", "0"], "--step must be a finite number of seconds > 0, got 0"),
    (["--scenario", "dip", "--stop-time", "nan"], "--stop-time must be a finite number of seconds > 0, got nan"),
    (["--scenario", "dip", "--stop-time", "1e12"], "is 1e+14 communication points, more than 1e+07"),
    (["--scenario", "dip", "--seed", "-1"], "--seed must lie in"),
    (["--inputs", "no_such.csv"], "no inputs file at no_such.csv"),
    (["--scenario", "dip", "--param", "rollover_horizon"], "--param needs NAME=NUMBER"),
])
def test_compare_refuses_what_it_cannot_run_before_opening_the_fmus(tmp_path, capsys, look_alike_fmus, extra,
                                                                    expected):
    surrogate, reference = look_alike_fmus
    out = tmp_path / "comparison"
    assert expected in refusal(capsys, "compare", "--surrogate", surrogate, "--reference", reference, "--out", out,
                               *extra)
    assert not out.exists()


def test_compare_names_an_fmu_that_carries_no_operator(tmp_path, capsys, look_alike_fmus):
    import zipfile

    with zipfile.ZipFile(tmp_path / "plain.fmu", "w") as archive:
        archive.writestr("modelDescription.xml", "<fmiModelDescription/>")
    line = refusal(capsys, "compare", "--surrogate", tmp_path / "plain.fmu", "--reference", look_alike_fmus[1],
                   "--scenario", "dip")
    assert line == f"error: {tmp_path / 'plain.fmu'} is not a surrogate FMU of opfmu (it has no resources/model.onnx)"



def test_a_machine_file_that_is_a_folder_is_refused_as_a_folder_without_an_error_code(capsys, files):
    line = refusal(capsys, "operator", "--machine", files / "a_folder", "--out", files / "out")
    assert line == f"error: machine file {files / 'a_folder'} is a folder, not a file"
    assert not (files / "out").exists()


def test_an_operator_path_that_is_a_folder_is_refused_as_a_folder_without_an_error_code(files):
    from opfmu.compare import CompareError, operator_machine

    with pytest.raises(CompareError) as refused:
        operator_machine(files / "a_folder")
    assert str(refused.value) == f"operator file {files / 'a_folder'} is a folder, not a file"


def test_compare_refuses_an_fmu_that_cannot_be_unpacked_in_one_line(tmp_path, capsys):
    import zipfile

    crafted = tmp_path / "crafted.fmu"
    with zipfile.ZipFile(crafted, "w") as archive:  # a file where unpacking needs a folder
        archive.writestr("modelDescription.xml", "<fmiModelDescription/>")
        archive.writestr("resources/model.onnx", "a")
        archive.writestr("resources/model.onnx/a", "b")
    line = refusal(capsys, "compare", "--surrogate", crafted, "--reference", crafted, "--scenario", "dip",
                   "--out", tmp_path / "out")
    assert line.startswith(f"error: {crafted} cannot be unpacked as an FMU: ")
    assert "opfmu_compare_" not in line and not (tmp_path / "out").exists()
