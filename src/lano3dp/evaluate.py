"""Closed-loop evaluation of a checkpoint in the simulator: many episodes, in parallel, to one JSON.

    result = evaluate(EvalConfig(checkpoint="runs/bowl", task="bowl_pour", variation="obstacle",
                                 episodes=20, guidance=GuidanceSettings(rho=0.02)))
    result["summary"]["success_rate"], result["summary"]["collision_rate"]
    result["summary"]["stage_rates"]   # e.g. {"reached_handle": 0.9, "grasped_handle": 0.6, ..., "opened": 0.4}

Each episode is a fresh scene from its seed (seed, seed + 1, ...; the default first
seed 1000000 keeps evaluation scenes apart from demonstration seeds: 0, 1, ... and their retries
at multiples of 100003, see lano3dp.collect). Episodes run in
`workers` spawned processes with one torch thread each (two OpenMP threads per process stall on a
shared 2-core machine; notes/cpu-cost.md sec. 1), and results come back in seed order, so the JSON does
not depend on the number of workers. Latencies measured with several workers include their contention.

The env is the built-in `TabletopEnv` by default, or a user's own simulator or robot from `env`, a factory
named 'module:factory' or 'path/to/file.py:factory' (`lano3dp.env_factory`: what the factory is called with, what
the env must return, and what degrades when the env is not the simulator); both are built by
`env_factory.make_env`.

Perception is built by `perception.factory.build_segmenter` from `perception.segmenter`: the simulator's
ground-truth masks by default ("sim"), or the paper's open-vocabulary detector + SAM ("open-vocab"); targets are
named by the phrases the scene uses (e.g. "blue bowl" among look-alikes) and obstacles, by default, are the
objects the scene marks as obstacles. Crop box and image size follow the dataset the checkpoint was
trained on (found through its train_config.json) and points per cloud follow the policy's config, so
evaluation sees what training saw. A guided evaluation uses the guidance the checkpoint was tuned with, where it
has a `guidance.json` (`tuned_config`); the results' config is what ran.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import shlex
import sys
import time
import types
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from lano3dp import env_factory
from lano3dp.errors import Lano3dpError
from lano3dp.guidance.settings import (  # noqa: F401 (GUIDANCE_PRESETS: re-export)
    GUIDANCE_PRESETS,
    GuidanceSettings,
    ObstacleSettings,
    load_guidance_tuning,
)
from lano3dp.jsonio import to_jsonable, write_json, write_text_atomic
from lano3dp.video import write_video

DEFAULT_EVAL_SEED = 1_000_000
SUMMARY_FIELDS = ("episodes", "success_rate", "collision_rate", "safe_success_rate", "error_rate",
                  "mean_min_clearance", "mean_path_length", "mean_steps", "latency_mean_s", "latency_p95_s")


@dataclass(frozen=True)
class PerceptionSettings:
    """How targets and obstacles are seen.

    Attributes:
        segmenter: "sim" (the simulator's ground-truth masks) or "open-vocab" (detector + SAM, the paper's
            perception; needs detector_dir and sam_dir, local weight folders, never downloaded).
        detector: "grounding_dino" or "owlv2" (open-vocab).
        detector_dir, sam_dir: (open-vocab) the weight folders.
        image_size: camera resolution (None: the dataset's the checkpoint was trained on).
    """

    segmenter: str = "sim"
    detector: str = "grounding_dino"
    detector_dir: str | None = None
    sam_dir: str | None = None
    image_size: int | None = None

    def __post_init__(self):
        check_segmenter_choice(self.segmenter)
        for name in ("detector_dir", "sam_dir"):  # a Path is saved as its text, so results stay JSON
            value = getattr(self, name)
            object.__setattr__(self, name, None if value is None else str(value))


# The nested sections of EvalConfig and RunConfig: field -> its type. A section may be given as a dict (a saved
# config read back), and `guidance` as a mode name alone, meaning the recommended preset in that mode.
_SECTIONS = {"guidance": GuidanceSettings, "obstacle": ObstacleSettings, "perception": PerceptionSettings}


def _build_sections(config) -> None:
    for name, kind in _SECTIONS.items():
        value = getattr(config, name)
        if isinstance(value, str) and kind is GuidanceSettings:
            value = GuidanceSettings(mode=value)
        elif isinstance(value, Mapping):
            value = kind(**value)
        elif not isinstance(value, kind):
            raise TypeError(f"{name} must be a {kind.__name__}, a dict of its fields"
                            + (" or a mode name" if kind is GuidanceSettings else "") + f", got {value!r}")
        setattr(config, name, value)


@dataclass
class EvalConfig:
    """One evaluation (saved verbatim in the results JSON; `from_dict` reads it back).

        EvalConfig(checkpoint="runs/bowl", variation="obstacle", guidance="clean")   # the recommended guidance
        EvalConfig(checkpoint="runs/bowl", variation="obstacle",
                   guidance=GuidanceSettings(rho=0.02), obstacle=ObstacleSettings(shape="box"))
        EvalConfig(..., guidance=GUIDANCE_PRESETS["paper"], scheduler="ddpm", steps=100,
                   obstacle=ObstacleSettings(body="sphere"))                          # the paper's form

    Attributes:
        checkpoint: a policy folder or a training run (its checkpoints/last).
        task: task name, the simulator's or one `env`'s factory knows (default: the checkpoint's task).
        variation: "clean" or axes joined by "+" (e.g. "obstacle", "clutter+camera").
        episodes: how many episodes; seeds are seed, seed + 1, ...
        seed: first episode seed (also seeds the sampling noise of each episode).
        obstacles: phrases of the objects to avoid; None = every object the scene marks as an obstacle.
        guidance: how chunks are guided (`guidance.GuidanceSettings`; its defaults are the recommended preset);
            a mode name ("none", "noisy", "clean") is that preset in that mode. Default: mode "none".
        obstacle: how obstacles become costs (`guidance.ObstacleSettings`: shape, margin, body, held radius,
            re-fitting before every chunk; see `guidance.obstacle_model.ObstacleModel`).
        perception: segmenter, detector and its weights, camera resolution (`PerceptionSettings`).
        scheduler, steps: inference scheduler and its number of denoising steps (None: the policy's default).
        n_action_steps: actions executed per chunk (None: the policy's).
        max_steps: episode step limit (None: the task's).
        obstacle_scenes_only: with an obstacle variation, evaluate the first `episodes` seeds from `seed` whose
            scene has room for every obstacle asked for (chosen from the layout alone, never from an outcome).
        workers: parallel processes (1 runs in this process).
        video_dir, n_videos: write MP4s of the first n_videos episodes there.
        out: results JSON path (None: not written).
        env: None for the built-in simulator, else an env factory: 'module:factory', 'path/to/file.py:factory',
            or a module-level callable (saved as its 'module:factory' name, so results and worker processes can
            re-make it). It is called with task, seed, variation, image_size, render_rgb and max_steps (those its
            signature names) and returns an env meeting `lano3dp.sim.protocol.SimulatorProtocol`; see
            `lano3dp.env_factory`. For a task the simulator does not know the skill check is skipped, and
            max_steps defaults to the env's own `max_steps` attribute.
    """

    checkpoint: str
    task: str | None = None
    variation: str = "clean"
    episodes: int = 20
    seed: int = DEFAULT_EVAL_SEED
    obstacles: list[str] | None = None
    guidance: GuidanceSettings = field(default_factory=lambda: GuidanceSettings(mode="none"))
    obstacle: ObstacleSettings = field(default_factory=ObstacleSettings)
    perception: PerceptionSettings = field(default_factory=PerceptionSettings)
    scheduler: str | None = None
    steps: int | None = None
    n_action_steps: int | None = None
    max_steps: int | None = None
    obstacle_scenes_only: bool = False
    workers: int = 1
    video_dir: str | None = None
    n_videos: int = 2
    out: str | None = None
    env: str | None = None

    def __post_init__(self):
        self.checkpoint = str(self.checkpoint)
        self.env = env_spec(self.env)
        _build_sections(self)
        if self.episodes < 1 or self.workers < 1:
            raise ValueError(f"episodes and workers must be >= 1, got {self.episodes}, {self.workers}")
        if self.obstacle_scenes_only and self.env is not None:
            raise ValueError("obstacle_scenes_only picks seeds from the built-in simulator's layouts; "
                             "a user's env picks its own scenes")

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> EvalConfig:
        """An EvalConfig from its saved dict (results JSON, episode log, executor cell): nested, or flat as
        results were saved before the settings were nested (see `saved_config`)."""
        return cls(**saved_config(data))


def env_spec(env) -> str | None:
    """An EvalConfig/RunConfig `env` as saved: None, or the factory's 'module:factory' text."""
    if env is None or isinstance(env, str):
        return env or None
    if callable(env):
        return env_factory.factory_name(env)
    raise env_factory.EnvFactoryError(f"env must be 'module:factory', 'path/to/file.py:factory' or a callable, "
                                      f"got a {type(env).__name__}")


def check_env_task(task: str, policy_config, env: str | None) -> None:
    """The skill check for the env's task: always in the simulator; in a user's env only when its task has a
    simulator task's name (another name says nothing about the skill)."""
    if env is not None:
        from lano3dp.sim.tasks import TASKS

        if task not in TASKS:
            return
    check_task_matches_policy(task, policy_config)


SEGMENTERS = {"sim": "oracle", "open-vocab": "open_vocab"}  # option value -> perception.factory kind


def check_segmenter_choice(segmenter: str) -> None:
    if segmenter not in SEGMENTERS:
        raise ValueError(f"segmenter must be one of {', '.join(SEGMENTERS)}, got {segmenter!r}")


def build_config_segmenter(config):
    """The segmenter an EvalConfig's or RunConfig's perception names, built by `perception.factory.build_segmenter`.

    Raises:
        ValueError: open-vocab without its weight folders (named).
        MissingWeightsError: a weight folder that does not exist or is incomplete.
    """
    from lano3dp.perception import factory

    perception = config.perception
    return factory.build_segmenter(factory.SegmenterConfig(
        kind=SEGMENTERS[perception.segmenter], detector=perception.detector,
        detector_dir=Path(perception.detector_dir) if perception.detector_dir else None,
        sam_dir=Path(perception.sam_dir) if perception.sam_dir else None))


class PolicyTaskMismatchError(Lano3dpError, ValueError):
    """A checkpoint asked to act on a task of another skill."""


@dataclass(frozen=True)
class DatasetSettings:
    """What evaluation copies from the training data: where the camera looked and how clouds were made."""

    task: str | None = None
    image_size: int | None = None
    n_points: int | None = None
    crop_low: tuple[float, ...] | None = None
    crop_high: tuple[float, ...] | None = None
    data: str | None = None


def dataset_settings(checkpoint: str | Path) -> DatasetSettings:
    """How the checkpoint's observations were made: from its own config (extra["observation"], written since
    checkpoints became self-contained), else from the training dataset named in its train_config.json."""
    from lano3dp.data.store import EpisodeStore
    from lano3dp.policy.modeling import load_config, resolve_checkpoint

    folder = resolve_checkpoint(checkpoint)
    extra = load_config(folder / "config.json").extra
    candidates = [folder / "train_config.json", folder.parent.parent / "train_config.json",
                  Path(checkpoint) / "train_config.json"]
    data = next((json.loads(path.read_text()).get("data") for path in candidates if path.exists()), None)
    attrs = extra.get("observation")
    if attrs is None and data and Path(data).exists():
        attrs = EpisodeStore.open(data).attrs
    if attrs is None:
        return DatasetSettings(task=extra.get("task"))
    low, high = attrs.get("crop_low"), attrs.get("crop_high")
    return DatasetSettings(task=extra.get("task") or attrs.get("task"),
                           image_size=attrs.get("image_size") or (attrs.get("camera") or {}).get("height"),
                           n_points=attrs.get("n_points"), crop_low=None if low is None else tuple(low),
                           crop_high=None if high is None else tuple(high), data=str(data) if data else None)


def check_task_matches_policy(task: str, policy_config) -> None:
    """Refuse to run a policy on a task of another skill (its object slots would get the wrong clouds)."""
    from lano3dp.sim.tasks import make_task

    trained_skill = policy_config.extra.get("skill")
    skill = make_task(task).skill
    if trained_skill is not None and trained_skill != skill:
        raise PolicyTaskMismatchError(
            f"the checkpoint was trained for skill '{trained_skill}' (task {policy_config.extra.get('task')!r}), "
            f"not '{skill}' (task {task!r}); pass a checkpoint of '{skill}' or --task "
            f"{policy_config.extra.get('task') or trained_skill}")


def tuned_config(config, checkpoint: str | Path):
    """`config` (an EvalConfig or RunConfig) with the guidance `checkpoint` was tuned with laid over its own
    (`GuidanceSettings.tuned_for`): what an evaluation runs and records."""
    from lano3dp.policy.modeling import resolve_checkpoint

    try:
        folder = resolve_checkpoint(checkpoint)
    except FileNotFoundError:  # loading the policy says so, with what was expected there
        return config
    guidance = config.guidance.tuned_for(load_guidance_tuning(folder))
    return config if guidance == config.guidance else replace(config, guidance=guidance)


def runtime_config(config: EvalConfig, seed: int, step_limit: float | None = None):
    """The runner's config for one episode of this evaluation (`step_limit`: the env's `max_ee_step`)."""
    from lano3dp.runtime import RuntimeConfig

    return RuntimeConfig.from_settings(config.guidance, config.obstacle, scheduler=config.scheduler,
                                       num_inference_steps=config.steps, n_action_steps=config.n_action_steps,
                                       step_limit=step_limit, seed=seed)


# ---- one process: policy + env + episodes ---------------------------------------------------------
class EpisodeRunner:
    """Loads the policy and builds the env once, then runs episodes by seed (used by every worker).

    `runner_class` is the controller each episode gets (a `runtime.PolicyRunner` subclass to change how it
    perceives or guides; None: PolicyRunner itself)."""

    def __init__(self, config: EvalConfig, runner_class=None):
        from lano3dp.perception import ObjectObserver
        from lano3dp.policy import DiffusionPolicy

        self.config = config = tuned_config(config, config.checkpoint)
        self.runner_class = runner_class
        self.policy = DiffusionPolicy.from_pretrained(config.checkpoint)
        settings = dataset_settings(config.checkpoint)
        self.settings = settings
        task = evaluation_task(config, settings, self.policy.config)
        check_env_task(task, self.policy.config, config.env)
        self.task = task
        image_size = config.perception.image_size or settings.image_size or 128
        needs_rgb = self.policy.config.observation.needs_rgb or bool(config.video_dir)
        self.env = env_factory.make_env(config.env, task=task, seed=config.seed, variation=config.variation,
                                        image_size=image_size, render_rgb=needs_rgb, max_steps=config.max_steps)
        # the simulator truncates at its own limit; a user's env may not, so its max_steps attribute bounds it
        self.max_steps = config.max_steps if config.env is None else (config.max_steps
                                                                      or getattr(self.env, "max_steps", None))
        self.observer = ObjectObserver(build_config_segmenter(config), n_points=self.policy.config.n_points,
                                       crop_low=settings.crop_low, crop_high=settings.crop_high)

    def run(self, seed: int, video_path: str | None = None) -> dict[str, Any]:
        from lano3dp.runtime import PolicyRunner, rollout, scene_obstacles

        config = self.config
        runner = (self.runner_class or PolicyRunner)(self.policy, self.observer, runtime_config(
            config, seed, step_limit=getattr(self.env, "max_ee_step", None)))
        slots = tuple(self.policy.config.object_names)
        carried = carried_slot_word(self.task)

        def on_reset(runner: PolicyRunner, frame, info) -> None:
            phrases = info.get("target_phrases") or {}
            targets = [phrases.get(slot, slot) for slot in slots] if slots else None
            obstacles = config.obstacles if config.obstacles is not None else scene_obstacles(frame)
            held = phrases.get(carried, carried) if carried else None
            runner.set_objects(targets if runner.policy_config.observation.object_slots else None, obstacles, held)

        frames: list[np.ndarray] = []
        on_frame = (lambda frame, info: frames.append(frame.rgb.copy())) if video_path else None
        result = rollout(self.env, runner, seed=seed, on_reset=on_reset, on_frame=on_frame,
                         max_steps=self.max_steps)
        record = result.to_dict(include_path=True)
        record["success_reported"] = self.env.reports_success  # False: the env never said, "success" is unmeasured
        if video_path and frames:
            write_video(video_path, frames)
            record["video"] = video_path
        return record

    def close(self) -> None:
        self.env.close()


def carried_slot_word(task: str) -> str | None:
    """The slot word of what the gripper carries in a registered task (its extent enlarges Q*), else None."""
    from lano3dp.sim.tasks import skill_registry

    registry = skill_registry()
    if task not in registry:
        return None
    spec = registry.get(task)
    return None if spec.carried_slot is None else spec.slot_words[spec.carried_slot]


_WORKER: EpisodeRunner | None = None
_WORKER_ERROR: BaseException | None = None


def _worker_init(config_dict: dict[str, Any], shapes: dict[str, bytes] | None = None,
                 observation_types: dict[str, bytes] | None = None) -> None:
    global _WORKER, _WORKER_ERROR
    os.environ["OMP_NUM_THREADS"] = "1"
    import torch

    torch.set_num_threads(1)
    try:
        # a spawned process has only the built-in shapes and observation types: register the parent's ones
        # (shapes_for_workers, observation_types_for_workers)
        if shapes or observation_types:
            import pickle

            from lano3dp.guidance.shapes import register_obstacle_shape
            from lano3dp.policy.observations import register_observation_type

            if config_dict.get("env"):  # a class may live in the --env file, imported under its own name
                env_factory.load_factory(config_dict["env"])
            for name, payload in (shapes or {}).items():
                register_obstacle_shape(name, pickle.loads(payload), replace=True)
            for name, payload in (observation_types or {}).items():
                register_observation_type(name, pickle.loads(payload), replace=True)
        _WORKER = EpisodeRunner(EvalConfig.from_dict(config_dict))
    except Exception as error:  # a Pool re-spawns workers whose initializer raises, forever: report it per job
        _WORKER_ERROR = error


def _worker_run(job: tuple[int, int, str | None]) -> tuple[int, dict[str, Any]]:
    if _WORKER_ERROR is not None:
        raise _WORKER_ERROR
    index, seed, video = job
    return index, _WORKER.run(seed, video)


def shapes_for_workers(name: str) -> dict[str, bytes]:
    """{name: pickled shape} for a user's obstacle shape, which spawned worker processes would not know."""
    from lano3dp.guidance.shapes import shape_for_workers

    return shape_for_workers(name)


def observation_types_for_workers(name: str) -> dict[str, bytes]:
    """{name: pickled observation type} for a user's type (a checkpoint's obs_type), likewise."""
    from lano3dp.policy.observations import observation_type_for_workers

    return observation_type_for_workers(name)


# ---- the whole evaluation ------------------------------------------------------------------------
def stage_breakdown(episodes: Sequence[dict[str, Any]]) -> tuple[dict[str, float], dict[str, int]]:
    """Where episodes fail: (stage -> fraction of episodes that reached it, furthest stage -> episodes that
    got that far and no further, with "none" for those that reached no stage), both in the task's order.

    Records without stages (results made before tasks had them) count as reaching none; with no record
    holding stages both are empty.
    """
    order = next((list(e["stages"]) for e in episodes if e.get("stages")), [])
    if not order:
        return {}, {}
    n = len(episodes)
    rates = {stage: round(sum(bool((e.get("stages") or {}).get(stage)) for e in episodes) / n, 4)
             for stage in order}
    furthest = {stage: 0 for stage in ["none", *order]}
    for e in episodes:
        key = e.get("stage") or "none"
        furthest[key] = furthest.get(key, 0) + 1
    return rates, furthest


def summarize(episodes: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Aggregate per-episode records into rates and means (clearance only over episodes that measured one)."""
    n = len(episodes)
    latencies = np.array([t for e in episodes for t in e["chunk_latency_s"]], dtype=np.float64)
    clearances = [e["min_clearance"] for e in episodes if e["min_clearance"] is not None]

    def rate(flag: Callable[[dict], bool]) -> float:
        return round(sum(bool(flag(e)) for e in episodes) / n, 4) if n else float("nan")

    def mean(values) -> float | None:
        values = list(values)
        return round(float(np.mean(values)), 5) if values else None

    stage_rates, furthest_stages = stage_breakdown(episodes)
    return {
        "episodes": n,
        "successes": sum(bool(e["success"]) for e in episodes),
        # The obstacle variation skips an obstacle where a layout leaves no room on the path: count
        # the episodes that really had one, so a collision rate is read against them.
        "episodes_with_obstacles": sum(bool(e.get("obstacles")) for e in episodes),
        "success_rate": rate(lambda e: e["success"]),
        "collision_rate": rate(lambda e: e["collided"]),
        "mean_collision_steps": mean(e["n_collision_steps"] for e in episodes),
        "safe_success_rate": rate(lambda e: e["success"] and not e["collided"]),
        "error_rate": rate(lambda e: e["error"] is not None),
        "mean_min_clearance": mean(clearances),
        "worst_min_clearance": round(min(clearances), 5) if clearances else None,
        "mean_path_length": mean(e["path_length"] for e in episodes),
        "mean_steps": mean(e["steps"] for e in episodes),
        "chunks": int(latencies.size),
        "latency_mean_s": round(float(latencies.mean()), 5) if latencies.size else None,
        "latency_p95_s": round(float(np.quantile(latencies, 0.95)), 5) if latencies.size else None,
        "mean_tries": mean(t for e in episodes for t in e["chunk_tries"]),
        "errors": sorted({e["error"].split(":")[0] for e in episodes if e["error"]}),
        "stage_rates": stage_rates,
        "furthest_stages": furthest_stages,
    }


# Fields that change how an evaluation runs, not what it measures: every episode is seeded by itself.
EVAL_FIELDS_NOT_MEASURED = ("workers",)
# Where each field of the flat EvalConfig (results saved before the settings were nested) lives now.
FLAT_EVAL_FIELDS = {
    "guidance": ("guidance", "mode"), "rho": ("guidance", "rho"), "last_steps": ("guidance", "last_steps"),
    "per_train_step": ("guidance", "per_train_step"), "metric_gradient": ("guidance", "metric_gradient"),
    "densify": ("guidance", "densify"), "checked": ("guidance", "checked"),
    "guide_when_needed": ("guidance", "guide_when_needed"),
    "obstacle_shape": ("obstacle", "shape"), "margin": ("obstacle", "margin"), "body": ("obstacle", "body"),
    "held_radius": ("obstacle", "held_radius"), "refit_obstacles": ("obstacle", "refit"),
    "segmenter": ("perception", "segmenter"), "detector": ("perception", "detector"),
    "detector_dir": ("perception", "detector_dir"), "sam_dir": ("perception", "sam_dir"),
    "image_size": ("perception", "image_size"),
}
# What flat results saved before a field existed were made with, where that is not the field's default.
EVAL_FIELDS_BEFORE = {"body": "sphere"}
# ... and the same for fields added to a settings section (every guided result before them ran without).
SECTION_FIELDS_BEFORE = {"guidance": {"anchored": False, "repair_steps": 0, "hold_unclear": False,
                                       "push_turn": 0.0, "bridge_gaps": False, "escape_when_inside": False,
                                       "follow_when_stuck": False,
                                       "tuned": False}}
# Fields that moved from one settings section to another: (from, to, name); a5d5ae9 saved these two as obstacle
# settings before they became guidance settings (tunable per policy).
MOVED_SECTION_FIELDS = (("obstacle", "guidance", "bridge_gaps"), ("obstacle", "guidance", "escape_when_inside"))
# Guidance fields that say how the settings were chosen, not what ran: a saved config has the tuning laid over it.
GUIDANCE_CHOICE_FIELDS = ("tuned", "keep")
EPISODE_LOG_FORMAT = "lano3dp-eval-episodes"


def measured_config(config: Mapping[str, Any]) -> dict[str, Any]:
    """A nested EvalConfig dict (with its checkpoint's tuning laid over it, `tuned_config`) as far as it changes
    the episodes: the worker count never does, nor how the guidance settings were chosen, and an unguided
    evaluation without checked execution never reads the other guidance settings, so results made under other
    guidance defaults stay current."""
    measured = {name: value for name, value in config.items() if name not in EVAL_FIELDS_NOT_MEASURED}
    guidance = measured.get("guidance")
    if isinstance(guidance, Mapping):
        guidance = measured["guidance"] = {name: value for name, value in guidance.items()
                                           if name not in GUIDANCE_CHOICE_FIELDS}
        if guidance.get("mode") == "none" and not guidance.get("checked"):
            measured["guidance"] = {"mode": "none", "checked": False}
    return measured


def saved_config(made: Mapping[str, Any]) -> dict[str, Any]:
    """A saved EvalConfig dict (results JSON, episode log) in today's nested form, with each measured field added
    since it was saved set to what it was made with (EVAL_FIELDS_BEFORE, SECTION_FIELDS_BEFORE, else the field's
    default), so adding a field keeps earlier results current and a killed evaluation's log resumable. A flat
    dict, saved before the settings were nested, has its fields moved into their sections (FLAT_EVAL_FIELDS)."""
    from dataclasses import MISSING

    made = json.loads(json.dumps(dict(made)))  # a copy, in JSON types
    flat = not any(isinstance(made.get(name), Mapping) for name in _SECTIONS)
    for old, (section, name) in FLAT_EVAL_FIELDS.items():  # "guidance" first: later keys fill its section
        if old in made and not isinstance(made[old], Mapping):
            value = made.pop(old)
        elif flat and old in EVAL_FIELDS_BEFORE:
            value = EVAL_FIELDS_BEFORE[old]
        else:
            continue
        if isinstance(home := made.setdefault(section, {}), dict):  # else no EvalConfig wrote it: it won't match
            home[name] = value
    for source, target, name in MOVED_SECTION_FIELDS:
        if isinstance(made.get(source), dict) and name in made[source] and isinstance(made.get(target), dict):
            made[target][name] = made[source].pop(name)
    for spec in fields(EvalConfig):
        if spec.name in EVAL_FIELDS_NOT_MEASURED or (spec.default is MISSING and spec.default_factory is MISSING):
            continue
        default = spec.default if spec.default_factory is MISSING else spec.default_factory()
        if spec.name in _SECTIONS:
            if isinstance(section := made.get(spec.name, {}), Mapping):  # else no EvalConfig wrote it: it won't match
                before = SECTION_FIELDS_BEFORE.get(spec.name, {})
                if spec.name == "guidance" and section.get("mode") == "none":
                    before = {}  # unguided: the guidance fields changed nothing, so today's defaults describe it
                made[spec.name] = {**json.loads(json.dumps(asdict(default))), **before, **section}
        elif spec.name not in made:
            made[spec.name] = json.loads(json.dumps(default))
    return made


def episode_log_path(out: str | Path) -> Path:
    """The JSONL log beside a results JSON: results.json -> results.episodes.jsonl."""
    out = Path(out)
    return out.with_name((out.stem if out.suffix == ".json" else out.name) + ".episodes.jsonl")


class EpisodeLog:
    """Finished episodes of one evaluation, one JSON line each, appended (and fsync'ed) as they finish.

    The first line says which evaluation the log belongs to (its EvalConfig up to the worker count, and
    the checkpoint's weights); a log of another evaluation is started afresh. A last line cut short by a
    kill is dropped; every complete line is an episode that is not run again.
    """

    def __init__(self, path: str | Path, identity: dict[str, Any]):
        self.path = Path(path)
        self.identity = identity
        self.records: dict[int, dict[str, Any]] = {}
        self._load()

    def _load(self) -> None:
        from lano3dp.errors import CorruptFileError

        if not self.path.exists():
            self._start()
            return
        raw = self.path.read_bytes()
        lines = raw.split(b"\n")
        complete, tail = lines[:-1], lines[-1]  # `tail` is what a kill mid-line left (b"" when none)
        try:
            header = json.loads(complete[0]) if complete else None
        except ValueError:
            header = None
        evaluation = header.get("evaluation") if isinstance(header, dict) else None
        if isinstance(evaluation, dict) and isinstance(evaluation.get("config"), dict):
            evaluation = {**evaluation, "config": measured_config(saved_config(evaluation["config"]))}
        if not header or header.get("format") != EPISODE_LOG_FORMAT or evaluation != self.identity:
            self._start()  # another evaluation's log (or an empty one): this evaluation starts from nothing
            return
        for number, line in enumerate(complete[1:], 2):
            try:
                entry = json.loads(line)
                self.records[int(entry["index"])] = entry["episode"]
            except (ValueError, KeyError, TypeError) as error:
                raise CorruptFileError(self.path, f"line {number} is not an episode record ({error}); delete the "
                                                  "file to evaluate every episode again") from error
        if tail:
            with open(self.path, "r+b") as handle:
                handle.truncate(len(raw) - len(tail))

    def _start(self) -> None:
        header = {"format": EPISODE_LOG_FORMAT, "evaluation": self.identity}
        write_text_atomic(self.path, json.dumps(header) + "\n")
        self.records = {}

    def append(self, index: int, record: dict[str, Any]) -> dict[str, Any]:
        """Write one finished episode; returns it as read back (JSON types), as every summary sees it."""
        record = json.loads(json.dumps(to_jsonable(record)))
        with open(self.path, "a") as handle:
            handle.write(json.dumps({"index": index, "episode": record}) + "\n")
            handle.flush()
            os.fsync(handle.fileno())
        self.records[index] = record
        return record


def evaluation_identity(config: EvalConfig, checkpoint: Path) -> dict[str, Any]:
    """What makes two evaluations the same: the config up to the worker count, and the exact weights."""
    from safetensors import safe_open

    from lano3dp.policy.modeling import CHECKSUM_KEY, WEIGHTS_NAME

    wanted = measured_config(json.loads(json.dumps(to_jsonable(asdict(config)))))
    weights = checkpoint / WEIGHTS_NAME
    try:
        with safe_open(str(weights), framework="pt") as handle:
            checksum = (handle.metadata() or {}).get(CHECKSUM_KEY)
    except Exception:  # loading the policy reports the damage
        checksum = None
    if checksum is None:
        stat = weights.stat()
        checksum = f"size={stat.st_size},mtime_ns={stat.st_mtime_ns}"
    return {"config": wanted, "checkpoint": str(checkpoint), "weights": checksum}


def evaluate(config: EvalConfig, progress: Callable[[int, int, dict], None] | None = None,
             command: str | None = None) -> dict[str, Any]:
    """Run every episode and return (and, with `config.out`, write) the results dict.

    With `config.out`, each finished episode is appended to `episode_log_path(config.out)` as it
    finishes, an evaluation killed part-way resumes from that log (its episodes are not run again),
    and the summary is made from the log. The output is locked: a second evaluation writing the same
    file is refused.

    Args:
        progress: called after each finished episode with (done, total, record); resumed episodes first.
        command: the command line to record (default: this process's argv).
    """
    from lano3dp.locking import WriteLock, prepare_parent

    lock = None
    if config.out:
        prepare_parent(config.out)  # a bad --out fails here, before the first episode
        lock = WriteLock(config.out).acquire()
    try:
        return _evaluate(config, progress, command)
    finally:
        if lock is not None:
            lock.release()


def evaluation_task(config: EvalConfig, settings: DatasetSettings, policy_config) -> str:
    """The task evaluated: the config's, else the one the checkpoint was trained on."""
    task = config.task or settings.task or policy_config.extra.get("task")
    if task is None:
        raise ValueError("no task given and the checkpoint does not say which task it was trained on; pass --task")
    return task


def evaluation_seeds(config: EvalConfig, checkpoint: Path) -> list[int]:
    """The episode seeds: seed, seed + 1, ...; or, with obstacle_scenes_only, the first seeds from seed on
    whose scene has room for the variation's obstacles."""
    if not config.obstacle_scenes_only:
        return [config.seed + i for i in range(config.episodes)]
    from lano3dp.policy.modeling import load_config
    from lano3dp.sim.env import obstacle_scene_seeds

    task = evaluation_task(config, dataset_settings(checkpoint), load_config(checkpoint / "config.json"))
    return obstacle_scene_seeds(task, config.variation, config.seed, config.episodes)


def _evaluate(config: EvalConfig, progress, command) -> dict[str, Any]:
    from lano3dp.data.store import library_versions
    from lano3dp.policy.modeling import load_config, resolve_checkpoint

    started = time.perf_counter()
    started_at = datetime.now(UTC).isoformat(timespec="seconds")
    checkpoint = resolve_checkpoint(config.checkpoint)
    tuning = load_guidance_tuning(checkpoint)
    config = replace(config, guidance=config.guidance.tuned_for(tuning))
    if config.out and Path(config.out).is_dir():  # Path("") is ".", a folder: out=None must pass
        raise IsADirectoryError(f"--out {config.out} is a folder; give the results JSON file to write")
    log = EpisodeLog(episode_log_path(config.out), evaluation_identity(config, checkpoint)) if config.out else None
    records: dict[int, dict[str, Any]] = dict(log.records) if log else {}
    seeds = evaluation_seeds(config, checkpoint)
    records = {index: record for index, record in records.items() if index < len(seeds)}
    resumed = len(records)
    jobs = []
    for index, seed in enumerate(seeds):
        video = None
        if config.video_dir and index < config.n_videos:
            video = str(Path(config.video_dir) / f"episode_{seed}.mp4")
        if index not in records:
            jobs.append((index, seed, video))
    done = 0
    for index in sorted(records):
        done += 1
        if progress:
            progress(done, len(seeds), records[index])

    def finished(index: int, record: dict[str, Any]) -> None:
        nonlocal done
        records[index] = log.append(index, record) if log else record
        done += 1
        if progress:
            progress(done, len(seeds), records[index])

    workers = max(1, min(config.workers, len(jobs)))
    if jobs and workers == 1:
        runner = EpisodeRunner(config)
        try:
            for index, seed, video in jobs:
                finished(index, runner.run(seed, video))
        finally:
            runner.close()
    elif jobs:
        context = mp.get_context("spawn")
        plugins = (shapes_for_workers(config.obstacle.shape),
                   observation_types_for_workers(load_config(checkpoint / "config.json").obs_type))
        with context.Pool(workers, initializer=_worker_init, initargs=(asdict(config), *plugins)) as pool:
            for index, record in pool.imap_unordered(_worker_run, jobs):
                finished(index, record)
    episodes = [records[index] for index in sorted(records)]
    summary = summarize(episodes)
    notes = []
    if episodes and not any(e.get("success_reported", True) for e in episodes):
        # an env without info["success"]: a success rate of 0 would read as a measurement
        summary.update(success_rate=None, safe_success_rate=None, successes=None)
        notes.append("the environment reports no info['success']: success is not measured")
    result = {
        "command": command if command is not None else shlex.join(["lano3dp", *sys.argv[1:]]),
        "config": asdict(config),
        "checkpoint": str(checkpoint),
        "guidance_tuning": config.guidance.tuning_taken(tuning),  # what of config.guidance the checkpoint chose
        "policy": load_config(checkpoint / "config.json").to_dict(),
        "summary": summary,
        "episodes": episodes,
        "timing": {"started_utc": started_at, "wall_s": round(time.perf_counter() - started, 2),
                   "workers": workers, "cpu_count": os.cpu_count(), "resumed_episodes": resumed},
        "versions": library_versions(),
        "env": config.env or "builtin",
        "notes": notes,
    }
    if config.out:
        write_json(config.out, result)
    return result


# ---- one instruction, end to end -----------------------------------------------------------------
@dataclass
class RunConfig:
    """`lano3dp run`: instruction -> plan -> perception -> (guided) policy -> one simulated episode.

    Attributes:
        instruction: what the user says, e.g. "pour the bowl into the pan and keep clear of the grey cylinder".
        checkpoint: the policy to run (default: the plan's skill's checkpoint in `registry`).
        registry: a skill registry JSON (SkillRegistry.to_json) naming a checkpoint per skill.
        task: simulator task, or the task `env`'s factory gets (default: the plan's skill, whose registry name
            is the task name).
        variation: scene variation (default: "obstacle" when the plan names obstacles, else "clean").
        guidance, obstacle, perception, scheduler, steps: as EvalConfig, but guided by default (the recommended
            preset, mode "clean").
        compare: also run the same scene without guidance, for the plot.
        seed: scene seed.
        out: folder for run.json, video.mp4 and top_view.png.
        env: as EvalConfig.env (None: the built-in simulator). With a user's env the scene is the one its reset
            gives (no search for a scene with room for an obstacle), the plan is grounded in the objects its
            frame names (not at all when it names none), and the factory gets task = the plan's skill unless
            `task` is given.
    """

    instruction: str
    checkpoint: str | None = None
    registry: str | None = None
    task: str | None = None
    variation: str | None = None
    guidance: GuidanceSettings = field(default_factory=GuidanceSettings)
    obstacle: ObstacleSettings = field(default_factory=ObstacleSettings)
    perception: PerceptionSettings = field(default_factory=PerceptionSettings)
    scheduler: str | None = None
    steps: int | None = None
    compare: bool = False
    max_steps: int | None = None
    seed: int = DEFAULT_EVAL_SEED
    out: str = "run_out"
    env: str | None = None

    def __post_init__(self):
        self.env = env_spec(self.env)
        _build_sections(self)


def ground_obstacles(frame, phrases: Sequence[str]) -> tuple[list[str], list[str]]:
    """Obstacle phrases -> what to segment in this scene, plus notes for the user.

    A phrase the scene has is kept. The simulator's obstacles are plain grey cylinders, so a phrase it
    does not have ("the mug") is mapped onto the scene's obstacle objects instead, and a note says so.
    """
    from lano3dp.perception import SimOracleSegmenter
    from lano3dp.perception.exceptions import PerceptionError
    from lano3dp.runtime import scene_obstacles

    segmenter = SimOracleSegmenter()  # what the simulated scene holds, whatever segmenter the policy then uses
    kept, missing, notes = [], [], []
    for phrase in phrases:
        try:
            found = segmenter.segment(frame, [phrase])[0].found
        except PerceptionError:  # ambiguous: several objects match; keep the phrase, perception will say more
            found = True
        (kept if found else missing).append(phrase)
    if missing:
        stand_ins = [name for name in scene_obstacles(frame) if name not in kept]
        if not stand_ins:
            raise ValueError(f"obstacle(s) {', '.join(repr(m) for m in missing)} are not in the scene and the scene "
                             f"has no obstacle objects; objects: {', '.join(sorted(frame.instance_names))}")
        notes.append(f"{', '.join(repr(m) for m in missing)} not in the simulated scene; avoiding its obstacle "
                     f"object(s) {', '.join(stand_ins)} instead")
        kept += stand_ins
    return kept, notes


_SCENE_TRIES = 20  # scenes `run` looks through for one with room for an obstacle


def run_instruction(config: RunConfig, log: Callable[[str], None] = print,
                    command: str | None = None) -> dict[str, Any]:
    """Plan, perceive, act: one episode for one instruction. Writes run.json, video.mp4 and top_view.png
    into `config.out`, which is locked while it runs (a second run into the same folder is refused)."""
    from lano3dp.locking import WriteLock

    with WriteLock(config.out):
        return _run_instruction(config, log, command)


def _run_instruction(config: RunConfig, log: Callable[[str], None], command: str | None) -> dict[str, Any]:
    from lano3dp.language import OfflineDecomposer, SkillRegistry, UnknownObjectError
    from lano3dp.perception import ObjectObserver
    from lano3dp.policy import DiffusionPolicy
    from lano3dp.policy.modeling import resolve_checkpoint
    from lano3dp.policy.pretrained import packaged_checkpoint, packaged_checkpoints
    from lano3dp.report import plot_top_view
    from lano3dp.runtime import PolicyRunner, RuntimeConfig, observe, rollout
    from lano3dp.sim.tasks import skill_registry

    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    registry = SkillRegistry.load(config.registry) if config.registry else skill_registry()
    decomposer = OfflineDecomposer(registry)
    plan = decomposer.decompose(config.instruction)
    log(f"plan: {plan.summary()}")
    for warning in plan.warnings:  # what the parser was unsure of: the user should see it before the robot moves
        log(f"warning: {warning}")
    checkpoint = config.checkpoint or (registry.get(plan.skill).checkpoint if plan.skill in registry else None)
    if checkpoint is None:
        if plan.skill not in packaged_checkpoints():
            raise ValueError(f"no checkpoint for skill '{plan.skill}' (none is packaged for it): pass --checkpoint, "
                             "or a --registry naming one")
        checkpoint = packaged_checkpoint(plan.skill)
        log(f"policy: the one packaged for {plan.skill} ({checkpoint.name})")
    policy = DiffusionPolicy.from_pretrained(checkpoint)
    tuning = load_guidance_tuning(resolve_checkpoint(checkpoint))
    if taken := config.guidance.tuning_taken(tuning):
        log("guidance: as this policy was tuned: " + ", ".join(f"{name} {value}" for name, value in taken.items()))
        config = replace(config, guidance=config.guidance.tuned_for(tuning))
    for note in config.guidance.ineffective():
        log(f"note: {note}")
    settings = dataset_settings(checkpoint)
    task = config.task or plan.skill
    check_env_task(task, policy.config, config.env)
    variation = config.variation or ("obstacle" if plan.obstacles else "clean")
    env = env_factory.make_env(config.env, task=task, seed=config.seed, variation=variation,
                               image_size=config.perception.image_size or settings.image_size or 128,
                               render_rgb=True, max_steps=config.max_steps)
    max_steps = config.max_steps if config.env is None else (config.max_steps or getattr(env, "max_steps", None))
    observer = ObjectObserver(build_config_segmenter(config), n_points=policy.config.n_points,
                              crop_low=settings.crop_low, crop_high=settings.crop_high)
    seed = config.seed
    frame, _ = observe(env, env.reset(seed=seed)[0])
    if plan.obstacles and config.env is None and env.episode.variation.has("obstacle"):
        # a layout can leave no room for an obstacle on the path (e.g. the drawer right beside the start):
        # show the instruction on the next scene that has one rather than fail on this one
        while not any(a.get("role") == "obstacle" for a in frame.instance_attributes.values()) \
                and seed < config.seed + _SCENE_TRIES:
            seed += 1
            env.reset(seed=seed)
            frame = env.frame()
        if seed != config.seed:
            log(f"note: scene {config.seed} has no room for an obstacle on the path; using scene {seed}")
    scene_objects = [n for n, a in frame.instance_attributes.items() if a.get("role") != "robot"]
    try:
        plan = decomposer.decompose(config.instruction, scene_objects or None)  # None: a frame naming no objects
        obstacles, notes = list(plan.obstacle_phrases), []
    except UnknownObjectError as error:  # e.g. an obstacle the simulator cannot show: stand in its obstacles
        log(f"note: {error}")
        obstacles, notes = ground_obstacles(frame, plan.obstacle_phrases)
    for note in notes:
        log(f"note: {note}")
    targets = plan.target_phrases if policy.config.observation.object_slots else None
    carried = registry.get(plan.skill).carried_slot if plan.skill in registry else None
    held = plan.target_phrases[carried] if carried is not None else None
    log(f"task {task} / {variation}, seed {seed}: targets {targets}, obstacles {obstacles}")

    conditions = [("guided" if config.guidance.guided else "unguided", config.guidance.mode)]
    if config.compare and config.guidance.guided:
        conditions.append(("unguided", "none"))
    episodes, paths = {}, []
    for label, mode in conditions:
        runtime = RuntimeConfig.from_settings(replace(config.guidance, mode=mode), config.obstacle,
                                              scheduler=config.scheduler, num_inference_steps=config.steps,
                                              step_limit=getattr(env, "max_ee_step", None), seed=seed)
        runner = PolicyRunner(policy, observer, runtime, target_phrases=targets, obstacle_phrases=obstacles,
                              held_object=held)
        frames: list[np.ndarray] = []
        result = rollout(env, runner, seed=seed, max_steps=max_steps,
                         on_frame=lambda f, info, frames=frames: frames.append(f.rgb.copy()))
        video = write_video(out / f"video_{label}.mp4", frames)
        record = result.to_dict(include_path=True)
        record["video"] = str(video)
        record["success_reported"] = env.reports_success
        episodes[label] = record
        outcome = ("success" if result.success else "failure") if env.reports_success else "success not reported"
        paths.append((f"{label}: {outcome}" + (", collided" if result.collided else ""), result.ee_path))
        clearance = "–" if result.min_clearance is None else f"{100 * result.min_clearance:.1f} cm"
        log(f"{label}: {outcome.upper() if result.success else outcome} after {result.steps} steps, "
            f"obstacle contact: {'yes' if result.collided else 'no'}, min clearance {clearance}, "
            f"path {result.path_length:.2f} m, {len(result.chunk_latency_s)} chunks, "
            f"mean latency {1000 * np.mean(result.chunk_latency_s or [0]):.0f} ms"
            + (f" ({result.error})" if result.error else ""))
    first = episodes[conditions[0][0]]
    plot = plot_top_view(out / "top_view.png", paths, obstacles=first["obstacles"], objects=first["targets"],
                         title=f"'{config.instruction}'")
    result = {"command": command or shlex.join(["lano3dp", *sys.argv[1:]]), "config": asdict(config),
              "plan": plan.model_dump(),
              "task": task, "variation": variation, "seed": seed, "obstacles": obstacles, "notes": notes,
              "checkpoint": str(checkpoint), "episodes": episodes, "top_view": str(plot)}
    write_json(out / "run.json", result)
    env.close()
    return result


class _CallableModule(types.ModuleType):
    """`lano3dp.evaluate` is this module once it is imported (Python sets a submodule as its package's
    attribute), and the public API promises `from lano3dp import evaluate; evaluate(config)`: calling the
    module calls the function, so both readings work."""

    def __call__(self, config: EvalConfig, progress: Callable[[int, int, dict], None] | None = None,
                 command: str | None = None) -> dict[str, Any]:
        return evaluate(config, progress, command)


sys.modules[__name__].__class__ = _CallableModule
