"""The packaged policies on held-out scenes: does each reproduce the success its record claims?

Each shipped policy (`lano3dp/checkpoints/<task>`) was scored, and chosen, on clean seeds 1000000 + i. This
evaluates it on `--episodes` clean episodes of other seeds (`--seed`, default 2000000 + i), as a user would
right after install, and sets the result beside the recorded one:

    OMP_NUM_THREADS=1 python bench/bench_packaged.py

Resumable (an evaluation in --work that is current, `pipeline.eval_stage`, is reused). Writes
<out-dir>/packaged<tag>.json and .md.
"""

from __future__ import annotations

from pathlib import Path

from _contract import bench_parser, parse, write_results
from lano3dp.evaluation import EvalConfig
from lano3dp.pipeline import eval_stage
from lano3dp.policy.pretrained import packaged_checkpoints, packaged_record
from lano3dp.report import markdown_table, percent, wilson_interval


def parse_args(argv=None):
    parser = bench_parser(__file__, __doc__, tasks=",".join(packaged_checkpoints()), episodes=50, seed=2_000_000,
                          workers=2)
    parser.add_argument("--work", type=Path, default=Path("bench/out/packaged"), help="the evaluations (cached)")
    return parse(parser, argv)


def main(argv=None) -> None:
    args = parse_args(argv)
    shipped = packaged_checkpoints()
    if unknown := sorted(set(args.tasks) - set(shipped)):
        raise SystemExit(f"no packaged policy for {', '.join(unknown)}; packaged: {', '.join(shipped)}")
    rows = []
    for task in args.tasks:
        config = EvalConfig(task=task, variation="clean", episodes=args.episodes, seed=args.seed,
                            workers=args.workers, out=str(args.work / f"{task}.json"))
        summary = eval_stage(config, log=print, command=args.command)["summary"]
        successes = summary["successes"]
        low, high = wilson_interval(successes, summary["episodes"])
        record = packaged_record(task)
        recorded = record.get("success_rate")
        rows.append({"task": task, "episodes": summary["episodes"], "successes": successes,
                     "success_rate": summary["success_rate"], "ci95": [low, high], "recorded_success": recorded,
                     "recorded_episodes": record.get("episodes"), "recipe": record.get("recipe"),
                     "recorded_within_interval": None if recorded is None else bool(low <= recorded <= high)})
        print(f"{task:20s} held-out {percent(summary['success_rate'])} ({percent(low)}-{percent(high)}), "
              f"recorded {percent(recorded) if recorded is not None else '-'}")
    print(write_results("packaged", args, {"seed": args.seed, "episodes": args.episodes, "rows": rows},
                        markdown=markdown_report).with_suffix(".md"))


def markdown_report(report: dict) -> str:
    rows = report["rows"]
    table = markdown_table(
        ["task", "recipe", "held-out success (95% CI)", "recorded (seeds 1000000 + i)", "recorded inside interval"],
        [[f"`{r['task']}`", r["recipe"] or "-",
          f"**{percent(r['success_rate'])}** ({r['successes']}/{r['episodes']}; {percent(r['ci95'][0])}–"
          f"{percent(r['ci95'][1])})",
          "-" if r["recorded_success"] is None else f"{percent(r['recorded_success'])} of {r['recorded_episodes']}",
          {True: "yes", False: "no", None: "-"}[r["recorded_within_interval"]]] for r in rows])
    return (f"# Packaged policies on held-out clean scenes\n\n"
            f"{report['episodes']} clean episodes per task, seeds {report['seed']} + i, under the simulator's motion "
            "limits; the records' figures came from seeds 1000000 + i, on which the policies were also chosen.\n\n"
            f"{table}\n")


if __name__ == "__main__":
    main()
