"""The command line: user mistakes are one line with exit code 2.

Refusals are checked in this process (opfmu.cli.main, as `python -m opfmu` runs it, without an
interpreter start-up each); the commands that do work run as the shell runs them."""
import subprocess
import sys

import numpy as np

from opfmu.cli import main
from surrogate.data import load_split

from conftest import preset_file, tiny


def opfmu(*args):
    return subprocess.run([sys.executable, "-m", "opfmu", *args], capture_output=True, text=True)


def in_process(capsys, *args):
    """`opfmu ARGS` run by opfmu.cli.main in this process: its exit code and output as subprocess.run
    gives them."""
    capsys.readouterr()
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return subprocess.CompletedProcess(["opfmu", *args], code, out, err)


def assert_one_line_error(result, *words):
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:"), result.stderr
    assert "Traceback" not in result.stderr
    for word in words:
        assert word in lines[0]


def test_unknown_preset_is_a_one_line_error(capsys, tmp_path):
    assert_one_line_error(in_process(capsys, "data", "--preset", "huge", "--out", tmp_path / "x"),
                          "unknown preset 'huge'")
    assert not (tmp_path / "x").exists()


def test_missing_output_directory_is_a_one_line_error(capsys):
    assert_one_line_error(in_process(capsys, "data", "--preset", "quick"), "--out")


def test_unknown_subcommand_is_a_one_line_error(capsys):
    assert_one_line_error(in_process(capsys, "frobnicate"), "invalid choice")


def test_malformed_preset_file_is_a_one_line_error(capsys, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    assert_one_line_error(in_process(capsys, "data", "--preset", bad, "--out", tmp_path / "d"), "not a valid preset")


def test_negative_worker_count_is_a_one_line_error(capsys, tmp_path):
    assert_one_line_error(in_process(capsys, "data", "--workers", "-1", "--out", tmp_path), "--workers")


def test_data_command_writes_the_splits_a_preview_and_a_summary(tmp_path):
    spec = preset_file(tmp_path / "p.json", tiny("paper"))
    result = opfmu("data", "--preset", str(spec), "--out", str(tmp_path / "d"), "--workers", "0", "--quiet")
    assert result.returncode == 0, result.stderr
    assert "dataset written to" in result.stdout and "delta" in result.stdout
    assert (tmp_path / "d" / "preview.png").stat().st_size > 10_000
    assert load_split(tmp_path / "d", "test")["x"].shape == (3, 1001, 4)
    assert np.isfinite(load_split(tmp_path / "d", "train")["x"]).all()


def test_a_preset_file_with_an_unknown_family_or_bad_counts_is_a_one_line_error(capsys, tmp_path):
    for name, changes in (("family", {"families": [["nope", 1.0]]}), ("counts", {"counts": {"train": -1}})):
        spec = tmp_path / f"{name}.json"
        spec.write_text(__import__("json").dumps({**tiny("paper").to_dict(), **changes}))
        assert_one_line_error(in_process(capsys, "data", "--preset", spec, "--out", tmp_path / name),
                              "not a valid preset")


def test_progress_off_a_terminal_is_plain_lines_not_bar_redraws(tmp_path):
    spec = preset_file(tmp_path / "p.json", tiny("paper"))
    result = opfmu("data", "--preset", str(spec), "--out", str(tmp_path / "d"), "--workers", "0")
    assert result.returncode == 0, result.stderr
    assert "\r" not in result.stderr
    assert "sampling train: 8/8 window (100%" in result.stderr  # before the solves: a case family runs grids
    assert "solving train: 8/8 traj (100%" in result.stderr


def test_line_progress_prints_at_most_one_line_per_interval_and_one_at_the_end():
    import io

    from reference_models.progress import LineProgress, progress_bar

    stream = io.StringIO()
    assert isinstance(progress_bar(1000, "work", "item", stream=stream), LineProgress)
    bar = LineProgress(1000, "work", "item", stream=stream, every=3600.0)
    for _ in range(1000):
        bar.update(1)
    bar.close()
    assert stream.getvalue().count("\n") == 1 and "work: 1000/1000 item (100%" in stream.getvalue()


def test_progress_that_is_off_shows_nothing_and_needs_no_tqdm():
    import io

    from reference_models.progress import progress_bar

    stream = io.StringIO()
    bar = progress_bar(10, "work", "item", enabled=False, stream=stream)
    bar.update(10)
    bar.set_postfix(loss=1.0)
    bar.close()
    assert stream.getvalue() == ""
    result = subprocess.run([sys.executable, "-c", "import sys; from reference_models.progress import progress_bar; "
                             "progress_bar(3, 'w', 'i').close(); print('tqdm' in sys.modules)"],
                            capture_output=True, text=True)
    assert result.stdout.strip() == "False" and result.stderr.startswith("w: 0/3 i (0%")
