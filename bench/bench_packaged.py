"""The packaged policies on held-out scenes: does each reproduce the success its record claims?

Each shipped policy (`lano3dp/checkpoints/<task>`) was scored, and chosen, on clean seeds 1000000 + i. This
evaluates it on `--episodes` clean episodes of other seeds (`--seed`, default 2000000 + i), as a user would
right after install, and sets the result beside the recorded one:

    OMP_NUM_THREADS=1 python bench/bench_packaged.py

Resumable (an evaluation whose JSON exists in --work with the same configuration is skipped). Writes
results/packaged<tag>.json and .md headed by the command.
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path

from lano3dp.evaluate import EvalConfig
from lano3dp.jsonio import write_json
from lano3dp.pipeline import eval_stage
from lano3dp.policy.pretrained import packaged_checkpoints, packaged_record
from lano3dp.report import markdown_table, percent, wilson_interval

ROOT = Path(__file__).resolve().parent.parent


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--tasks", default=None, help="comma-separated (default: every packaged policy)")
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--seed", type=int, default=2_000_000, help="first seed (the records used 1000000)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--work", type=Path, default=ROOT / "bench" / "out" / "packaged")
    parser.add_argument("--tag", default="")
    parser.add_argument("--results", type=Path, default=ROOT / "results", help="folder of the JSON and Markdown")
    return parser.parse_args(argv)


def main(argv=None) -> None:
    args = parse_args(argv)
    shipped = packaged_checkpoints()
    tasks = args.tasks.split(",") if args.tasks else sorted(shipped)
    rows = []
    for task in tasks:
        config = EvalConfig(checkpoint=str(shipped[task]), task=task, variation="clean", episodes=args.episodes,
                            seed=args.seed, workers=args.workers, out=str(args.work / f"{task}.json"))
        summary = eval_stage(config, log=print)["summary"]
        successes = round(summary["success_rate"] * summary["episodes"])
        low, high = wilson_interval(successes, summary["episodes"])
        record = packaged_record(task)
        recorded = record.get("success_rate")
        rows.append({"task": task, "episodes": summary["episodes"], "successes": successes,
                     "success_rate": summary["success_rate"], "ci95": [low, high], "recorded_success": recorded,
                     "recorded_episodes": record.get("episodes"), "recipe": record.get("recipe"),
                     "recorded_within_interval": None if recorded is None else bool(low <= recorded <= high)})
        print(f"{task:20s} held-out {percent(summary['success_rate'])} ({percent(low)}-{percent(high)}), "
              f"recorded {percent(recorded) if recorded is not None else '-'}")
    given = sys.argv[1:] if argv is None else argv
    command = "python bench/bench_packaged.py" + "".join(f" {shlex.quote(a)}" for a in given)
    report = {"command": f"OMP_NUM_THREADS=1 {command}", "when_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
              "seed": args.seed, "episodes": args.episodes, "rows": rows}
    write_json(args.results / f"packaged{args.tag}.json", report)
    table = markdown_table(
        ["task", "recipe", "held-out success (95% CI)", "recorded (seeds 1000000 + i)", "recorded inside interval"],
        [[f"`{r['task']}`", r["recipe"] or "-",
          f"**{percent(r['success_rate'])}** ({r['successes']}/{r['episodes']}; {percent(r['ci95'][0])}–"
          f"{percent(r['ci95'][1])})",
          "-" if r["recorded_success"] is None else f"{percent(r['recorded_success'])} of {r['recorded_episodes']}",
          {True: "yes", False: "no", None: "-"}[r["recorded_within_interval"]]] for r in rows])
    text = (f"# Packaged policies on held-out clean scenes\n\nMade by `{report['command']}` ({report['when_utc']}).\n\n"
            f"{args.episodes} clean episodes per task, seeds {args.seed} + i, under the simulator's motion limits; "
            "the records' figures came from seeds 1000000 + i, on which the policies were also chosen.\n\n"
            f"{table}\n")
    (args.results / f"packaged{args.tag}.md").write_text(text)
    print(args.results / f"packaged{args.tag}.md")


if __name__ == "__main__":
    main()
