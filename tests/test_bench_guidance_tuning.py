"""The per-policy guidance tuning's rule and report, on synthetic scores (no simulation)."""

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
