"""The paper's comparison, at equal CPU budgets: Lan-o3dp vs DP3 vs Diffusion Policy, cell by cell.

A cell is one (task, method, training seed): it trains a policy for a CPU budget (`--minutes` CPU-minutes on one
thread; the step count follows the budget: `train.plan_budget`) on `--demos` scripted demonstrations of clean
scenes, checkpointing `--checkpoints` times along the way, then evaluates
  - each earlier checkpoint on `--curve-episodes` clean episodes (the learning curve; no best-k selection),
  - the final checkpoint on `--episodes` clean episodes (the headline number),
  - the final checkpoint under each scene change (`--variations`, `--variation-episodes` each); Lan-o3dp once per
    segmenter (`--segmenters`: the simulator's ground truth beside perception that can fail), the baselines,
    which segment nothing, once,
  - the final checkpoint with a novel obstacle on the path, for the tasks with room for one (`--obstacle-tasks`),
    unguided and guided (the recommended preset), `--variation-episodes` each.
Methods share everything but the observation: "objects" (Lan-o3dp: clouds of the task's objects chosen by name),
"scene" (DP3: the cropped scene cloud), "image" (Diffusion Policy: a 96x96 RGB image). Evaluation episodes use
seeds --seed + i, apart from the demonstrations'. Every evaluation steps `--batch` episodes together.

Each finished cell writes a small record (`results/protocol/cells/<task>-<method>-seed<k>.json`: provenance, the
budget, the steps reached, each evaluation's success with its 95% interval) and, with `--commit`, commits it, so
the protocol advances across interruptions and machines. Datasets and checkpoints stay in `--work` (not committed;
a cell interrupted mid-way trains again from its last checkpoint there, or from scratch on another machine). A cell
is current while its record was made at this code's behaviour version with this configuration; `--cpu-hours H`
runs the next missing or stale cells, in order, until H CPU-hours are spent. The report (`results/protocol.json`,
`.md`, `_success.png`, `_curves.png`, `_drops.png`) is generated from the committed cells only.

    OMP_NUM_THREADS=1 python bench/bench_protocol.py --cpu-hours 2 --commit     # the next cells, ~15 CPU-min each
    OMP_NUM_THREADS=1 python bench/bench_protocol.py --report-only              # the report from committed cells
    OMP_NUM_THREADS=1 python bench/bench_protocol.py --plan                     # every cell and whether it is current
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, NamedTuple

from _contract import ROOT, bench_parser, parse, relative, results_path, write_results
from lano3dp import provenance
from lano3dp.evaluation import EvalConfig, GuidanceChoice, PerceptionSettings
from lano3dp.evaluation.results import results_file
from lano3dp.jsonio import write_json
from lano3dp.report import markdown_table, percent, wilson_interval

METHODS = {"objects": "Lan-o3dp (object clouds)", "scene": "DP3 (scene cloud)", "image": "Diffusion Policy (RGB)"}
# the paper's seven simulated tasks (its Table I)
PAPER_TASKS = ("open_drawer", "open_wine_bottle", "sweep_to_dustpan", "phone_on_base", "put_item_in_drawer",
               "water_plants", "close_microwave")
CELLS = "protocol/cells"  # below --out-dir


class CellSpec(NamedTuple):
    task: str
    method: str
    seed: int

    @property
    def name(self) -> str:
        return f"{self.task}-{self.method}-seed{self.seed}"


def parse_args(argv=None) -> argparse.Namespace:
    parser = bench_parser(__file__, __doc__, tasks=",".join(PAPER_TASKS), episodes=50, seed=1_000_000, workers=1)
    parser.add_argument("--methods", default="objects,scene,image", help="comma-separated: objects, scene, image")
    parser.add_argument("--train-seeds", default="0,1,2", help="comma-separated training seeds")
    parser.add_argument("--minutes", type=float, default=10.0, help="CPU-minutes of training per cell (one thread)")
    parser.add_argument("--demos", type=int, default=40, help="demonstrations per task")
    parser.add_argument("--checkpoints", type=int, default=4, help="checkpoints along training (the last is final)")
    parser.add_argument("--curve-episodes", type=int, default=20, help="episodes per earlier checkpoint")
    parser.add_argument("--variation-episodes", type=int, default=20, help="episodes per scene change and per "
                                                                            "obstacle condition")
    parser.add_argument("--variations", default="clutter,similar,instance,camera,background",
                        help="scene changes evaluated on the final checkpoint ('' for none)")
    parser.add_argument("--segmenters", default="sim,error-model",
                        help="Lan-o3dp's segmenters under scene changes: sim (ground truth) and error-model "
                             "(perception that can fail)")
    parser.add_argument("--obstacle-tasks", default="put_item_in_drawer",
                        help="tasks given the obstacle rows (those with room for an obstacle on the path)")
    parser.add_argument("--batch", type=int, default=16, help="episodes stepped together in every evaluation")
    parser.add_argument("--work", type=Path, default=ROOT / "bench" / "out" / "protocol",
                        help="datasets and checkpoints (large; not committed)")
    parser.add_argument("--cpu-hours", type=float, default=0.0, help="run missing or stale cells until this much "
                                                                     "CPU time is spent (0: run none)")
    parser.add_argument("--cells", default="", help="only these cells (comma-separated names), e.g. "
                                                    "open_drawer-objects-seed0")
    parser.add_argument("--commit", action="store_true", help="git-commit each cell's record as it finishes")
    parser.add_argument("--plan", action="store_true", help="list every cell and whether it is current, and exit")
    parser.add_argument("--report-only", action="store_true", help="write the report from the committed cells")
    return parse(parser, argv)


def _words(text: str) -> list[str]:
    return [item for item in text.split(",") if item]


def cell_specs(args: argparse.Namespace) -> list[CellSpec]:
    """Every cell, in the order they are run: by seed, then task, then method (so seed 0 of every task comes
    first, and a partial protocol compares the methods on the same tasks)."""
    unknown = sorted(set(_words(args.methods)) - set(METHODS))
    if unknown:
        raise SystemExit(f"unknown methods {unknown}; choose from {sorted(METHODS)}")
    specs = [CellSpec(task, method, int(seed)) for seed in _words(args.train_seeds) for task in args.tasks
             for method in _words(args.methods)]
    wanted = set(_words(args.cells))
    return [spec for spec in specs if not wanted or spec.name in wanted]


def cell_config(spec: CellSpec, args: argparse.Namespace) -> dict[str, Any]:
    """What a cell's record must have been made with to be current (besides the behaviour version)."""
    return {"task": spec.task, "method": spec.method, "train_seed": spec.seed, "cpu_minutes": args.minutes,
            "threads": 1, "demos": args.demos, "recipe": "compact: 64 points per object cloud, absolute actions",
            "checkpoints": args.checkpoints, "episodes": args.episodes, "curve_episodes": args.curve_episodes,
            "variation_episodes": args.variation_episodes, "variations": _words(args.variations),
            "segmenters": _words(args.segmenters) if spec.method == "objects" else ["sim"],
            "obstacle_rows": spec.task in _words(args.obstacle_tasks), "eval_seed": args.seed}


def cell_path(spec: CellSpec, args: argparse.Namespace) -> Path:
    return Path(args.out_dir) / CELLS / f"{spec.name}.json"


def is_current(spec: CellSpec, args: argparse.Namespace) -> bool:
    path = cell_path(spec, args)
    if not path.exists():
        return False
    try:
        record = json.loads(path.read_text())
    except ValueError:
        return False
    return provenance.result_is_current(record) and record.get("config") == cell_config(spec, args)


# ---- one cell ------------------------------------------------------------------------------------------
def run_cell(spec: CellSpec, args: argparse.Namespace, log) -> Path:
    """Train and evaluate one cell; writes and returns its record."""
    import torch

    from lano3dp.pipeline import collect_stage, eval_stage, train_stage
    from lano3dp.policy.checkpoint import list_checkpoints
    from lano3dp.train import policy_config_for_dataset

    torch.set_num_threads(1)
    config = cell_config(spec, args)
    work = Path(args.work)
    cell_started = time.process_time()
    data = collect_stage(spec.task, args.demos, work / "data" / f"{spec.task}.zarr", log=log, n_points=64,
                         progress=False)
    run = work / "runs" / spec.name
    cpu_started = time.process_time()
    final = train_stage(data, run, policy_config=policy_config_for_dataset(data, obs_type=spec.method,
                                                                           action_frame="absolute"),
                        minutes=args.minutes, n_checkpoints=args.checkpoints, seed=spec.seed, log=log,
                        progress=False)
    train_cpu_s = time.process_time() - cpu_started
    saved = json.loads((run / "train_config.json").read_text())
    checkpoints = [(step, path) for step, path in list_checkpoints(run / "checkpoints")]

    def evaluation(name: str, checkpoint: Path, episodes: int, variation: str = "clean", guidance: str = "none",
                   segmenter: str = "sim") -> dict[str, Any]:
        config_ = EvalConfig(checkpoint=str(checkpoint), task=spec.task, variation=variation, episodes=episodes,
                             seed=args.seed, obstacle_scenes_only=variation.startswith("obstacle"),
                             guidance=GuidanceChoice(guidance), perception=PerceptionSettings(segmenter=segmenter),
                             batch=args.batch, out=str(work / "evals" / spec.name / f"{name}.json"))
        summary = eval_stage(config_, log=log)["summary"]
        low, high = wilson_interval(summary["successes"], summary["episodes"])
        log(f"{spec.name} {name}: {summary['successes']}/{summary['episodes']}")
        return {"episodes": summary["episodes"], "successes": summary["successes"],
                "success_rate": summary["success_rate"], "interval95": [low, high],
                "collision_rate": summary["collision_rate"], "episodes_with_obstacles":
                    summary["episodes_with_obstacles"], "stage_rates": summary["stage_rates"]}

    evaluations: dict[str, Any] = {}
    for step, path in checkpoints[:-1]:
        evaluations[f"curve_step{step}"] = {"step": step, **evaluation(f"curve_step{step}", path,
                                                                        args.curve_episodes)}
    evaluations["final"] = {"step": checkpoints[-1][0], **evaluation("final", final, args.episodes)}
    for variation in config["variations"]:
        for segmenter in config["segmenters"]:
            evaluations[f"{variation}_{segmenter}"] = evaluation(f"{variation}_{segmenter}", final,
                                                                 args.variation_episodes, variation,
                                                                 segmenter=segmenter)
    if config["obstacle_rows"] and spec.method == "objects":
        evaluations["obstacle_unguided"] = evaluation("obstacle_unguided", final, args.variation_episodes,
                                                      "obstacle")
        evaluations["obstacle_guided"] = evaluation("obstacle_guided", final, args.variation_episodes, "obstacle",
                                                    guidance="recommended")
    plan = saved.get("budget_plan") or {}
    training = {"cpu_minutes_budget": args.minutes, "planned_steps": saved["steps"],
                "steps_reached": checkpoints[-1][0], "probe_cpu_s_per_step": plan.get("cpu_s_per_step"),
                "stopped_by_budget": saved.get("extra", {}).get("stopped_by_budget_at") is not None,
                "train_cpu_s_this_session": round(train_cpu_s, 1),
                "cell_cpu_s_this_session": round(time.process_time() - cell_started, 1)}
    record = results_file("protocol_cell", config, {"cell": spec.name, "training": training,
                                                    "evaluations": evaluations}, command=args.command)
    path = cell_path(spec, args)
    write_json(path, record)
    return path


def commit_cell(path: Path, spec: CellSpec, log) -> None:
    """Commit the cell's record alone (other changes in the tree are left as they are); a commit git refuses
    (e.g. in the middle of a merge) is said, and the record stays on disk for a later commit."""
    try:
        subprocess.run(["git", "add", str(path)], cwd=ROOT, check=True, capture_output=True)
        subprocess.run(["git", "commit", "-q", "-m", f"Protocol cell {spec.name} (bench/bench_protocol.py)", "--",
                        str(path)], cwd=ROOT, check=True, capture_output=True)
    except (OSError, subprocess.CalledProcessError) as error:
        log(f"could not commit {relative(path)} ({error}); it is written, commit it by hand")


# ---- the report from committed cells --------------------------------------------------------------------
def committed_cells(args: argparse.Namespace) -> list[dict[str, Any]]:
    """Every cell record git tracks under the cells folder (a record written but not committed is not used)."""
    folder = Path(args.out_dir) / CELLS
    try:
        listed = subprocess.run(["git", "ls-files", "--", str(folder)], cwd=ROOT, capture_output=True, text=True,
                                check=True).stdout.split()
    except (OSError, subprocess.CalledProcessError):
        listed = []
    return [json.loads((ROOT / name).read_text()) for name in sorted(listed) if name.endswith(".json")]


def report(args: argparse.Namespace) -> dict[str, Any]:
    """The protocol's numbers from the committed cells: per (task, method) the seeds' final success with
    intervals, mean and spread over seeds; the curves; the scene changes per segmenter; the obstacle rows."""
    import numpy as np

    cells = committed_cells(args)
    tasks: dict[str, dict[str, Any]] = {}
    cpu_s = 0.0
    commands: dict[str | None, list[str]] = {}  # the command that ran each cell
    for record in cells:
        config, evaluations = record["config"], record["evaluations"]
        entry = tasks.setdefault(config["task"], {}).setdefault(config["method"], {"seeds": {}})
        entry["seeds"][str(config["train_seed"])] = {
            "training": record["training"], "final": evaluations["final"],
            "current": provenance.result_is_current(record),
            "curve": [{"step": v["step"], "success_rate": v["success_rate"]} for k, v in evaluations.items()
                      if k.startswith("curve_")] + [{"step": evaluations["final"]["step"],
                                                      "success_rate": evaluations["final"]["success_rate"]}],
            "variations": {k: v for k, v in evaluations.items() if not k.startswith(("curve_", "final",
                                                                                      "obstacle_"))},
            "obstacle": {k: v for k, v in evaluations.items() if k.startswith("obstacle_")}}
        cpu_s += record["training"].get("cell_cpu_s_this_session", 0.0)
        commands.setdefault((record.get("provenance") or {}).get("command"), []).append(record["cell"])
    for methods in tasks.values():
        for entry in methods.values():
            finals = [seed["final"]["success_rate"] for seed in entry["seeds"].values()]
            entry["mean_final"] = float(np.mean(finals))
            entry["spread_final"] = float(np.std(finals)) if len(finals) > 1 else None
    return {"cells": len(cells), "cells_planned": len(cell_specs(args)), "tasks": tasks,
            "cpu_hours": round(cpu_s / 3600, 2),
            "cell_commands": [{"command": command, "cells": names} for command, names in commands.items()]}


def markdown(record: dict[str, Any]) -> str:
    tasks = record["tasks"]
    lines = ["# The paper's comparison at equal CPU budgets", "",
             f"{record['cells']} of {record['cells_planned']} cells committed "
             f"({record['cpu_hours']} CPU-hours of training and evaluation in them, as measured by the sessions "
             "that ran them). Each cell: one training seed, "
             f"{record['setup']['minutes']} CPU-minutes on one thread, {record['setup']['demos']} demonstrations; "
             f"final checkpoint on {record['setup']['episodes']} clean episodes (95% Wilson intervals); scene changes "
             f"and obstacle rows on {record['setup']['variation_episodes']} episodes each. `sim` = the simulator's "
             "ground-truth masks, `error-model` = those masks through a model of detector, SAM and tracker errors "
             "(docs/perception-error-model.md).", ""]
    lines += [f"Cells run by `{entry['command']}`: {', '.join(entry['cells'])}." for entry in record["cell_commands"]]
    lines += [""]
    rows = []
    for task, methods in tasks.items():
        for method, entry in methods.items():
            seeds = ", ".join(f"{seed}: {percent(s['final']['success_rate'])} "
                              f"({percent(s['final']['interval95'][0])}–{percent(s['final']['interval95'][1])}), "
                              f"{s['training']['steps_reached']} steps"
                              for seed, s in sorted(entry["seeds"].items()))
            spread = "–" if entry["spread_final"] is None else f"± {100 * entry['spread_final']:.0f}"
            rows.append([task, METHODS.get(method, method), f"{percent(entry['mean_final'])} {spread}", seeds])
    lines += ["## Clean success of the final checkpoint", "",
              markdown_table(["task", "method", "mean ± sd over seeds", "per seed (interval, steps reached)"], rows),
              ""]
    axis_rows = []
    for task, methods in tasks.items():
        for method, entry in methods.items():
            names = sorted({name for s in entry["seeds"].values() for name in s["variations"]})
            for name in names:
                values = [s["variations"][name] for s in entry["seeds"].values() if name in s["variations"]]
                successes, episodes = sum(v["successes"] for v in values), sum(v["episodes"] for v in values)
                low, high = wilson_interval(successes, episodes)
                axis_rows.append([task, METHODS.get(method, method), name,
                                  f"{percent(successes / episodes)} ({percent(low)}–{percent(high)})", len(values)])
    if axis_rows:
        lines += ["## Scene changes (final checkpoint; seeds pooled)", "",
                  markdown_table(["task", "method", "change_segmenter", "success (95% interval)", "seeds"],
                                 axis_rows), ""]
    obstacle_rows = []
    for task, methods in tasks.items():
        for method, entry in methods.items():
            for seed, s in sorted(entry["seeds"].items()):
                for name, value in s["obstacle"].items():
                    obstacle_rows.append([task, METHODS.get(method, method), seed, name,
                                          f"{value['successes']}/{value['episodes']}",
                                          percent(value["collision_rate"])])
    if obstacle_rows:
        lines += ["## Novel obstacle on the path (final checkpoint)", "",
                  markdown_table(["task", "method", "seed", "condition", "success", "touched"], obstacle_rows), ""]
    return "\n".join(lines)


def write_report(args: argparse.Namespace) -> Path:
    body = report(args)
    body["setup"] = {"minutes": args.minutes, "demos": args.demos, "episodes": args.episodes,
                     "variation_episodes": args.variation_episodes, "curve_episodes": args.curve_episodes}
    written = write_results("protocol", args, body, markdown=markdown)
    plot_report(body, args)  # after: provenance reads the tree as the run found it, not with its own plot changed
    return written


def plot_report(body: dict[str, Any], args: argparse.Namespace) -> None:
    from lano3dp.report import plot_success_intervals

    cells: dict[tuple[str, str], list[tuple[int, int]]] = {}
    for task, methods in body["tasks"].items():
        for method, entry in methods.items():
            cells[(task, METHODS.get(method, method))] = [(s["final"]["successes"], s["final"]["episodes"])
                                                          for s in entry["seeds"].values()]
    if cells:
        plot_success_intervals(results_path("protocol", args, "_success.png"), cells,
                               title="final checkpoint's clean success per task and method")


# ---- the driver ------------------------------------------------------------------------------------------
def main(argv=None) -> int:
    args = parse_args(argv)
    started = time.process_time()

    def log(message: str) -> None:
        print(f"[{time.process_time() - started:7.0f} CPU-s] {message}", flush=True)

    specs = cell_specs(args)
    if args.plan:
        for spec in specs:
            print(f"{spec.name:45s} {'current' if is_current(spec, args) else 'to run'}")
        return 0
    if not args.report_only:
        for spec in specs:
            if time.process_time() - started >= args.cpu_hours * 3600:
                break
            if is_current(spec, args):
                continue
            log(f"cell {spec.name}")
            path = run_cell(spec, args, log)
            if args.commit:
                commit_cell(path, spec, log)
            log(f"cell {spec.name} done: {relative(path)}")
    write_report(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
