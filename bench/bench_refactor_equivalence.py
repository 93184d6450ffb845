"""A refactor proves itself episode for episode: the same seeds give the same outcomes before and after.

The reference side runs the code of `--reference-commit` (the runtime before its redesign) through its own command
line, in a git worktree of that commit; the other side runs this checkout's `evaluate`. Each cell is one task,
guidance preset and variation; every episode is compared on success, steps, obstacle contact, contact steps and the
simulator's minimum clearance (to 1e-6 m). Cells are cached per side under --work (a killed run continues).

Cells: bowl_pour, put_item_in_drawer and bottle_in_drawer, 20 clean and 20 obstacle episodes each under the
recommended guidance (as each policy was tuned: preset "tuned") and the paper's form (preset "paper"), plus 10
two-obstacle and 10 moving-obstacle episodes of put_item_in_drawer (recommended).

    OMP_NUM_THREADS=1 python bench/bench_refactor_equivalence.py                         # ~4 CPU-hours
    OMP_NUM_THREADS=1 python bench/bench_refactor_equivalence.py --tasks bowl_pour --presets tuned --episodes 2

The reference side never changes, so a later commit can be checked against a saved run's reference outcomes
(`--reference-from results/refactor_equivalence.json`), which halves the cost.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
from pathlib import Path

from _contract import relative, write_script_results
from lano3dp.evaluation import EvalConfig, GuidanceChoice, evaluate
from lano3dp.jsonio import write_json
from lano3dp.report import markdown_table

ROOT = Path(__file__).resolve().parent.parent
TASKS = ("bowl_pour", "put_item_in_drawer", "bottle_in_drawer")
COMPARED = ("success", "steps", "collided", "n_collision_steps")
CLEARANCE_TOLERANCE = 1e-6  # m
# how the reference command line (before the redesign) named each preset's guidance
REFERENCE_GUIDANCE = {"tuned": ["--guidance", "clean"],
                      "paper": ["--guidance", "clean", "--guidance-preset", "paper", "--scheduler", "ddpm",
                                "--steps", "100", "--body", "sphere"]}


def cells(tasks, presets, episodes: int, extra_episodes: int) -> list[dict]:
    """(name, task, preset, variation, episodes, obstacle scenes only, refit) of every cell."""
    found = []
    for preset in presets:
        for task in tasks:
            for variation in ("obstacle", "clean"):
                found.append({"name": f"{task}-{preset}-{variation}", "task": task, "preset": preset,
                              "variation": variation, "episodes": episodes})
    if "tuned" in presets and "put_item_in_drawer" in tasks and extra_episodes:
        found += [{"name": "put_item_in_drawer-tuned-obstacle2", "task": "put_item_in_drawer", "preset": "tuned",
                   "variation": "obstacle:2", "episodes": extra_episodes},
                  {"name": "put_item_in_drawer-tuned-moving", "task": "put_item_in_drawer", "preset": "tuned",
                   "variation": "obstacle:moving", "episodes": extra_episodes}]
    return found


def run_after(cell: dict, seed: int, out: Path, workers: int = 1) -> dict:
    """This checkout's evaluation of a cell (cached in `out`)."""
    if out.exists():
        return json.loads(out.read_text())
    changes = {"obstacles.refit": True} if "moving" in cell["variation"] else {}
    config = EvalConfig(task=cell["task"], variation=cell["variation"], episodes=cell["episodes"], seed=seed,
                        obstacle_scenes_only=cell["variation"] != "clean",
                        guidance=GuidanceChoice(cell["preset"], changes), workers=workers)
    result = evaluate(config)
    write_json(out, result)
    return result


def reference_source(commit: str, work: Path) -> Path:
    """A worktree of `commit` (made once), whose src/ the reference side imports."""
    folder = work / f"src_{commit}"
    if not folder.exists():
        subprocess.run(["git", "worktree", "add", "--detach", str(folder), commit], cwd=ROOT, check=True,
                       capture_output=True)
    return folder


def saved_reference(path: Path, seed: int, reference_commit: str) -> dict[str, list[dict]]:
    """The reference side's episodes per cell name, from an earlier run's results file of the same seed and
    reference commit."""
    record = json.loads(path.read_text())
    made = record["config"]
    if made["compared"] != [*COMPARED, "min_clearance"]:
        sys.exit(f"{path} compared {made['compared']}; run without --reference-from")
    if (made["seed"], made["reference_commit"]) != (seed, reference_commit):
        sys.exit(f"{path} was made with seed {made['seed']} against {made['reference_commit']}; "
                 "give the same --seed and --reference-commit, or run without --reference-from")
    return {cell["name"]: [{"seed": row["seed"], **row["reference"]} for row in cell["rows"]]
            for cell in record["cells"]}


def run_reference(cell: dict, seed: int, out: Path, source: Path) -> dict:
    """The reference commit's evaluation of a cell, through its own command line (cached in `out`)."""
    if out.exists():
        return json.loads(out.read_text())
    command = ["eval", "--task", cell["task"], "--variation", cell["variation"], "--episodes", str(cell["episodes"]),
               "--seed", str(seed), "--out", str(out), *REFERENCE_GUIDANCE[cell["preset"]]]
    if cell["variation"] != "clean":
        command.append("--obstacle-scenes-only")
    if "moving" in cell["variation"]:
        command.append("--refit-obstacles")
    environment = {**os.environ, "PYTHONPATH": str(source / "src"), "OMP_NUM_THREADS": "1"}
    launcher = "import sys; from lano3dp.cli import main; sys.argv[0] = 'lano3dp'; main()"
    subprocess.run([sys.executable, "-c", launcher, *command], env=environment, check=True, cwd=source)
    return json.loads(out.read_text())


def compare(reference: list[dict], after: list[dict]) -> list[dict]:
    """Per episode: both sides' outcomes and whether they are the same."""
    rows = []
    for old, new in zip(reference, after, strict=True):
        same = old["seed"] == new["seed"] and all(old[k] == new[k] for k in COMPARED)
        a, b = old["min_clearance"], new["min_clearance"]
        same = same and ((a is None and b is None) or (a is not None and b is not None
                                                         and abs(a - b) <= CLEARANCE_TOLERANCE))
        rows.append({"seed": new["seed"], "same": same,
                     "reference": {k: old[k] for k in (*COMPARED, "min_clearance")},
                     "after": {k: new[k] for k in (*COMPARED, "min_clearance")}})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tasks", default=",".join(TASKS))
    parser.add_argument("--presets", default="tuned,paper")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--extra-episodes", type=int, default=10, help="two-obstacle and moving-obstacle episodes")
    parser.add_argument("--seed", type=int, default=1_000_000)
    parser.add_argument("--reference-commit", default="f126fbe")
    parser.add_argument("--work", type=Path, default=ROOT / "bench" / "out" / "refactor_equivalence")
    parser.add_argument("--out-dir", type=Path, default=ROOT / "results")
    parser.add_argument("--tag", default="")
    parser.add_argument("--workers", type=int, default=1, help="this checkout's episode processes (each episode "
                                                               "is seeded alone: the outcomes do not depend on it)")
    parser.add_argument("--reference-from", type=Path, default=None,
                        help="take the reference side's outcomes from this earlier results file (same seed and "
                             "reference commit) instead of running it")
    args = parser.parse_args()

    saved = (saved_reference(args.reference_from, args.seed, args.reference_commit) if args.reference_from
             else None)
    source = None if saved is not None else reference_source(args.reference_commit, args.work)
    report = []
    for cell in cells(args.tasks.split(","), args.presets.split(","), args.episodes, args.extra_episodes):
        if saved is not None:
            if cell["name"] not in saved or len(saved[cell["name"]]) != cell["episodes"]:
                sys.exit(f"{args.reference_from} has no {cell['episodes']}-episode cell {cell['name']}; "
                         "run without --reference-from")
            reference_episodes = saved[cell["name"]]
        else:
            reference_path = args.work / "reference" / f"{cell['name']}.json"
            reference_episodes = run_reference(cell, args.seed, reference_path, source)["episodes"]
        after = run_after(cell, args.seed, args.work / "after" / f"{cell['name']}.json", args.workers)
        rows = compare(reference_episodes, after["episodes"])
        made = after.get("provenance") or {}
        report.append({**cell, "identical": all(r["same"] for r in rows), "episodes_compared": len(rows),
                       "after_commit": made.get("commit"), "after_dirty": made.get("dirty"),
                       "differing_seeds": [r["seed"] for r in rows if not r["same"]], "rows": rows})
        print(f"{cell['name']}: {sum(r['same'] for r in rows)}/{len(rows)} identical", flush=True)
    config = {"tasks": args.tasks, "presets": args.presets, "episodes": args.episodes, "workers": args.workers,
              "extra_episodes": args.extra_episodes, "seed": args.seed, "reference_commit": args.reference_commit,
              "reference_from": relative(args.reference_from) if args.reference_from else None,
              "compared": [*COMPARED, "min_clearance"], "clearance_tolerance_m": CLEARANCE_TOLERANCE}
    verdict = all(c["identical"] for c in report)
    table = markdown_table(["cell", "episodes", "identical"],
                           [[c["name"], c["episodes_compared"], "yes" if c["identical"] else
                             f"no: seeds {c['differing_seeds']}"] for c in report])
    page = (f"# Refactor equivalence against {args.reference_commit}\n\n"
            f"Every episode compared on {', '.join(config['compared'])} (clearance to {CLEARANCE_TOLERANCE:g} m): "
            f"{'all identical' if verdict else 'NOT all identical'}. This side's episodes ran at commit(s) "
            f"{', '.join(sorted({str(c['after_commit'])[:10] for c in report}))}; the reference side through "
            f"{args.reference_commit}'s own command line"
            f"{f' (its outcomes as saved in {relative(args.reference_from)})' if args.reference_from else ''}."
            f"\n\n{table}\n")
    command = shlex.join(["python", "bench/bench_refactor_equivalence.py",
                          *(relative(a) if Path(a).is_absolute() else a for a in sys.argv[1:])])
    write_script_results(f"refactor_equivalence{args.tag}", command=command, config=config,
                         body={"identical": verdict, "cells": report}, markdown=lambda record: page,
                         out_dir=args.out_dir)


if __name__ == "__main__":
    main()
