"""Evaluation speed: episodes per CPU-second of `evaluate`, sequential and batched, episode for episode the same.

Everything is process CPU time (`time.process_time`, all threads) on one torch thread, measured side by side in one
run, so the ratios hold on a busy machine (the absolute numbers do not). Parts, on a packaged policy (--tasks):

    load       a fresh process importing torch, then the policy and loading the checkpoint; beside it what
               importing diffusers costs, which every policy load paid before the own DDPM/DDIM steps
    sampling   predict_action_chunk: CPU ms per chunk at batch 1 and per chunk at batch --batch (DDIM-10), median
               over --chunks calls
    modes      after one untimed episode of each condition (`warm_up`), `evaluate` of --episodes clean episodes
               (unguided) and --episodes obstacle episodes (obstacle scenes only, the checkpoint's tuned guidance):
                   sequential   one episode after another (EvalConfig(batch=1))
                   batched      --batch episodes stepped together, their chunks sampled in one call, and the
                                same for each --also-batch (50: the whole evaluation at once)
               each with its per-episode outcomes (success, steps, contact), compared episode by episode, and
               the largest difference in an episode's minimum clearance to the obstacle

50 episodes, a table's size, so that the batch stays full for most of the run: at 24 the later episodes end
nearly alone and the batched ratio falls (1.22 clean at 24, 1.96 at 50, one run each).

    OMP_NUM_THREADS=1 python bench/bench_eval_speed.py                  # ~5 CPU-minutes
    OMP_NUM_THREADS=1 python bench/bench_eval_speed.py --episodes 4 --chunks 5 --tag _smoke
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import time
from typing import Any

import numpy as np
import torch

from _contract import Unused, bench_parser, parse, write_results
from lano3dp.evaluation import EvalConfig, GuidanceChoice, evaluate
from lano3dp.policy import DiffusionPolicy
from lano3dp.policy.pretrained import packaged_checkpoint
from lano3dp.report import markdown_table

# Conditions of a mode: the variation and guidance each evaluates.
CONDITIONS = {
    "clean": dict(variation="clean", guidance="none"),
    "obstacle": dict(variation="obstacle", guidance="tuned", obstacle_scenes_only=True),
}
COMPARED = ("success", "steps", "collided")  # an episode's outcome

LOAD_CODE = """
import sys, time
started = time.process_time()
import torch  # noqa: F401
imported = time.process_time()
from lano3dp.policy import DiffusionPolicy
from lano3dp.policy.pretrained import packaged_checkpoint
DiffusionPolicy.from_pretrained(packaged_checkpoint(sys.argv[1]))
loaded = time.process_time()
dynamo = "torch._dynamo" in sys.modules
try:
    from diffusers import DDIMScheduler, DDPMScheduler  # noqa: F401
    diffusers_s = round(time.process_time() - loaded, 3)
except ImportError:
    diffusers_s = None
print(round(imported - started, 3), round(loaded - imported, 3), diffusers_s, dynamo)
"""


def load_cost(task: str, repeats: int = 3) -> dict[str, Any]:
    """CPU-s of a fresh process importing the policy and loading `task`'s checkpoint (median of `repeats`)."""
    rows = []
    for _ in range(repeats):
        out = subprocess.run([sys.executable, "-c", LOAD_CODE, task], capture_output=True, text=True, check=True,
                             env=os.environ | {"OMP_NUM_THREADS": "1"}).stdout.split()
        rows.append((float(out[0]), float(out[1]), None if out[2] == "None" else float(out[2]), out[3] == "True"))
    diffusers = [row[2] for row in rows if row[2] is not None]
    return {"torch_import_cpu_s": statistics.median(row[0] for row in rows),
            "policy_import_and_load_cpu_s": statistics.median(row[1] for row in rows),
            "diffusers_import_cpu_s": statistics.median(diffusers) if diffusers else None,
            "torch_dynamo_imported_by_load": any(row[3] for row in rows), "repeats": repeats}


def observation(policy: DiffusionPolicy, seed: int, batch: int) -> dict[str, np.ndarray]:
    """Object clouds round random centres in the workspace and a state inside the training range."""
    rng = np.random.default_rng(seed)
    config = policy.config
    stats = policy.normalizer_stats()["state"]
    centres = rng.uniform([0.3, -0.3, 0.05], [0.7, 0.3, 0.15], size=(batch, 1, config.n_slots, 1, 3))
    clouds = centres + rng.normal(0, 0.03, size=(batch, 1, config.n_slots, config.n_points, 3))
    state = rng.uniform(stats["min"], stats["max"], size=(batch, 1, config.state_dim))
    return {"object_clouds": clouds.astype(np.float32), "state": state.astype(np.float32)}


def chunk_costs(task: str, chunks: int, batch: int) -> dict[str, Any]:
    """Median CPU ms per DDIM-10 chunk sampled alone and within a batch of `batch`, interleaved call by call."""
    policy = DiffusionPolicy.from_pretrained(packaged_checkpoint(task))
    alone, together = [], []
    for index in range(chunks + 1):  # the first warms up
        obs = observation(policy, index, batch)
        started = time.process_time()
        policy.predict_action_chunk({k: v[:1] for k, v in obs.items()}, generator=torch.Generator().manual_seed(0))
        spent_alone = time.process_time() - started
        started = time.process_time()
        policy.predict_action_chunk(obs, generator=[torch.Generator().manual_seed(i) for i in range(batch)])
        spent_together = (time.process_time() - started) / batch
        if index:
            alone.append(spent_alone)
            together.append(spent_together)
    alone_ms, together_ms = 1000 * statistics.median(alone), 1000 * statistics.median(together)
    return {"cpu_ms_per_chunk_alone": round(alone_ms, 2), "cpu_ms_per_chunk_batched": round(together_ms, 2),
            "batch": batch, "chunks": chunks, "alone_over_batched": round(alone_ms / together_ms, 2)}


def warm_up(task: str, seed: int) -> None:
    """One untimed episode of each condition, so that neither mode pays what a process pays once (the English
    lexicon of the scene's object names, the first GL context, lazy imports): the sequential mode, timed first,
    paid them before."""
    for condition in CONDITIONS.values():
        condition = dict(condition, guidance=GuidanceChoice(condition["guidance"]))
        evaluate(EvalConfig(task=task, episodes=1, seed=seed, **condition))


def run_mode(task: str, episodes: int, seed: int, batch: int) -> dict[str, Any]:
    """`evaluate` of every condition in this process: its CPU time and per-episode outcomes."""
    results = {}
    for name, condition in CONDITIONS.items():
        condition = dict(condition, guidance=GuidanceChoice(condition["guidance"]))
        config = EvalConfig(task=task, episodes=episodes, seed=seed, batch=batch, **condition)
        started = time.process_time()
        result = evaluate(config)
        spent = time.process_time() - started
        outcomes = [{"seed": e["seed"], **{k: e[k] for k in COMPARED}, "min_clearance": e["min_clearance"]}
                    for e in result["episodes"]]
        results[name] = {"episodes": len(outcomes), "cpu_s": round(spent, 2),
                         "episodes_per_cpu_s": round(len(outcomes) / spent, 4), "outcomes": outcomes,
                         "successes": sum(o["success"] for o in outcomes)}
        print(f"batch {batch:>2} {name:>8}: {len(outcomes)} episodes in {spent:.1f} CPU-s "
              f"({len(outcomes) / spent:.3f} per CPU-s), success {results[name]['successes']}/{len(outcomes)}",
              flush=True)
    return results


def same_outcome(a: dict, b: dict) -> bool:
    return a["seed"] == b["seed"] and all(a[k] == b[k] for k in COMPARED)


def clearance_difference(a: dict, b: dict) -> float | None:
    """|a - b| of the episode's minimum clearance in m; None where neither saw an obstacle, inf where one did."""
    x, y = a["min_clearance"], b["min_clearance"]
    if x is None and y is None:
        return None
    return float("inf") if x is None or y is None else abs(x - y)


def batched_modes(record: dict[str, Any]) -> list[tuple[int, dict, dict]]:
    """(batch, mode, comparisons) of every batched mode of a record: --batch, then each --also-batch."""
    modes = [(record["config"]["batch"], record["modes"]["batched"], record["comparisons"])]
    for batch, comparisons in record.get("comparisons_also", {}).items():
        modes.append((int(batch), record["modes"][f"batched_{batch}"], comparisons))
    return modes


def compare(sequential: dict, batched: dict) -> dict[str, Any]:
    """Per condition: the ratio of episodes per CPU-second and how many episodes ended the same."""
    comparisons = {}
    for name in CONDITIONS:
        pairs = list(zip(sequential[name]["outcomes"], batched[name]["outcomes"], strict=True))
        differences = [d for d in (clearance_difference(a, b) for a, b in pairs) if d is not None]
        comparisons[name] = {
            "batched_over_sequential": round(batched[name]["episodes_per_cpu_s"]
                                             / sequential[name]["episodes_per_cpu_s"], 2),
            "same_outcomes": sum(same_outcome(a, b) for a, b in pairs), "episodes": len(pairs),
            "largest_clearance_difference_m": max(differences) if differences else None}
    return comparisons


def markdown(record: dict[str, Any]) -> str:
    rows = []
    for batch, batched, comparisons in batched_modes(record):
        for name in CONDITIONS:
            sequential, comparison = record["modes"]["sequential"][name], comparisons[name]
            largest = comparison["largest_clearance_difference_m"]
            rows.append([name, batch, sequential["episodes"], sequential["episodes_per_cpu_s"],
                         batched[name]["episodes_per_cpu_s"], comparison["batched_over_sequential"],
                         f"{comparison['same_outcomes']} of {sequential['episodes']}",
                         "no obstacle" if largest is None else f"{largest:.1e}"])
    sampling = record["sampling"]
    machine = (record.get("provenance") or {}).get("machine") or {}
    on = f"Measured on {machine['processor']}, {machine.get('cpu_count')} cores, one torch thread.\n\n" if (
        machine.get("processor")) else ""
    return ("# Evaluation speed: sequential and batched\n\n## Episodes per CPU-second\n\n" + on
            + markdown_table(["condition", "batch", "episodes", "sequential", "batched",
                              "ratio", "same outcome (success, steps, contact)",
                              "largest clearance difference (m)"], rows)
            + f"\n\nDDIM-10 chunk: {sampling['cpu_ms_per_chunk_alone']} CPU-ms alone, "
              f"{sampling['cpu_ms_per_chunk_batched']} CPU-ms each in a batch of {sampling['batch']} "
              f"({sampling['alone_over_batched']}x). Policy load: {record['load']['policy_import_and_load_cpu_s']} "
              f"CPU-s (diffusers, no longer imported: {record['load']['diffusers_import_cpu_s']} CPU-s).\n")


def main(argv: list[str] | None = None) -> None:
    parser = bench_parser(__file__, __doc__, tasks="put_item_in_drawer", episodes=50, seed=1_000_000,
                          workers=Unused("batched evaluation runs in one process; the ratio is per CPU-second"))
    parser.add_argument("--batch", type=int, default=16, help="episodes stepped together in the batched mode")
    parser.add_argument("--also-batch", type=int, nargs="*", default=[50],
                        help="further batch sizes measured in the same run (50: a 50-episode evaluation at once)")
    parser.add_argument("--chunks", type=int, default=20, help="sampling calls timed")
    args = parse(parser, argv)
    torch.set_num_threads(1)
    (task,) = args.tasks
    body: dict[str, Any] = {"load": load_cost(task), "sampling": chunk_costs(task, args.chunks, args.batch)}
    print(f"load {body['load']}\nsampling {body['sampling']}", flush=True)
    warm_up(task, args.seed - 1)
    body["modes"] = {"sequential": run_mode(task, args.episodes, args.seed, 1),
                     "batched": run_mode(task, args.episodes, args.seed, args.batch)}
    body["comparisons"] = compare(body["modes"]["sequential"], body["modes"]["batched"])
    body["comparisons_also"] = {}
    for batch in args.also_batch:
        body["modes"][f"batched_{batch}"] = run_mode(task, args.episodes, args.seed, batch)
        body["comparisons_also"][str(batch)] = compare(body["modes"]["sequential"], body["modes"][f"batched_{batch}"])
    print(body["comparisons"], body["comparisons_also"])
    setup = {"task": task, "checkpoint": f"packaged:{task}", "episodes": args.episodes, "seed": args.seed,
              "batch": args.batch, "also_batch": args.also_batch, "chunks": args.chunks, "conditions": CONDITIONS,
              "clock": "process CPU time (time.process_time, every thread), one torch thread"}
    write_results("bench_eval_speed", args, {**body, "setup": setup}, markdown=markdown)


if __name__ == "__main__":
    main()
