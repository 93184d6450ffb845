"""What an evaluation (`lano3dp eval`) and an instruction run (`lano3dp run`) are told: one typed tree each.

    EvalConfig(checkpoint="runs/bowl", variation="obstacle", guidance=GuidanceChoice("tuned"))
    EvalConfig(..., guidance=GuidanceChoice("paper"))                                   # the paper's form
    EvalConfig(..., guidance=GuidanceChoice("recommended", {"sampler.rho": 0.02}))      # a preset, one change

The guidance is named, not spelled out: a preset (`guidance.settings`) plus dotted overrides, resolved when the
policy is loaded ("tuned" is the checkpoint's own tuning), so a saved config re-makes its run. Results save the
config as given and the guidance tree that ran. `load_config_file` reads a YAML or JSON file (a results JSON's
"config" section too) and `with_assignments` applies `--set path=value` pairs to it.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from lano3dp import env_factory
from lano3dp.config_tree import SettingsError, from_dict, overrides, parse_assignment, to_dict
from lano3dp.guidance.settings import TUNED, GuidanceSettings, preset_names, resolve_guidance
from lano3dp.runtime import SUCCESS_AT

DEFAULT_EVAL_SEED = 1_000_000  # apart from demonstration seeds (0, 1, ... and retries at multiples of 100003)
SEGMENTERS = {"sim": "oracle", "error-model": "error_model", "open-vocab": "open_vocab"}  # option -> factory kind
DETECTORS = ("grounding_dino", "owlv2")
_STRICT = {"extra": "forbid"}


@dataclass(frozen=True)
class PerceptionSettings:
    """How targets and obstacles are seen.

    Attributes:
        segmenter: "sim" (the simulator's ground-truth masks), "error-model" (those masks through a model of
            detector, SAM and tracker errors: `perception.error_model`) or "open-vocab" (detector + SAM, the paper's
            perception; needs detector_dir and sam_dir, local weight folders, never downloaded).
        detector: "grounding_dino" or "owlv2" (open-vocab).
        detector_dir, sam_dir: (open-vocab) the weight folders.
        image_size: camera resolution (None: that of the data the checkpoint was trained on).
    """

    __pydantic_config__ = _STRICT

    segmenter: str = "sim"
    detector: str = "grounding_dino"
    detector_dir: str | None = None
    sam_dir: str | None = None
    image_size: int | None = None

    def __post_init__(self):
        if self.segmenter not in SEGMENTERS:
            raise ValueError(f"segmenter must be one of {', '.join(SEGMENTERS)}, got {self.segmenter!r}")
        if self.detector not in DETECTORS:
            raise ValueError(f"detector must be one of {', '.join(DETECTORS)}, got {self.detector!r}")
        for name in ("detector_dir", "sam_dir"):  # a Path is saved as its text, so results stay JSON
            value = getattr(self, name)
            object.__setattr__(self, name, None if value is None else str(value))
        if self.segmenter == "open-vocab" and not (self.detector_dir and self.sam_dir):
            raise ValueError("segmenter open-vocab needs local weight folders: set detector_dir and sam_dir")
        if self.image_size is not None and self.image_size < 16:
            raise ValueError(f"image_size must be >= 16, got {self.image_size}")


def _flatten(changes: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """{"sampler": {"rho": 1}} and {"sampler.rho": 1} alike -> {"sampler.rho": 1}; values that are dicts of a
    free-keyed field (filter options) are kept whole below it."""
    flat: dict[str, Any] = {}
    for key, value in changes.items():
        path = f"{prefix}{key}"
        if isinstance(value, Mapping) and value and not path.startswith("execution.options"):
            flat.update(_flatten(value, f"{path}."))
        else:
            flat[path] = value
    return flat


@dataclass(frozen=True)
class GuidanceChoice:
    """A guidance preset by name ("none", "a_k", "paper", "recommended", "tuned", or a registered one) and dotted
    overrides below `guidance.` (e.g. {"sampler.rho": 0.02}); nested dicts are read as dotted paths too."""

    __pydantic_config__ = _STRICT

    preset: str = "none"
    overrides: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        if self.preset not in preset_names():
            raise ValueError(f"unknown guidance preset {self.preset!r}; presets: {', '.join(preset_names())}")
        object.__setattr__(self, "overrides", _flatten(self.overrides))
        # refused now, before any work: "tuned" is checked on the recommended preset it defaults to (the checkpoint's
        # own is checked again when it is loaded)
        resolve_guidance("recommended" if self.preset == TUNED else self.preset, self.overrides, None)

    def resolve(self, tuning) -> GuidanceSettings:
        """The settings that run, given the checkpoint's tuning (`guidance.settings.load_guidance_tuning`)."""
        return resolve_guidance(self.preset, self.overrides, tuning)


@dataclass(frozen=True)
class EvalConfig:
    """One evaluation (saved in the results JSON; `EvalConfig.from_dict` reads it back).

    Attributes:
        checkpoint: a policy folder, a training run (its checkpoints/last), or None: the policy packaged for
            `task` ("packaged:<task>" names one explicitly).
        task: task name, the simulator's or one `env`'s factory knows (default: the checkpoint's task).
        variation: "clean" or axes joined by "+" (e.g. "obstacle", "clutter+camera").
        episodes: how many; seeds are seed, seed + 1, ... (or the first obstacle scenes from seed on).
        seed: first episode seed (also seeds the sampling noise of each episode).
        obstacles: phrases of the objects to avoid; None = every object the scene marks as an obstacle.
        guidance: the guidance preset and overrides (default: none, unguided).
        perception: segmenter, detector and its weights, camera resolution.
        n_action_steps: actions executed per chunk (None: the policy's).
        max_steps: episode step limit (None: the task's, or a user env's `max_steps` attribute).
        success_at: "first" (success at any step ends the episode) or "end" (at the episode's last step).
        obstacle_scenes_only: with an obstacle variation, the first `episodes` seeds from `seed` whose scene has
            room for every obstacle asked for (chosen from the layout alone, never from an outcome).
        workers: parallel processes (1 runs in this process); never changes an episode.
        batch: episodes stepped together in one process, their chunks sampled in one policy call
            (`evaluation.batched`); each keeps its own noise, but a batched matrix product rounds differently, so
            an episode can end otherwise in rare cases: results of another batch are another evaluation.
        video_dir, n_videos: MP4s of the first n_videos episodes there.
        rerun_dir: a Rerun recording (.rrd) per episode there (needs lano3dp[viewer]).
        out: results JSON path (None: not written).
        env: None for the built-in simulator, else an env factory 'module:factory' or 'path/to/file.py:factory'
            (a callable is saved by that name), see `lano3dp.env_factory`.
    """

    __pydantic_config__ = _STRICT

    checkpoint: str | None = None
    task: str | None = None
    variation: str = "clean"
    episodes: int = 20
    seed: int = DEFAULT_EVAL_SEED
    obstacles: tuple[str, ...] | None = None
    guidance: GuidanceChoice = field(default_factory=GuidanceChoice)
    perception: PerceptionSettings = field(default_factory=PerceptionSettings)
    n_action_steps: int | None = None
    max_steps: int | None = None
    success_at: str = "first"
    obstacle_scenes_only: bool = False
    workers: int = 1
    batch: int = 1
    video_dir: str | None = None
    n_videos: int = 2
    rerun_dir: str | None = None
    out: str | None = None
    env: str | None = None

    def __post_init__(self):
        if self.checkpoint is not None:
            object.__setattr__(self, "checkpoint", str(self.checkpoint))
        elif self.task is None:
            raise ValueError("give a checkpoint, or a task to evaluate the policy packaged for it")
        object.__setattr__(self, "env", env_spec(self.env))
        if isinstance(self.guidance, str):  # a preset name alone
            object.__setattr__(self, "guidance", GuidanceChoice(self.guidance))
        if self.obstacles is not None:
            object.__setattr__(self, "obstacles", tuple(self.obstacles))
        for name in ("out", "video_dir", "rerun_dir"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, str(getattr(self, name)))
        if self.episodes < 1 or self.workers < 1 or self.batch < 1:
            raise ValueError(f"episodes, workers and batch must be >= 1, got {self.episodes}, {self.workers}, "
                             f"{self.batch}")
        if self.workers > 1 and self.batch > 1:
            raise ValueError(f"batch {self.batch} steps episodes together in one process and workers {self.workers} "
                             "spreads them over processes: choose one (batch for the most episodes per CPU-second)")
        if self.success_at not in SUCCESS_AT:
            raise ValueError(f"success_at must be one of {', '.join(SUCCESS_AT)}, got {self.success_at!r}")
        if self.obstacle_scenes_only and self.env is not None:
            raise ValueError("obstacle_scenes_only picks seeds from the built-in simulator's layouts; a user's env "
                             "picks its own scenes")

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> EvalConfig:
        return from_dict(cls, data)

    def to_dict(self) -> dict[str, Any]:
        return to_dict(self)

    def replace(self, **changes) -> EvalConfig:
        return overrides(self, changes)


@dataclass(frozen=True)
class RunConfig:
    """`lano3dp run`: instruction -> plan -> perception -> (guided) policy -> episodes in a few scenes.

    Attributes:
        instruction: what the user says, e.g. "pour the bowl into the pan and keep clear of the grey cylinder".
        checkpoint: the policy to run (default: the plan's skill's checkpoint in `registry`, else the packaged one).
        registry: a skill registry JSON (SkillRegistry.to_json) naming a checkpoint per skill.
        task: simulator task, or the task `env`'s factory gets (default: the plan's skill).
        variation: scene variation (default: "obstacle" when the plan names obstacles, else "clean").
        scenes: scenes the instruction runs in (the first ones from `seed` with room for its obstacles).
        guidance: as EvalConfig's, but "tuned" by default (the policy's own guidance).
        compare: also run each scene without guidance.
        llm: plan with an OpenAI-compatible language model (`language.LLMDecomposer`, configured from the
            environment: LANO3DP_LLM_BASE_URL / _MODEL / _API_KEY), the offline parser as its fallback.
        mapping: phrase -> scene object, for a target the user names by a word the scene does not use (e.g.
            {"teapot": "block"}); never guessed (`language.grounding.ground_plan`).
        perception, max_steps, seed, env, rerun_dir: as EvalConfig's.
        out: folder for run.json, the videos and the top view.
    """

    __pydantic_config__ = _STRICT

    instruction: str
    checkpoint: str | None = None
    registry: str | None = None
    task: str | None = None
    variation: str | None = None
    scenes: int = 1
    guidance: GuidanceChoice = field(default_factory=lambda: GuidanceChoice(TUNED))
    perception: PerceptionSettings = field(default_factory=PerceptionSettings)
    compare: bool = False
    llm: bool = False
    mapping: dict[str, str] = field(default_factory=dict)
    max_steps: int | None = None
    seed: int = DEFAULT_EVAL_SEED
    rerun_dir: str | None = None
    out: str = "run_out"
    env: str | None = None

    def __post_init__(self):
        object.__setattr__(self, "env", env_spec(self.env))
        if isinstance(self.guidance, str):
            object.__setattr__(self, "guidance", GuidanceChoice(self.guidance))
        for name in ("checkpoint", "registry", "out", "rerun_dir"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, str(getattr(self, name)))
        if self.scenes < 1:
            raise ValueError(f"scenes must be >= 1, got {self.scenes}")

    def to_dict(self) -> dict[str, Any]:
        return to_dict(self)


def env_spec(env) -> str | None:
    """An `env` as saved: None, or the factory's 'module:factory' text."""
    if env is None or isinstance(env, str):
        return env or None
    if callable(env):
        return env_factory.factory_name(env)
    raise env_factory.EnvFactoryError(f"env must be 'module:factory', 'path/to/file.py:factory' or a callable, "
                                      f"got a {type(env).__name__}")


def load_config_file(path: str | Path) -> dict[str, Any]:
    """A config file's settings as a dict: YAML or JSON; a results JSON gives its "config" section."""
    import yaml

    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text()) if path.suffix in (".yaml", ".yml") else json.loads(path.read_text())
    except (OSError, ValueError, yaml.YAMLError) as error:
        raise SettingsError(f"--config {path}: cannot read it ({str(error).splitlines()[0]})") from None
    if isinstance(data, dict) and isinstance(data.get("config"), dict) and "provenance" in data:
        data = data["config"]  # a results file: what it was made with
    if not isinstance(data, dict):
        raise SettingsError(f"--config {path}: holds no settings (a mapping of section.field: value)")
    return data


def with_assignments(data: Mapping[str, Any], assignments: Sequence[str]) -> dict[str, Any]:
    """`data` (a config dict) with `--set path=value` assignments applied; `guidance.<path>` goes to the guidance
    overrides, `guidance.preset` names the preset."""
    data = json.loads(json.dumps(dict(data)))
    for text in assignments:
        path, value = parse_assignment(text)
        keys = path.split(".")
        if keys[0] == "guidance" and len(keys) > 1 and keys[1] not in ("preset", "overrides"):
            guidance = data.setdefault("guidance", {})
            guidance.setdefault("overrides", {})[".".join(keys[1:])] = value
            continue
        node = data
        for key in keys[:-1]:
            node = node.setdefault(key, {})
            if not isinstance(node, dict):
                raise SettingsError(f"--set {text}: {key} is a setting, not a section")
        node[keys[-1]] = value
    return data


def config_field_names(cls) -> list[str]:
    return [f.name for f in fields(cls)]
