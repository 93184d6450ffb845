"""The obstacle bench's samplers (library presets plus overrides), failure classes and report, on synthetic episode
records (no simulation)."""

from bench_loader import load_bench
from lano3dp.evaluation.bundle import resolve_folder
from lano3dp.guidance.settings import guidance_preset, load_guidance_tuning

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
    row = bench.row(summary, episodes, {"cost.push_turn": 60.0}, {"success_rate": 0.8})
    assert row["ratio_to_clean"] == 0.625 and row["seeds"] == [1, 2, 3, 4]
    assert row["failure_classes"]["grasp missed"] == 1 and row["failure_classes"]["touched the obstacle"] == 1
    assert sum(row["failure_classes"].values()) == 2
    low, high = row["success_interval"]
    assert low < 0.5 < high
    samplers = {name: sampler.describe() for name, sampler in bench.SAMPLERS.items()}
    report = bench.markdown_report({"samplers": samplers, "policies": {}, "tasks": {"put_item_in_drawer": {
                                        "clean": {**row, "success_rate": 0.8}, "rows": {
                                            "obstacle/default": {"variation": "obstacle", "sampler": "default",
                                                                 **row}}}}})
    assert "| obstacle | default | 4 | 50%" in report and "grasp missed" in report
    assert "Sampler default here takes the guidance this checkpoint was tuned with (its guidance.json): " \
           "cost.push_turn 60.0." in report
    assert "**no_walls** tuned obstacles.bridge_gaps=False without escape" in report


def test_the_fixed_samplers_are_the_library_presets_and_the_ablations_change_only_what_they_name():
    def resolved(sampler, task="put_item_in_drawer", moving=False):
        choice = bench.SAMPLERS[sampler].choice(None, task, moving)
        return choice.resolve(load_guidance_tuning(resolve_folder(None, task)))

    assert resolved("none") == guidance_preset("none") and resolved("A_k") == guidance_preset("a_k")
    assert resolved("paper") == guidance_preset("paper")
    assert resolved("turned") == guidance_preset("recommended").with_changes({"cost.push_turn": 60.0})
    assert resolved("turned_half").sampler.rho == 0.02 and resolved("turned_half").cost.push_turn == 60.0
    tuned = resolved("default")  # put_item_in_drawer's guidance.json turns the push
    assert tuned.cost.push_turn == 60.0 and resolved("sphere") == tuned.with_changes({"obstacles.body": "sphere"})
    assert resolved("default", moving=True) == tuned.with_changes({"obstacles.refit": True})
    no_walls = resolved("no_walls")
    assert not no_walls.obstacles.bridge_gaps and no_walls.execution.filters == ("repair", "hold", "follow")


def test_no_walls_takes_only_the_escape_out_of_a_tuning_that_already_dropped_a_filter():
    tuning = load_guidance_tuning(resolve_folder(None, "bowl_pour"))  # bowl_pour's guidance.json: no follow
    assert "follow" not in tuning.settings().execution.filters
    choice = bench.SAMPLERS["no_walls"].choice(None, "bowl_pour", False)
    assert choice.resolve(tuning).execution.filters == ("repair", "hold")
