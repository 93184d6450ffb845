"""A checkpoint carries the guidance its task was tuned with (`guidance.json`): the recommended preset takes it
for every option the user did not give, evaluation and `run` record what ran, and a bad file fails with its path."""

from __future__ import annotations

import json
import shutil
from dataclasses import asdict

import pytest
from typer.testing import CliRunner

from lano3dp.errors import CorruptFileError
from lano3dp.evaluate import EvalConfig, RunConfig, runtime_config, tuned_config
from lano3dp.guidance import GUIDANCE_PRESETS, GuidanceSettings, load_guidance_tuning, save_guidance_tuning
from lano3dp.pipeline import cached_eval
from test_stages import tiny_checkpoint  # noqa: F401 (a fixture: the policy tuned_checkpoint copies)

TUNING = {"push_turn": 60.0, "rho": 0.02}


@pytest.fixture(scope="module")
def tuned_checkpoint(tiny_checkpoint, tmp_path_factory):  # noqa: F811 (the imported fixture, requested)
    """test_stages' untrained tiny open_drawer policy, in a folder that says it was tuned with TUNING."""
    folder = tmp_path_factory.mktemp("tuned") / "policy"
    shutil.copytree(tiny_checkpoint, folder)
    save_guidance_tuning(folder, TUNING, measured="tests/test_guidance_tuning.py")
    return folder


def test_the_tuning_is_laid_over_every_setting_the_user_did_not_keep():
    settings = GuidanceSettings(rho=0.05, keep=("rho",))
    tuned = settings.tuned_for(TUNING)
    assert (tuned.push_turn, tuned.rho, tuned.densify) == (60.0, 0.05, settings.densify)
    assert tuned.tuned_for(TUNING) == tuned  # once is all it does
    assert GuidanceSettings(tuned=False).tuned_for(TUNING) == GuidanceSettings(tuned=False)
    assert GuidanceSettings(mode="none").tuned_for(TUNING) == GuidanceSettings(mode="none")  # unguided: nothing
    assert GUIDANCE_PRESETS["paper"].tuned_for(TUNING) == GUIDANCE_PRESETS["paper"]  # the paper's form is fixed
    with pytest.raises(ValueError, match="keep names no tunable guidance setting: mode"):
        GuidanceSettings(keep=("mode",))


def test_a_tuning_file_round_trips_and_a_bad_one_names_its_path(tmp_path):
    assert load_guidance_tuning(tmp_path) == {}  # no file: nothing tuned
    path = save_guidance_tuning(tmp_path, TUNING, measured="results/x.md")
    assert load_guidance_tuning(tmp_path) == TUNING
    assert json.loads(path.read_text())["measured"] == "results/x.md"
    with pytest.raises(ValueError, match="mode cannot be tuned"):
        save_guidance_tuning(tmp_path, {"mode": "none"}, measured="")
    for text, reason in (("{not json", "not a guidance tuning"),
                         (json.dumps({"format": "lano3dp-guidance-tuning", "settings": {"scale": 1}}),
                          "scale cannot be tuned"),
                         (json.dumps({"format": "lano3dp-guidance-tuning", "settings": {"push_turn": 95}}),
                          r"push_turn must be in \[0, 90\)"),
                         (json.dumps({"settings": {}}), "not a lano3dp-guidance-tuning file")):
        path.write_text(text)
        with pytest.raises(CorruptFileError, match=reason) as error:
            load_guidance_tuning(tmp_path)
        assert str(path) in str(error.value)


def test_an_evaluation_runs_and_records_the_tuned_guidance(tuned_checkpoint, tmp_path):
    asked = EvalConfig(checkpoint=str(tuned_checkpoint), task="open_drawer", guidance="clean")
    ran = tuned_config(asked, tuned_checkpoint)
    assert (ran.guidance.push_turn, ran.guidance.rho) == (60.0, 0.02)
    runtime = runtime_config(ran, seed=0)
    assert runtime.push_turn == 60.0 and runtime.guidance.scale == 0.02
    assert tuned_config(EvalConfig(checkpoint=str(tuned_checkpoint)), tuned_checkpoint).guidance.rho == \
        GuidanceSettings().rho  # unguided evaluations are left as asked
    assert tuned_config(RunConfig("open the drawer"), tuned_checkpoint).guidance.push_turn == 60.0


def test_lano3dp_eval_takes_the_tuning_under_the_options_given(tuned_checkpoint, tmp_path):
    from lano3dp.cli import app

    out = tmp_path / "results.json"
    result = CliRunner().invoke(app, ["eval", "--checkpoint", str(tuned_checkpoint), "--task", "open_drawer",
                                      "--guidance", "clean", "--rho", "0.05", "--episodes", "1", "--max-steps", "3",
                                      "--out", str(out)])
    assert result.exit_code == 0, result.output + repr(result.exception)
    assert "as the checkpoint was tuned" in result.output and "rho=0.05" in result.output
    data = json.loads(out.read_text())
    assert (data["config"]["guidance"]["push_turn"], data["config"]["guidance"]["rho"]) == (60.0, 0.05)
    assert data["guidance_tuning"] == {"push_turn": 60.0}  # what the checkpoint chose; rho was the user's
    # the same command again is the same evaluation: its results are reused
    again = EvalConfig(checkpoint=str(tuned_checkpoint), task="open_drawer", episodes=1, max_steps=3, out=str(out),
                       guidance=GuidanceSettings(rho=0.05, keep=("rho",)))
    assert cached_eval(again) is not None
    assert cached_eval(EvalConfig(**{**asdict(again), "guidance": GuidanceSettings(rho=0.05, tuned=False)})) is None

    untuned = tmp_path / "untuned.json"
    result = CliRunner().invoke(app, ["eval", "--checkpoint", str(tuned_checkpoint), "--task", "open_drawer",
                                      "--guidance", "clean", "--no-checkpoint-guidance", "--episodes", "1",
                                      "--max-steps", "3", "--out", str(untuned)])
    assert result.exit_code == 0, result.output + repr(result.exception)
    data = json.loads(untuned.read_text())
    assert data["config"]["guidance"]["push_turn"] == 0.0 and data["guidance_tuning"] == {}


def test_lano3dp_run_says_it_takes_the_tuning_and_records_what_ran(tuned_checkpoint, tmp_path):
    from lano3dp.cli import app

    out = tmp_path / "run"
    result = CliRunner().invoke(app, ["run", "open the drawer", "--checkpoint", str(tuned_checkpoint),
                                      "--max-steps", "2", "--image-size", "32", "--out", str(out)])
    assert result.exit_code == 0, result.output + repr(result.exception)
    assert "guidance: as this policy was tuned: push_turn 60.0, rho 0.02" in result.output
    guidance = json.loads((out / "run.json").read_text())["config"]["guidance"]
    assert (guidance["push_turn"], guidance["rho"]) == (60.0, 0.02)


def test_a_tuned_turn_without_the_anchored_path_is_named_as_doing_nothing(tuned_checkpoint, tmp_path):
    from lano3dp.cli import app

    assert GuidanceSettings(push_turn=30.0).ineffective() == []
    assert GuidanceSettings(mode="none", push_turn=30.0, anchored=False).ineffective() == []
    (note,) = GuidanceSettings(push_turn=30.0, anchored=False).ineffective()
    assert note.startswith("push_turn 30 has no effect without anchored")
    result = CliRunner().invoke(app, ["eval", "--checkpoint", str(tuned_checkpoint), "--task", "open_drawer",
                                      "--guidance", "clean", "--no-anchored", "--episodes", "1", "--max-steps", "2",
                                      "--out", str(tmp_path / "r.json")])
    assert result.exit_code == 0, result.output + repr(result.exception)
    assert "push_turn 60 has no effect without anchored" in " ".join(result.output.split())
