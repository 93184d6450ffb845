"""The per-policy guidance tuning: its rule, report and --policy (synthetic scores, no simulation)."""

import json

import pytest

from bench_loader import load_bench

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
    report = bench.markdown_report({"command": "python bench/bench_guidance_tuning.py", "tuning_seed": 3_000_000,
                                    "rule": "r", "candidates": bench.CANDIDATES, "tasks": {"bowl_pour": {
                                        "scores": scores(recommended=(50, 0), turned=(70, 2)), "chosen": "turned"}}})
    assert "| bowl_pour | **turned** | 70/100 (10%–90%) | 2/100 |" in report
    assert "| bowl_pour | recommended | 50/100" in report


def test_a_policy_given_is_tuned_and_its_winner_written_into_its_own_folder(tmp_path, monkeypatch):
    """--policy TASK=PATH evaluates that folder, not the packaged one, and --write saves the winner beside it."""
    folder = tmp_path / "candidate"
    folder.mkdir()
    evaluated = []

    def fake_eval_stage(config, command=None):
        evaluated.append(config.checkpoint)
        guidance = config.guidance  # turned wins: 8 against 5 (preset) and 7 (turned_half, rho 0.02)
        successes = 5 + 3 * (guidance.push_turn == 60.0) - (guidance.rho == 0.02)
        return {"summary": {"episodes": 10, "successes": successes, "stage_rates": {}},
                "episodes": [{"collided": False}] * 10}

    monkeypatch.setattr(bench, "eval_stage", fake_eval_stage)
    monkeypatch.setattr(bench, "packaged_checkpoint", lambda task: pytest.fail("the packaged policy was used"))
    monkeypatch.setattr(bench, "ROOT", tmp_path)
    (tmp_path / "results").mkdir()
    bench.main(["--tasks", "bowl_pour", "--policy", f"bowl_pour={folder}", "--episodes", "10", "--work",
                str(tmp_path / "work"), "--write"])
    assert set(evaluated) == {str(folder)}
    assert json.loads((folder / "guidance.json").read_text())["settings"] == {"push_turn": 60.0}
