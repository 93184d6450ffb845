"""`run_instruction`: one instruction, end to end: plan -> policy bundle -> scenes -> guided (and unguided) episodes.

The instruction is planned once, by any decomposer (the offline parser by default, the LLM planner with
`RunConfig.llm`), and grounded in each scene's objects, never substituting one object for another. It runs in
`scenes` scenes (the first from `seed` on with room for its obstacles), guided and, with `compare`, unguided;
the first scene's episodes keep a video and the top view (a rule fixed before any outcome is seen), and the
output aggregates every scene.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from lano3dp import env_factory
from lano3dp.evaluation.bundle import PolicyBundle
from lano3dp.evaluation.config import RunConfig
from lano3dp.evaluation.results import results_file, summarize
from lano3dp.guidance.settings import GuidanceSettings
from lano3dp.jsonio import write_json
from lano3dp.runtime import PolicyRunner, rollout
from lano3dp.video import write_video

Log = Callable[[str], None]


def run_instruction(config: RunConfig, log: Log = print, command: str | None = None,
                    decomposer=None) -> dict[str, Any]:
    """Plan, perceive, act. Writes run.json, a video per condition of the first scene and its top view into
    `config.out`, which is locked while it runs (a second run into the same folder is refused).

    Args:
        decomposer: anything with `decompose(instruction, scene_objects=None) -> TaskPlan` (default: the offline
            parser, or the LLM planner with `config.llm`, on `config.registry`'s skills).
    """
    from lano3dp.locking import WriteLock

    with WriteLock(config.out):
        return _run(config, log, command, decomposer)


def make_decomposer(config: RunConfig, registry):
    """The offline parser, or with `config.llm` the LLM planner configured from the environment (the offline
    parser as its fallback)."""
    from lano3dp.language import OfflineDecomposer

    offline = OfflineDecomposer(registry)
    if not config.llm:
        return offline
    from lano3dp.language.llm import LLMConfig, LLMDecomposer

    return LLMDecomposer(LLMConfig.from_env(), registry, fallback=offline)


def _checkpoint(config: RunConfig, registry, skill: str, log: Log) -> str | Path:
    from lano3dp.policy.pretrained import packaged_checkpoint, packaged_checkpoints

    checkpoint = config.checkpoint or (registry.get(skill).checkpoint if skill in registry else None)
    if checkpoint is None:
        if skill not in packaged_checkpoints():
            raise ValueError(f"no checkpoint for skill '{skill}' (none is packaged for it): pass --checkpoint, or a "
                             "--registry naming one")
        checkpoint = packaged_checkpoint(skill)
        log(f"policy: the one packaged for {skill}")
    return checkpoint


def _ground(plan, frame, registry, mapping) -> tuple[Any, list[str], list[str]]:
    """The plan named in this scene's words (a registered synonym of a slot finds the scene's object, "blue bowl"
    among look-alikes), its obstacle phrases here, and notes for the user. A target the scene lacks is an error
    naming it and what the scene holds, never another object in its place (`language.grounding`); a named
    obstacle the demo scene lacks is its grey cylinder, with a note."""
    from lano3dp.language.grounding import ground_plan

    scene = {n: a for n, a in frame.instance_attributes.items() if a.get("role") != "robot"}
    if not scene:  # a frame naming no objects is not grounded
        return plan, list(plan.obstacle_phrases), []
    grounded = ground_plan(plan, scene, registry, mapping=mapping, obstacle_stand_ins=True)
    return grounded.plan, grounded.obstacles, grounded.notes


def _scene_seeds(config: RunConfig, task: str, variation: str, wants_obstacles: bool) -> list[int]:
    if wants_obstacles and config.env is None:
        from lano3dp.sim import Variation
        from lano3dp.sim.env import obstacle_scene_seeds

        if Variation.parse(variation).has("obstacle"):
            return obstacle_scene_seeds(task, variation, config.seed, config.scenes)
    return [config.seed + i for i in range(config.scenes)]


def _conditions(config: RunConfig, guidance: GuidanceSettings, has_obstacles: bool) -> list[tuple[str, Any]]:
    """(label, settings) of each condition: guided, and unguided beside it with `compare`. Without an obstacle
    there is nothing to guide against, and the episode is labelled unguided."""
    unguided = guidance.with_changes({"sampler.mode": "none", "sampler.strategy": "always",
                                      "execution.filters": [], "execution.options": {}})
    if not guidance.guided or not has_obstacles:
        return [("unguided", unguided)]
    return [("guided", guidance)] + ([("unguided", unguided)] if config.compare else [])


def _run(config: RunConfig, log: Log, command: str | None, decomposer) -> dict[str, Any]:
    from lano3dp.geometry.frame import observe
    from lano3dp.language import SkillRegistry
    from lano3dp.report import plot_top_view
    from lano3dp.sim.tasks import skill_registry

    registry = SkillRegistry.load(config.registry) if config.registry else skill_registry()
    decomposer = decomposer or make_decomposer(config, registry)
    plan = decomposer.decompose(config.instruction)
    log(f"plan: {plan.summary()}")
    for warning in plan.warnings:  # what the planner was unsure of: the user sees it before the robot moves
        log(f"warning: {warning}")
    bundle = PolicyBundle.load(_checkpoint(config, registry, plan.skill, log))
    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)  # once the plan and the policy hold: a refusal leaves no folder
    guidance = config.guidance.resolve(bundle.tuning)
    if config.guidance.preset == "tuned" and bundle.tuning is not None:
        log(f"guidance: as this policy was tuned ({', '.join(f'{k} {v}' for k, v in bundle.tuning.overrides.items())})")
    task = config.task or plan.skill
    bundle.check_task(task, config.env)
    variation = config.variation or ("obstacle" if plan.obstacles else "clean")
    policy = bundle.policy
    env = env_factory.make_env(config.env, task=task, seed=config.seed, variation=variation,
                               image_size=config.perception.image_size or bundle.observation.image_size or 128,
                               render_rgb=True, max_steps=config.max_steps)
    max_steps = config.max_steps if config.env is None else (config.max_steps or getattr(env, "max_steps", None))
    observer = bundle.observer(config.perception)
    carried = registry.get(plan.skill).carried_slot if plan.skill in registry else None
    conditions = _conditions(config, guidance, bool(plan.obstacles))
    seeds = _scene_seeds(config, task, variation, bool(plan.obstacles))
    log(f"task {task} / {variation}: {len(seeds)} scene(s) from seed {seeds[0]}, "
        f"{' and '.join(label for label, _ in conditions)}; the first scene keeps its videos and top view")
    runners = {label: PolicyRunner(policy, observer, settings, step_limit=getattr(env, "max_ee_step", None))
               for label, settings in conditions}
    episodes: dict[str, list[dict[str, Any]]] = {label: [] for label, _ in conditions}
    scenes, paths, all_notes = [], [], []
    for number, seed in enumerate(seeds):
        frame, _ = observe(env, env.reset(seed=seed)[0])
        grounded, obstacles, notes = _ground(plan, frame, registry, config.mapping or None)
        for note in notes:
            if note not in all_notes:
                log(f"note: {note}")
                all_notes.append(note)
        targets = grounded.target_phrases if policy.config.observation.object_slots else None
        held = grounded.target_phrases[carried] if carried is not None else None
        scenes.append({"seed": seed, "targets": targets, "obstacles": obstacles})
        for label, _ in conditions:
            runner = runners[label]
            runner.set_objects(targets, obstacles, held)
            frames: list[np.ndarray] = []
            keep = number == 0
            result = rollout(env, runner, seed=seed, max_steps=max_steps,
                             on_frame=(lambda f, info, frames=frames: frames.append(f.rgb.copy())) if keep else None)
            record = result.to_dict(include_path=keep)
            record["success_reported"] = env.reports_success
            if keep:
                record["video"] = str(write_video(out / f"video_{label}.mp4", frames))
                paths.append((_outcome(result, env.reports_success, label), result.ee_path))
            episodes[label].append(record)
            log(f"scene {number + 1}/{len(seeds)} (seed {seed}) {label}: {_episode_line(result, env.reports_success)}")
    env.close()
    first = episodes[conditions[0][0]][0]
    plot = plot_top_view(out / "top_view.png", paths, obstacles=first["obstacles"], objects=first["targets"],
                         title=f"'{config.instruction}' (scene {seeds[0]})")
    summaries = {label: summarize(records) for label, records in episodes.items()}
    for label, summary in summaries.items():
        log(f"{label} over {summary['episodes']} scene(s): {_summary_line(summary)}")
    result = results_file("run", config.to_dict(), {
        "plan": plan.model_dump(), "task": task, "variation": variation, "checkpoint": bundle.label,
        "guidance": guidance.to_dict(), "scenes": scenes, "notes": all_notes, "summary": summaries,
        "episodes": episodes, "top_view": str(plot),
    }, command=command)
    write_json(out / "run.json", result)
    return result


def _outcome(result, reported: bool, label: str) -> str:
    outcome = ("success" if result.success else "failure") if reported else "success not reported"
    return f"{label}: {outcome}" + (", touched the obstacle" if result.collided else "")


def _episode_line(result, reported: bool) -> str:
    outcome = ("SUCCESS" if result.success else "failure") if reported else "success not reported"
    clearance = "–" if result.min_clearance is None else f"{100 * result.min_clearance:.1f} cm"
    return (f"{outcome} after {result.steps} steps, obstacle contact {'yes' if result.collided else 'no'}, "
            f"min clearance {clearance}" + (f" ({result.error})" if result.error else ""))


def _summary_line(summary: dict[str, Any]) -> str:
    success = "success not reported" if summary["success_rate"] is None else \
        f"success {summary['successes']}/{summary['episodes']}"
    touched = round(summary["collision_rate"] * summary["episodes"])
    return f"{success}, touched an obstacle in {touched}/{summary['episodes']}"
