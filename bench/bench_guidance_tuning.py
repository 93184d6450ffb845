"""Choose the guidance each packaged policy ships with (its guidance.json), on tuning scenes only.

For each task, each candidate below guides the packaged policy on the first --episodes obstacle scenes from seed
3000000 (scenes `bench_obstacles` never uses: its table starts at 1000000, the held-out clean scenes at 2000000).
The rule, fixed before the tuning scenes were widened from 50 to 100 (and before those runs): the candidate with
the most successes among those touching the obstacle in at most 5% of episodes; ties go to the recommended
preset. `--write` saves the winner into the evaluated folder (nothing when the recommended preset wins, and an
earlier file is then removed): the packaged one, or the policy folder `--policy TASK=PATH` names (a candidate
exported with `lano3dp.policy.pretrained.export_fp16`, tuned before it is shipped).

    recommended   the recommended preset (`GuidanceSettings()`)
    turned        each obstacle's push turned 60 degrees round it (`TurnedPush`)
    turned_half   turned, with half the push (rho 0.02)

    OMP_NUM_THREADS=1 python bench/bench_guidance_tuning.py --write        # ~15 min on 2 cores

Resumable (evaluations are cached in --work). Writes results/guidance_tuning<tag>.json and .md headed by the
command. The table rows that the chosen settings then earn come from `bench_obstacles.py` (sampler default).
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path

from lano3dp.evaluate import EvalConfig
from lano3dp.guidance.settings import GUIDANCE_TUNING_NAME, save_guidance_tuning
from lano3dp.jsonio import write_json
from lano3dp.pipeline import eval_stage
from lano3dp.policy.pretrained import packaged_checkpoint
from lano3dp.report import markdown_table, percent, wilson_interval

ROOT = Path(__file__).resolve().parent.parent
TUNING_SEED = 3_000_000
MAX_TOUCH = 0.05
# candidate -> the GuidanceSettings fields it sets over the recommended preset (what guidance.json would hold)
CANDIDATES = {
    "recommended": {},
    "turned": {"push_turn": 60.0},
    "turned_half": {"push_turn": 60.0, "rho": 0.02},
}


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tasks", default="bowl_pour,put_item_in_drawer,bottle_in_drawer")
    parser.add_argument("--episodes", type=int, default=100, help="tuning obstacle scenes per candidate")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--work", default="bench/out/guidance_tuning")
    parser.add_argument("--tag", default="")
    parser.add_argument("--policy", action="append", default=[], metavar="TASK=PATH",
                        help="tune this policy folder for TASK instead of the packaged policy")
    parser.add_argument("--write", action="store_true", help="save each task's winner into the folder evaluated")
    return parser.parse_args(argv)


def choose(scores: dict[str, dict]) -> str:
    """The rule: most successes among candidates touching in at most MAX_TOUCH of episodes; ties to the first
    listed (the recommended preset)."""
    allowed = [name for name, score in scores.items() if score["touches"] <= MAX_TOUCH * score["episodes"]]
    return max(allowed, key=lambda name: scores[name]["successes"]) if allowed else "recommended"


def main(argv=None) -> int:
    args = parse_args(argv)
    tasks = [t for t in args.tasks.split(",") if t]
    work = Path(args.work)
    command = shlex.join(["python", "bench/bench_guidance_tuning.py", *(argv if argv is not None else sys.argv[1:])])
    started = time.perf_counter()
    results: dict = {"command": command, "config": vars(args), "candidates": CANDIDATES, "tuning_seed": TUNING_SEED,
                     "rule": "most successes among candidates touching in at most 5% of episodes; ties to the "
                             "recommended preset", "tasks": {}}
    policies = {task: Path(path) for task, path in (item.split("=", 1) for item in args.policy)}
    for task in tasks:
        checkpoint = policies.get(task) or packaged_checkpoint(task)
        scores = {}
        for name, settings in CANDIDATES.items():
            print(f"[{time.perf_counter() - started:6.0f}s] {task} / {name}", flush=True)
            # tuned=False: each candidate as written, whatever guidance.json the folder holds now
            config = EvalConfig(checkpoint=str(checkpoint), task=task, variation="obstacle", episodes=args.episodes,
                                seed=TUNING_SEED, obstacle_scenes_only=True, workers=args.workers,
                                guidance={"mode": "clean", **settings, "tuned": False},
                                out=str(work / task / f"{name}.json"))
            result = eval_stage(config, command=command)
            summary, touches = result["summary"], sum(bool(e["collided"]) for e in result["episodes"])
            scores[name] = {"episodes": summary["episodes"], "successes": summary["successes"], "touches": touches,
                            "success_interval": list(wilson_interval(summary["successes"], summary["episodes"])),
                            "stage_rates": summary["stage_rates"]}
        winner = choose(scores)
        results["tasks"][task] = {"scores": scores, "chosen": winner, "settings": CANDIDATES[winner]}
        if args.write:
            path = checkpoint / GUIDANCE_TUNING_NAME
            if CANDIDATES[winner]:
                save_guidance_tuning(checkpoint, CANDIDATES[winner], measured=(
                    f"chosen by `{command}` (results/guidance_tuning{args.tag}.md): {winner}, "
                    f"{scores[winner]['successes']} of {scores[winner]['episodes']} tuning obstacle scenes from seed "
                    f"{TUNING_SEED}, against {scores['recommended']['successes']} with the recommended preset"))
            elif path.exists():
                path.unlink()
        write_json(ROOT / "results" / f"guidance_tuning{args.tag}.json", results)
        (ROOT / "results" / f"guidance_tuning{args.tag}.md").write_text(markdown_report(results))
    return 0


def markdown_report(results: dict) -> str:
    rows = []
    for task, entry in results["tasks"].items():
        for name, score in entry["scores"].items():
            low, high = score["success_interval"]
            rows.append([task, ("**" + name + "**") if name == entry["chosen"] else name,
                         f"{score['successes']}/{score['episodes']} ({percent(low)}–{percent(high)})",
                         f"{score['touches']}/{score['episodes']}"])
    return "\n".join([
        "# Guidance tuned per packaged policy", "", f"Command: `{results['command']}`", "",
        f"Tuning scenes: the first obstacle scenes from seed {results['tuning_seed']} with room for the obstacle. "
        f"Rule: {results['rule']}. Candidates: " + "; ".join(f"**{name}** {settings or '(the preset)'}"
                                                             for name, settings in results["candidates"].items())
        + ". The chosen one is in bold; intervals are 95% Wilson.", "",
        markdown_table(["task", "candidate", "success", "touched"], rows), ""])


if __name__ == "__main__":
    raise SystemExit(main())
