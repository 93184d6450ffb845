"""Obstacle avoidance that keeps the task: the paper's bowl-pour test (its Fig. 4) and two more.

Per task, the policy packaged for it (`lano3dp eval --task T` without --checkpoint) is evaluated
  - on clean scenes (its clean success, the reference), and
  - with a novel obstacle on the demonstrated path, by these samplers (library presets, `guidance.settings`,
    plus dotted overrides; SAMPLERS below):
        none          no guidance (preset none)
        A_k           the cost on the noisy sample A_k, the prior work the paper contrasts with (preset a_k)
        paper         the paper's form: A_0|k, DDPM-100, S = 10, the push in normalised units, a ball of the held
                      object's diameter round the EE point, waypoints only (preset paper)
        default       the project's guidance as this checkpoint was tuned (preset tuned: its guidance.json, else
                      recommended)
        sphere        default with the earlier body model, a ball round the EE point (obstacles.body=sphere)
        turned        the recommended preset with each obstacle's push turned 60 degrees round it (cost.push_turn)
        turned_half   turned, with half the push (sampler.rho=0.02)
        no_walls      default without the walls across narrow gaps and without the escape filter
  Only default, sphere and no_walls take a checkpoint's tuning; the others are fixed forms.
  - and, with default, both turned samplers and no_walls (and none beside them), the harder rows of
    `--extra-variations`: a box, a cluster of two, two obstacles, one that moves (re-fitted before every chunk).
Obstacle episodes use the first seeds from --seed (1000000) whose layout has room for the obstacles (chosen from
the layout alone: `EvalConfig.obstacle_scenes_only`), clean ones --seed + i.

Every failed episode is classified from its stages and contacts (`failure_class`). Evaluations are cached in
--work and reused while current (the same evaluation at the same `BEHAVIOUR_VERSION`: `pipeline.eval_stage`).
Outputs: <out-dir>/obstacles<tag>.json and .md.

    OMP_NUM_THREADS=1 python bench/bench_obstacles.py                      # ~1.5 h on 2 cores
    OMP_NUM_THREADS=1 python bench/bench_obstacles.py --episodes 4 --tasks bowl_pour --extra-variations \
        obstacle:moving --tag _smoke                                        # a few minutes
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from _contract import bench_parser, parse, write_results
from lano3dp.evaluation import EvalConfig, GuidanceChoice
from lano3dp.evaluation.bundle import resolve_folder
from lano3dp.guidance.settings import TUNED, load_guidance_tuning, resolve_guidance
from lano3dp.pipeline import cached_eval, eval_stage
from lano3dp.report import markdown_table, percent, wilson_interval


@dataclass(frozen=True)
class Sampler:
    """A guidance variant: a library preset ("tuned": the checkpoint's own tuning), dotted overrides on it, and
    chunk filters taken out of whatever the preset (or the tuning) runs."""

    preset: str
    overrides: dict[str, Any] = field(default_factory=dict)
    without_filters: tuple[str, ...] = ()

    def choice(self, checkpoint: str | None, task: str, moving: bool) -> GuidanceChoice:
        """The guidance of one evaluation of `checkpoint` (None: the packaged policy of `task`); a moving obstacle
        is re-fitted before every chunk."""
        changes = {**self.overrides, **({"obstacles.refit": True} if moving else {})}
        if self.without_filters:
            tuning = load_guidance_tuning(resolve_folder(checkpoint, task)) if self.preset == TUNED else None
            runs = resolve_guidance(self.preset, changes, tuning).execution.filters
            changes["execution.filters"] = [name for name in runs if name not in self.without_filters]
        return GuidanceChoice(self.preset, changes)

    def describe(self) -> str:
        parts = [self.preset] + [f"{path}={value}" for path, value in self.overrides.items()]
        return " ".join(parts) + (f" without {', '.join(self.without_filters)}" if self.without_filters else "")


SAMPLERS = {
    "none": Sampler("none"),
    "A_k": Sampler("a_k"),
    "paper": Sampler("paper"),
    "default": Sampler(TUNED),
    "sphere": Sampler(TUNED, {"obstacles.body": "sphere"}),  # the default before the swept body: its ablation
    # the recommended preset with each push turned round, and that with half the push
    "turned": Sampler("recommended", {"cost.push_turn": 60.0}),
    "turned_half": Sampler("recommended", {"cost.push_turn": 60.0, "sampler.rho": 0.02}),
    # the default without the walls across narrow gaps and the escape from inside the margin: their ablation
    "no_walls": Sampler(TUNED, {"obstacles.bridge_gaps": False}, without_filters=("escape",)),
}
# the harder rows compare the project's own guidance with none, not prior work's forms
EXTRA_SAMPLERS = ("none", "default", "turned", "turned_half", "no_walls")
FAILURE_CLASSES = ("target not seen", "touched the obstacle", "path blocked", "grasp missed", "lost on the carry",
                   "last stage unfinished", "other")
# a hand held this many steps in a row has spent a sixth of an episode or more waiting for a way round
PATH_BLOCKED_STEPS = 20


def held_still_steps(episode: dict) -> int:
    """The longest run of steps the runtime held the hand because no start of a chunk kept clear (each such chunk
    executes one step of holding: the "hold" chunk filter)."""
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


def parse_args(argv=None):
    parser = bench_parser(__file__, __doc__, tasks="bowl_pour,put_item_in_drawer,bottle_in_drawer", episodes=50,
                          seed=1_000_000, workers=2)
    parser.add_argument("--samplers", default=",".join(SAMPLERS), help=f"comma-separated, from {', '.join(SAMPLERS)}")
    parser.add_argument("--extra-variations", default="obstacle:moving,obstacle:2,obstacle:box,obstacle:cluster",
                        help="harder rows, with the samplers of EXTRA_SAMPLERS")
    parser.add_argument("--extra-tasks", default="bowl_pour", help="tasks of the harder rows")
    parser.add_argument("--policy", action="append", default=[], metavar="TASK=PATH",
                        help="evaluate this checkpoint or training run for TASK instead of the packaged policy")
    parser.add_argument("--work", default="bench/out/obstacles", help="the evaluations (cached)")
    parser.add_argument("--report-only", action="store_true", help="tabulate what --work holds")
    return parse(parser, argv)


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
    samplers = [s for s in args.samplers.split(",") if s]
    if unknown := sorted(set(samplers) - set(SAMPLERS)):
        raise SystemExit(f"unknown samplers {unknown}; choose from {', '.join(SAMPLERS)}")
    extra_variations = [v for v in args.extra_variations.split(",") if v]
    extra_tasks = [t for t in args.extra_tasks.split(",") if t]
    work = Path(args.work)
    policies = dict(item.split("=", 1) for item in args.policy)
    started = time.perf_counter()

    def log(message: str) -> None:
        print(f"[{time.perf_counter() - started:7.0f}s] {message}", flush=True)

    def evaluate(task: str, variation: str, name: str, sampler: str) -> tuple[dict, list[dict], dict] | None:
        checkpoint = policies.get(task)
        chosen = SAMPLERS[sampler]
        config = EvalConfig(checkpoint=checkpoint, task=task, variation=variation, episodes=args.episodes,
                            seed=args.seed, workers=args.workers, out=str(work / task / f"{name}.json"),
                            obstacle_scenes_only=variation != "clean",
                            guidance=chosen.choice(checkpoint, task, "moving" in variation))
        if args.report_only:
            result = cached_eval(config)
            if result is None:
                return None
        else:
            log(f"{task} / {variation} / {sampler}")
            result = eval_stage(config, log=log, command=args.command)
        tuning = load_guidance_tuning(resolve_folder(checkpoint, task)) if chosen.preset == TUNED else None
        return result["summary"], result["episodes"], dict(tuning.overrides) if tuning else {}

    body: dict = {"samplers": {name: SAMPLERS[name].describe() for name in samplers}, "policies": policies,
                  "tasks": {}, "note": "2-core CPU shared with other jobs: latencies are pessimistic"}

    def write() -> Path:
        body["wall_s"] = round(time.perf_counter() - started, 1)
        return write_results("obstacles", args, body, markdown=markdown_report)

    for task in args.tasks:
        entry = body["tasks"].setdefault(task, {"rows": {}})
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
            write()
    log(f"done: {write()}")
    return 0


def _interval(values) -> str:
    low, high = values
    return "–" if low is None else f"{percent(low)}–{percent(high)}"


def markdown_report(results: dict) -> str:
    seed = results.get("config", {}).get("seed", 1_000_000)
    lines = ["# Obstacle avoidance that keeps the task", "",
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
