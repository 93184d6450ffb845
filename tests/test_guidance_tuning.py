"""A checkpoint carries the guidance its task was tuned with (`guidance.json`: a preset plus overrides): the "tuned"
preset is that, the user's `--set` goes on top, evaluation and `run` record what ran, and a bad file fails with its
path."""

from __future__ import annotations

import json
import shutil

import pytest
from typer.testing import CliRunner

from lano3dp.errors import CorruptFileError
from lano3dp.evaluation import EvalConfig, GuidanceChoice
from lano3dp.guidance.settings import guidance_preset, load_guidance_tuning, save_guidance_tuning
from lano3dp.pipeline import cached_eval
from test_stages import tiny_checkpoint  # noqa: F401 (a fixture: the policy tuned_checkpoint copies)

TUNING = {"cost.push_turn": 60.0, "sampler.rho": 0.02}


@pytest.fixture(scope="module")
def tuned_checkpoint(tiny_checkpoint, tmp_path_factory):  # noqa: F811 (the imported fixture, requested)
    """test_stages' untrained tiny open_drawer policy, in a folder that says it was tuned with TUNING."""
    folder = tmp_path_factory.mktemp("tuned") / "policy"
    shutil.copytree(tiny_checkpoint, folder)
    save_guidance_tuning(folder, TUNING, measured="tests/test_guidance_tuning.py")
    return folder


def test_a_tuning_file_round_trips_and_a_bad_one_names_its_path(tmp_path):
    assert load_guidance_tuning(tmp_path) is None  # no file: nothing tuned
    path = save_guidance_tuning(tmp_path, TUNING, measured="results/x.md")
    tuning = load_guidance_tuning(tmp_path)
    assert (tuning.preset, tuning.overrides, tuning.measured) == ("recommended", TUNING, "results/x.md")
    assert tuning.settings() == guidance_preset("recommended").with_changes(TUNING)
    with pytest.raises(ValueError, match="no such setting"):
        save_guidance_tuning(tmp_path, {"sampler.scale": 1}, measured="")
    good = json.loads(path.read_text())
    for text, reason in (("{not json", "not a guidance tuning"),
                         (json.dumps({**good, "overrides": {"cost.push_turn": 95}}), r"push_turn must be in \[0, 90\)"),
                         (json.dumps({**good, "preset": "fast"}), "unknown guidance preset 'fast'"),
                         (json.dumps({**good, "format": "x"}), "not a lano3dp-guidance-tuning file")):
        path.write_text(text)
        with pytest.raises(CorruptFileError, match=reason) as error:
            load_guidance_tuning(tmp_path)
        assert str(path) in str(error.value)


def test_lano3dp_eval_runs_the_tuning_under_the_users_changes_and_records_it(tuned_checkpoint, tmp_path):
    from lano3dp.cli import app

    out = tmp_path / "results.json"
    result = CliRunner().invoke(app, ["eval", "--checkpoint", str(tuned_checkpoint), "--task", "open_drawer",
                                      "--guidance-preset", "tuned", "--set", "guidance.sampler.rho=0.05",
                                      "--episodes", "1", "--max-steps", "3", "--out", str(out)])
    assert result.exit_code == 0, result.output + repr(result.exception)
    data = json.loads(out.read_text())
    assert data["config"]["guidance"] == {"preset": "tuned", "overrides": {"sampler.rho": 0.05}}
    assert (data["guidance"]["cost"]["push_turn"], data["guidance"]["sampler"]["rho"]) == (60.0, 0.05)
    # the same evaluation, however its guidance is named, is reused; another guidance is not
    again = EvalConfig(checkpoint=str(tuned_checkpoint), task="open_drawer", episodes=1, max_steps=3, out=str(out),
                       guidance=GuidanceChoice("recommended", {"cost.push_turn": 60.0, "sampler.rho": 0.05}))
    assert cached_eval(again) is not None
    assert cached_eval(again.replace(guidance=GuidanceChoice("recommended", {"sampler.rho": 0.05}))) is None

    untuned = tmp_path / "untuned.json"
    result = CliRunner().invoke(app, ["eval", "--checkpoint", str(tuned_checkpoint), "--task", "open_drawer",
                                      "--guidance-preset", "recommended", "--episodes", "1", "--max-steps", "3",
                                      "--out", str(untuned)])
    assert result.exit_code == 0, result.output + repr(result.exception)
    assert json.loads(untuned.read_text())["guidance"]["cost"]["push_turn"] == 0.0


def test_lano3dp_run_says_it_takes_the_tuning_and_records_what_ran(tuned_checkpoint, tmp_path):
    from lano3dp.cli import app

    out = tmp_path / "run"
    result = CliRunner().invoke(app, ["run", "open the drawer", "--checkpoint", str(tuned_checkpoint),
                                      "--max-steps", "2", "--set", "perception.image_size=32", "--out", str(out)])
    assert result.exit_code == 0, result.output + repr(result.exception)
    assert "guidance: as this policy was tuned (cost.push_turn 60.0, sampler.rho 0.02)" in result.output
    guidance = json.loads((out / "run.json").read_text())["guidance"]
    assert (guidance["cost"]["push_turn"], guidance["sampler"]["rho"]) == (60.0, 0.02)


def test_a_tuned_turn_without_the_anchored_path_is_refused_naming_both(tuned_checkpoint, tmp_path):
    from lano3dp.cli import app

    result = CliRunner().invoke(app, ["eval", "--checkpoint", str(tuned_checkpoint), "--task", "open_drawer",
                                      "--guidance-preset", "tuned", "--set", "guidance.cost.anchored=false",
                                      "--episodes", "1", "--max-steps", "2", "--out", str(tmp_path / "r.json")])
    assert result.exit_code == 1 and "cost.push_turn 60" in result.output and "cost.anchored" in result.output
    assert not (tmp_path / "r.json").exists()
