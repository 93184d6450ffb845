"""Obstacle avoidance that keeps the task: the paper's bowl-pour test (its Fig. 4) and two more.

Per task, the policy packaged for it (`lano3dp eval --task T` without --checkpoint) is evaluated
  - on clean scenes (its clean success, the reference), and
  - with a novel obstacle on the demonstrated path, by four samplers:
        none      no guidance
        A_k       the cost on the noisy sample A_k (the prior work the paper contrasts with), otherwise as default
                  without the two additions of the project's own (the path costed from the hand, the push after
                  sampling)
        paper     the paper's form: A_0|k, DDPM-100, S = 10, the push in normalised action units (rho 4, the
                  smallest that kept bench_guidance's synthetic paths clear), Q* from a ball of the held
                  object's diameter round the EE point, waypoints only
        default   the project's: A_0|k, the policy's DDIM, every step guided, rho 0.04 m per guided step
                  (`MetricGradient`), segments densified x4, the hand and the held object as a swept body, the
                  path costed from the hand (`AnchoredPath`) and pushed clear after sampling (`push_clear`),
                  with the guidance the checkpoint was tuned with laid over it where it has a guidance.json,
                  walls across gaps too narrow for the hand and a hand inside the margin free to move away
        sphere    the default with the previous body model (a ball of the held object's diameter round the EE)
        turned    the recommended preset with each obstacle's push turned 60 degrees round it (`TurnedPush`)
        turned_half   turned, with half the push (rho 0.02)
        no_walls  the default without the walls across narrow gaps and the escape from inside the margin
  The samplers other than default, sphere and no_walls are fixed forms: a checkpoint's tuning does not change them.
  - and, with the default, both turned samplers and no_walls (and none beside them), the harder rows of
    `--extra-variations`: a box, a cluster of two, two obstacles, one that moves (re-fitted before every chunk).
Obstacle episodes use the first seeds from --seed (1000000) whose layout has room for the obstacles (chosen from
the layout alone: `EvalConfig.obstacle_scenes_only`), clean ones --seed + i.

Every failed episode is classified from its stages and contacts (`failure_class`). Evaluations are cached
in --work, keyed by their configuration (a re-run only adds what is missing; delete a JSON after changing
the runtime's code). Outputs: results/obstacles<tag>.json and .md, headed by the command.

    OMP_NUM_THREADS=1 python bench/bench_obstacles.py                      # ~1.5 h on 2 cores
    OMP_NUM_THREADS=1 python bench/bench_obstacles.py --episodes 4 --tasks bowl_pour --extra-variations \
        obstacle:moving --tag _smoke                                        # a few minutes
"""

from __future__ import annotations

import argparse
import platform
import shlex
import sys
import time
from collections import Counter
from dataclasses import asdict
from pathlib import Path

from lano3dp.evaluate import GUIDANCE_PRESETS, EvalConfig
from lano3dp.jsonio import write_json
from lano3dp.pipeline import eval_stage
from lano3dp.policy.pretrained import packaged_checkpoint
from lano3dp.report import markdown_table, percent, wilson_interval

ROOT = Path(__file__).resolve().parent.parent
# EvalConfig fields of each sampler; a guidance mode alone is the recommended preset in that mode
SAMPLERS = {
    "none": {"guidance": "none"},
    "A_k": {"guidance": {"mode": "noisy", "anchored": False, "repair_steps": 0, "hold_unclear": False,
                         "push_turn": 0.0, "bridge_gaps": False, "escape_when_inside": False,
                         "follow_when_stuck": False, "tuned": False}},
    "paper": {"guidance": asdict(GUIDANCE_PRESETS["paper"]), "scheduler": "ddpm", "steps": 100,
              "obstacle": {"body": "sphere"}},
    "default": {"guidance": "clean"},
    "sphere": {"guidance": "clean", "obstacle": {"body": "sphere"}},  # the default before the swept body: its ablation
    # the recommended preset with each push turned round, and that with half the push
    "turned": {"guidance": {"mode": "clean", "push_turn": 60.0, "tuned": False}},
    "turned_half": {"guidance": {"mode": "clean", "push_turn": 60.0, "rho": 0.02, "tuned": False}},
    # the default without the walls across narrow gaps and the escape from inside the margin: their ablation
    "no_walls": {"guidance": {"mode": "clean", "bridge_gaps": False, "escape_when_inside": False,
                              "keep": ["bridge_gaps", "escape_when_inside"]}},
}
# the harder rows compare the project's own guidance with none, not prior work's forms
EXTRA_SAMPLERS = ("none", "default", "turned", "turned_half", "no_walls")
FAILURE_CLASSES = ("target not seen", "touched the obstacle", "path blocked", "grasp missed", "lost on the carry",
                   "last stage unfinished", "other")
# a hand held this many steps in a row has spent a sixth of an episode or more waiting for a way round
PATH_BLOCKED_STEPS = 20


def held_still_steps(episode: dict) -> int:
    """The longest run of steps the runtime held the hand because no start of a chunk kept clear (each such chunk
    executes one step of holding; `RuntimeConfig.hold_unclear`)."""
    longest = run = 0
    for executed in episode.get("chunk_executed") or ():
        run = run + 1 if executed == 0 else 0
        longest = max(longest, run)
    return longest


def failure_class(episode: dict) -> str | None:
    """Why an episode failed (None if it succeeded), from its error, contacts and the task's stages.

    target not seen: perception found no target (e.g. the obstacle hid it from every camera in the first frame);
    touched the obstacle: a failure with contact (the path was blocked or the detour too narrow);
    path blocked: held still for PATH_BLOCKED_STEPS steps in a row or more, no chunk finding a clear way round;
    grasp missed: a task with a "grasped" stage that never got there (e.g. pushed off by the guidance);
    lost on the carry: grasped, but never reached the stage before the last (e.g. the pan, the drawer):
        the detour left the demonstrations' states, or was too wide to come back;
    last stage unfinished: at the goal, the final stage (pour, place) never completed.
    """
    if episode["success"]:
        return None
    error = episode.get("error") or ""
    if "NotFound" in error or "TooFewPoints" in error:
        return "target not seen"
    if episode["collided"]:
        return "touched the obstacle"
    if held_still_steps(episode) >= PATH_BLOCKED_STEPS:
        return "path blocked"
    stages = list((episode.get("stages") or {}).items())
    if not stages:
        return "other"
    names = [name for name, _ in stages]
    reached = [flag for _, flag in stages]
    if "grasped" in names and not reached[names.index("grasped")]:
        return "grasp missed"
    if len(stages) >= 2 and not reached[-2]:
        return "lost on the carry"
    if not reached[-1]:
        return "last stage unfinished"
    return "other"


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tasks", default="bowl_pour,put_item_in_drawer,bottle_in_drawer")
    parser.add_argument("--samplers", default=",".join(SAMPLERS))
    parser.add_argument("--episodes", type=int, default=50, help="episodes per row (obstacle rows: with obstacles)")
    parser.add_argument("--extra-variations", default="obstacle:moving,obstacle:2,obstacle:box,obstacle:cluster",
                        help="harder rows, default sampler and none")
    parser.add_argument("--extra-tasks", default="bowl_pour", help="tasks of the harder rows")
    parser.add_argument("--policy", action="append", default=[], metavar="TASK=PATH",
                        help="evaluate this checkpoint or training run for TASK instead of the packaged policy")
    parser.add_argument("--seed", type=int, default=1_000_000)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--work", default="bench/out/obstacles")
    parser.add_argument("--tag", default="")
    parser.add_argument("--report-only", action="store_true", help="tabulate what --work holds")
    return parser.parse_args(argv)


def row(summary: dict, episodes: list[dict], tuning: dict, clean: dict | None) -> dict:
    low, high = wilson_interval(summary["successes"], summary["episodes"])
    classes = Counter(c for c in map(failure_class, episodes) if c is not None)
    contact_steps = [e["n_collision_steps"] for e in episodes]
    entry = {
        "episodes": summary["episodes"], "episodes_with_obstacles": summary["episodes_with_obstacles"],
        "success_rate": summary["success_rate"], "success_interval": [low, high],
        "touch_rate": summary["collision_rate"], "touch_interval": list(wilson_interval(
            sum(e["collided"] for e in episodes), len(episodes))),
        "mean_contact_steps": summary["mean_collision_steps"], "max_contact_steps": max(contact_steps, default=0),
        "mean_min_clearance": summary["mean_min_clearance"], "worst_min_clearance": summary["worst_min_clearance"],
        "mean_path_length": summary["mean_path_length"], "latency_mean_s": summary["latency_mean_s"],
        "failure_classes": {c: classes.get(c, 0) for c in FAILURE_CLASSES},
        "stage_rates": summary["stage_rates"], "seeds": [e["seed"] for e in episodes],
        "guidance_tuning": tuning,  # what of the guidance the checkpoint's tuning set
    }
    if clean is not None:
        entry["clean_success_rate"] = clean["success_rate"]
        entry["ratio_to_clean"] = (round(summary["success_rate"] / clean["success_rate"], 3)
                                   if clean["success_rate"] else None)
    return entry


def main(argv=None) -> int:
    args = parse_args(argv)
    tasks = [t for t in args.tasks.split(",") if t]
    samplers = [s for s in args.samplers.split(",") if s]
    if unknown := sorted(set(samplers) - set(SAMPLERS)):
        raise SystemExit(f"unknown samplers {unknown}; choose from {', '.join(SAMPLERS)}")
    extra_variations = [v for v in args.extra_variations.split(",") if v]
    extra_tasks = [t for t in args.extra_tasks.split(",") if t]
    work = Path(args.work)
    policies = dict(item.split("=", 1) for item in args.policy)
    command = shlex.join(["python", "bench/bench_obstacles.py", *(argv if argv is not None else sys.argv[1:])])
    started = time.perf_counter()

    def log(message: str) -> None:
        print(f"[{time.perf_counter() - started:7.0f}s] {message}", flush=True)

    def evaluate(task: str, variation: str, name: str, sampler: str) -> tuple[dict, list[dict], dict] | None:
        out = work / task / f"{name}.json"
        options = dict(SAMPLERS[sampler])
        obstacle = {**options.pop("obstacle", {}), "refit": "moving" in variation}
        config = EvalConfig(checkpoint=policies.get(task) or str(packaged_checkpoint(task)), task=task,
                            variation=variation, episodes=args.episodes, seed=args.seed, workers=args.workers,
                            out=str(out), obstacle_scenes_only=variation != "clean", obstacle=obstacle, **options)
        if args.report_only:
            from lano3dp.pipeline import cached_eval

            result = cached_eval(config)
            if result is None:
                return None
        else:
            log(f"{task} / {variation} / {sampler}")
            result = eval_stage(config, log=log, command=command)
        return result["summary"], result["episodes"], result.get("guidance_tuning") or {}

    results: dict = {"command": command, "config": vars(args), "samplers": SAMPLERS, "policies": policies, "tasks": {},
                     "machine": {"platform": platform.platform(), "python": platform.python_version(),
                                 "note": "2-core CPU shared with other jobs: latencies are pessimistic"}}
    out_json = ROOT / "results" / f"obstacles{args.tag}.json"
    out_md = ROOT / "results" / f"obstacles{args.tag}.md"
    for task in tasks:
        entry = results["tasks"].setdefault(task, {"rows": {}})
        clean = evaluate(task, "clean", "clean", "none")
        clean_summary = clean[0] if clean else None
        if clean:
            entry["clean"] = row(*clean, None)
        jobs = [("obstacle", s) for s in samplers]
        if task in extra_tasks:
            jobs += [(v, s) for v in extra_variations for s in EXTRA_SAMPLERS if s in samplers]
        for variation, sampler in jobs:
            name = f"{variation.replace(':', '_')}_{sampler}"
            measured = evaluate(task, variation, name, sampler)
            if measured:
                entry["rows"][f"{variation}/{sampler}"] = {"variation": variation, "sampler": sampler,
                                                           **row(*measured, clean_summary)}
            results["wall_s"] = round(time.perf_counter() - started, 1)
            write_json(out_json, results)
            out_md.write_text(markdown_report(results))
    write_json(out_json, results)
    out_md.write_text(markdown_report(results))
    log(f"done: {out_json.relative_to(ROOT)}, {out_md.relative_to(ROOT)}")
    return 0


def _interval(values) -> str:
    low, high = values
    return "–" if low is None else f"{percent(low)}–{percent(high)}"


def markdown_report(results: dict) -> str:
    seed = results.get("config", {}).get("seed", 1_000_000)
    lines = ["# Obstacle avoidance that keeps the task", "", f"Command: `{results['command']}`", "",
             "Policies: " + (", ".join(f"{t}: `{p}`" for t, p in results["policies"].items()) + "; others: " if
                             results["policies"] else "") +
             "the packaged ones (`src/lano3dp/checkpoints/<task>`, training seed 0, see their "
             f"record.json). Obstacle rows: the first seeds from {seed} whose layout has room for the obstacles; "
             f"clean: seeds {seed} + i. Intervals: 95% Wilson. touch = any contact of hand or held object with "
             "an obstacle; contact steps = steps with contact (mean over episodes); clearance = the simulator's "
             "smallest gap (m), mean over episodes; ratio = success / the same policy's clean success.", "",
             "Samplers: " + "; ".join(f"**{name}** {options}" for name, options in results["samplers"].items()), ""]
    for task, entry in results["tasks"].items():
        lines += [f"## {task}", ""]
        if "clean" in entry:
            clean = entry["clean"]
            lines += [f"Clean success: {percent(clean['success_rate'])} ({_interval(clean['success_interval'])}), "
                      f"{clean['episodes']} episodes.", ""]
        table = []
        for r in entry["rows"].values():
            table.append([r["variation"], r["sampler"], r["episodes_with_obstacles"],
                          f"{percent(r['success_rate'])} ({_interval(r['success_interval'])})",
                          r.get("ratio_to_clean"),
                          f"{percent(r['touch_rate'])} ({_interval(r['touch_interval'])})",
                          r["mean_contact_steps"],
                          None if r["mean_min_clearance"] is None else f"{100 * r['mean_min_clearance']:.1f} cm",
                          None if r["latency_mean_s"] is None else f"{1000 * r['latency_mean_s']:.0f} ms"])
        tuned = {r["sampler"]: r["guidance_tuning"] for r in entry["rows"].values() if r.get("guidance_tuning")}
        for sampler, tuning in tuned.items():
            lines += [f"Sampler {sampler} here takes the guidance this checkpoint was tuned with (its "
                      f"guidance.json): " + ", ".join(f"{name} {value}" for name, value in tuning.items()) + ".",
                      ""]
        if table:
            lines += [markdown_table(["variation", "sampler", "episodes w/ obstacle", "success", "ratio to clean",
                                      "touch", "contact steps", "clearance", "latency/chunk"], table), ""]
            lines += ["Failures by class:", "",
                      markdown_table(["variation", "sampler", *FAILURE_CLASSES],
                                     [[r["variation"], r["sampler"], *(r["failure_classes"][c]
                                                                       for c in FAILURE_CLASSES)]
                                      for r in entry["rows"].values()]), ""]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())
