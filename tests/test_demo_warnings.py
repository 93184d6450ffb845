"""The demo's report: its training warnings say what a budget stop means (the learning rate follows the budget),
and its text names the guidance the guided condition ran."""

import json

from lano3dp.cli.demo_cmd import training_warnings
from lano3dp.train import PROGRESS_NAME


def _checkpoint(tmp_path, step, cpu_s):
    checkpoint = tmp_path / f"step_{step:07d}"
    checkpoint.mkdir()
    (checkpoint / PROGRESS_NAME).write_text(json.dumps({"step": step, "cpu_s": cpu_s, "stopped_by_budget": True}))
    return checkpoint


def test_a_budget_stop_names_the_steps_and_that_the_rate_still_decayed(tmp_path):
    config = {"steps": 7200, "policy": {"extra": {"task": "put_item_in_drawer"}}}
    (warning,) = training_warnings(config, _checkpoint(tmp_path, 6936, 600.0))
    assert "step 6936 of 7200 planned" in warning and "10.0 CPU-min" in warning
    assert "decayed to 0" in warning and "did not finish" not in warning


def test_a_short_run_is_called_under_trained_and_a_full_one_gets_no_warning(tmp_path):
    config = {"steps": 3000, "policy": {"extra": {"task": "put_item_in_drawer"}}}
    assert any("under-trained: 3000 steps" in w for w in training_warnings(config, _checkpoint(tmp_path, 3000, 1.0)))
    config = {"steps": 5000, "policy": {"extra": {"task": "put_item_in_drawer"}}}
    assert training_warnings(config, _checkpoint(tmp_path, 5000, 1.0)) == []


def test_the_report_describes_the_guidance_the_demo_ran():
    from lano3dp.cli.demo_cmd import describe_guidance
    from lano3dp.guidance.settings import guidance_preset

    paper = describe_guidance(guidance_preset("paper"))
    assert "normalised action units" in paper and "S = 10" in paper and "on the waypoints" in paper
    assert "chunk filters" not in paper
    recommended = describe_guidance(guidance_preset("recommended"))
    assert "in metres" in recommended and "densified" in recommended and "hand's present position" in recommended
    assert "chunk filters repair, hold, escape, follow" in recommended
