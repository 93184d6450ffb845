"""How a policy acts safely, as one settings tree, nested by what each part changes, with named presets.

    GuidanceSettings
      sampler     how a chunk is drawn: the scheduler, the guidance mode (none | noisy A_k | clean A_0|k),
                  rho, S, and the strategy (always guided, guided only when needed, checked and re-sampled)
      cost        the cost recipe (`guidance.recipe`): the push in metres, the path densified, costed from the
                  hand, turned round each obstacle
      obstacles   the obstacle tracker (`guidance.obstacles`): the fitted shape, the body kept clear, the
                  margin, re-fitting, walls across gaps too narrow for the hand
      execution   the chunk filters run on a guided sample before it executes (`guidance.execution`), in order,
                  with their options: repair, hold, escape, follow (or filters registered from outside)

Presets (`guidance_preset(name)`, `register_guidance_preset`): "none" (no guidance), "a_k" (the cost on the noisy
A_k, prior work's form), "paper" (the paper's Algorithm 1: A_0|k, DDPM-100, S = 10, the push in normalised units, a ball
round the EE point, waypoints only) and "recommended" (this project's defaults, the dataclass defaults below).
"tuned" is the checkpoint's own tuning (its `guidance.json`: a preset plus overrides), or "recommended" for a
policy without one; it is resolved when the policy is loaded (`resolve_guidance`). A variant is a preset plus
dotted overrides (`config_tree.overrides`), e.g. recommended without boundary following:
`guidance_preset("recommended").with_changes({"execution.filters": ["repair", "hold", "escape"]})`.

Combinations that cannot work are refused when the settings are built (`SettingsError`, naming both settings);
the filters' own needs are checked by `guidance.execution.check_filters`. What each part was measured to do is
in the documentation's guidance page and the results files, not here.

This module imports neither torch nor the sampler, so the command line reads it for --help cheaply.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lano3dp.config_tree import SettingsError, from_dict, overrides, to_dict
from lano3dp.errors import CorruptFileError
from lano3dp.jsonio import write_json

# Metres beyond contact at which an obstacle cost starts pushing (part of Q*).
SAFETY_MARGIN = 0.02
GUIDANCE_MODES = ("none", "noisy", "clean")  # none; the cost on A_k (prior work); on A_0|k (the paper)
PUSH_WEIGHTS = ("constant", "alpha_bar")  # see guidance.sampler's module docstring
BODY_MODELS = ("swept", "sphere")
SCHEDULERS = ("ddpm", "ddim")
STRATEGIES = ("always", "when_needed", "checked")
ON_UNCLEAR = ("execute", "stop")
_STRICT = {"extra": "forbid"}  # pydantic's config for these dataclasses: an unknown key is an error


def _check_choice(name: str, value, choices) -> None:
    if value not in choices:
        raise ValueError(f"{name} must be one of {', '.join(map(str, choices))}, got {value!r}")


@dataclass(frozen=True)
class SamplerSettings:
    """How each chunk is drawn from the policy.

    Attributes:
        mode: "none", "noisy" (the cost on A_k, prior work) or "clean" (on A_0|k, the paper's Algorithm 1).
        rho: the guidance scale: metres per guided step with `cost.metric_push`, else normalised action units.
        last_steps: S; guide while the training-scale step k <= S (100: every step).
        per_train_step: multiply rho by the scheduler stride, so DDIM pushes as much in total as DDPM-100.
        clip_range: guided steps clip the x_0 estimate to [-r, r] (normalised units) instead of the scheduler's
            [-1, 1]; None keeps the scheduler's.
        push_weight: "constant" (the paper) or "alpha_bar" (each push times sqrt(abar_k abar_k-1); for DDIM).
        scheduler, steps: "ddpm" or "ddim" and its denoising steps (None: the policy's own).
        strategy: "always" guide; "when_needed": sample the policy's own chunk first and guide only when it
            comes within the margin of an obstacle; "checked": re-sample with a larger rho while the executed
            part collides (`guidance.checked`), starting unguided when mode is "none".
        on_unclear: ("checked") when no try is clear: "execute" the clearest one, or "stop" the episode.
    """

    __pydantic_config__ = _STRICT

    mode: str = "clean"
    rho: float = 0.04
    last_steps: int = 100
    per_train_step: bool = False
    clip_range: float | None = None
    push_weight: str = "constant"
    scheduler: str | None = None
    steps: int | None = None
    strategy: str = "always"
    on_unclear: str = "execute"

    def __post_init__(self):
        _check_choice("mode", self.mode, GUIDANCE_MODES)
        _check_choice("push_weight", self.push_weight, PUSH_WEIGHTS)
        _check_choice("strategy", self.strategy, STRATEGIES)
        _check_choice("on_unclear", self.on_unclear, ON_UNCLEAR)
        if self.scheduler is not None:
            _check_choice("scheduler", self.scheduler, SCHEDULERS)
        if self.rho < 0 or self.last_steps < 0 or (self.steps is not None and self.steps < 1):
            raise ValueError(f"need rho >= 0, last_steps >= 0 and steps >= 1, got {self.rho}, {self.last_steps}, "
                             f"{self.steps}")
        if self.clip_range is not None and not 0 < self.clip_range < float("inf"):
            raise ValueError(f"clip_range must be a finite number > 0 or null, got {self.clip_range}")


@dataclass(frozen=True)
class CostSettings:
    """The cost guidance descends (`guidance.recipe.CostRecipe`).

    Attributes:
        metric_push: push isotropically in metres (`guidance.MetricGradient`, from the policy's action
            normaliser); False is the paper's push in normalised units (rho then needs to be far larger).
        densify: points per path segment the cost and the checks see (1: waypoints only, as the paper).
        anchored: cost the path from the EE's present position through the waypoints (`guidance.AnchoredPath`),
            so the step from the hand to the first action is pushed clear too (the paper: the waypoints alone).
        push_turn: degrees each obstacle's push is turned round it, towards the side the chunk already passes
            (`guidance.TurnedPush`; needs `anchored`; 0: straight away from it, the paper's).
    """

    __pydantic_config__ = _STRICT

    metric_push: bool = True
    densify: int = 4
    anchored: bool = True
    push_turn: float = 0.0

    def __post_init__(self):
        if self.densify < 1:
            raise ValueError(f"densify must be >= 1, got {self.densify}")
        if not 0 <= self.push_turn < 90:
            raise ValueError(f"push_turn must be in [0, 90) degrees, got {self.push_turn}")


@dataclass(frozen=True)
class ObstacleSettings:
    """How obstacles are tracked and become costs (`guidance.obstacles.ObstacleTracker`).

    Attributes:
        shape: the registered shape fitted to each obstacle's points: "cylinder" (the paper), "box", "points",
            or one registered with `lano3dp.guidance.register_obstacle_shape`.
        margin: metres beyond contact at which the cost starts pushing (part of Q*).
        body: what must stay clear: "swept" (the hand as a row of balls along its finger axis plus, while the
            grasp flag is set, the held object as a ball at its fitted centre, re-measured every chunk) or
            "sphere" (the paper: one ball of `held_radius` round the EE point for the whole episode).
        held_radius: ("sphere") its radius in m; None measures it as `held_extent` x the held object's radius.
        refit: re-segment and re-fit the obstacles before every chunk (moving obstacles); else they are fitted
            once, on the first frame, before the arm can occlude them.
        bridge_gaps: guide against a wall across every gap between two obstacles too narrow for the body, so
            the path goes round the pair rather than stalling at the gap (`guidance.bridge_narrow_gaps`).
        held_extent: ("sphere") multiple of the held object's fitted radius; 2 = its diameter (the paper's).
        gripper_radius: ("sphere") lower bound of the held radius: the open hand's half-span about the EE axis.
        hand_half_span, hand_radius: ("swept") the hand's half length along its finger axis and its half
            thickness, m (the defaults cover the simulator's 13 x 4 cm palm and its fingers).
        xy_only: measure distances in the horizontal plane only (the paper's setting).
    """

    __pydantic_config__ = _STRICT

    shape: str = "cylinder"
    margin: float = SAFETY_MARGIN
    body: str = "swept"
    held_radius: float | None = None
    refit: bool = False
    bridge_gaps: bool = True
    held_extent: float = 2.0
    gripper_radius: float = 0.07
    hand_half_span: float = 0.065
    hand_radius: float = 0.025
    xy_only: bool = True

    def __post_init__(self):
        from lano3dp.guidance.shapes import get_obstacle_shape

        get_obstacle_shape(self.shape)  # an unknown name fails here, naming the registered ones
        _check_choice("body", self.body, BODY_MODELS)
        if self.held_radius is not None and self.body != "sphere":
            raise ValueError("held_radius sizes the 'sphere' body; with body 'swept' the hand and the held "
                             "object are measured (set obstacles.body=sphere to fix a radius)")
        if min(self.margin, self.held_extent, self.gripper_radius) < 0 or (self.held_radius or 0) < 0:
            raise ValueError("margin, held_radius, held_extent and gripper_radius must be >= 0")
        if not 0 < self.hand_radius <= self.hand_half_span:
            raise ValueError(f"need 0 < hand_radius <= hand_half_span, got {self.hand_radius}, {self.hand_half_span}")


@dataclass(frozen=True)
class ExecutionSettings:
    """The chunk filters run, in order, on every guided sample before it executes (`guidance.execution`).

    Attributes:
        filters: registered filter names, in the order they run. Built in: "repair" (push the path the arm
            will take clear of the margin by plain descent), "hold" (execute only the start predicted to keep
            half the margin; hold still when none does), "escape" (after hold: a hand already inside half the
            margin may move where it gets no closer, or steps straight out), "follow" (after hold: a hand held
            still for several chunks follows the nearest obstacle's boundary).
        options: per filter, its options (`{"repair": {"steps": 20}}`); a filter's defaults fill the rest.
    """

    __pydantic_config__ = _STRICT

    filters: tuple[str, ...] = ("repair", "hold", "escape", "follow")
    options: dict[str, dict[str, Any]] = field(default_factory=dict)

    def __post_init__(self):
        if len(set(self.filters)) != len(self.filters):
            raise ValueError(f"filters lists one twice: {list(self.filters)}")
        if unused := sorted(set(self.options) - set(self.filters)):
            raise ValueError(f"options for {', '.join(unused)}, which is not among the filters {list(self.filters)}")


@dataclass(frozen=True)
class GuidanceSettings:
    """Everything about how a policy's chunks are drawn and made safe (see the module docstring)."""

    __pydantic_config__ = _STRICT

    sampler: SamplerSettings = field(default_factory=SamplerSettings)
    cost: CostSettings = field(default_factory=CostSettings)
    obstacles: ObstacleSettings = field(default_factory=ObstacleSettings)
    execution: ExecutionSettings = field(default_factory=ExecutionSettings)

    def __post_init__(self):
        for problem in _conflicts(self):
            raise ValueError(problem)

    @property
    def guided(self) -> bool:
        return self.sampler.mode != "none"

    def with_changes(self, changes: Mapping[str, Any]) -> GuidanceSettings:
        """A copy with dotted-path changes, e.g. {"sampler.rho": 0.02}, checked as a whole."""
        return overrides(self, changes, where="guidance")

    def to_dict(self) -> dict[str, Any]:
        return to_dict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> GuidanceSettings:
        return from_dict(cls, data, where="guidance")


def _conflicts(settings: GuidanceSettings) -> list[str]:
    """Combinations of settings that cannot work, each one line naming both settings."""
    s, found = settings.sampler, []
    if s.mode == "none" and settings.execution.filters:
        found.append(f"execution.filters {list(settings.execution.filters)} act on guided chunks, and sampler.mode "
                     "none guides none: set execution.filters=[] (the 'none' preset) or a guided mode")
    if s.mode == "none" and s.strategy == "when_needed":
        found.append("sampler.strategy when_needed guides a chunk only when needed, and sampler.mode none never "
                     "guides: use strategy always, or a guided mode")
    if s.mode != "none" and s.rho == 0 and s.strategy != "checked":
        found.append(f"sampler.rho 0 with sampler.mode {s.mode} pushes nothing: set rho > 0, or use the 'none' "
                     "preset")
    if s.on_unclear == "stop" and s.strategy != "checked":
        found.append(f"sampler.on_unclear stop acts when checked execution finds no clear chunk, and "
                     f"sampler.strategy is {s.strategy}: set strategy checked")
    if settings.cost.push_turn and not settings.cost.anchored:
        found.append(f"cost.push_turn {settings.cost.push_turn:g} turns the push round the hand's way past the "
                     "obstacle, which needs cost.anchored (the hand's position): set cost.anchored=true")
    return found


# ---- presets -------------------------------------------------------------------------------------------
TUNED = "tuned"  # the checkpoint's own tuning (its guidance.json), else "recommended"
_PRESETS: dict[str, GuidanceSettings] = {}


def register_guidance_preset(name: str, settings: GuidanceSettings, *, replace: bool = False) -> GuidanceSettings:
    """Make `settings` available as `guidance_preset(name)` and `--guidance-preset name` (its filters are checked
    now)."""
    from lano3dp.guidance.execution import check_filters

    if name == TUNED or (name in _PRESETS and not replace and _PRESETS[name] != settings):
        raise SettingsError(f"a guidance preset named {name!r} exists already; pass replace=True to replace it")
    if not isinstance(settings, GuidanceSettings):
        raise SettingsError(f"preset {name!r} must be a GuidanceSettings, got a {type(settings).__name__}")
    check_filters(settings.execution)
    _PRESETS[name] = settings
    return settings


def guidance_preset(name: str) -> GuidanceSettings:
    """The named preset ("tuned" depends on a checkpoint: see `resolve_guidance`)."""
    try:
        return _PRESETS[name]
    except KeyError:
        raise SettingsError(f"unknown guidance preset {name!r}; presets: {', '.join(preset_names())}") from None


def preset_names() -> list[str]:
    """Every preset a user can name, "tuned" included."""
    return [*_PRESETS, TUNED]


_PRESETS.update({
    "recommended": GuidanceSettings(),
    "none": GuidanceSettings(sampler=SamplerSettings(mode="none"), execution=ExecutionSettings(filters=())),
    # prior work's form: the cost on the noisy sample A_k, on the waypoints alone, nothing after sampling
    "a_k": GuidanceSettings(sampler=SamplerSettings(mode="noisy"), cost=CostSettings(anchored=False),
                            obstacles=ObstacleSettings(bridge_gaps=False), execution=ExecutionSettings(filters=())),
    # the paper's Algorithm 1 as published: DDPM-100, S = 10, the push in normalised units (rho 4 is the smallest
    # with which bench_guidance's DDPM-100 waypoints cleared the obstacle), waypoints only, and a ball of the held
    # object's diameter kept clear round the EE point
    "paper": GuidanceSettings(
        sampler=SamplerSettings(rho=4.0, last_steps=10, scheduler="ddpm", steps=100),
        cost=CostSettings(metric_push=False, densify=1, anchored=False),
        obstacles=ObstacleSettings(body="sphere", bridge_gaps=False), execution=ExecutionSettings(filters=())),
})


# ---- a checkpoint's own tuning -------------------------------------------------------------------------
GUIDANCE_TUNING_NAME = "guidance.json"
GUIDANCE_TUNING_FORMAT = "lano3dp-guidance-tuning"
GUIDANCE_TUNING_VERSION = 2  # 2: a preset plus dotted overrides (1 held flat fields: docs/compat.md)


@dataclass(frozen=True)
class GuidanceTuning:
    """What a policy folder's `guidance.json` holds: the preset its guidance starts from, the overrides chosen
    for this policy's weights, and where that was measured."""

    preset: str
    overrides: dict[str, Any]
    measured: str

    def settings(self) -> GuidanceSettings:
        return guidance_preset(self.preset).with_changes(self.overrides)


def load_guidance_tuning(checkpoint: str | Path) -> GuidanceTuning | None:
    """The guidance a policy folder was tuned with (None when it has no `guidance.json`).

    A file that is not a tuning of this version, or whose overrides do not apply, fails here with its path, before
    any episode runs."""
    path = Path(checkpoint) / GUIDANCE_TUNING_NAME
    if not path.exists():
        return None
    try:
        data = json.loads(path.read_text())
        if data.get("format") != GUIDANCE_TUNING_FORMAT:
            raise ValueError(f"not a {GUIDANCE_TUNING_FORMAT} file")
        if data.get("version") != GUIDANCE_TUNING_VERSION:
            raise ValueError(f"version {data.get('version')}, not {GUIDANCE_TUNING_VERSION}; convert it with "
                             "`lano3dp migrate`")
        tuning = GuidanceTuning(preset=data["preset"], overrides=dict(data["overrides"]),
                                measured=str(data.get("measured", "")))
        tuning.settings()
    except (ValueError, KeyError, TypeError, AttributeError) as error:
        raise CorruptFileError(path, f"not a guidance tuning ({error}); fix or delete it") from None
    return tuning


def save_guidance_tuning(checkpoint: str | Path, overrides: Mapping[str, Any], measured: str,
                         preset_name: str = "recommended") -> Path:
    """Write the guidance `checkpoint` was tuned with (atomically): `preset_name` plus dotted `overrides`, with
    `measured`, where the tuning was chosen and confirmed (results files and commands)."""
    from lano3dp.policy.integrity import MANIFEST_NAME, reseal_after_writing

    GuidanceTuning(preset_name, dict(overrides), measured).settings()  # refuses what would not load
    path = write_json(Path(checkpoint) / GUIDANCE_TUNING_NAME,
                      {"format": GUIDANCE_TUNING_FORMAT, "version": GUIDANCE_TUNING_VERSION, "preset": preset_name,
                       "overrides": dict(overrides), "measured": measured})
    if (Path(checkpoint) / MANIFEST_NAME).exists():  # a sealed checkpoint stays sealed, over the new tuning
        reseal_after_writing(checkpoint, [GUIDANCE_TUNING_NAME])
    return path


def resolve_guidance(preset_name: str, changes: Mapping[str, Any] | None = None,
                     tuning: GuidanceTuning | None = None) -> GuidanceSettings:
    """The settings that run: the named preset ("tuned": `tuning`'s, else "recommended"), then the user's dotted
    `changes` (paths below `guidance.`), checked as a whole, filters included."""
    from lano3dp.guidance.execution import check_filters

    if preset_name == TUNED:
        base = tuning.settings() if tuning is not None else guidance_preset("recommended")
    else:
        base = guidance_preset(preset_name)
    settings = base.with_changes(changes) if changes else base
    check_filters(settings.execution)
    return settings
