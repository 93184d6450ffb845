"""Choose the guidance each packaged policy ships with (its guidance.json), on tuning scenes only.

For each task, each candidate below guides the packaged policy on the first --episodes obstacle scenes from seed
3000000 (scenes `bench_obstacles` never uses: its table starts at 1000000, the held-out clean scenes at 2000000).
The rule, fixed before the tuning scenes were widened from 50 to 100 (and before those runs): the candidate with
the most successes among those touching the obstacle in at most 5% of episodes; ties go to the recommended
preset. `--write` saves the winner into the evaluated folder (nothing when the recommended preset wins, and an
earlier file is then removed): the packaged one, or the policy folder `--policy TASK=PATH` names (a candidate
exported with `lano3dp.policy.pretrained.export_fp16`, tuned before it is shipped).

    recommended   the recommended preset
    turned        recommended, each obstacle's push turned 60 degrees round it (cost.push_turn=60)
    turned_half   turned, with half the push (sampler.rho=0.02)

    OMP_NUM_THREADS=1 python bench/bench_guidance_tuning.py --write        # ~15 min on 2 cores

Resumable (current evaluations in --work are reused). Writes <out-dir>/guidance_tuning<tag>.json and .md. The
table rows that the chosen settings then earn come from `bench_obstacles.py` (sampler default).
"""

from __future__ import annotations

import time
from pathlib import Path

from _contract import bench_parser, parse, write_results
from lano3dp.evaluation import EvalConfig, GuidanceChoice
from lano3dp.guidance.settings import GUIDANCE_TUNING_NAME, save_guidance_tuning
from lano3dp.pipeline import eval_stage
from lano3dp.policy.pretrained import packaged_checkpoint
from lano3dp.report import markdown_table, percent, wilson_interval

TUNING_SEED = 3_000_000
MAX_TOUCH = 0.05
PRESET = "recommended"
# candidate -> the dotted overrides it sets on the recommended preset (what guidance.json would hold)
CANDIDATES = {
    "recommended": {},
    "turned": {"cost.push_turn": 60.0},
    "turned_half": {"cost.push_turn": 60.0, "sampler.rho": 0.02},
}


def parse_args(argv=None):
    parser = bench_parser(__file__, __doc__, tasks="bowl_pour,put_item_in_drawer,bottle_in_drawer", episodes=100,
                          seed=TUNING_SEED, workers=2)
    parser.add_argument("--work", default="bench/out/guidance_tuning", help="the evaluations (cached)")
    parser.add_argument("--policy", action="append", default=[], metavar="TASK=PATH",
                        help="tune this policy folder for TASK instead of the packaged policy")
    parser.add_argument("--write", action="store_true", help="save each task's winner into the folder evaluated")
    return parse(parser, argv)


def choose(scores: dict[str, dict]) -> str:
    """The rule: most successes among candidates touching in at most MAX_TOUCH of episodes; ties to the first
    listed (the recommended preset)."""
    allowed = [name for name, score in scores.items() if score["touches"] <= MAX_TOUCH * score["episodes"]]
    return max(allowed, key=lambda name: scores[name]["successes"]) if allowed else "recommended"


def main(argv=None) -> int:
    args = parse_args(argv)
    work = Path(args.work)
    started = time.perf_counter()
    body: dict = {"candidates": {name: {"preset": PRESET, "overrides": changes}
                                 for name, changes in CANDIDATES.items()},
                  "tuning_seed": args.seed, "rule": "most successes among candidates touching in at most 5% of "
                                                    "episodes; ties to the recommended preset", "tasks": {}}
    policies = {task: Path(path) for task, path in (item.split("=", 1) for item in args.policy)}
    for task in args.tasks:
        checkpoint = policies.get(task) or packaged_checkpoint(task)
        scores = {}
        for name, changes in CANDIDATES.items():
            print(f"[{time.perf_counter() - started:6.0f}s] {task} / {name}", flush=True)
            # each candidate on the recommended preset, whatever guidance.json the folder holds now
            config = EvalConfig(checkpoint=str(checkpoint), task=task, variation="obstacle", episodes=args.episodes,
                                seed=args.seed, obstacle_scenes_only=True, workers=args.workers,
                                guidance=GuidanceChoice(PRESET, changes), out=str(work / task / f"{name}.json"))
            result = eval_stage(config, command=args.command)
            summary, touches = result["summary"], sum(bool(e["collided"]) for e in result["episodes"])
            scores[name] = {"episodes": summary["episodes"], "successes": summary["successes"], "touches": touches,
                            "success_interval": list(wilson_interval(summary["successes"], summary["episodes"])),
                            "stage_rates": summary["stage_rates"]}
        winner = choose(scores)
        body["tasks"][task] = {"scores": scores, "chosen": winner, "overrides": CANDIDATES[winner]}
        if args.write:
            path = checkpoint / GUIDANCE_TUNING_NAME
            if CANDIDATES[winner]:
                save_guidance_tuning(checkpoint, CANDIDATES[winner], preset_name=PRESET, measured=(
                    f"chosen by `{args.command}` (results/guidance_tuning{args.tag}.md): {winner}, "
                    f"{scores[winner]['successes']} of {scores[winner]['episodes']} tuning obstacle scenes from seed "
                    f"{args.seed}, against {scores['recommended']['successes']} with the recommended preset"))
            elif path.exists():
                path.unlink()
        write_results("guidance_tuning", args, body, markdown=markdown_report)
    return 0


def _candidate(entry) -> str:
    if isinstance(entry, dict) and "overrides" in entry:  # {"preset", "overrides"}
        return f"{entry['preset']} {entry['overrides']}" if entry["overrides"] else "(the preset)"
    return str(entry or "(the preset)")  # files made before the presets: the flat fields it set


def markdown_report(results: dict) -> str:
    rows = []
    for task, entry in results["tasks"].items():
        for name, score in entry["scores"].items():
            low, high = score["success_interval"]
            rows.append([task, ("**" + name + "**") if name == entry["chosen"] else name,
                         f"{score['successes']}/{score['episodes']} ({percent(low)}–{percent(high)})",
                         f"{score['touches']}/{score['episodes']}"])
    return "\n".join([
        "# Guidance tuned per packaged policy", "",
        f"Tuning scenes: the first obstacle scenes from seed {results['tuning_seed']} with room for the obstacle. "
        f"Rule: {results['rule']}. Candidates: " + "; ".join(f"**{name}** {_candidate(entry)}"
                                                             for name, entry in results["candidates"].items())
        + ". The chosen one is in bold; intervals are 95% Wilson.", "",
        markdown_table(["task", "candidate", "success", "touched"], rows), ""])


if __name__ == "__main__":
    raise SystemExit(main())
