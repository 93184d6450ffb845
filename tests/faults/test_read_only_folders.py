"""Read-only folders: a command that would write into one fails at once, before any work, naming the folder; one
that only reads from one (evaluating a read-only run into results elsewhere) works."""

from __future__ import annotations

import json
import shutil

import pytest
from typer.testing import CliRunner

from faults_common import assert_one_line, read_only
from lano3dp.cli import app
from lano3dp.errors import StorageError
from lano3dp.jsonio import write_json


@pytest.fixture
def a_run(tiny_checkpoint, tmp_path):
    """A training run's layout holding the tiny open_drawer policy as its last checkpoint."""
    run = tmp_path / "run"
    shutil.copytree(tiny_checkpoint, run / "checkpoints" / "step_0000001")
    (run / "checkpoints" / "last").symlink_to("step_0000001")
    (run / "train_config.json").write_text(json.dumps({"steps": 1}))
    return run


def no_work(monkeypatch):
    """Fail the test if evaluation starts: the refusal must come before any episode."""
    import lano3dp.evaluation

    def started(*args, **kwargs):
        raise AssertionError("evaluation started")

    monkeypatch.setattr(lano3dp.evaluation, "evaluate", started)


def test_results_into_a_read_only_run_folder_are_refused_at_once_naming_it(a_run, monkeypatch):
    no_work(monkeypatch)
    out = a_run / "eval.json"
    with read_only(a_run):
        result = CliRunner().invoke(app, ["eval", "--checkpoint", str(a_run), "--task", "open_drawer", "--out",
                                          str(out)])
    line = assert_one_line(result, 2, f"cannot write {out}: {a_run} does not take new files")
    assert "Read-only file system" in line or "Permission denied" in line
    assert not out.exists()


def test_evaluating_a_read_only_run_into_results_elsewhere_works(a_run, tmp_path):
    out = tmp_path / "results" / "r.json"
    with read_only(a_run):
        result = CliRunner().invoke(app, ["eval", "--checkpoint", str(a_run), "--task", "open_drawer", "--episodes",
                                          "1", "--max-steps", "2", "--out", str(out)])
    assert result.exit_code == 0, (result.output, result.exception)
    assert json.loads(out.read_text())["summary"]["episodes"] == 1


def test_resuming_a_read_only_run_is_refused_at_once_naming_the_run(a_run, reach_data):
    """Its parent folder takes files, so checking only the parent let this through to the first write."""
    with read_only(a_run):
        result = CliRunner().invoke(app, ["train", "--data", str(reach_data), "--out", str(a_run)])
    assert_one_line(result, 2, f"cannot write {a_run}: {a_run} does not take new files")


def test_adding_to_a_read_only_dataset_is_refused_at_once(reach_data, tmp_path):
    dataset = tmp_path / "d.zarr"
    shutil.copytree(reach_data, dataset)
    with read_only(dataset):
        result = CliRunner().invoke(app, ["collect", "--task", "open_drawer", "--episodes", "9", "--out",
                                          str(dataset)])
    assert_one_line(result, 2, f"cannot write {dataset}: {dataset} does not take new files")


def test_a_json_writer_in_a_read_only_folder_names_the_file_and_leaves_nothing(tmp_path):
    folder = tmp_path / "results"
    path = write_json(folder / "r.json", {"episodes": 1})
    with read_only(folder):
        with pytest.raises(StorageError, match=rf"cannot write {path}: (Read-only file system|Permission denied)"):
            write_json(path, {"episodes": 2})
    assert json.loads(path.read_text()) == {"episodes": 1} and [p.name for p in folder.iterdir()] == ["r.json"]
