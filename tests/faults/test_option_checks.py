"""Options are checked against what the rest of the pipeline needs before any work starts, and a bad one is one
line naming the option or file and what to do (never a traceback without --debug, never blame on the wrong thing).
"""

from __future__ import annotations

from pathlib import Path

import torch
from typer.testing import CliRunner

from faults_common import assert_one_line, error_lines, tree_digest
from lano3dp.cli import app
from lano3dp.data import EpisodeStore
from lano3dp.evaluation import PolicyTaskMismatchError


def _bad_invocations(tmp: Path, checkpoint: Path, data: Path) -> list[tuple[list[str], int, str]]:
    a_file = tmp / "a_file"
    a_file.write_text("x")
    corrupt = tmp / "corrupt"
    corrupt.mkdir()
    (corrupt / "config.json").write_text("{not json")
    (corrupt / "model.safetensors").write_bytes((checkpoint / "model.safetensors").read_bytes())
    cuda = [] if torch.cuda.is_available() else [(["train", "--data", str(data), "--out", str(tmp / "r"),
                                                    "--device", "cuda"], 2, "CUDA is not available")]
    return [
        (["collect", "--task", "open_drawer", "--episodes", "-3", "--out", str(tmp / "c.zarr")], 2, "--episodes"),
        (["collect", "--task", "open_drawer", "--n-points", "0", "--out", str(tmp / "c.zarr")], 2, "--n-points"),
        (["collect", "--task", "no_such_task", "--out", str(tmp / "c.zarr")], 2, "unknown task 'no_such_task'"),
        (["collect", "--task", "open_drawer", "--variation", "bogus", "--out", str(tmp / "c.zarr")], 2, "bogus"),
        (["collect", "--task", "open_drawer", "--out", str(a_file / "c.zarr")], 2, "a_file is a file"),
        (["video", "--task", "open_drawer", "--out", str(tmp / "v.txt")], 2, "must end in .mp4 or .gif"),
        (["train", "--data", str(tmp / "missing.zarr"), "--out", str(tmp / "r")], 2, "missing.zarr does not exist"),
        (["train", "--data", str(data), "--out", str(a_file / "run")], 2, "a_file is a file"),
        (["train", "--data", str(checkpoint), "--out", str(tmp / "r2")], 1, "policy: unreadable dataset"),
        *cuda,
        (["eval", "--checkpoint", str(checkpoint), "--guidance-preset", "bogus"], 2,
         "unknown guidance preset 'bogus'; presets: recommended, none, a_k, paper"),
        (["eval", "--checkpoint", str(checkpoint), "--set", "guidance.sampler.mode=bogus"], 2,
         "mode must be one of none, noisy, clean"),
        (["eval", "--checkpoint", str(checkpoint), "--task", "nope"], 2, "unknown task 'nope'"),
        (["eval", "--checkpoint", str(checkpoint), "--out", str(a_file / "r.json")], 2, "a_file is a file"),
        (["eval", "--checkpoint", str(corrupt), "--task", "open_drawer", "--out", str(tmp / "r.json")], 1,
         "corrupt/manifest.json: missing"),  # an unsealed folder is refused before any of its files is read
        (["eval", "--checkpoint", str(data), "--task", "open_drawer", "--out", str(tmp / "r.json")], 1,
         "no policy checkpoint in"),
        (["eval", "--checkpoint", str(checkpoint), "--task", "close_microwave", "--out", str(tmp / "r.json")], 1,
         "trained for skill 'open_drawer'"),
        (["run", "open the drawer", "--guidance-preset", "bogus"], 2, "unknown guidance preset 'bogus'"),
        (["run", "open the drawer", "--out", str(a_file)], 2, "is a file; give a folder"),
        (["demo", "--task", "nope", "--out", str(tmp / "demo")], 2, "unknown task 'nope'"),
        (["demo", "--guidance-preset", "fast", "--out", str(tmp / "demo")], 2, "unknown guidance preset 'fast'"),
        (["guidance-figures", "--analytic", "--obstacle", "0", "0", "0.1", "--out", str(tmp / "g"), "--scheduler",
          "bogus"], 2, "'bogus' is not one of ddpm, ddim"),
        (["plan", "open the drawer", "--registry", str(tmp / "missing.json")], 1, "missing.json"),
        (["checkpoint", "seal", str(tmp / "nowhere")], 1, "no policy checkpoint in"),
    ]


def test_every_command_reports_bad_options_in_one_line_with_its_exit_code(tiny_checkpoint, reach_data, tmp_path):
    runner = CliRunner()
    for args, code, text in _bad_invocations(tmp_path, tiny_checkpoint, reach_data):
        result = runner.invoke(app, args)
        errors = error_lines(result)
        assert result.exit_code == code, (args, result.output, result.exception)
        assert len(errors) == 1 and text in errors[0], (args, result.stderr)
        assert "Traceback" not in result.output, args
    assert not (tmp_path / "c.zarr").exists() and not (tmp_path / "r.json").exists()  # refused before any work


def test_debug_shows_the_traceback_of_a_user_error(tiny_checkpoint, tmp_path):
    result = CliRunner().invoke(app, ["--debug", "eval", "--checkpoint", str(tiny_checkpoint), "--task",
                                      "close_microwave", "--out", str(tmp_path / "r.json")])
    assert result.exit_code == 1 and isinstance(result.exception, PolicyTaskMismatchError)


def test_an_image_too_small_for_the_objects_is_named_before_any_episode_not_blamed_on_the_expert(tmp_path):
    """--image-size 16 passed validation, and collect then reported ten failed expert seeds."""
    out = tmp_path / "d.zarr"
    result = CliRunner().invoke(app, ["collect", "--task", "put_item_in_drawer", "--episodes", "2", "--image-size",
                                      "16", "--no-progress", "--out", str(out)])
    assert_one_line(result, 1, "--image-size 16 is too small for put_item_in_drawer: the camera sees",
                    "in the first frame of seed 0, and each object needs 10; use a larger --image-size (default 128)")
    assert "expert" not in error_lines(result)[0]
    assert list(tmp_path.iterdir()) == []


def test_a_garbage_registry_names_the_file(tmp_path):
    """It said only "Expecting value: line 1 column 1"."""
    cases = {"empty.json": ("", "the file is empty"),
             "garbage.json": ("garbage", "JSONDecodeError: Expecting value: line 1 column 1"),
             "wrong.json": ('[{"name": 3}]', "name: Input should be a valid string (and 3 more)")}
    for name, (text, reason) in cases.items():
        (tmp_path / name).write_text(text)
        for command in (["plan", "open the drawer"], ["run", "open the drawer", "--out", str(tmp_path / "run")]):
            result = CliRunner().invoke(app, [*command, "--registry", str(tmp_path / name)])
            assert_one_line(result, 1, f"{tmp_path / name}: not a skill registry ({reason}")
    assert not (tmp_path / "run").exists()  # refused before anything is written


def test_outputs_are_never_nested_in_another_dataset_or_run_and_never_of_another_kind(reach_data, tmp_path):
    """collect --out inside another dataset's folder created a store nested in it."""
    dataset = tmp_path / "d.zarr"
    EpisodeStore.create(dataset, {"skill": "s"})
    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    (run / "train_config.json").write_text("{}")
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "todo.txt").write_text("buy milk")
    before = tree_digest(tmp_path)
    collect = ["collect", "--task", "open_drawer", "--episodes", "1", "--out"]
    train = ["train", "--data", str(reach_data), "--out"]
    for args, text in [
        ([*collect, str(dataset / "inner.zarr")], f"is inside the dataset {dataset}; give a folder outside it"),
        ([*collect, str(run / "demos.zarr")], f"is inside the training run {run}; give a folder outside it"),
        ([*collect, str(run)], f"{run} is a training run, not a dataset; give a new folder"),
        ([*collect, str(tmp_path / "notes")], "notes is a folder of other files, not a dataset"),
        ([*train, str(dataset / "run")], f"is inside the dataset {dataset}; give a folder outside it"),
        ([*train, str(dataset)], f"{dataset} is a dataset, not a training run"),
    ]:
        assert_one_line(CliRunner().invoke(app, args), 2, text)
    assert tree_digest(tmp_path) == before
