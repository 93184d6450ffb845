"""The paper's evaluation protocol, sized for a CPU: Lan-o3dp vs DP3 vs Diffusion Policy.

Per task:
  1. collect `--demos` scripted-expert demonstrations of clean scenes (one dataset: every method's keys);
  2. per method and training seed, train `--steps` steps, checkpointing every `--eval-every`;
  3. evaluate every checkpoint on `--episodes` clean episodes. Reported: the paper's number (mean of the
     best `--best-k` evaluations along training) and the honest one (the final checkpoint);
  4. evaluate the final checkpoint on each variation axis (`--variations`: clutter, camera, background,
     similar, ...), the generalisation table of the paper;
  5. obstacle test on the final Lan-o3dp checkpoint (`--obstacle-methods` for the others) of the
     `--obstacle-tasks`: a novel obstacle on the expert's path, without and with cost guidance (A_0|k):
     success and collision rates. Those tasks carry an object along a transport segment with room for
     an obstacle (door and drawer handles are within reach of the gripper's start: no obstacle fits
     there); one not in `--tasks` gets the obstacle methods trained on clean scenes, steps 1-3 only.

Methods share everything but the observation: "objects" (Lan-o3dp: clouds of the task's objects chosen by
name), "scene" (DP3: the cropped scene cloud), "image" (Diffusion Policy: a 96x96 RGB image). Evaluation
episodes use seeds 1000000 + i, apart from the demonstrations'.

The protocol is a graph of cells (`lano3dp.executor`): one collect cell per task, one train cell per (task,
method, seed), one eval cell per evaluation, each declaring the CPU cores it keeps busy (1; an evaluation
--eval-workers). `--plan` prints it. `--executor local` runs it on this machine (`--workers N`: N cores' worth
of cells at once in spawned processes); `--executor ray` makes each cell a Ray task, on a local instance bound
to 127.0.0.1 or on the cluster `--ray-address` names, with `--work` on a filesystem every node sees. The
report is assembled from the work folder once the cells are done (--report-only does only that).

Every cell is resumable: datasets grow to size, training runs resume from their last checkpoint, an
evaluation whose JSON exists with the same configuration is skipped, so a re-run, by either executor,
continues where the last one stopped. Outputs:
    <work>/...                                 datasets, runs, per-evaluation JSONs (large; not committed)
    results/protocol<tag>.json                 every number, the configuration, the command, the seeds
    results/protocol<tag>.md                   the tables, headed by the command that made them
    results/protocol<tag>_success.png          final success per task and method, 95% Wilson intervals
    results/protocol<tag>_drops.png            clean minus varied success per variation axis and method

The default protocol (3 tasks x 3 methods x 2000 steps, 20 episodes per evaluation, and Lan-o3dp on the
obstacle task) takes about 6-7 CPU-hours here, most of it training the two baselines (a step of the
scene-cloud encoder costs ~4x, of the image encoder ~5x, a Lan-o3dp step). `--workers 2` uses both cores.
A reduced run, e.g. for a smoke check:

    OMP_NUM_THREADS=1 python bench/bench_protocol.py --tasks bowl_pour --demos 20 --steps 400 --eval-every 200 \
        --episodes 5 --variations camera,clutter --tag _reduced
"""

from __future__ import annotations

import argparse
import platform
import shlex
import sys
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from lano3dp.evaluate import GUIDANCE_PRESETS, EvalConfig
from lano3dp.executor import (
    Cell,
    CellFailedError,
    RayNotInstalledError,
    collect_cell,
    describe,
    eval_cell,
    make_executor,
    train_cell,
)
from lano3dp.jsonio import write_json
from lano3dp.pipeline import cached_eval
from lano3dp.report import markdown_table, percent, plot_success_intervals, plot_variation_drops, wilson_interval

ROOT = Path(__file__).resolve().parent.parent
METHODS = {"objects": "Lan-o3dp (object clouds)", "scene": "DP3 (scene cloud)", "image": "Diffusion Policy (RGB)"}
# The three shortest-horizon tasks: the ones a CPU can train in minutes (bowl_pour needs far longer).
DEFAULT_TASKS = "open_drawer,close_microwave,open_wine_bottle"
# A pick-and-place whose transport segment has room for an obstacle in most layouts (tests/test_tasks_common.py).
DEFAULT_OBSTACLE_TASKS = "put_item_in_drawer"


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tasks", default=DEFAULT_TASKS, help="comma-separated simulator tasks")
    parser.add_argument("--methods", default="objects,scene,image", help="comma-separated: objects, scene, image")
    parser.add_argument("--demos", type=int, default=40, help="demonstrations per task")
    parser.add_argument("--points", type=int, default=128, help="points per object cloud in the dataset (the CPU "
                                                                "notes' cheap setting; the paper used more)")
    parser.add_argument("--steps", type=int, default=2000, help="training steps per run")
    parser.add_argument("--eval-every", type=int, default=400, help="evaluate a checkpoint every this many steps")
    parser.add_argument("--episodes", type=int, default=20, help="episodes per evaluation")
    parser.add_argument("--best-k", type=int, default=5, help="the paper's number: mean of the k best evaluations")
    parser.add_argument("--variations", default="clutter,camera,background,similar",
                        help="variation axes evaluated on the final checkpoint ('' for none)")
    parser.add_argument("--obstacle-tasks", default=DEFAULT_OBSTACLE_TASKS,
                        help="tasks given the obstacle test ('' none); trained just for it if not in --tasks")
    parser.add_argument("--obstacle-methods", default="objects", help="methods given the obstacle test ('' none)")
    parser.add_argument("--obstacle-episodes", type=int, default=40,
                        help="episodes of the obstacle test (twice the default --episodes: only about 4 in 5 "
                             "layouts have room for an obstacle, and the guidance claim rests on this test)")
    parser.add_argument("--rho", type=float, default=GUIDANCE_PRESETS["recommended"].rho,
                        help="guidance scale (metres per guided step)")
    parser.add_argument("--rho-sweep", default="0.01,0.02", help="further guidance scales of the obstacle test, "
                                                                 "for its success/collision trade-off ('' none)")
    parser.add_argument("--last-steps", type=int, default=GUIDANCE_PRESETS["recommended"].last_steps,
                        help="guidance S")
    parser.add_argument("--batch-size", type=int, default=64)
    parser.add_argument("--lr", type=float, default=1e-3)
    parser.add_argument("--model", default="small", help="UNet size: small (5.4 M), medium (18 M), dp (67 M)")
    parser.add_argument("--seeds", default="0", help="comma-separated training seeds")
    parser.add_argument("--executor", choices=("local", "ray"), default="local",
                        help="who runs the cells: local (this machine, --workers processes) or ray (one Ray task "
                             "per cell; needs pip install 'lano3dp[ray]')")
    parser.add_argument("--workers", type=int, default=1,
                        help="local executor: CPU cores' worth of cells run at once (1: in this process)")
    parser.add_argument("--ray-address", default=None,
                        help="ray executor: join this cluster ('auto', 'ray://host:10001'); default: start a local "
                             "instance on 127.0.0.1")
    parser.add_argument("--ray-cpus", type=int, default=None,
                        help="ray executor: CPUs of the local instance (default: all of this machine's)")
    parser.add_argument("--eval-workers", type=int, default=1,
                        help="processes per evaluation cell (its declared CPU need)")
    parser.add_argument("--work", default=str(ROOT / "bench" / "out" / "protocol"),
                        help="datasets, runs, evals; with --executor ray, a folder every node sees at this path")
    parser.add_argument("--results", default=str(ROOT / "results"),
                        help="folder of protocol<tag>.json|md and its plots")
    parser.add_argument("--tag", default="", help="suffix of results/protocol<tag>.json|md")
    parser.add_argument("--plan", action="store_true", help="print the graph of cells and exit")
    parser.add_argument("--note", default="", help="a line printed under the table's title (e.g. 'reduced run')")
    parser.add_argument("--report-only", action="store_true",
                        help="train and evaluate nothing: tabulate what the work folder holds (runs made by several "
                             "processes, e.g. one per task); what is missing is marked 'not run'")
    return parser.parse_args(argv)


class Overrides(NamedTuple):
    """Settings the command line does not expose, for reduced runs (tests): each a dict of keyword arguments.

    collect: to `collect.collect` (e.g. image_size); policy: to `train.policy_config_for_dataset` (UNet and
    encoder widths); train: to `pipeline.train_stage` (e.g. val_ratio); eval: EvalConfig fields (e.g. max_steps).
    The report reads the evaluations back with the same EvalConfigs, so give it the same overrides.
    """

    collect: dict = {}
    policy: dict = {}
    train: dict = {}
    eval: dict = {}


class Run(NamedTuple):
    """One (task, method, seed) training run of the protocol and the evaluations planned on it."""

    task: str
    method: str
    seed: int
    data: Path
    folder: Path
    obstacle_only: bool
    evals: dict  # name -> EvalConfig; "clean_step0000400", ..., "<variation>_final", "obstacle_*"


def _lists(args: argparse.Namespace) -> dict[str, list]:
    return {"tasks": [t for t in args.tasks.split(",") if t], "methods": [m for m in args.methods.split(",") if m],
            "variations": [v for v in args.variations.split(",") if v],
            "obstacle_methods": [m for m in args.obstacle_methods.split(",") if m],
            "obstacle_tasks": [t for t in args.obstacle_tasks.split(",") if t],
            "seeds": [int(s) for s in args.seeds.split(",") if s]}


def checkpoint_steps(steps: int, every: int) -> list[int]:
    """The steps a run of `steps` checkpointing every `every` saves: each multiple of `every`, and the last."""
    return sorted({*range(every, steps + 1, every), steps})


def dataset_path(args: argparse.Namespace, task: str) -> Path:
    return Path(args.work) / "data" / f"{task}_n{args.points}.zarr"


def plan_runs(args: argparse.Namespace, overrides: Overrides = Overrides()) -> list[Run]:
    """Every training run of the protocol with its evaluations, in the report's order."""
    from lano3dp.policy.checkpoint import checkpoint_name

    lists, work = _lists(args), Path(args.work)
    runs = []
    for task in [*lists["tasks"], *(t for t in lists["obstacle_tasks"] if t not in lists["tasks"])]:
        obstacle_only = task not in lists["tasks"]
        for method in lists["methods"]:
            if obstacle_only and method not in lists["obstacle_methods"]:
                continue
            for seed in lists["seeds"]:
                folder = work / "runs" / task / method / f"seed{seed}"
                evals_dir = work / "evals" / task / method / f"seed{seed}"

                def config(step: int, variation: str, name: str, guidance: str = "none", episodes=None,
                           rho: float | None = None, folder=folder, evals_dir=evals_dir, task=task) -> EvalConfig:
                    fields = {"checkpoint": str(folder / "checkpoints" / checkpoint_name(step)), "task": task,
                              "variation": variation, "episodes": episodes or args.episodes,
                              "guidance": {"mode": guidance, "rho": args.rho if rho is None else rho,
                                           "last_steps": args.last_steps},
                              "workers": args.eval_workers, "out": str(evals_dir / f"{name}.json")}
                    return EvalConfig(**{**fields, **overrides.eval})

                evals = {f"clean_step{step:07d}": config(step, "clean", f"clean_step{step:07d}")
                         for step in checkpoint_steps(args.steps, args.eval_every)}
                if not obstacle_only:
                    evals |= {f"{v}_final": config(args.steps, v, f"{v}_final") for v in lists["variations"]}
                if method in lists["obstacle_methods"] and task in lists["obstacle_tasks"]:
                    n = args.obstacle_episodes or args.episodes
                    evals["obstacle_none"] = config(args.steps, "obstacle", "obstacle_none", "none", n)
                    evals["obstacle_clean"] = config(args.steps, "obstacle", "obstacle_clean", "clean", n)
                    for rho in _floats(args.rho_sweep):
                        if rho != args.rho:
                            name = f"obstacle_clean_rho{rho:g}"
                            evals[name] = config(args.steps, "obstacle", name, "clean", n, rho)
                runs.append(Run(task, method, seed, dataset_path(args, task), folder, obstacle_only, evals))
    return runs


def build_graph(args: argparse.Namespace, overrides: Overrides = Overrides()) -> list[Cell]:
    """The protocol as cells: collect per task -> train per (task, method, seed) -> one cell per evaluation.

    The report is not a cell: it is assembled from the work folder once the cells are done (`collect_results`),
    which is also what --report-only does.
    """
    from lano3dp.policy import down_dims_for

    cells, collected = [], set()
    for run in plan_runs(args, overrides):
        collect_name = f"collect {run.task}"
        if collect_name not in collected:
            collected.add(collect_name)
            cells.append(collect_cell(collect_name, run.task, args.demos, run.data,
                                      **{"n_points": args.points, **overrides.collect}))
        key = f"{run.task} {run.method}/seed{run.seed}"
        policy = {"obs_type": run.method, "down_dims": list(down_dims_for(args.model)), **overrides.policy}
        cells.append(train_cell(f"train {key}", run.data, run.folder, steps=args.steps, policy=policy,
                                inputs=[collect_name], **{"batch_size": args.batch_size, "lr": args.lr,
                                                          "ckpt_every": args.eval_every, "seed": run.seed,
                                                          **overrides.train}))
        cells += [eval_cell(f"eval {key} {name}", config, inputs=[f"train {key}"])
                  for name, config in run.evals.items()]
    return cells


def main(argv=None, overrides: Overrides = Overrides()) -> int:
    args = parse_args(argv)
    unknown = sorted(set(_lists(args)["methods"]) - set(METHODS))
    if unknown:
        raise SystemExit(f"unknown methods {unknown}; choose from {sorted(METHODS)}")
    command = shlex.join(["python", "bench/bench_protocol.py", *(argv if argv is not None else sys.argv[1:])])
    started = time.perf_counter()

    def log(message: str) -> None:
        print(f"[{time.perf_counter() - started:7.0f}s] {message}", flush=True)

    cells = build_graph(args, overrides)
    if args.plan:
        print(describe(cells))
        return 0
    if not args.report_only:
        try:
            executor = make_executor(args.executor, workers=args.workers, ray_address=args.ray_address,
                                     ray_cpus=args.ray_cpus)
        except RayNotInstalledError as error:
            raise SystemExit(f"--executor ray: {error}") from None
        try:
            done = executor.run(cells, log=log)
        except CellFailedError as error:
            raise SystemExit(f"{error}\nThe cells done so far are kept in {args.work}; re-run to continue.") \
                from None
        log(f"graph: ran {len(done.executed)} cells, {len(done.skipped)} were done already")
    results = collect_results(args, command, overrides)
    results["wall_s"] = round(time.perf_counter() - started, 1)
    out_json, out_md = write_report(results, args)
    log(f"done: {out_json}, {out_md}")
    return 0


def collect_results(args: argparse.Namespace, command: str, overrides: Overrides = Overrides()) -> dict:
    """Every number of the protocol, read from the work folder; what is missing is marked not run."""
    results: dict = {"command": command, "config": vars(args), "tasks": {}, "machine": {
        "platform": platform.platform(), "python": platform.python_version(), "note": "2-core CPU shared with other "
        "jobs while this ran: timings are pessimistic"}}
    for run in plan_runs(args, overrides):
        entry = run_entry(run, args)
        results["tasks"].setdefault(run.task, {})[f"{run.method}/seed{run.seed}"] = \
            {**entry, "obstacle_only": run.obstacle_only}
    return results


def write_report(results: dict, args: argparse.Namespace) -> tuple[Path, Path]:
    """results/protocol<tag>.json and .md, and the two plots beside them (linked from the .md)."""
    folder = Path(args.results)
    out_json, out_md = folder / f"protocol{args.tag}.json", folder / f"protocol{args.tag}.md"
    figures = plot_report(results, args, folder)
    write_json(out_json, results)
    out_md.write_text(markdown_report(results, args, figures))
    return out_json, out_md


def run_entry(run: Run, args: argparse.Namespace) -> dict:
    """One run's row of the report: the curve, the paper's best-k and the final, variations, obstacle test."""
    from lano3dp.policy.checkpoint import checkpoint_name

    not_run = {"method": METHODS[run.method], "seed": run.seed, "not_run": True}
    final = run.folder / "checkpoints" / checkpoint_name(args.steps)
    if not final.is_dir():
        return not_run

    def evaluation(name: str) -> dict | None:
        cached = cached_eval(run.evals[name]) if name in run.evals else None
        return None if cached is None else _compact(cached["summary"])

    entry = {"method": METHODS[run.method], "seed": run.seed, "run": str(run.folder), "parameters": _parameters(final),
             "steps": args.steps, "curve": []}
    for step in checkpoint_steps(args.steps, args.eval_every):
        if (point := evaluation(f"clean_step{step:07d}")) is not None:
            entry["curve"].append({"step": step, **point})
    if not entry["curve"] or entry["curve"][-1]["step"] != args.steps:
        return not_run
    rates = sorted((point["success_rate"] for point in entry["curve"]), reverse=True)
    entry["paper_best_k"] = float(np.mean(rates[: args.best_k]))
    entry["best_k_used"] = min(args.best_k, len(rates))
    entry["final"] = entry["curve"][-1]
    entry["variations"] = {v: evaluation(f"{v}_final") for v in _lists(args)["variations"]} \
        if not run.obstacle_only else {}
    if "obstacle_none" in run.evals:
        entry["obstacle"] = {"no_guidance": evaluation("obstacle_none"), "guidance": evaluation("obstacle_clean")}
        entry["obstacle_sweep"] = {name.removeprefix("obstacle_clean_rho"): evaluation(name) for name in run.evals
                                   if name.startswith("obstacle_clean_rho")}
    return entry


def _rate(summary: dict | None, evaluated: bool = True) -> str:
    if not evaluated:
        return "–"
    return "not run" if summary is None else percent(summary["success_rate"])


def _floats(text: str) -> list[float]:
    return [float(item) for item in text.split(",") if item]


def _parameters(checkpoint: Path) -> int:
    from lano3dp.policy import DiffusionPolicy

    return int(sum(p.numel() for p in DiffusionPolicy.from_pretrained(checkpoint).parameters()))


def _compact(summary: dict) -> dict:
    keep = ("episodes", "episodes_with_obstacles", "successes", "success_rate", "collision_rate",
            "mean_collision_steps", "safe_success_rate",
            "mean_min_clearance",
            "error_rate", "latency_mean_s", "stage_rates")
    return {k: summary.get(k) for k in keep}


def success_cells(results: dict) -> dict[tuple[str, str], list[tuple[int, int]]]:
    """(task, method label) -> the final checkpoint's (successes, episodes) per seed that ran."""
    cells: dict[tuple[str, str], list[tuple[int, int]]] = {}
    for task, entries in results["tasks"].items():
        for entry in entries.values():
            seeds = cells.setdefault((task, entry["method"]), [])
            if not entry.get("not_run"):
                seeds.append((entry["final"]["successes"], entry["final"]["episodes"]))
    return cells


def variation_drops(results: dict) -> dict[str, dict[str, list[float]]]:
    """method label -> variation axis -> clean minus varied final success, one value per (task, seed) run."""
    drops: dict[str, dict[str, list[float]]] = {}
    for entries in results["tasks"].values():
        for entry in entries.values():
            if entry.get("not_run") or entry.get("obstacle_only"):
                continue
            by_axis = drops.setdefault(entry["method"], {})
            for axis, summary in entry.get("variations", {}).items():
                if summary is not None:
                    by_axis.setdefault(axis, []).append(entry["final"]["success_rate"] - summary["success_rate"])
    return drops


def plot_report(results: dict, args: argparse.Namespace, folder: Path) -> dict[str, str]:
    """The plots beside the tables: {"success": file name, "drops": file name} for those with data."""
    figures = {}
    cells = success_cells(results)
    if any(cells.values()):
        path = plot_success_intervals(folder / f"protocol{args.tag}_success.png", cells,
                                      title="final checkpoint's clean success per task and method")
        figures["success"] = path.name
    drops = variation_drops(results)
    if any(drops.values()):
        path = plot_variation_drops(folder / f"protocol{args.tag}_drops.png", drops)
        figures["drops"] = path.name
    return figures


def markdown_report(results: dict, args: argparse.Namespace, figures: dict[str, str] | None = None) -> str:
    lines = [f"# Protocol benchmark{' (' + args.note + ')' if args.note else ''}", "",
             f"Command: `{results['command']}`", "",
             f"Training seeds: {args.seeds}; evaluation seeds 1000000 + i; {args.demos} demonstrations per task "
             f"({args.points} points per object cloud, 512 per scene cloud, 96x96 RGB); "
             f"{args.steps} training steps (batch {args.batch_size}, lr {args.lr:g}, UNet '{args.model}'); "
             f"{args.episodes} episodes per evaluation ({args.obstacle_episodes or args.episodes} in the obstacle "
             f"test), a checkpoint every {args.eval_every} steps.", "",
             "Paper = mean success of the best "
             f"{args.best_k} evaluations along training (the paper's number); final = the last checkpoint (the "
             "honest one). Intervals are 95% Wilson intervals of the final checkpoint's success.", ""]
    figures = figures or {}
    if "success" in figures:
        lines += [f"![final clean success per task and method, 95% Wilson intervals]({figures['success']})", ""]
    drops = variation_drops(results)
    if any(drops.values()):
        axes = list(dict.fromkeys(axis for by_axis in drops.values() for axis in by_axis))
        rows = [[method, *(f"{100 * np.mean(by_axis[a]):+.0f} ({len(by_axis[a])})" if by_axis.get(a) else "–"
                           for a in axes)] for method, by_axis in drops.items()]
        lines += ["Generalisation: clean minus varied success of the final checkpoints, in points, mean over "
                  "(task, seed) runs (how many in brackets); positive = the change costs success.", "",
                  markdown_table(["method", *axes], rows), ""]
        if "drops" in figures:
            lines += [f"![success lost under each scene change, per method]({figures['drops']})", ""]
    for task, entries in results["tasks"].items():
        lines += [f"## {task}", ""]
        rows = []
        variation_names = args.variations.split(",") if args.variations else []
        for entry in entries.values():
            evaluated = not entry.get("obstacle_only")  # a task run for the obstacle test has no variation axes
            if entry.get("not_run"):
                rows.append([entry["method"], entry["seed"], "–", "–", "not run", "not run",
                             *(_rate(None, evaluated) for _ in variation_names)])
                continue
            final = entry["final"]
            low, high = wilson_interval(final["successes"], final["episodes"])
            rows.append([entry["method"], entry["seed"], f"{entry['parameters'] / 1e6:.2f} M", entry["steps"],
                         f"{percent(entry['paper_best_k'])} (best {entry['best_k_used']})",
                         f"{percent(final['success_rate'])} ({percent(low)}–{percent(high)})",
                         *(_rate(entry["variations"].get(v), evaluated) for v in variation_names)])
        lines += [markdown_table(["method", "seed", "params", "steps", "paper: best-k clean", "final clean",
                                  *variation_names], rows), ""]
        curve_rows = [[entry["method"], entry["seed"],
                       ", ".join(f"{p['step']}: {percent(p['success_rate'])}" for p in entry["curve"])]
                      for entry in entries.values() if not entry.get("not_run")]
        lines += ["Success along training (clean):", "", markdown_table(["method", "seed", "step: success"],
                                                                        curve_rows), ""]
        obstacle_rows = []
        for entry in entries.values():
            if "obstacle" not in entry:
                continue
            runs = [("no guidance", entry["obstacle"]["no_guidance"]),
                    (f"guidance A_0|k, rho {args.rho:g}", entry["obstacle"]["guidance"]),
                    *((f"guidance A_0|k, rho {rho}", s) for rho, s in entry.get("obstacle_sweep", {}).items())]
            for label, s in runs:
                if s is None:
                    obstacle_rows.append([entry["method"], entry["seed"], label, "not run", *["–"] * 6])
                    continue
                clearance = s["mean_min_clearance"]
                obstacle_rows.append([entry["method"], entry["seed"], label, s["episodes"],
                                      s.get("episodes_with_obstacles", "–"), percent(s["success_rate"]),
                                      percent(s["collision_rate"]), s.get("mean_collision_steps"),
                                      percent(s["safe_success_rate"]),
                                      "–" if clearance is None else f"{100 * clearance:.1f} cm"])
        if obstacle_rows:
            lines += [f"Novel obstacle on the path (rho in m per guided step, S = {args.last_steps}). Collision = "
                      "share of all episodes with any contact with the obstacle; an episode where no obstacle fits "
                      "the path is run without one.",
                      "", markdown_table(["method", "seed", "sampling", "episodes", "with an obstacle placed",
                                          "success", "collision",
                                          "contact steps / episode", "success w/o collision", "mean min clearance"],
                                         obstacle_rows), ""]
    if args.report_only:
        lines += ["Assembled by --report-only from the work folder: the runs' compute time is not this command's.",
                  ""]
    else:
        lines += [f"Wall time: {results.get('wall_s', 0) / 60:.0f} min on {results['machine']['platform']} "
                  f"({results['machine']['note']}).", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
