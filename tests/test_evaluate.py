"""Aggregation, reporting and resumability of evaluations (no simulator, no policy)."""

from __future__ import annotations

import json
from dataclasses import asdict, replace

import numpy as np
import pytest

from lano3dp.evaluate import EvalConfig, runtime_config, summarize
from lano3dp.guidance import GUIDANCE_PRESETS, GuidanceSettings, ObstacleSettings
from lano3dp.jsonio import write_json
from lano3dp.pipeline import cached_eval, eval_stage
from lano3dp.report import markdown_table, plot_rates, plot_top_view, wilson_interval


def episode(success: bool, collided: bool, clearance: float | None, path: float, latencies, error=None) -> dict:
    return {"success": success, "collided": collided, "n_collision_steps": 3 * int(collided),
            "min_clearance": clearance, "path_length": path,
            "steps": 100, "chunk_latency_s": list(latencies), "chunk_tries": [1] * len(latencies), "error": error}


def test_summary_rates_and_means():
    episodes = [
        episode(True, False, 0.05, 1.0, [0.1, 0.1]),
        episode(True, True, -0.01, 1.2, [0.2]),
        episode(False, False, None, 0.8, [0.3], error="ObjectNotFoundError: object 'pan' was not found"),
        episode(False, True, 0.0, 1.0, []),
    ]
    for record, obstacles in zip(episodes, ([{"shape": "Cylinder"}], [{"shape": "Cylinder"}], [], []), strict=True):
        record["obstacles"] = obstacles
    summary = summarize(episodes)
    assert summary["episodes"] == 4 and summary["successes"] == 2
    assert summary["episodes_with_obstacles"] == 2  # a layout with no room for one is not hidden
    assert summary["success_rate"] == 0.5
    assert summary["collision_rate"] == 0.5
    assert summary["mean_collision_steps"] == pytest.approx(1.5)  # 3 steps in each of 2 colliding episodes
    assert summary["safe_success_rate"] == 0.25  # only the first one succeeded without touching
    assert summary["error_rate"] == 0.25 and summary["errors"] == ["ObjectNotFoundError"]
    # clearance is averaged over the episodes that measured one (3 of 4)
    assert summary["mean_min_clearance"] == pytest.approx((0.05 - 0.01 + 0.0) / 3, abs=1e-5)
    assert summary["worst_min_clearance"] == -0.01
    assert summary["mean_path_length"] == pytest.approx(1.0)
    assert summary["chunks"] == 4 and summary["latency_mean_s"] == pytest.approx(0.175)


def test_wilson_interval():
    low, high = wilson_interval(0, 10)
    assert low == 0.0 and high == pytest.approx(0.2775, abs=1e-3)
    low, high = wilson_interval(10, 10)
    assert high == 1.0 and low == pytest.approx(0.7225, abs=1e-3)
    low, high = wilson_interval(5, 10)
    assert low == pytest.approx(0.2366, abs=1e-3) and high == pytest.approx(0.7634, abs=1e-3)
    assert wilson_interval(0, 0) == (None, None)


def test_markdown_table():
    table = markdown_table(["a", "b"], [[1, None], [0.12345, "x|y"]])
    assert table.splitlines() == ["| a | b |", "|---|---|", "| 1 | – |", "| 0.123 | x\\|y |"]


def test_eval_config_to_guidance_and_runtime():
    assert runtime_config(EvalConfig(checkpoint="c"), seed=0).guidance is None
    config = EvalConfig(checkpoint="c", guidance=GuidanceSettings(rho=0.02, last_steps=100, checked=True,
                                                                  guided_clip_range=3.0, push_weight="alpha_bar"),
                        obstacle=ObstacleSettings(margin=0.03))
    runtime = runtime_config(config, seed=7)
    guidance = runtime.guidance
    assert guidance.mode == "clean" and guidance.scale == 0.02 and guidance.last_steps == 100
    assert guidance.guided_clip_range == 3.0 and guidance.push_weight == "alpha_bar"
    assert runtime.seed == 7 and runtime.metric_gradient and runtime.densify == 4 and runtime.checked is not None
    assert runtime.obstacle.margin == 0.03 and runtime.guided
    with pytest.raises(ValueError, match="guidance"):
        EvalConfig(checkpoint="c", guidance="sometimes")


def test_eval_stage_reuses_results_made_with_the_same_config(tmp_path):
    out = tmp_path / "eval.json"
    config = EvalConfig(checkpoint=str(tmp_path / "no_such_checkpoint"), episodes=3, out=str(out))
    write_json(out, {"config": asdict(config), "summary": {"success_rate": 0.5}})
    assert eval_stage(config)["summary"]["success_rate"] == 0.5  # not re-run (the checkpoint does not exist)
    more_workers = EvalConfig(checkpoint=config.checkpoint, episodes=3, workers=2, out=str(out))
    assert eval_stage(more_workers)["summary"]["success_rate"] == 0.5  # seeded episodes: same results
    changed = EvalConfig(checkpoint=config.checkpoint, episodes=4, out=str(out))
    with pytest.raises(FileNotFoundError, match="no policy checkpoint"):
        eval_stage(changed)  # a different config is evaluated anew


# A results config as saved before the settings were nested (bench/out work folders hold such files).
FLAT_SAVED = {"checkpoint": "run", "task": "bowl_pour", "variation": "obstacle", "episodes": 3, "seed": 1_000_000,
              "obstacles": None, "guidance": "clean", "rho": 4.0, "last_steps": 10, "per_train_step": False,
              "metric_gradient": False, "densify": 1, "scheduler": "ddpm", "steps": 100, "checked": False,
              "margin": 0.02, "held_radius": None, "n_action_steps": None, "max_steps": None, "image_size": None,
              "workers": 2, "video_dir": None, "n_videos": 2, "out": None, "segmenter": "sim",
              "detector": "grounding_dino", "detector_dir": None, "sam_dir": None, "env": None,
              "obstacle_scenes_only": True, "refit_obstacles": False, "guide_when_needed": False,
              "obstacle_shape": "cylinder"}  # no "body": saved before it existed, when guidance kept a sphere clear


def test_results_saved_flat_before_the_settings_were_nested_are_read_into_them(tmp_path):
    out = tmp_path / "paper.json"
    saved = {"config": {**FLAT_SAVED, "out": str(out)}, "summary": {"success_rate": 0.25}}
    write_json(out, saved)
    paper = EvalConfig(checkpoint="run", task="bowl_pour", variation="obstacle", episodes=3,
                       guidance=GUIDANCE_PRESETS["paper"], scheduler="ddpm", steps=100,
                       obstacle=ObstacleSettings(body="sphere"), obstacle_scenes_only=True, out=str(out))
    assert EvalConfig.from_dict(saved["config"]) == replace(paper, workers=2)
    assert cached_eval(paper) == saved  # the same evaluation: reused
    for changed in (replace(paper, guidance=replace(paper.guidance, rho=2.0)),
                    replace(paper, obstacle=ObstacleSettings(body="swept")),  # today's default, not what was saved
                    replace(paper, guidance=replace(paper.guidance, push_weight="alpha_bar"))):
        assert cached_eval(changed) is None  # stale for another evaluation: it is run anew
    write_json(out, {**saved, "config": {**saved["config"], "guidance": 7, "obstacle": "x"}})
    assert cached_eval(paper) is None  # a saved config no EvalConfig could have written is not reused either


def test_guided_results_saved_before_the_anchored_path_and_the_repair_are_not_taken_for_todays(tmp_path):
    out = tmp_path / "guided.json"
    today = EvalConfig(checkpoint="run", task="bowl_pour", variation="obstacle", episodes=3,
                       guidance=GUIDANCE_PRESETS["recommended"], out=str(out))
    before = json.loads(json.dumps(asdict(today)))
    for name in ("anchored", "repair_steps"):
        before["guidance"].pop(name)  # saved before the fields existed
    write_json(out, {"config": before, "summary": {"success_rate": 0.5}})
    read = EvalConfig.from_dict(before)
    assert (read.guidance.anchored, read.guidance.repair_steps) == (False, 0)  # what that code ran
    assert cached_eval(today) is None  # so today's default is evaluated anew
    assert cached_eval(replace(today, guidance=replace(today.guidance, anchored=False, repair_steps=0))) is not None


def test_results_saved_before_the_cut_to_the_clear_start_are_not_taken_for_todays(tmp_path):
    out = tmp_path / "guided.json"
    today = EvalConfig(checkpoint="run", task="bowl_pour", variation="obstacle", episodes=3,
                       guidance=GUIDANCE_PRESETS["recommended"], out=str(out))
    before = json.loads(json.dumps(asdict(today)))
    before["guidance"].pop("hold_unclear")  # results/obstacles_anchored*.json were saved so
    write_json(out, {"config": before, "summary": {"success_rate": 0.5}})
    assert EvalConfig.from_dict(before).guidance.hold_unclear is False
    assert cached_eval(today) is None
    assert cached_eval(replace(today, guidance=replace(today.guidance, hold_unclear=False))) is not None


def test_results_saved_before_the_gap_walls_and_the_escape_are_read_as_made_without_them(tmp_path):
    out = tmp_path / "two.json"
    today = EvalConfig(checkpoint="run", task="bowl_pour", variation="obstacle:2", episodes=3,
                       guidance=GUIDANCE_PRESETS["recommended"], out=str(out))
    before = json.loads(json.dumps(asdict(today)))
    for name in ("bridge_gaps", "escape_when_inside"):
        before["guidance"].pop(name)  # saved before the fields existed
    write_json(out, {"config": before, "summary": {"success_rate": 0.5}})
    assert cached_eval(today) is None  # what that code ran is not today's default
    without = replace(today, guidance=replace(today.guidance, bridge_gaps=False, escape_when_inside=False))
    assert cached_eval(without) is not None
    # saved while both were obstacle settings: read into the guidance section
    moved = json.loads(json.dumps(asdict(today)))
    moved["obstacle"].update(bridge_gaps=moved["guidance"].pop("bridge_gaps"),
                             escape_when_inside=moved["guidance"].pop("escape_when_inside"))
    write_json(out, {"config": moved, "summary": {"success_rate": 0.5}})
    assert cached_eval(today) is not None


def test_unguided_results_stay_current_when_a_guidance_default_changes(tmp_path):
    out = tmp_path / "clean.json"
    today = EvalConfig(checkpoint="run", task="bowl_pour", episodes=3, out=str(out))  # unguided
    made_then = json.loads(json.dumps(asdict(today)))
    made_then["guidance"]["rho"] = 2 * today.guidance.rho  # made under another default: unguided, nothing read it
    write_json(out, {"config": made_then, "summary": {"success_rate": 0.5}})
    assert cached_eval(today) is not None
    # checked execution escalates from rho even without guidance, so there the setting counts
    checked = replace(today, guidance=replace(today.guidance, checked=True))
    write_json(out, {"config": {**made_then, "guidance": {**made_then["guidance"], "checked": True}},
                     "summary": {"success_rate": 0.5}})
    assert cached_eval(checked) is None


def test_write_json_is_atomic_and_handles_numpy_and_infinity(tmp_path):
    path = write_json(tmp_path / "a" / "r.json", {"x": np.float32(1.5), "y": np.arange(2), "z": float("inf")})
    assert json.loads(path.read_text()) == {"x": 1.5, "y": [0, 1], "z": None}
    assert not list(tmp_path.glob("a/*.tmp"))


def test_plots_are_written(tmp_path):
    path = np.array([[0.3, -0.2, 0.2], [0.4, 0.0, 0.2], [0.5, 0.2, 0.2]])
    obstacle = {"shape": "Cylinder", "center": [0.4, 0.0], "radius": 0.03, "safety_distance": 0.12}
    top = plot_top_view(tmp_path / "top.png", [("run", path)], obstacles=[obstacle], objects={"pan": [0.5, 0.2]})
    rates = plot_rates(tmp_path / "rates.png", [("a", {"success_rate": 0.5, "collision_rate": 0.1,
                                                       "safe_success_rate": 0.4})])
    for png in (top, rates):
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 5000


def test_the_carried_object_comes_from_the_skill_registry():
    from lano3dp.evaluate import carried_slot_word

    assert carried_slot_word("bowl_pour") == "bowl"
    assert carried_slot_word("close_microwave") is None  # the door is pushed: Q* holds the gripper alone
    assert carried_slot_word("a_task_no_registry_knows") is None
