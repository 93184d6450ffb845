"""The per-policy guidance tuning: its rule, report and --policy (synthetic scores, no simulation)."""

import json

import pytest

from bench_loader import load_bench
from lano3dp.guidance.settings import load_guidance_tuning

bench = load_bench("bench_guidance_tuning")


def scores(**given):
    return {name: {"episodes": 100, "successes": successes, "touches": touches, "success_interval": [0.1, 0.9]}
            for name, (successes, touches) in given.items()}


def test_the_most_successful_candidate_that_keeps_clear_wins_and_ties_go_to_the_preset():
    assert bench.choose(scores(recommended=(50, 0), turned=(70, 2), turned_half=(80, 0))) == "turned_half"
    assert bench.choose(scores(recommended=(50, 0), turned=(70, 5), turned_half=(80, 6))) == "turned"  # 6% touched
    assert bench.choose(scores(recommended=(70, 0), turned=(70, 0), turned_half=(60, 0))) == "recommended"
    assert bench.choose(scores(recommended=(70, 9), turned=(80, 9), turned_half=(60, 9))) == "recommended"


def test_the_report_marks_the_chosen_candidate():
    candidates = {name: {"preset": "recommended", "overrides": changes} for name, changes in bench.CANDIDATES.items()}
    report = bench.markdown_report({"tuning_seed": 3_000_000, "rule": "r", "candidates": candidates, "tasks": {
                                    "bowl_pour": {
                                        "scores": scores(recommended=(50, 0), turned=(70, 2)), "chosen": "turned"}}})
    assert "| bowl_pour | **turned** | 70/100 (10%–90%) | 2/100 |" in report
    assert "| bowl_pour | recommended | 50/100" in report
    assert "**turned_half** recommended {'cost.push_turn': 60.0, 'sampler.rho': 0.02}" in report


def test_a_policy_given_is_tuned_and_its_winner_written_into_its_own_folder(tmp_path, monkeypatch):
    """--policy TASK=PATH evaluates that folder, not the packaged one, and --write saves the winner beside it."""
    folder = tmp_path / "candidate"
    folder.mkdir()
    evaluated = []

    def fake_eval_stage(config, command=None):
        evaluated.append(config.checkpoint)
        assert config.guidance.preset == "recommended" and config.seed == 3_000_000
        changes = config.guidance.overrides  # turned wins: 8 against 5 (preset) and 7 (turned_half, rho 0.02)
        successes = 5 + 3 * (changes.get("cost.push_turn") == 60.0) - (changes.get("sampler.rho") == 0.02)
        return {"summary": {"episodes": 10, "successes": successes, "stage_rates": {}},
                "episodes": [{"collided": False}] * 10}

    monkeypatch.setattr(bench, "eval_stage", fake_eval_stage)
    monkeypatch.setattr(bench, "packaged_checkpoint", lambda task: pytest.fail("the packaged policy was used"))
    bench.main(["--tasks", "bowl_pour", "--policy", f"bowl_pour={folder}", "--episodes", "10", "--work",
                str(tmp_path / "work"), "--out-dir", str(tmp_path / "results"), "--write"])
    assert set(evaluated) == {str(folder)}
    saved = json.loads((folder / "guidance.json").read_text())
    assert saved["preset"] == "recommended" and saved["overrides"] == {"cost.push_turn": 60.0}
    assert load_guidance_tuning(folder).settings().cost.push_turn == 60.0  # it loads as the tuning it names
    report = json.loads((tmp_path / "results" / "guidance_tuning.json").read_text())
    assert report["kind"] == "guidance_tuning" and report["tasks"]["bowl_pour"]["chosen"] == "turned"
    assert report["provenance"]["command"].startswith("python bench/bench_guidance_tuning.py --tasks bowl_pour")
