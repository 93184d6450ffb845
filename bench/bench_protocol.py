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

Every stage is resumable: datasets grow to size, training runs resume from their last checkpoint, an
evaluation whose JSON exists with the same configuration is skipped. Outputs:
    <work>/...                                 datasets, runs, per-evaluation JSONs (large; not committed)
    results/protocol<tag>.json                 every number, the configuration, the command, the seeds
    results/protocol<tag>.md                   the tables, headed by the command that made them

The default protocol (3 tasks x 3 methods x 2000 steps, 20 episodes per evaluation, and Lan-o3dp on the
obstacle task) takes about 6-7 CPU-hours here, most of it training the two baselines (a step of the
scene-cloud encoder costs ~4x, of the image encoder ~5x, a Lan-o3dp step). One process per task over
one --work folder uses both cores; then --report-only tabulates the folder. A reduced run, e.g. for a smoke check:

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

import numpy as np

from lano3dp.evaluate import DEFAULT_LAST_STEPS, DEFAULT_RHO, EvalConfig, write_json
from lano3dp.pipeline import cached_eval, collect_stage, eval_stage, train_stage
from lano3dp.report import markdown_table, percent, wilson_interval

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
    parser.add_argument("--rho", type=float, default=DEFAULT_RHO, help="guidance scale (metres per guided step)")
    parser.add_argument("--rho-sweep", default="0.01,0.02", help="further guidance scales of the obstacle test, "
                                                                 "for its success/collision trade-off ('' none)")
    parser.add_argument("--last-steps", type=int, default=DEFAULT_LAST_STEPS, help="guidance S")
    parser.add_argument("--batch-size", type=int, default=64)
    parser.add_argument("--lr", type=float, default=1e-3)
    parser.add_argument("--model", default="small", help="UNet size: small (5.4 M), medium (18 M), dp (67 M)")
    parser.add_argument("--seeds", default="0", help="comma-separated training seeds")
    parser.add_argument("--workers", type=int, default=1, help="parallel evaluation processes")
    parser.add_argument("--work", default=str(ROOT / "bench" / "out" / "protocol"), help="datasets, runs, evals")
    parser.add_argument("--tag", default="", help="suffix of results/protocol<tag>.json|md")
    parser.add_argument("--note", default="", help="a line printed under the table's title (e.g. 'reduced run')")
    parser.add_argument("--report-only", action="store_true",
                        help="train and evaluate nothing: tabulate what the work folder holds (runs made by several "
                             "processes, e.g. one per task); what is missing is marked 'not run'")
    return parser.parse_args(argv)


def summary_cells(summary: dict) -> tuple[str, str]:
    low, high = wilson_interval(summary["successes"], summary["episodes"])
    return percent(summary["success_rate"]), f"{percent(low)}–{percent(high)}"


def main(argv=None) -> int:
    args = parse_args(argv)
    tasks = [t for t in args.tasks.split(",") if t]
    methods = [m for m in args.methods.split(",") if m]
    unknown = sorted(set(methods) - set(METHODS))
    if unknown:
        raise SystemExit(f"unknown methods {unknown}; choose from {sorted(METHODS)}")
    variations = [v for v in args.variations.split(",") if v]
    obstacle_methods = [m for m in args.obstacle_methods.split(",") if m]
    obstacle_tasks = [t for t in args.obstacle_tasks.split(",") if t]
    seeds = [int(s) for s in args.seeds.split(",") if s]
    work = Path(args.work)
    command = shlex.join(["python", "bench/bench_protocol.py", *(argv if argv is not None else sys.argv[1:])])
    started = time.perf_counter()

    def log(message: str) -> None:
        print(f"[{time.perf_counter() - started:7.0f}s] {message}", flush=True)

    results: dict = {"command": command, "config": vars(args), "tasks": {}, "machine": {
        "platform": platform.platform(), "python": platform.python_version(), "note": "2-core CPU shared with other "
        "jobs while this ran: timings are pessimistic"}}
    out_json = ROOT / "results" / f"protocol{args.tag}.json"
    out_md = ROOT / "results" / f"protocol{args.tag}.md"

    for task in [*tasks, *(t for t in obstacle_tasks if t not in tasks)]:
        obstacle_only = task not in tasks
        data = work / "data" / f"{task}_n{args.points}.zarr"
        if not args.report_only:
            collect_stage(task, args.demos, data, log=log, progress=False, n_points=args.points)
        task_result = results["tasks"].setdefault(task, {})
        for method in methods:
            if obstacle_only and method not in obstacle_methods:
                continue
            for seed in seeds:
                entry = run_method(task, method, seed, data, work, args, log, command,
                                   obstacle=method in obstacle_methods and task in obstacle_tasks,
                                   variations=[] if obstacle_only else variations)
                task_result[f"{method}/seed{seed}"] = {**entry, "obstacle_only": obstacle_only}
                results["wall_s"] = round(time.perf_counter() - started, 1)
                write_json(out_json, results)
                out_md.write_text(markdown_report(results, args))
    log(f"done: {out_json}, {out_md}")
    return 0


def run_method(task: str, method: str, seed: int, data: Path, work: Path, args: argparse.Namespace, log,
               command: str, *, obstacle: bool, variations: list[str]) -> dict:
    """Train one (task, method, seed) run and evaluate it: the curve, the variations, the obstacle test."""
    from lano3dp.policy import down_dims_for
    from lano3dp.policy.checkpoint import list_checkpoints
    from lano3dp.train import policy_config_for_dataset

    key = f"{task} {method}/seed{seed}"
    run = work / "runs" / task / method / f"seed{seed}"
    if not args.report_only:
        policy = policy_config_for_dataset(data, obs_type=method, down_dims=down_dims_for(args.model))
        log(f"{key}: train {args.steps} steps")
        train_stage(data, run, policy_config=policy, steps=args.steps, batch_size=args.batch_size, lr=args.lr,
                    ckpt_every=args.eval_every, seed=seed, log=log, progress=False)
    checkpoints = [(step, path) for step, path in list_checkpoints(run / "checkpoints") if step <= args.steps] \
        if (run / "checkpoints").is_dir() else []
    if not checkpoints or checkpoints[-1][0] != args.steps:
        log(f"{key}: not trained to {args.steps} steps; marked not run")
        return {"method": METHODS[method], "seed": seed, "not_run": True}
    evals = work / "evals" / task / method / f"seed{seed}"

    def evaluate(checkpoint: Path, variation: str, name: str, guidance: str = "none", episodes=None,
                 rho: float | None = None) -> dict | None:
        config = EvalConfig(checkpoint=str(checkpoint), task=task, variation=variation,
                            episodes=episodes or args.episodes, guidance=guidance, rho=args.rho if rho is None else rho,
                            last_steps=args.last_steps, workers=args.workers, out=str(evals / f"{name}.json"))
        if args.report_only:
            if (results := cached_eval(config)) is None:
                return None
            summary = results["summary"]
        else:
            summary = eval_stage(config, log=log, command=command)["summary"]
        cells = summary_cells(summary)
        log(f"{key} {name}: success {cells[0]} ({cells[1]}), collisions {percent(summary['collision_rate'])}")
        return _compact(summary)

    entry = {"method": METHODS[method], "seed": seed, "run": str(run), "parameters": _parameters(checkpoints[-1][1]),
             "steps": args.steps, "curve": []}
    for step, checkpoint in checkpoints:
        if (point := evaluate(checkpoint, "clean", f"clean_step{step:07d}")) is not None:
            entry["curve"].append({"step": step, **point})
    if not entry["curve"] or entry["curve"][-1]["step"] != args.steps:
        return {"method": METHODS[method], "seed": seed, "not_run": True}
    rates = sorted((point["success_rate"] for point in entry["curve"]), reverse=True)
    entry["paper_best_k"] = float(np.mean(rates[: args.best_k]))
    entry["best_k_used"] = min(args.best_k, len(rates))
    entry["final"] = entry["curve"][-1]
    final = checkpoints[-1][1]
    entry["variations"] = {v: evaluate(final, v, f"{v}_final") for v in variations}
    if obstacle:
        n = args.obstacle_episodes or args.episodes
        entry["obstacle"] = {"no_guidance": evaluate(final, "obstacle", "obstacle_none", "none", n),
                             "guidance": evaluate(final, "obstacle", "obstacle_clean", "clean", n)}
        entry["obstacle_sweep"] = {f"{rho:g}": evaluate(final, "obstacle", f"obstacle_clean_rho{rho:g}", "clean",
                                                        n, rho)
                                   for rho in _floats(args.rho_sweep) if rho != args.rho}
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


def markdown_report(results: dict, args: argparse.Namespace) -> str:
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
