"""The obstacle bench's failure classes and report, on synthetic episode records (no simulation)."""

from bench_loader import load_bench

bench = load_bench("bench_obstacles")

STAGES = ("reached_block", "grasped", "lifted", "carried_to_drawer", "placed")


def episode(success=False, collided=False, reached=0, error=None, seed=0):
    return {"seed": seed, "success": success, "collided": collided, "error": error, "n_collision_steps": int(collided),
            "stages": {name: i < reached for i, name in enumerate(STAGES)}}


def test_every_failure_gets_the_class_its_stages_and_contacts_say():
    assert bench.failure_class(episode(success=True, reached=5)) is None
    assert bench.failure_class(episode(error="ObjectNotFoundError: object 'block' was not found")) == "target not seen"
    assert bench.failure_class(episode(collided=True, reached=3)) == "touched the obstacle"
    assert bench.failure_class(episode(reached=1)) == "grasp missed"
    held = [None, 0, *[0] * (bench.PATH_BLOCKED_STEPS - 1), 2]
    assert bench.failure_class({**episode(reached=1), "chunk_executed": held}) == "path blocked"
    assert bench.failure_class({**episode(reached=1), "chunk_executed": held[:-2]}) == "grasp missed"
    assert bench.failure_class({**episode(success=True, reached=5), "chunk_executed": held}) is None
    assert bench.failure_class(episode(reached=3)) == "lost on the carry"
    assert bench.failure_class(episode(reached=4)) == "last stage unfinished"
    assert bench.failure_class({**episode(), "stages": {}}) == "other"


def test_a_row_counts_classes_and_reads_success_against_the_clean_one():
    episodes = [episode(success=True, reached=5, seed=1), episode(reached=1, seed=2),
                episode(collided=True, reached=2, seed=3), episode(success=True, reached=5, seed=4)]
    summary = {"episodes": 4, "successes": 2, "episodes_with_obstacles": 4, "success_rate": 0.5,
               "collision_rate": 0.25, "mean_collision_steps": 0.25, "mean_min_clearance": 0.02,
               "worst_min_clearance": -0.01, "mean_path_length": 1.0, "latency_mean_s": 0.1, "stage_rates": {}}
    row = bench.row(summary, episodes, {"push_turn": 60.0}, {"success_rate": 0.8})
    assert row["ratio_to_clean"] == 0.625 and row["seeds"] == [1, 2, 3, 4]
    assert row["failure_classes"]["grasp missed"] == 1 and row["failure_classes"]["touched the obstacle"] == 1
    assert sum(row["failure_classes"].values()) == 2
    low, high = row["success_interval"]
    assert low < 0.5 < high
    report = bench.markdown_report({"command": "python bench/bench_obstacles.py", "samplers": bench.SAMPLERS,
                                    "policies": {}, "tasks": {"put_item_in_drawer": {
                                        "clean": {**row, "success_rate": 0.8}, "rows": {
                                            "obstacle/default": {"variation": "obstacle", "sampler": "default",
                                                                 **row}}}}})
    assert "| obstacle | default | 4 | 50%" in report and "grasp missed" in report
    assert "Sampler default here takes the guidance this checkpoint was tuned with (its guidance.json): " \
           "push_turn 60.0." in report
