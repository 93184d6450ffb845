"""Why guided obstacle episodes fail: the detour itself, or the obstacle in the scene?

On the first seeds whose layout has room for an obstacle (as `bench_obstacles`), the same policy runs in three
conditions:
    clean      no obstacle, no guidance (the policy's own success on these scenes);
    phantom    no obstacle in the scene, but guidance against the obstacle of the obstacle scene of that seed
               (fitted from that scene's first frame): the detour without occlusion or contact;
    obstacle   the obstacle in the scene, guided (the `bench_obstacles` default row).
If phantom is far below clean, the guided detour takes the policy off its demonstrations and it then misses the
task; the scene's obstacle (occluding a target, being touched) explains only the gap between phantom and obstacle.

    OMP_NUM_THREADS=1 python bench/bench_phantom_obstacle.py --task put_item_in_drawer --episodes 100
    OMP_NUM_THREADS=1 python bench/bench_phantom_obstacle.py --task put_item_in_drawer \
        --checkpoint bench/out/dart20/runs/put_item_in_drawer_dart_seed0 --tag _dart20

Writes results/phantom_obstacle_<task><tag>.json headed by the command.
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path

from lano3dp.evaluate import EpisodeRunner, EvalConfig, evaluation_seeds
from lano3dp.geometry.frame import observe
from lano3dp.jsonio import write_json
from lano3dp.policy.pretrained import packaged_checkpoint
from lano3dp.report import percent, wilson_interval
from lano3dp.runtime import PolicyRunner, scene_obstacles
from lano3dp.sim.env import TabletopEnv

ROOT = Path(__file__).resolve().parent.parent
CONDITIONS = ("clean", "phantom", "obstacle")


class PhantomRunner(PolicyRunner):
    """A runner that guides against obstacles fitted in another frame (the obstacle scene of the same seed)."""

    phantom_frame = None
    phantom_phrases: tuple[str, ...] = ()

    def set_objects(self, target_phrases=None, obstacle_phrases=None, held_object=None):
        super().set_objects(target_phrases, self.phantom_phrases, held_object)

    def fit_obstacles(self, frame):
        return super().fit_obstacles(self.phantom_frame)


def run_condition(condition: str, task: str, checkpoint: str, seeds: list[int],
                  max_steps: int | None = None) -> list[dict]:
    variation = "obstacle" if condition == "obstacle" else "clean"
    guidance = "none" if condition == "clean" else "clean"
    config = EvalConfig(checkpoint=checkpoint, task=task, variation=variation, guidance=guidance, episodes=len(seeds),
                        max_steps=max_steps)
    runner = EpisodeRunner(config, runner_class=PhantomRunner if condition == "phantom" else None)
    obstacle_env = TabletopEnv(task, variation="obstacle") if condition == "phantom" else None
    records = []
    try:
        for seed in seeds:
            if obstacle_env is not None:
                obs, _ = obstacle_env.reset(seed=seed)
                frame, _ = observe(obstacle_env, obs)
                PhantomRunner.phantom_frame, PhantomRunner.phantom_phrases = frame, tuple(scene_obstacles(frame))
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
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default="put_item_in_drawer")
    parser.add_argument("--checkpoint", default=None, help="default: the policy packaged for --task")
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--conditions", default=",".join(CONDITIONS))
    parser.add_argument("--tag", default="")
    args = parser.parse_args(argv)
    checkpoint = args.checkpoint or str(packaged_checkpoint(args.task))
    seeds = evaluation_seeds(EvalConfig(checkpoint=checkpoint, task=args.task, variation="obstacle",
                                        obstacle_scenes_only=True, episodes=args.episodes), Path(checkpoint))
    command = "OMP_NUM_THREADS=1 python bench/bench_phantom_obstacle.py " + shlex.join(sys.argv[1:] if argv is None
                                                                                         else argv)
    result = {"command": command, "task": args.task, "checkpoint": _relative(checkpoint), "seeds": seeds,
              "conditions": {}}
    for condition in args.conditions.split(","):
        started = time.process_time()
        records = run_condition(condition, args.task, checkpoint, seeds)
        result["conditions"][condition] = {**summary(records), "cpu_s": round(time.process_time() - started, 1),
                                           "episodes_detail": records}
        stats = result["conditions"][condition]
        print(f"{condition:9s} success {percent(stats['success'])} "
              f"({percent(stats['ci95'][0])}-{percent(stats['ci95'][1])}), touched {percent(stats['touched'])}",
              flush=True)
    write_json(ROOT / "results" / f"phantom_obstacle_{args.task}{args.tag}.json", result)
    return result


def _relative(path: str) -> str:
    resolved = Path(path).resolve()
    return str(resolved.relative_to(ROOT)) if resolved.is_relative_to(ROOT) else Path(path).name


if __name__ == "__main__":
    main()
