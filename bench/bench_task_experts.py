"""Scripted-expert success rates of the simulator tasks over seeded episodes.

Each episode runs through `TabletopEnv` (tiny 16x16 render, no RGB: the physics is what is
measured): reset with the seed, replay `env.expert_plan()` plus 15 steps holding the last action,
and count it solved if the env reports success before `max_steps`. Also records whether any
episode was already solved at reset (it must not be) and the wall time per episode.

    OMP_NUM_THREADS=1 python bench/bench_task_experts.py --tasks open_drawer,close_microwave \
        --variations clean,instance+clutter --episodes 100

Writes <out-dir>/task_experts<tag>.json.
"""

from __future__ import annotations

import json
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from _contract import Unused, bench_parser, parse, write_results  # noqa: E402
from lano3dp.sim import TabletopEnv  # noqa: E402

DEFAULT_TASKS = "open_drawer,bottle_in_drawer,close_microwave,put_item_in_drawer,phone_on_base"


def run_episode(env: TabletopEnv, seed: int, extra_steps: int = 15) -> dict:
    env.reset(seed=seed)
    at_reset = bool(env.task.is_success(env.sim, env.episode.layout))
    actions = env.expert_plan().actions()
    actions = np.concatenate([actions, np.repeat(actions[-1:], extra_steps, axis=0)])
    solved, steps = False, 0
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        steps += 1
        if terminated or truncated:
            solved = terminated
            break
    return {"seed": seed, "solved": solved, "solved_at_reset": at_reset, "steps": steps}


def main(argv=None) -> None:
    parser = bench_parser(__file__, __doc__, tasks=DEFAULT_TASKS, episodes=100, seed=0,
                          workers=Unused("the expert's episodes run one by one in this process, timed"))
    parser.add_argument("--variations", default="clean", help="comma-separated scene variations")
    args = parse(parser, argv)

    results = []
    for task in args.tasks:
        for variation in args.variations.split(","):
            env = TabletopEnv(task, variation=variation, image_size=16, render_rgb=False)
            start = time.perf_counter()
            episodes = [run_episode(env, seed) for seed in range(args.seed, args.seed + args.episodes)]
            elapsed = time.perf_counter() - start
            env.close()
            row = {
                "task": task,
                "variation": variation,
                "episodes": len(episodes),
                "success_rate": float(np.mean([e["solved"] for e in episodes])),
                "solved_at_reset": int(sum(e["solved_at_reset"] for e in episodes)),
                "mean_steps": float(np.mean([e["steps"] for e in episodes])),
                "seconds_per_episode": elapsed / len(episodes),
                "failed_seeds": [e["seed"] for e in episodes if not e["solved"]],
            }
            results.append(row)
            print(json.dumps(row), flush=True)
    write_results("task_experts", args, {
        "results": results, "mujoco": mujoco.__version__,
        "note": "wall times on a shared 2-core machine with other jobs running: upper bounds"})


if __name__ == "__main__":
    main()
