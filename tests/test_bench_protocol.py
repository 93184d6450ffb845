"""The protocol benchmark's table: runs missing from the work folder are shown as not run, never dropped."""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def load_bench():
    spec = importlib.util.spec_from_file_location("bench_protocol", ROOT / "bench" / "bench_protocol.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def summary(successes: int, episodes: int = 20, **extra) -> dict:
    return {"episodes": episodes, "episodes_with_obstacles": extra.pop("placed", None), "successes": successes,
            "success_rate": successes / episodes, "collision_rate": extra.pop("collision", 0.0),
            "mean_collision_steps": extra.pop("contact", 0.0), "safe_success_rate": successes / episodes,
            "mean_min_clearance": extra.pop("clearance", None), "error_rate": 0.0, "latency_mean_s": 0.1}


def test_report_marks_missing_runs_and_evaluations_as_not_run():
    bench = load_bench()
    args = bench.parse_args(["--tasks", "open_drawer", "--variations", "clutter,camera", "--rho-sweep", "0.01",
                             "--report-only"])
    trained = {"method": bench.METHODS["objects"], "seed": 0, "parameters": 5_400_000, "steps": 2000,
               "curve": [{"step": 1000, **summary(8)}, {"step": 2000, **summary(12)}],
               "paper_best_k": 0.5, "best_k_used": 2, "final": {"step": 2000, **summary(12)},
               "variations": {"clutter": summary(10), "camera": None},
               "obstacle": {"no_guidance": summary(13, placed=18, collision=0.9, contact=19.8, clearance=-0.031),
                            "guidance": summary(5, placed=18, collision=0.65, contact=0.95, clearance=-0.001)},
               "obstacle_sweep": {"0.01": None}}
    missing = {"method": bench.METHODS["scene"], "seed": 0, "not_run": True}
    results = {"command": "python bench/bench_protocol.py --report-only", "machine": {"platform": "x", "note": "y"},
               "tasks": {"open_drawer": {"objects/seed0": trained, "scene/seed0": missing}}}
    text = bench.markdown_report(results, args)
    assert "| Lan-o3dp (object clouds) | 0 | 5.40 M | 2000 | 50% (best 2) | 60% (39%–78%) | 50% | not run |" in text
    assert "| DP3 (scene cloud) | 0 | – | – | not run | not run | not run | not run |" in text
    assert "| guidance A_0\\|k, rho 0.01 | not run |" in text
    assert "| no guidance | 20 | 18 | 65% | 90% | 19.8 | 65% | -3.1 cm |" in text
    assert "Assembled by --report-only" in text


def test_a_task_run_only_for_the_obstacle_test_has_no_variation_cells():
    bench = load_bench()
    args = bench.parse_args(["--tasks", "open_drawer", "--obstacle-tasks", "put_item_in_drawer",
                             "--variations", "clutter", "--report-only"])
    assert args.obstacle_tasks == "put_item_in_drawer"
    obstacle_only = {"method": bench.METHODS["objects"], "seed": 0, "not_run": True, "obstacle_only": True}
    results = {"command": "c", "machine": {"platform": "x", "note": "y"},
               "tasks": {"put_item_in_drawer": {"objects/seed0": obstacle_only}}}
    assert "| Lan-o3dp (object clouds) | 0 | – | – | not run | not run | – |" in bench.markdown_report(results, args)
