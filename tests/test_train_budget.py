"""`train --minutes M` is a budget the run plans for: the steps follow a timing probe, `--steps` only caps them."""

import json

import pytest
from typer.testing import CliRunner

from lano3dp import train as train_module
from lano3dp.cli import app
from lano3dp.pipeline import train_stage
from lano3dp.train import (
    TRAINING_OVERHEAD,
    TrainConfig,
    default_warmup_steps,
    plan_budget,
    policy_config_for_dataset,
    time_training_step,
)
from test_train import MICRO, write_reach_store


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return write_reach_store(tmp_path_factory.mktemp("budget") / "reach.zarr", episodes=4)


def fixed_probe(seconds_per_step: float, calls: list | None = None):
    """A timing probe standing in for time_training_step: every step costs `seconds_per_step` CPU-s."""

    def probe(data, policy_config, batch_size, **options):
        if calls is not None:
            calls.append(batch_size)
        return seconds_per_step

    return probe


def test_the_planned_steps_are_the_budget_over_the_probed_step_cost(data):
    policy = policy_config_for_dataset(data, **MICRO)
    for seconds, minutes in ((0.1, 2.0), (0.4, 2.0), (0.1, 10.0)):
        plan = plan_budget(data, policy, 8, minutes, probe=fixed_probe(seconds))
        assert plan.steps == plan.budget_steps == int(minutes * 60 / (seconds * TRAINING_OVERHEAD))
        assert (plan.cpu_minutes, plan.probe_cpu_s_per_step, plan.step_cap) == (minutes, seconds, None)
    assert plan_budget(data, policy, 8, 2.0, probe=fixed_probe(0.1)).steps == 1132
    # --steps caps the plan only where the budget buys more
    assert plan_budget(data, policy, 8, 2.0, step_cap=500, probe=fixed_probe(0.1)).steps == 500
    assert plan_budget(data, policy, 8, 2.0, step_cap=5000, probe=fixed_probe(0.1)).steps == 1132
    # a budget too small for the minimum still trains min_steps
    assert plan_budget(data, policy, 8, 0.001, probe=fixed_probe(1.0), min_steps=50).steps == 50
    with pytest.raises(ValueError, match="must be > 0 minutes"):
        plan_budget(data, policy, 8, 0.0, probe=fixed_probe(0.1))


def test_the_probe_times_the_step_of_this_run_on_this_data(data):
    policy = policy_config_for_dataset(data, **MICRO)
    small = time_training_step(data, policy, 2, warmup=1, steps=3)
    # batches far apart: with the micro policy a step is mostly fixed cost, and 2 against 48 came out reversed
    # once on a machine busy with two other jobs
    large = time_training_step(data, policy, 256, warmup=1, steps=3)
    assert 0 < small < large < 5.0  # CPU-s per step, growing with the batch


def test_train_minutes_plans_its_steps_and_records_the_plan(data, tmp_path, monkeypatch):
    """`lano3dp train --minutes`: the steps the budget buys (not the old default 3000), the warm-up and the
    cosine over them, and the budget, the probe's CPU-s/step and the planned steps in train_config.json."""
    calls = []
    monkeypatch.setattr(train_module, "time_training_step", fixed_probe(0.5, calls))
    run = tmp_path / "run"
    options = ["train", "--data", str(data), "--out", str(run), "--batch-size", "4", "--horizon", "8",
               "--n-action-steps", "4", "--val-ratio", "0", "--no-progress", "--threads", "1"]
    result = CliRunner().invoke(app, options + ["--minutes", "0.5"])
    assert result.exit_code == 0, result.output
    planned = int(0.5 * 60 / (0.5 * TRAINING_OVERHEAD))  # 56
    assert f"{planned} steps planned for 0.5 CPU-min (0.500 CPU-s per step probed)" in result.output
    saved = json.loads((run / "train_config.json").read_text())
    assert saved["steps"] == planned and saved["cpu_minutes"] == 0.5
    assert saved["warmup_steps"] == default_warmup_steps(planned) == 10
    assert saved["budget_plan"] == {"cpu_minutes": 0.5, "probe_cpu_s_per_step": 0.5, "overhead": TRAINING_OVERHEAD,
                                    "budget_steps": planned, "step_cap": None, "steps": planned, "threads": 1}
    assert f"step_{planned:07d}" in result.output  # trained to the planned step, its budget not spent
    assert TrainConfig.from_dict(saved).budget_plan.steps == planned
    # the same command again resumes the run it planned: no new probe, no new plan
    again = CliRunner().invoke(app, options + ["--minutes", "0.5"])
    assert again.exit_code == 0, again.output
    assert calls == [4] and json.loads((run / "train_config.json").read_text())["steps"] == planned


def test_train_steps_caps_a_budget_only_when_given(data, tmp_path, monkeypatch):
    monkeypatch.setattr(train_module, "time_training_step", fixed_probe(0.5))
    run = tmp_path / "capped"
    result = CliRunner().invoke(app, ["train", "--data", str(data), "--out", str(run), "--batch-size", "4",
                                      "--horizon", "8", "--n-action-steps", "4", "--val-ratio", "0", "--no-progress",
                                      "--minutes", "0.5", "--steps", "12"])
    assert result.exit_code == 0, result.output
    saved = json.loads((run / "train_config.json").read_text())
    assert saved["steps"] == 12
    assert saved["budget_plan"]["step_cap"] == 12 and saved["budget_plan"]["budget_steps"] == 56


def test_train_stage_plans_the_same_way_and_keeps_its_plan_on_resume(data, tmp_path, monkeypatch):
    monkeypatch.setattr(train_module, "time_training_step", fixed_probe(0.5))
    policy = policy_config_for_dataset(data, **MICRO)
    run = tmp_path / "stage"
    final = train_stage(data, run, policy_config=policy, minutes=0.5, steps=8, batch_size=4, val_ratio=0.0,
                        progress=False)
    saved = json.loads((run / "train_config.json").read_text())
    assert final.name == "step_0000008" and saved["steps"] == 8 and saved["budget_plan"]["budget_steps"] == 56
    messages = []
    assert train_stage(data, run, policy_config=policy, minutes=0.5, steps=8, log=messages.append) == final
    assert messages == [f"train: {run} is complete (8 steps); skipping"]
    with pytest.raises(ValueError, match="started for 8 steps, not 9"):
        train_stage(data, run, policy_config=policy, minutes=0.5, steps=9)
