"""The generalisation rows of Lan-o3dp with the ground-truth segmenter and with the perception error model, side by
side (issue 36, item 2).

Each cell is one `lano3dp eval --task T --variation V --episodes N --segmenter S` of the packaged policy (the same
`EpisodeRunner`, episode seeds 1000000 + i), run here episode by episode so that every episode also records what
the error model did to it: which object each phrase was grounded on, and how many frames were lost or had a
boundary error. Cells are saved under --work as they finish (a re-run skips them); the report is made from them.

    OMP_NUM_THREADS=1 python bench/bench_perception_errors.py --episodes 20
    python bench/bench_perception_errors.py --report-only

writes results/perception_error_model.{json,md}.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from pathlib import Path

from _contract import relative, write_script_results

ROOT = Path(__file__).resolve().parent.parent
SEGMENTERS = {"sim": "oracle (ground truth)", "error-model": "error model"}


def cell_path(work: Path, task: str, variation: str, segmenter: str, episodes: int) -> Path:
    return work / f"{task}_{variation}_{segmenter}_{episodes}.json"


def run_cell(task: str, variation: str, segmenter: str, episodes: int, seed: int, out: Path) -> dict:
    from lano3dp.evaluate import EpisodeRunner, EvalConfig, summarize

    from lano3dp.policy.pretrained import PACKAGED_ROOT

    config = EvalConfig(checkpoint=str(PACKAGED_ROOT / task), task=task, variation=variation, episodes=episodes,
                        seed=seed, perception={"segmenter": segmenter})
    runner = EpisodeRunner(config)
    records, started = [], time.perf_counter()
    for episode_seed in range(seed, seed + episodes):
        record = runner.run(episode_seed)
        record.pop("ee_path", None)
        perception = runner.observer.segmenter
        if hasattr(perception, "counts"):
            record["perception"] = {"groundings": perception.groundings,
                                    "misgroundings": perception.misgroundings,
                                    "events": {k: v for k, v in perception.counts.items() if k != "calls"}}
        records.append(record)
        print(f"{task} {variation} {segmenter} seed {episode_seed}: success {record['success']}"
              f" {record.get('perception', {}).get('events', '')}", flush=True)
    runner.close()
    result = {"config": {"task": task, "variation": variation, "segmenter": segmenter, "episodes": episodes,
                         "seed": seed},
              "command": f"lano3dp eval --task {task} --variation {variation} --episodes {episodes} "
                         f"--segmenter {segmenter}",
              "summary": summarize(records), "episodes": records, "wall_s": round(time.perf_counter() - started, 1)}
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1, default=str) + "\n")
    return result


def perception_account(result: dict) -> dict:
    """Episodes with a phrase grounded on another object, with one never found, how they ended, and the error
    model's events summed over the cell."""
    wrong = [r for r in result["episodes"]
             if any(chosen is not None for _, chosen in ((r.get("perception") or {}).get("misgroundings") or {})
                    .values())]
    missed = [r for r in result["episodes"]
              if any(chosen is None for _, chosen in ((r.get("perception") or {}).get("misgroundings") or {})
                     .values())]
    events = {}
    for record in result["episodes"]:
        for key, value in ((record.get("perception") or {}).get("events") or {}).items():
            events[key] = events.get(key, 0) + value
    return {"wrong_object_episodes": len(wrong), "wrong_object_successes": sum(r["success"] for r in wrong),
            "never_found_episodes": len(missed), "events": events}


def report(args, command: str) -> dict:
    from lano3dp.perception import PerceptionErrorModel
    from lano3dp.report import markdown_table, percent, wilson_interval

    cells, rows = [], []
    for task in args.tasks.split(","):
        for variation in args.variations.split(","):
            row = [f"`{task}`", variation]
            for segmenter in SEGMENTERS:
                path = cell_path(args.work, task, variation, segmenter, args.episodes)
                if not path.exists():
                    row.append("not run")
                    continue
                result = json.loads(path.read_text())
                summary = result["summary"]
                successes, n = summary["successes"], summary["episodes"]
                low, high = wilson_interval(successes, n)
                cell = {"task": task, "variation": variation, "segmenter": segmenter, "episodes": n,
                        "successes": successes, "success_rate": summary["success_rate"],
                        "ci95": [round(low, 4), round(high, 4)], "error_rate": summary.get("error_rate"),
                        "stage_rates": summary.get("stage_rates"), "command": result["command"],
                        "seeds": [result["config"]["seed"], result["config"]["seed"] + n - 1]}
                if segmenter == "error-model":
                    cell["perception"] = perception_account(result)
                cells.append(cell)
                row.append(f"{percent(summary['success_rate'])} ({successes}/{n}; {percent(low)}–{percent(high)})")
            cell = next((c for c in cells if (c["task"], c["variation"], c["segmenter"]) ==
                         (task, variation, "error-model")), None)
            account = cell["perception"] if cell else None
            row.append(f"{account['wrong_object_episodes']} wrong object ({account['wrong_object_successes']} "
                       f"still succeeded), {account['never_found_episodes']} never found" if account else "")
            rows.append(row)
    body = {"error_model": PerceptionErrorModel().to_dict(), "error_model_doc": "docs/perception-error-model.md",
            "cells": cells,
            "note": "packaged policies; 'sim' is the simulator's ground-truth segmenter, 'error-model' the same "
                    "masks through perception.error_model.PerceptionErrorModel() (published-numbers rates); the same "
                    "episode seeds for both. perception.events sums ErrorModelSegmenter.counts over a cell's "
                    "episodes: segment calls affected, so a frame the runtime asks about twice (targets together, "
                    "then one by one after a loss; other views) counts twice"}
    page = "\n".join([
        "# Generalisation rows: ground-truth segmenter against the perception error model", "",
        "Each cell's `lano3dp eval` command is in the JSON. Packaged policies, "
        f"{args.episodes} episodes per cell on the same seeds (1000000 + i) for both segmenters; success with its "
        "95% Wilson interval. The error model and where each of its rates comes from: "
        "docs/perception-error-model.md.", "",
        markdown_table(["task", "variation", SEGMENTERS["sim"], SEGMENTERS["error-model"],
                        "error model: episodes grounded on another object / never found"], rows), ""])
    config = {name: relative(value) if isinstance(value, Path) else value for name, value in vars(args).items()
              if name != "work"}
    path = write_script_results("perception_error_model", command=command, config=config, body=body,
                                markdown=lambda record: page)
    return json.loads(path.read_text())


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tasks", default="put_item_in_drawer,open_drawer")
    parser.add_argument("--variations", default="clean,clutter,similar,instance,camera,background")
    parser.add_argument("--segmenters", default="error-model,sim", help="which columns to run, in this order")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=1_000_000)
    parser.add_argument("--work", type=Path, default=ROOT / "bench" / "out" / "perception")
    parser.add_argument("--report-only", action="store_true")
    args = parser.parse_args(argv)
    command = "OMP_NUM_THREADS=1 python bench/bench_perception_errors.py " + shlex.join(
        sys.argv[1:] if argv is None else argv)
    if not args.report_only:
        import torch

        torch.set_num_threads(1)
        for segmenter in args.segmenters.split(","):
            for task in args.tasks.split(","):
                for variation in args.variations.split(","):
                    out = cell_path(args.work, task, variation, segmenter, args.episodes)
                    if not out.exists():
                        run_cell(task, variation, segmenter, args.episodes, args.seed, out)
    report(args, command)
    print((ROOT / "results" / "perception_error_model.md").read_text())


if __name__ == "__main__":
    main()
