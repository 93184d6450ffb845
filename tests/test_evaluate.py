"""Aggregation, reporting and resumability of evaluations (no simulator, no policy)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lano3dp import provenance
from lano3dp.evaluation import EvalConfig, GuidanceChoice, evaluation_identity, summarize
from lano3dp.evaluation.evaluator import current_identity
from lano3dp.jsonio import write_json
from lano3dp.pipeline import cached_eval
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


def test_success_plot_draws_a_perfect_score(tmp_path):
    # 100 of 100 pooled: the Wilson bound computes a hair under 1.0, which matplotlib's error bars refuse
    from lano3dp.report import plot_success_intervals

    path = tmp_path / "success.png"
    plot_success_intervals(path, {("task", "method"): [(50, 50), (50, 50)]}, title="perfect")
    assert path.stat().st_size > 0


def test_markdown_table():
    table = markdown_table(["a", "b"], [[1, None], [0.12345, "x|y"]])
    assert table.splitlines() == ["| a | b |", "|---|---|", "| 1 | – |", "| 0.123 | x\\|y |"]


def test_an_evaluation_is_named_by_what_changes_its_episodes():
    config = EvalConfig(task="bowl_pour", variation="obstacle", episodes=3, guidance=GuidanceChoice("tuned"))
    guidance = config.guidance.resolve(None)
    identity = evaluation_identity(config, guidance, weights="w")
    # where it writes and how many processes run it never change an episode
    assert evaluation_identity(config.replace(workers=2, out="x.json", video_dir="v"), guidance, "w") == identity
    # the guidance that runs counts, however it was named
    named_so = config.replace(guidance=GuidanceChoice("recommended"))
    assert evaluation_identity(named_so, guidance, "w") == identity
    assert evaluation_identity(config, guidance.with_changes({"sampler.rho": 0.02}), "w") != identity
    assert evaluation_identity(config.replace(episodes=4), guidance, "w") != identity
    assert evaluation_identity(config, guidance, "other weights") != identity


def _saved(config: EvalConfig, success_rate: float) -> dict:
    """A results file as `evaluate` writes it, for the cache to judge."""
    identity = current_identity(config)
    return {"schema": "lano3dp-results/1", "provenance": {"behaviour_version": provenance.BEHAVIOUR_VERSION},
            "config": config.to_dict(), "identity": identity, "summary": {"success_rate": success_rate}}


def test_a_cached_result_is_current_only_for_this_evaluation_at_this_behaviour_version(tmp_path, monkeypatch):
    out = tmp_path / "eval.json"
    config = EvalConfig(task="bowl_pour", episodes=3, out=str(out))  # the packaged policy: no training needed
    write_json(out, _saved(config, 0.5))
    assert cached_eval(config)["summary"]["success_rate"] == 0.5
    assert cached_eval(config.replace(workers=2)) is not None  # seeded episodes: the same results
    assert cached_eval(config.replace(episodes=4)) is None  # another evaluation: made anew
    assert cached_eval(config.replace(guidance=GuidanceChoice("paper"))) is None
    # code that behaves differently makes it stale, whatever its config says
    monkeypatch.setattr(provenance, "BEHAVIOUR_VERSION", provenance.BEHAVIOUR_VERSION + 1)
    assert cached_eval(config) is None
    write_json(out, _saved(config, 0.25))  # made by this code: current again
    assert cached_eval(config)["summary"]["success_rate"] == 0.25
    out.write_text(out.read_text()[:40])  # a results file cut short is evaluated anew
    assert cached_eval(config) is None


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
    from lano3dp.evaluation.bundle import carried_slot_word

    assert carried_slot_word("bowl_pour") == "bowl"
    assert carried_slot_word("close_microwave") is None  # the door is pushed: Q* holds the gripper alone
    assert carried_slot_word("a_task_no_registry_knows") is None
