"""Why open_drawer fails on new drawer instances, and whether a recipe fixes it (issue 36, item 5).

    train     collect the shipped recipe's 40 clean demonstrations (bench_learning's dataset) and train a recipe
              from bench_learning.RECIPES on them with the shipped budget and seed (10 CPU-minutes, seed 0); no
              evaluation (run `eval` for that)
    clouds    what the policy receives: per episode seed, the first frame's drawer cloud (as evaluation makes it) on
              clean and instance scenes, its top, centroid, the points on the handle bar, against the handle's height
    eval      evaluate checkpoints on variations, `--episodes` each, every episode traced
    report    tabulate the evaluations in --work into results/instances_open_drawer.{json,md}: success with 95%
              intervals, and per failure where the hand closed against where the handle was

The trace of an episode: the drawer's scale, its handle's height and the grasp point the expert uses (from the
episode's layout, `OpenDrawer.handle_grasp`), against the lowest height the hand reached within 3 cm (xy) of the
handle and its closest approach. Training never sees the instance variation: the demonstrations are clean.

    OMP_NUM_THREADS=1 python bench/bench_instances.py train --recipe compact_cut_lift
    OMP_NUM_THREADS=1 python bench/bench_instances.py eval --checkpoint packaged \\
        --checkpoint bench/out/learning/runs/open_drawer_compact_cut_lift_seed0 --variations clean,instance
    python bench/bench_instances.py report
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import shlex
import sys
import time
from pathlib import Path

import numpy as np

from _contract import relative, write_script_results

ROOT = Path(__file__).resolve().parent.parent
TASK = "open_drawer"
NEAR_XY = 0.03  # m: "at the handle" in xy, as the task's reached_handle stage (REACH_TOLERANCE)


def bench_learning():
    """bench/bench_learning.py as a module: its RECIPES and dataset naming are the shipped recipe's."""
    spec = importlib.util.spec_from_file_location("bench_learning", ROOT / "bench" / "bench_learning.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def train(args) -> Path:
    from lano3dp.pipeline import collect_stage, train_stage
    from lano3dp.train import policy_config_for_dataset

    learning = bench_learning()
    settings = learning.RECIPES[args.recipe]
    collect_options = settings.get("collect", {})
    suffix = "".join(f"_{key}{value:g}" for key, value in collect_options.items())
    data = collect_stage(TASK, args.demos, args.work / "data" / f"{TASK}_{settings['points']}pts{suffix}.zarr",
                         log=print, seed=0, n_points=settings["points"], progress=False, **collect_options)
    run = args.work / "runs" / f"{TASK}_{args.recipe}_seed{args.seed}"
    policy = policy_config_for_dataset(data, **settings["policy"])
    return train_stage(data, run, policy_config=policy, minutes=args.minutes, n_checkpoints=args.checkpoints,
                       batch_size=64, lr=1e-3, seed=args.seed, threads=1, progress=False, log=print,
                       **settings.get("train", {}))


def checkpoint_label(checkpoint: str) -> str:
    return "packaged" if checkpoint == "packaged" else Path(checkpoint).name


def resolve(checkpoint: str) -> str:
    from lano3dp.policy.pretrained import PACKAGED_ROOT

    return str(PACKAGED_ROOT / TASK) if checkpoint == "packaged" else checkpoint


def trace(episode: dict, variation: str) -> dict:
    """Where the hand went against where the handle was, for one evaluated episode."""
    from lano3dp.sim.env import sample_episode
    from lano3dp.sim.tasks import make_task
    from lano3dp.sim.variations import Variation

    task = make_task(TASK)
    layout, _ = sample_episode(task, episode["seed"], Variation.parse(variation))
    grasp, _, _ = task.handle_grasp(None, layout)
    path = np.asarray(episode["ee_path"], dtype=float)
    near = np.linalg.norm(path[:, :2] - grasp[:2], axis=1) < NEAR_XY
    closest = int(np.argmin(np.linalg.norm(path - grasp, axis=1)))
    return {"seed": episode["seed"], "success": bool(episode["success"]), "stage": episode.get("stage"),
            "scale": layout.objects["drawer"].scale, "handle_z": round(float(grasp[2]), 4),
            "lowest_z_at_handle": round(float(path[near, 2].min()), 4) if near.any() else None,
            "closest_distance": round(float(np.linalg.norm(path[closest] - grasp)), 4),
            "closest_offset": np.round(path[closest] - grasp, 4).tolist()}


def evaluate(args) -> None:
    from lano3dp.evaluation import EvalConfig
    from lano3dp.evaluation import evaluate as run_evaluation

    for checkpoint in args.checkpoint:
        for variation in args.variations.split(","):
            out = args.work / "instances" / f"{checkpoint_label(checkpoint)}_{variation}_{args.episodes}.json"
            if out.exists():
                print(f"{out} exists; skipping")
                continue
            out.parent.mkdir(parents=True, exist_ok=True)
            config = EvalConfig(checkpoint=resolve(checkpoint), task=TASK, variation=variation,
                                episodes=args.episodes, seed=args.seed, workers=args.workers)
            started = time.perf_counter()
            result = run_evaluation(config)
            result["traces"] = [trace(e, variation) for e in result["episodes"]]
            result["wall_s"] = round(time.perf_counter() - started, 1)
            result["command"] = "python bench/bench_instances.py " + shlex.join(sys.argv[1:])
            for episode in result["episodes"]:  # the traces keep what the report needs; the paths are large
                episode.pop("ee_path", None)
            out.write_text(json.dumps(result, indent=1, default=str))
            print(f"{checkpoint_label(checkpoint)} {variation}: {result['summary']['success_rate']:.0%}")


def clouds(args) -> None:
    """The drawer cloud of each episode's first frame, clean against instance, next to the handle's height."""
    from lano3dp.evaluation import PerceptionSettings, PolicyBundle
    from lano3dp.geometry.frame import observe
    from lano3dp.sim.env import TabletopEnv

    bundle = PolicyBundle.load(resolve(args.checkpoint[0] if args.checkpoint else "packaged"), task=TASK)
    observer = bundle.observer(PerceptionSettings())
    rows = []
    for variation in ("clean", "instance"):
        env = TabletopEnv(TASK, variation=variation, image_size=bundle.observation.image_size, render_rgb=False)
        for seed in range(args.seed, args.seed + args.episodes):
            obs, info = env.reset(seed=seed)
            frame, _ = observe(env, obs)
            cloud = observer.observe(frame, [info["target_phrases"]["drawer"]]).points[0]
            grasp, _, pull = env.task.handle_grasp(None, env.episode.layout)
            # points within 2 cm of the handle bar's axis (a horizontal segment across the pull direction)
            across = np.cross([0.0, 0.0, 1.0], pull)
            offset = cloud - grasp
            along = offset @ across
            radial = np.linalg.norm(offset - np.outer(along, across), axis=1)
            on_handle = int(((np.abs(along) < 0.05) & (radial < 0.02)).sum())
            rows.append({"variation": variation, "seed": seed, "scale": env.episode.layout.objects["drawer"].scale,
                         "handle_z": round(float(grasp[2]), 4), "cloud_top_z": round(float(cloud[:, 2].max()), 4),
                         "cloud_centroid_z": round(float(cloud[:, 2].mean()), 4), "points_on_handle": on_handle,
                         "top_minus_handle_z": round(float(cloud[:, 2].max() - grasp[2]), 4)})
        env.close()
    for row in rows:
        print(row)
    out = args.work / "instances" / "clouds.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(rows, indent=1) + "\n")


def report(args) -> None:
    from lano3dp.report import markdown_table, percent, wilson_interval

    rows, cells = [], []
    for path in sorted((args.work / "instances").glob("*_*_[0-9]*.json")):
        result = json.loads(path.read_text())
        summary, traces = result["summary"], result["traces"]
        successes, n = summary["successes"], summary["episodes"]
        low, high = wilson_interval(successes, n)
        failures = [t for t in traces if not t["success"]]
        by_scale = {}
        for t in traces:
            entry = by_scale.setdefault(str(t["scale"]), {"episodes": 0, "successes": 0, "gaps_m": []})
            entry["episodes"] += 1
            entry["successes"] += t["success"]
            if t["lowest_z_at_handle"] is not None:
                entry["gaps_m"].append(round(t["lowest_z_at_handle"] - t["handle_z"], 4))
        for entry in by_scale.values():
            gaps = entry.pop("gaps_m")
            entry["median_lowest_z_minus_handle_z_m"] = round(float(np.median(gaps)), 4) if gaps else None
        cell = {"checkpoint": path.stem.rsplit("_", 2)[0], "variation": result["config"]["variation"],
                "episodes": n, "successes": successes, "success_rate": summary["success_rate"],
                "ci95": [round(low, 4), round(high, 4)], "stage_rates": summary.get("stage_rates"),
                "by_scale": by_scale, "failures": len(failures), "evaluation_command": result.get("command"),
                "traces": traces}
        cells.append(cell)
        scales = "; ".join(f"x{s}: {e['successes']}/{e['episodes']}, "
                           f"hand {e['median_lowest_z_minus_handle_z_m']:+.3f} m"
                           for s, e in sorted(by_scale.items()) if e["median_lowest_z_minus_handle_z_m"] is not None)
        rows.append([cell["checkpoint"], cell["variation"], f"{percent(summary['success_rate'])} ({successes}/{n}; "
                     f"{percent(low)}–{percent(high)})", scales])
    command = "python bench/bench_instances.py " + shlex.join(sys.argv[1:])
    clouds_path = args.work / "instances" / "clouds.json"
    body = {"task": TASK, "cells": cells,
            "first_frame_clouds": json.loads(clouds_path.read_text()) if clouds_path.exists() else None,
            "note": "hand = median over episodes of the lowest EE height within 3 cm (xy) of the handle minus the "
                    "handle's height (negative: below the bar)"}
    path = write_script_results(f"instances_open_drawer{args.tag}", command=command, config=script_config(args),
                                body=body,
                                markdown=lambda record: "\n".join([
                                    "# open_drawer on new drawer instances", "",
                                    markdown_table(["checkpoint", "variation", "success (95% CI)",
                                                    "per scale: successes, hand vs handle height"], rows), "",
                                    record["note"], ""]))
    print(path.with_suffix(".md").read_text())


def script_config(args: argparse.Namespace) -> dict:
    return {name: relative(value) if isinstance(value, Path) else value for name, value in vars(args).items()
            if name != "work"}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("command", choices=("train", "clouds", "eval", "report"))
    parser.add_argument("--recipe", default="compact_cut_lift")
    parser.add_argument("--seed", type=int, default=0, help="training seed (train) or first episode seed (eval)")
    parser.add_argument("--demos", type=int, default=40)
    parser.add_argument("--minutes", type=float, default=10.0, help="training budget, CPU-minutes")
    parser.add_argument("--checkpoints", type=int, default=3)
    parser.add_argument("--checkpoint", action="append", default=[],
                        help="'packaged' or a checkpoint / run folder (repeatable)")
    parser.add_argument("--variations", default="clean,instance")
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--work", type=Path, default=ROOT / "bench" / "out" / "learning")
    parser.add_argument("--tag", default="", help="report: suffix of the results' name, "
                                                  "results/instances_open_drawer<tag>.json")
    args = parser.parse_args(argv)
    if args.command in ("eval", "clouds") and args.seed == 0:
        args.seed = 1_000_000  # evaluation seeds, apart from the demonstrations'
    {"train": train, "clouds": clouds, "eval": evaluate, "report": report}[args.command](args)


if __name__ == "__main__":
    main()
