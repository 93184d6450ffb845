"""Simulator benchmark: scripted-expert success and the cost of a control step, per task.

For every registered task (or --tasks), `--episodes` seeded episodes (seeds --seed + i, from 0; clean
variation) run the scripted expert through `TabletopEnv` at 128x128 with depth + segmentation
rendered every step in one fused pass (no RGB, `render_rgb=False`), and record:

    success           fraction solved before max_steps (failed seeds listed)
    steps             control steps per episode until success (mean, max)
    ms_per_step       wall time of `env.step` (physics 100 ms at 4 ms steps + one depth+seg render),
                      median and mean; `cpu_ms_per_step` is process CPU time per step (less sensitive
                      to other jobs on this shared 2-core machine)
    reset_ms          scene build + compile + settle + first render, mean

With --collect N it also times `collect` of N bowl_pour episodes (object + scene clouds and
96x96 RGB, the full dataset path) into a temporary folder.

Results go to <out-dir>/bench_sim<tag>.json (one run, every task asked for; give tasks run apart a --tag).

    OMP_NUM_THREADS=1 python bench/bench_sim.py                      # all tasks, 100 seeds each
    OMP_NUM_THREADS=1 python bench/bench_sim.py --tasks bowl_pour --episodes 20 --collect 40
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("LP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from _contract import Unused, bench_parser, parse, write_results  # noqa: E402
from lano3dp.sim import TabletopEnv, task_names  # noqa: E402


def bench_task(task: str, episodes: int, image_size: int, first_seed: int = 0) -> dict:
    env = TabletopEnv(task, image_size=image_size, render_rgb=False)
    successes, failed, lengths, step_wall, step_cpu, reset_ms = 0, [], [], [], [], []
    try:
        for seed in range(first_seed, first_seed + episodes):
            t0 = time.perf_counter()
            env.reset(seed=seed)
            reset_ms.append(1000 * (time.perf_counter() - t0))
            actions = env.expert_plan().actions()
            info = {"success": False}
            steps = env.max_steps
            for t in range(env.max_steps):
                wall, cpu = time.perf_counter(), time.process_time()
                _, _, terminated, truncated, info = env.step(actions[min(t, len(actions) - 1)])
                step_wall.append(time.perf_counter() - wall)
                step_cpu.append(time.process_time() - cpu)
                if terminated or truncated:
                    steps = t + 1
                    break
            if info["success"]:
                successes += 1
                lengths.append(steps)
            else:
                failed.append(seed)
    finally:
        env.close()
    wall = 1000 * np.asarray(step_wall)
    return {
        "episodes": episodes,
        "success": successes / episodes,
        "failed_seeds": failed,
        "steps_mean": float(np.mean(lengths)) if lengths else None,
        "steps_max": int(np.max(lengths)) if lengths else None,
        "max_steps": env.max_steps,
        "ms_per_step_median": float(np.median(wall)),
        "ms_per_step_mean": float(np.mean(wall)),
        "cpu_ms_per_step": float(1000 * np.mean(step_cpu)),
        "reset_ms": float(np.mean(reset_ms)),
        "image_size": image_size,
        "render": "fused depth+segmentation, one pass, no RGB",
    }


def bench_collect(episodes: int) -> dict:
    from lano3dp.collect import collect

    with tempfile.TemporaryDirectory() as folder:
        t0, c0 = time.perf_counter(), time.process_time()
        result = collect("bowl_pour", episodes, Path(folder) / "demo.zarr", progress=False)
        return {"task": "bowl_pour", "episodes": result.added, "steps": result.steps,
                "seconds": time.perf_counter() - t0, "cpu_seconds": time.process_time() - c0,
                "failed_seeds": result.failed_seeds, "image_size": 128, "n_points": 256}


def main(argv=None) -> None:
    parser = bench_parser(__file__, __doc__, tasks=",".join(task_names()), episodes=100, seed=0,
                          workers=Unused("it times one process; parallel episodes would share its cores"))
    parser.add_argument("--image-size", type=int, default=128)
    parser.add_argument("--collect", type=int, default=0, help="also time collecting this many episodes")
    args = parse(parser, argv)

    body: dict = {"tasks": {}, "note": "2-core machine shared with other jobs; wall times are upper bounds"}
    for task in args.tasks:
        started = time.perf_counter()
        entry = body["tasks"][task] = bench_task(task, args.episodes, args.image_size, args.seed)
        entry["finished_utc"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
        print(f"{task:20s} success {entry['success']:.2f}  {entry['ms_per_step_median']:.2f} ms/step (median wall), "
              f"{entry['cpu_ms_per_step']:.2f} ms CPU  [{time.perf_counter() - started:.0f} s]", flush=True)
        body["load_average_at_end"] = os.getloadavg()
        write_results("bench_sim", args, body, kind="sim")
    if args.collect:
        body["collect"] = bench_collect(args.collect)
        print(f"collect {args.collect} bowl_pour episodes: {body['collect']['seconds']:.1f} s wall, "
              f"{body['collect']['cpu_seconds']:.1f} s CPU", flush=True)
        write_results("bench_sim", args, body, kind="sim")


if __name__ == "__main__":
    main()
