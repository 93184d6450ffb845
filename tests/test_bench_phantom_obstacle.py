"""bench_phantom_obstacle: guidance against an obstacle that is not in the scene (the detour alone)."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import pytest  # noqa: E402

from bench_loader import load_bench  # noqa: E402

bench = load_bench("bench_phantom_obstacle")


def test_the_phantom_condition_guides_against_the_obstacle_scenes_obstacle_in_a_clean_scene():
    seed = 1_000_001
    phantom, = bench.run_condition("phantom", "put_item_in_drawer", None, [seed], max_steps=8)
    clean, = bench.run_condition("clean", "put_item_in_drawer", None, [seed], max_steps=8)
    # the runner fitted the other scene's obstacle, while the simulator had none to touch or measure
    assert len(phantom["obstacles"]) == 1 and phantom["obstacles"][0]["kind"] == "cylinder"
    assert phantom["error"] is None and not phantom["collided"] and phantom["min_clearance"] is None
    assert clean["obstacles"] == [] and clean["min_clearance"] is None


def test_summary_gives_success_with_its_interval_and_the_grasp_rate():
    records = [{"success": True, "collided": False, "stages": {"grasped": True}},
               {"success": False, "collided": True, "stages": {"grasped": False}}]
    stats = bench.summary(records)
    assert stats["episodes"] == 2 and stats["success"] == 0.5 and stats["grasped"] == 0.5
    assert stats["touched"] == 0.5 and stats["ci95"][0] < 0.5 < stats["ci95"][1]


def test_a_script_without_parallel_workers_refuses_the_option_with_its_reason(capsys):
    with pytest.raises(SystemExit) as stop:
        bench.main(["--workers", "2"])
    assert stop.value.code == 2
    assert "--workers does not apply to bench_phantom_obstacle.py: the three conditions run one episode at a " \
           "time" in capsys.readouterr().err
