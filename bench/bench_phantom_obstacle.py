"""Why guided obstacle episodes fail: the detour itself, or the obstacle in the scene?

On the first seeds from --seed whose layout has room for an obstacle (as `bench_obstacles`), the same policy runs
in three conditions:
    clean      no obstacle, no guidance (the policy's own success on these scenes);
    phantom    no obstacle in the scene, but guidance against the obstacle of the obstacle scene of that seed
               (fitted from that scene's first frame): the detour without occlusion or contact;
    obstacle   the obstacle in the scene, guided (the `bench_obstacles` default row: preset tuned).
If phantom is far below clean, the guided detour takes the policy off its demonstrations and it then misses the
task; the scene's obstacle (occluding a target, being touched) explains only the gap between phantom and obstacle.

    OMP_NUM_THREADS=1 python bench/bench_phantom_obstacle.py --tasks put_item_in_drawer --episodes 100
    OMP_NUM_THREADS=1 python bench/bench_phantom_obstacle.py --tasks put_item_in_drawer \
        --checkpoint bench/out/dart20/runs/put_item_in_drawer_dart_seed0 --tag _dart20

Writes <out-dir>/phantom_obstacle_<task><tag>.json per task.
"""

from __future__ import annotations

import time

from _contract import Unused, bench_parser, parse, relative, write_results
from lano3dp.evaluation import EvalConfig, GuidanceChoice
from lano3dp.evaluation.bundle import PolicyBundle
from lano3dp.evaluation.episodes import EpisodeRunner
from lano3dp.evaluation.evaluator import evaluation_seeds
from lano3dp.geometry.frame import observe
from lano3dp.guidance.obstacles import ObstacleTracker
from lano3dp.report import percent, wilson_interval
from lano3dp.runtime import scene_obstacles
from lano3dp.sim.env import TabletopEnv

CONDITIONS = ("clean", "phantom", "obstacle")


class PhantomTracker(ObstacleTracker):
    """A tracker that fits the obstacles of another frame (the obstacle scene of the same seed), whatever the
    scene it runs in shows; the held object is still measured in the real scene."""

    phantom_frame = None
    phantom_phrases: tuple[str, ...] = ()

    def set_objects(self, phrases, held_object):
        super().set_objects(self.phantom_phrases, held_object)

    def update(self, frame, step):
        super().update(self.phantom_frame, step)


def run_condition(condition: str, task: str, checkpoint: str | None, seeds: list[int],
                  max_steps: int | None = None) -> list[dict]:
    variation = "obstacle" if condition == "obstacle" else "clean"
    choice = GuidanceChoice("none" if condition == "clean" else "tuned")
    config = EvalConfig(checkpoint=checkpoint, task=task, variation=variation, guidance=choice, episodes=len(seeds),
                        max_steps=max_steps)
    bundle = PolicyBundle.load(checkpoint, task=task)
    runner = EpisodeRunner(config, choice.resolve(bundle.tuning), bundle)
    obstacle_env = None
    if condition == "phantom":
        policy_runner = runner.runner
        policy_runner.tracker = PhantomTracker(policy_runner.observer, policy_runner.guidance.obstacles,
                                               policy_runner.views)
        obstacle_env = TabletopEnv(task, variation="obstacle")
    records = []
    try:
        for seed in seeds:
            if obstacle_env is not None:
                obs, _ = obstacle_env.reset(seed=seed)
                frame, _ = observe(obstacle_env, obs)
                PhantomTracker.phantom_frame, PhantomTracker.phantom_phrases = frame, tuple(scene_obstacles(frame))
            record = runner.run(seed)
            records.append({key: record.get(key) for key in ("seed", "success", "collided", "stages", "error",
                                                             "min_clearance", "steps", "obstacles")})
    finally:
        runner.close()
        if obstacle_env is not None:
            obstacle_env.close()
    return records


def summary(records: list[dict]) -> dict:
    n, wins = len(records), sum(bool(r["success"]) for r in records)
    low, high = wilson_interval(wins, n)
    grasped = [r for r in records if "grasped" in (r["stages"] or {})]
    return {"episodes": n, "success": wins / n, "ci95": [low, high],
            "grasped": (sum(bool(r["stages"]["grasped"]) for r in grasped) / len(grasped)) if grasped else None,
            "touched": sum(bool(r["collided"]) for r in records) / n}


def main(argv: list[str] | None = None) -> dict:
    parser = bench_parser(__file__, __doc__, tasks="put_item_in_drawer", episodes=100, seed=1_000_000,
                          workers=Unused("the three conditions run one episode at a time in this process"))
    parser.add_argument("--checkpoint", default=None, help="default: the policy packaged for the task (one task)")
    parser.add_argument("--conditions", default=",".join(CONDITIONS))
    args = parse(parser, argv)
    if args.checkpoint and len(args.tasks) != 1:
        parser.error("--checkpoint is one task's policy: give one task")
    results = {}
    for task in args.tasks:
        seeds = evaluation_seeds(EvalConfig(checkpoint=args.checkpoint, task=task, variation="obstacle",
                                            obstacle_scenes_only=True, episodes=args.episodes, seed=args.seed), task)
        body = {"task": task, "checkpoint": relative(args.checkpoint) if args.checkpoint else f"packaged:{task}",
                "seeds": seeds, "conditions": {}}
        for condition in args.conditions.split(","):
            started = time.process_time()
            records = run_condition(condition, task, args.checkpoint, seeds)
            body["conditions"][condition] = {**summary(records), "cpu_s": round(time.process_time() - started, 1),
                                             "episodes_detail": records}
            stats = body["conditions"][condition]
            print(f"{task} {condition:9s} success {percent(stats['success'])} "
                  f"({percent(stats['ci95'][0])}-{percent(stats['ci95'][1])}), touched {percent(stats['touched'])}",
                  flush=True)
        results[task] = body
        print(write_results(f"phantom_obstacle_{task}", args, body, kind="phantom_obstacle"))
    return results


if __name__ == "__main__":
    main()
