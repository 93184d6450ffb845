"""Closed-loop runtime: frames -> the policy's observations -> (guided) action chunks -> env steps.

The loop of the paper's deployment phase (Fig. 1), for any environment that meets the simulator
protocol (`lano3dp.sim.protocol`): `reset(seed, options) -> (obs, info)` and
`step(action (10,)) -> (obs, reward, terminated, truncated, info)`, where `obs` carries an
`RGBDFrame` and the 11-D robot state.

    PolicyRunner     drives the policy through its control contract (`reset`, `select_action`): the policy
                     keeps the last n_obs_steps observations and the queued actions, and re-plans when the
                     queue is empty (receding horizon, as Diffusion Policy). The runner adds what only it
                     knows: each frame becomes the policy's visual input (object clouds / scene cloud /
                     96x96 RGB: its observation type's `runtime_input`, `policy.observations`), obstacle
                     phrases become guidance costs, and each chunk is sampled guided, checked or guided when
                     needed and recorded (its `plan` is the `sample` hook of `select_action`).
                     A policy trained with a time stride S (PolicyConfig.time_stride) observes and acts every
                     S env steps and each of its actions spans S env steps (`interpolate_action`).
    rollout          runs one episode with a runner and measures it (success, obstacle contacts, minimum
                     clearance, EE path length, latency per chunk).

Obstacles become costs as in the paper: segment the obstacle and fit a vertical cylinder to its points
(`guidance.fitting.fit_cylinder`; `ObstacleModel.shape` picks another shape registered in `guidance.shapes`).
What must keep clear of it is, by default, the swept body (`ObstacleModel.body="swept"`,
`guidance.costs.SweptBody`): the hand as a row of balls along its finger
axis plus the held object as a ball at its fitted centre, re-measured before each chunk. The paper's
model (`body="sphere"`) hinges the xy distance of every waypoint at Q* = obstacle radius + held-object
extent + margin, the extent measured from the held object's cloud (the paper used the bowl's diameter).

This module imports torch and the policy/guidance layers but never the simulator: the env is
duck-typed, so a user's own robot plugs in the same way.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from functools import partial
from typing import Any

import numpy as np
import torch

from lano3dp.errors import EmptyCloudError, Lano3dpError
from lano3dp.geometry.frame import RGBDFrame, observe
from lano3dp.geometry.rotations import quat_to_rot6d, rot6d_to_matrix, rot6d_to_quat, slerp
from lano3dp.guidance.checked import CheckConfig, checked_sample
from lano3dp.guidance.costs import (
    ExecutedPath,
    ObstacleSet,
    PositionCost,
    body_reach,
    clear_prefix,
    obstacle_guidance_cost,
    push_clear,
)
from lano3dp.guidance.fitting import bridge_narrow_gaps, fit_cylinder
from lano3dp.guidance.obstacle_model import ObstacleModel  # re-exported: configs and tests build it from here
from lano3dp.guidance.sampler import GuidanceConfig, GuidanceMode
from lano3dp.guidance.settings import GUIDANCE_PRESETS, GuidanceSettings, ObstacleSettings
from lano3dp.guidance.shapes import (
    BUILTIN_OBSTACLE_SHAPES,
    describe_obstacle,  # re-exported: results and plots read it from here
)
from lano3dp.perception.exceptions import ObjectNotFoundError, PerceptionError, TooFewPointsError
from lano3dp.perception.observer import ObjectClouds
from lano3dp.policy.modeling import ActionChunk

# The built-in shapes (kept for code that imported it); `guidance.obstacle_shape_names()` lists every registered one.
OBSTACLE_SHAPES = BUILTIN_OBSTACLE_SHAPES
# Points enough for a first-frame target cloud that an obstacle mostly hides (FPS repeats them to N): its
# centroid is still the object's, where failing the episode would be certain.
FIRST_FRAME_MIN_POINTS = 3
# A hand held still this many chunks in a row follows the obstacles' boundary (PolicyRunner.follow_obstacles).
FOLLOW_AFTER_HOLDS = 5
FOLLOW_STEP_M = 0.03
FOLLOW_MAX_STEPS = 40
FOLLOW_CLEARANCE = 0.75  # share of the margin a step keeps: headroom above the hold's half
GRASP_FLAG = 10  # index of the grasp flag in the 11-D robot state
_RECOMMENDED = GUIDANCE_PRESETS["recommended"]


class ClosedLoopError(Lano3dpError, RuntimeError):
    """The closed loop cannot continue (e.g. no collision-free chunk under checked execution)."""


@dataclass(frozen=True)
class RuntimeConfig:
    """How the runner samples and executes; `from_settings` builds it from a user's `guidance.GuidanceSettings`
    and `ObstacleSettings`, whose defaults are these.

    Attributes:
        guidance: None or mode "none" for plain sampling; else the paper's guidance (mode "clean") or A_k guidance.
        scheduler: "ddpm" or "ddim" (None: the policy's configured inference scheduler).
        num_inference_steps: denoising steps (None: the policy's default for that scheduler).
        n_action_steps: actions executed per chunk before re-planning (None: the policy's n_action_steps).
        obstacle: how obstacles become costs.
        checked: re-sample a chunk with a larger rho while its executed part still collides (None: off).
        on_unclear: under checked execution, what to do when no try is clear: "execute" the clearest try anyway
            (and count it) or "stop" the episode.
        metric_gradient: make the guidance push isotropic in metres (`guidance.costs.MetricGradient`, from the
            policy's action normaliser; beyond the paper; on by default, as in the recommended preset). Without
            it the per-axis min-max normaliser makes the push across a narrow demonstration range far weaker than
            the push along the path, and rho is in normalised units; with it rho reads as metres per guided step.
        densify: cost (and check) the path with `densify - 1` extra points inside each segment, so a segment
            cannot straddle a thin obstacle between two clear waypoints (`guidance.costs.Densified`; 1 = off;
            default the recommended preset's 4).
        guide_when_needed: sample the policy's own chunk first and guide only when its horizon comes closer
            than the margin to an obstacle (one extra unguided sample per chunk near obstacles; beyond the paper).
        anchored: the cost sees the path from the EE's present position (`guidance.AnchoredPath`).
        repair_steps: after a guided sample, at most this many 1 cm steps of plain cost descent until the path the
            arm will take through the chunk clears the obstacles by the margin (`guidance.push_clear` on
            `guidance.ExecutedPath`; 0: off).
        hold_unclear: after the repair, execute only the start of the chunk predicted to clear the obstacles by
            half the margin, and hold still when none does (`guidance.clear_prefix`); the next chunk re-plans.
        push_turn: degrees each obstacle's push is turned round it (`guidance.TurnedPush`; with `anchored`).
        bridge_gaps: guide against a wall across every gap between two obstacles too narrow for the body
            (`ObstacleModel.passable_gap`, `guidance.bridge_narrow_gaps`) too.
        escape_when_inside: with `hold_unclear`, a hand already closer than half the margin may execute the
            start of a chunk that gets it no closer, and steps straight out (`PolicyRunner.retreat`) when every
            chunk leads deeper, rather than hold still.
        follow_when_stuck: with `hold_unclear`, a hand held still FOLLOW_AFTER_HOLDS chunks in a row follows the
            nearest obstacle's boundary until its chunks run again with a clear way on (`follow_obstacles`).
        step_limit: metres the end effector moves at most per env step, which the executed path is predicted
            under (the built-in simulator's `max_ee_step`, filled in by evaluation and `run`; None: every
            waypoint is assumed reached).
        seed: seeds the sampling noise (one torch.Generator per runner, re-seeded on reset).
    """

    guidance: GuidanceConfig | None = None
    scheduler: str | None = None
    num_inference_steps: int | None = None
    n_action_steps: int | None = None
    obstacle: ObstacleModel = field(default_factory=ObstacleModel)
    checked: CheckConfig | None = None
    on_unclear: str = "execute"
    # the recommended preset's, so a runner built without settings guides as `lano3dp eval --guidance clean`
    metric_gradient: bool = _RECOMMENDED.metric_gradient
    densify: int = _RECOMMENDED.densify
    guide_when_needed: bool = _RECOMMENDED.guide_when_needed
    anchored: bool = _RECOMMENDED.anchored
    repair_steps: int = _RECOMMENDED.repair_steps
    hold_unclear: bool = _RECOMMENDED.hold_unclear
    push_turn: float = _RECOMMENDED.push_turn
    bridge_gaps: bool = _RECOMMENDED.bridge_gaps
    escape_when_inside: bool = _RECOMMENDED.escape_when_inside
    follow_when_stuck: bool = _RECOMMENDED.follow_when_stuck
    step_limit: float | None = None
    seed: int = 0

    def __post_init__(self):
        if self.on_unclear not in ("execute", "stop"):
            raise ValueError(f"on_unclear must be 'execute' or 'stop', got {self.on_unclear!r}")
        if self.n_action_steps is not None and self.n_action_steps < 1:
            raise ValueError(f"n_action_steps must be >= 1, got {self.n_action_steps}")
        if self.densify < 1:
            raise ValueError(f"densify must be >= 1, got {self.densify}")
        if self.repair_steps < 0:
            raise ValueError(f"repair_steps must be >= 0, got {self.repair_steps}")
        if not 0 <= self.push_turn < 90:
            raise ValueError(f"push_turn must be in [0, 90) degrees, got {self.push_turn}")

    @property
    def guided(self) -> bool:
        return self.guidance is not None and self.guidance.mode is not GuidanceMode.NONE and self.guidance.scale > 0

    @classmethod
    def from_settings(cls, guidance: GuidanceSettings, obstacle: ObstacleSettings | None = None, *,
                      scheduler: str | None = None, num_inference_steps: int | None = None,
                      n_action_steps: int | None = None, step_limit: float | None = None,
                      seed: int = 0) -> RuntimeConfig:
        """The runner's config for a user's guidance and obstacle settings (as `lano3dp eval` and `run` build it);
        `step_limit` is the env's `max_ee_step` where it has one."""
        obstacle = obstacle or ObstacleSettings()
        sampler = None if not guidance.guided else GuidanceConfig(
            mode=guidance.mode, scale=guidance.rho, last_steps=guidance.last_steps,
            per_train_step=guidance.per_train_step, guided_clip_range=guidance.guided_clip_range,
            push_weight=guidance.push_weight)
        # checked execution escalates from rho (at least 1 mm, so an unguided first try can escalate at all)
        checked = CheckConfig(initial_scale=max(guidance.rho, 1e-3), densify=guidance.densify) if guidance.checked \
            else None
        return cls(guidance=sampler, scheduler=scheduler, num_inference_steps=num_inference_steps,
                   n_action_steps=n_action_steps,
                   obstacle=ObstacleModel(shape=obstacle.shape, margin=obstacle.margin, body=obstacle.body,
                                          held_radius=obstacle.held_radius, refit_every_chunk=obstacle.refit),
                   checked=checked, metric_gradient=guidance.metric_gradient, densify=guidance.densify,
                   guide_when_needed=guidance.guide_when_needed, anchored=guidance.anchored,
                   repair_steps=guidance.repair_steps, hold_unclear=guidance.hold_unclear,
                   push_turn=guidance.push_turn, bridge_gaps=guidance.bridge_gaps,
                   escape_when_inside=guidance.escape_when_inside, follow_when_stuck=guidance.follow_when_stuck,
                   step_limit=step_limit, seed=seed)

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        if self.guidance is not None:
            data["guidance"]["mode"] = self.guidance.mode.value
        return data


@dataclass
class ChunkRecord:
    """One planning call.

    Attributes:
        step: env step at which the chunk was planned.
        latency_s: wall time of planning the chunk: sampling (+ re-tries) and its checks, seconds (the frame's
            perception and the obstacle fits before it are not in it).
        sample_s: wall time of sampling alone (all tries), seconds.
        tries: samples drawn (1 unless checked execution re-sampled).
        scale: rho of the executed sample (0 when unguided).
        predicted_clearance: smallest clearance (m) of the executed waypoints to the fitted obstacles, as the
            runner sees them (None without obstacles).
        clear: False when checked execution found no collision-free try.
        repaired: plain cost-descent steps taken on the sample afterwards (`RuntimeConfig.repair_steps`).
        executed: actions kept when the runner cut the chunk short to what it predicts clear (0: it held still;
            `RuntimeConfig.hold_unclear`); None: the whole chunk ran.
        trajectory: (H, 10) the whole sampled horizon (metric).
    """

    step: int
    latency_s: float
    sample_s: float
    tries: int = 1
    scale: float = 0.0
    predicted_clearance: float | None = None
    clear: bool = True
    repaired: int = 0
    executed: int | None = None
    trajectory: np.ndarray | None = None


def scene_obstacles(frame: RGBDFrame) -> list[str]:
    """Names of the objects the simulator marks as obstacles (ground truth; for evaluation defaults)."""
    return sorted(name for name, attributes in frame.instance_attributes.items()
                  if attributes.get("role") == "obstacle")


_UNCHANGED = object()  # set_objects' "leave as is", since None means "nothing held"


def interpolate_action(previous: np.ndarray, target: np.ndarray, steps: int) -> np.ndarray:
    """(steps, 10) env actions from the `previous` commanded (10,) action to the (10,) `target`, the last one
    `target` itself: position and gripper linearly, rotation by slerp (a policy action of a time-strided
    policy spans `steps` env steps, so the env is led along it rather than told to jump)."""
    target = np.asarray(target, dtype=np.float32)
    if steps == 1:
        return target[None]
    previous = np.asarray(previous, dtype=np.float64)
    fractions = np.arange(1, steps + 1, dtype=np.float64) / steps
    actions = previous + fractions[:, None] * (target.astype(np.float64) - previous)
    q0, q1 = rot6d_to_quat(previous[3:9]), rot6d_to_quat(target[3:9])
    actions[:, 3:9] = quat_to_rot6d(np.stack([slerp(q0, q1, t) for t in fractions]))
    actions = actions.astype(np.float32)
    actions[-1] = target  # exactly what the policy asked for, not a round trip through quaternions
    return actions


class PolicyRunner:
    """Receding-horizon controller around a `DiffusionPolicy`.

    The policy owns the observation window and the action queue (`select_action`); the runner turns frames into
    its observations, obstacles into costs, and samples and records each chunk when the policy asks for one.

    Args:
        policy: a `policy.ControlPolicy`: `config` (PolicyConfig), `predict_action_chunk`, `reset` and
            `select_action` with its `sample` hook (a DiffusionPolicy; `policy.ChunkedControl` gives the last two
            to any chunk sampler); its `normalizer` is read for the metric push (`metric_gradient`).
        observer: an `ObjectObserver` (segmenter + FPS); needed for "objects" policies and for obstacles.
        config: sampling / guidance / execution settings.
        target_phrases: words naming the policy's object slots in this scene, in slot order (default: the
            policy's `object_names`), e.g. ("blue bowl", "pan") among look-alikes.
        obstacle_phrases: objects to avoid; each becomes a cost (needs `observer`).
        held_object: phrase of the object the gripper carries, whose extent enlarges Q* (the skill registry's
            carried slot, `SkillSpec.carried_slot`); None for a skill that carries nothing (the gripper alone).
        visual_fn: frame -> visual input of one step, overriding the default for the policy's obs_type
            (e.g. the scene-cloud settings the dataset was recorded with).
    """

    def __init__(self, policy, observer=None, config: RuntimeConfig | None = None, *,
                 target_phrases: Sequence[str] | None = None, obstacle_phrases: Sequence[str] = (),
                 held_object: str | None = None,
                 visual_fn: Callable[[RGBDFrame], np.ndarray] | None = None):
        self.policy = policy
        self.policy_config = policy.config
        self.observer = observer
        self.config = config or RuntimeConfig()
        pc = self.policy_config
        self.n_obs_steps = int(pc.n_obs_steps)
        self.time_stride = pc.time_stride
        self.n_action_steps = int(self.config.n_action_steps or pc.n_action_steps)
        if self.n_action_steps > pc.horizon - pc.n_obs_steps + 1:
            raise ValueError(f"n_action_steps {self.n_action_steps} exceeds what one chunk holds "
                             f"(horizon {pc.horizon} - n_obs_steps {pc.n_obs_steps} + 1)")
        self.target_phrases = tuple(target_phrases) if target_phrases is not None else tuple(pc.object_names)
        if pc.observation.object_slots:
            if len(self.target_phrases) != len(pc.object_names):
                raise ValueError(f"the policy has {len(pc.object_names)} object slots {tuple(pc.object_names)} but "
                                 f"{len(self.target_phrases)} target phrases were given: {self.target_phrases}")
            if observer is None and visual_fn is None:
                raise ValueError(f"an {pc.obs_type!r} policy needs an observer (segmenter) to build its object "
                                 "clouds")
        self.obstacle_phrases = tuple(obstacle_phrases)
        if self.obstacle_phrases and observer is None:
            raise ValueError(f"obstacles {self.obstacle_phrases} need an observer to segment them")
        self.held_object = held_object or None
        self.visual_fn = visual_fn or self._default_visual
        self.env_actions: deque[np.ndarray] = deque()  # the env steps of the policy action being executed
        self.commanded: np.ndarray | None = None  # the last action handed to the env
        self.chunks: list[ChunkRecord] = []
        self.obstacle_cost: PositionCost | None = None
        self.obstacles: ObstacleSet | None = None
        self.gap_walls: list[PositionCost] = []  # walls across gaps too narrow to pass (RuntimeConfig.bridge_gaps)
        self.held_radius: float | None = None
        self.step_count = 0
        self.held_clouds = 0  # frames in which a hidden target kept its previous cloud
        self.partly_hidden: list[str] = []  # targets taken from a few points in the first frame
        # () -> this moment from the env's other cameras (its optional `other_views`), set per episode by `reset`
        self.other_views: Callable[[], Sequence[RGBDFrame]] | None = None
        self.seen_from_other_views: list[str] = []  # targets and obstacles the first frame missed, found there
        self._rendered_views: tuple[int, list[RGBDFrame]] | None = None  # (step, other views rendered at it)
        self.stale_obstacle_fits = 0  # re-fits skipped because the obstacle was out of view
        self.held_in_a_row = 0  # chunks held still in a row (RuntimeConfig.follow_when_stuck)
        self._following: tuple[float | None, int] | None = None  # (side, steps) while following a boundary
        self.followed_steps = 0  # steps taken along obstacle boundaries this episode
        self._last_clouds: np.ndarray | None = None
        self._held_ball: tuple[np.ndarray, float] | None = None  # (offset from the EE, radius) of the held object
        self.initial_targets: dict[str, list[float]] = {}  # phrase -> centroid (m) in the first frame
        self.stopped_reason: str | None = None
        self.generator = torch.Generator().manual_seed(self.config.seed)
        self.policy.reset()  # whatever the policy queued before belongs to no episode of this runner

    # ---- episode ---------------------------------------------------------------------------
    def reset(self, seed: int | None = None,
              other_views: Callable[[], Sequence[RGBDFrame]] | None = None) -> None:
        """Start an episode: reset the policy (its window and queued actions), forget the fitted obstacles and what
        was perceived, re-seed the sampling noise. `other_views` (the env's, if it has other cameras) is where a
        target or obstacle the observation camera cannot see in the first frame is looked for."""
        self.policy.reset()
        self.env_actions.clear()
        self.commanded = None
        self.chunks = []
        self.obstacle_cost = None
        self.obstacles = None
        self.gap_walls = []
        self.held_radius = None
        self.step_count = 0
        self.held_clouds = 0
        self.partly_hidden = []
        self.other_views = other_views
        self.seen_from_other_views = []
        self._rendered_views = None
        self.stale_obstacle_fits = 0
        self.held_in_a_row = 0
        self._following = None
        self.followed_steps = 0
        self._last_clouds = None
        self._held_ball = None
        self.initial_targets = {}
        self.stopped_reason = None
        self.generator = torch.Generator().manual_seed(self.config.seed if seed is None else int(seed))

    def set_objects(self, target_phrases: Sequence[str] | None = None, obstacle_phrases: Sequence[str] | None = None,
                    held_object: str | None | object = _UNCHANGED) -> None:
        """Change what this episode's scene calls the targets (slot order), which objects to avoid, and what
        the gripper carries (None: nothing)."""
        if target_phrases is not None:
            target_phrases = tuple(target_phrases)
            if self.policy_config.observation.object_slots and \
                    len(target_phrases) != len(self.policy_config.object_names):
                raise ValueError(f"the policy has {len(self.policy_config.object_names)} object slots but "
                                 f"{len(target_phrases)} target phrases were given: {target_phrases}")
            self.target_phrases = target_phrases
        if obstacle_phrases is not None:
            if obstacle_phrases and self.observer is None:
                raise ValueError(f"obstacles {tuple(obstacle_phrases)} need an observer to segment them")
            self.obstacle_phrases = tuple(obstacle_phrases)
        if held_object is not _UNCHANGED:
            self.held_object = held_object or None
        self.obstacle_cost = None
        self.obstacles = None
        self.gap_walls = []

    # ---- observations ------------------------------------------------------------------------
    def _default_visual(self, frame: RGBDFrame) -> np.ndarray:
        return self.policy_config.observation.runtime_input(self, frame)

    def object_clouds(self, frame: RGBDFrame) -> np.ndarray:
        """(K, N, 3) target clouds in slot order.

        A target that is momentarily hidden (too few points, e.g. the pan under the tilted bowl, or behind an
        obstacle) keeps its previous cloud, as a video tracker would and as the demonstrations were recorded
        (`lano3dp.collect`). In the first frame a target with only a few points in view is taken from those;
        one not in view at all is looked for in the env's other views, and is taken from there whenever the
        observation camera cannot see it; one seen nowhere is an error the caller sees.
        """
        try:
            clouds = self.observer.observe(frame, self.target_phrases).points
        except PerceptionError:
            if self._last_clouds is None:
                clouds = self._first_clouds(frame)
            else:
                clouds = []
                for slot, phrase in enumerate(self.target_phrases):
                    try:
                        clouds.append(self.observer.observe(frame, [phrase]).points[0])
                    except PerceptionError as hidden:
                        clouds.append(self._hidden_target_cloud(slot, phrase, hidden))
                clouds = np.stack(clouds)
        if self._last_clouds is None:
            self.initial_targets = {phrase: clouds[k].mean(0).round(4).tolist()
                                    for k, phrase in enumerate(self.target_phrases)}
        self._last_clouds = clouds
        return clouds

    def _first_clouds(self, frame: RGBDFrame) -> np.ndarray:
        """The first frame's target clouds (`_first_cloud` each)."""
        return np.stack([self._first_cloud(frame, phrase) for phrase in self.target_phrases])

    def _first_cloud(self, frame: RGBDFrame, phrase: str) -> np.ndarray:
        """A target the obstacle mostly hides in the first frame is taken from the few points still in view
        (FIRST_FRAME_MIN_POINTS) rather than failing the episode: there is no earlier cloud. One with fewer
        still, or none, is looked for in the other views."""
        try:
            return self.observer.observe(frame, [phrase]).points[0]
        except TooFewPointsError:
            pass
        except ObjectNotFoundError as not_found:
            return self._observe_in_other_views(phrase, not_found).points[0]
        try:
            cloud = self.observer.observe(frame, [phrase], min_points=FIRST_FRAME_MIN_POINTS).points[0]
        except TooFewPointsError as hidden:
            return self._observe_in_other_views(phrase, hidden).points[0]
        self.partly_hidden.append(phrase)
        return cloud

    def _hidden_target_cloud(self, slot: int, phrase: str, hidden: PerceptionError) -> np.ndarray:
        """A target the camera cannot see after the first frame: from the other views if it was first found
        there (the camera may never see it: it stands behind the obstacle), else its previous cloud."""
        if phrase in self.seen_from_other_views:
            try:
                return self._observe_in_other_views(phrase, hidden).points[0]
            except PerceptionError:
                pass
        self.held_clouds += 1
        return self._last_clouds[slot]

    def _observe_in_other_views(self, phrase: str, hidden: PerceptionError, instances: bool = False) -> ObjectClouds:
        """`phrase` from the other view that sees most of it (every instance with `instances`); raises `hidden`,
        the observation camera's error, when no view sees it or the env has no other views."""
        found = None
        for view in self._views_now():
            try:
                seen = (self.observer.observe_instances(view, [phrase]) if instances
                        else self.observer.observe(view, [phrase]))
            except PerceptionError:
                continue
            if found is None or seen.point_counts.sum() > found.point_counts.sum():
                found = seen
        if found is None:
            raise hidden
        if phrase not in self.seen_from_other_views:
            self.seen_from_other_views.append(phrase)
        return found

    def _views_now(self) -> list[RGBDFrame]:
        """The env's other views of this step, rendered once however many objects are looked for in them."""
        if self.other_views is None:
            return []
        if self._rendered_views is None or self._rendered_views[0] != self.step_count:
            self._rendered_views = (self.step_count, list(self.other_views()))
        return self._rendered_views[1]

    def _observe_anywhere(self, frame: RGBDFrame, phrase: str, instances: bool = False) -> ObjectClouds:
        """`phrase` in `frame` (every instance with `instances`), or in the other view that sees most of it
        when the camera cannot see it."""
        try:
            return (self.observer.observe_instances(frame, [phrase]) if instances
                    else self.observer.observe(frame, [phrase]))
        except PerceptionError as hidden:
            return self._observe_in_other_views(phrase, hidden, instances)

    def policy_input(self, frame: RGBDFrame, state: np.ndarray) -> dict[str, np.ndarray]:
        """One observation as `select_action` takes it: {visual key: (1, ...), "state": (1, 11)}."""
        visual = np.asarray(self.visual_fn(frame))
        state = np.asarray(state, dtype=np.float32)
        return {self.policy_config.visual_key: visual[None], "state": state[None]}

    # ---- obstacles -------------------------------------------------------------------------
    def measure_held_radius(self, frame: RGBDFrame) -> float:
        """Metres around the EE point to keep clear: the held object's extent, at least the gripper's."""
        model = self.config.obstacle
        if model.held_radius is not None:
            return float(model.held_radius)
        if not self.held_object:
            return model.gripper_radius
        # measured before the grasp: the obstacle may stand in front of it
        points = self._observe_anywhere(frame, self.held_object).points[0]
        radius = fit_cylinder(points).radius
        return max(model.gripper_radius, model.held_extent * radius)

    def fit_obstacles(self, frame: RGBDFrame) -> ObstacleSet:
        """Segment every obstacle phrase in `frame` and fit its shape (see ObstacleModel). With the "sphere"
        body the shapes carry the held radius; with "swept" they are bare and `guidance_cost` adds the body."""
        sphere = self.config.obstacle.body == "sphere"
        if sphere:
            self.held_radius = self.measure_held_radius(frame)
        # Every matching instance is its own obstacle: "avoid the mugs" fits one cylinder per mug.
        try:
            clouds = list(self.observer.observe_instances(frame, self.obstacle_phrases).points)
        except PerceptionError:
            if self.obstacles is not None:
                raise  # a re-fit: the caller keeps the last fit
            # the first fit: an obstacle hidden behind another is looked for in the other views
            clouds = [points for phrase in self.obstacle_phrases
                      for points in self._observe_anywhere(frame, phrase, instances=True).points]
        return ObstacleSet([self.config.obstacle.fit(points, self.held_radius if sphere else 0.0)
                            for points in clouds])

    def swept_body(self, frame: RGBDFrame, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(K, 3) world offsets from the EE point and (K,) radii of what moves with it now: the hand, and
        the held object while the grasp flag is set (its last seen ball when the hand hides it)."""
        offsets, radii = self.config.obstacle.hand_balls(state[3:9])
        if not self.held_object or state[GRASP_FLAG] < 0.5:
            self._held_ball = None
            return offsets, radii
        try:
            held = fit_cylinder(self.observer.observe(frame, [self.held_object]).points[0])
            offset = np.array([*held.center.tolist(), (held.z_min + held.z_max) / 2]) - state[:3]
            # a flag set while the named object is nowhere near the hand (another object is held, or the
            # env's flag is stale) must not drag a ball across the table with the hand
            near = np.linalg.norm(offset) - held.radius <= self.config.obstacle.hand_half_span
            self._held_ball = (offset, held.radius) if near else None
        except (PerceptionError, EmptyCloudError):
            pass  # keep the ball measured before the hand covered the object
        if self._held_ball is None:
            return offsets, radii
        return np.vstack([offsets, self._held_ball[0]]), np.append(radii, self._held_ball[1])

    def update_obstacles(self, frame: RGBDFrame, state: np.ndarray) -> None:
        """Before a chunk: fit the obstacles if not yet fitted (re-fit them with `refit_every_chunk`) and build
        the cost, re-measuring the swept body as it is now."""
        if not self.obstacle_phrases:
            return
        model = self.config.obstacle
        if self.obstacles is None:
            self.obstacles = self.fit_obstacles(frame)
            self.obstacle_cost = None
        elif model.refit_every_chunk:
            try:
                self.obstacles = self.fit_obstacles(frame)
                self.obstacle_cost = None
            except (PerceptionError, EmptyCloudError):
                self.stale_obstacle_fits += 1  # the arm hides it now: keep the last fit
        if self.obstacle_cost is None:
            self.gap_walls = bridge_narrow_gaps(list(self.obstacles), model.passable_gap(self.held_radius or 0.0)) \
                if self.config.bridge_gaps else []
        if self.obstacle_cost is None or model.body == "swept" or self.config.anchored:
            self.obstacle_cost = self.guidance_cost(frame, np.asarray(state, dtype=np.float32))

    def guided_obstacles(self) -> list[PositionCost]:
        """The fitted obstacles and the walls across gaps too narrow to pass (`RuntimeConfig.bridge_gaps`)."""
        return list(self.obstacles) + self.gap_walls

    def guidance_cost(self, frame: RGBDFrame, state: np.ndarray) -> PositionCost:
        """The cost guidance descends for the next chunk: the fitted obstacles against the body model."""
        body = self.swept_body(frame, state) if self.config.obstacle.body == "swept" else None
        metric_scale = self.policy.normalizer.scale("action")[:3] if self.config.metric_gradient else None
        cost = obstacle_guidance_cost(self.guided_obstacles(), body=body, densify=self.config.densify,
                                      action_scale=metric_scale, start=state[:3] if self.config.anchored else None,
                                      turn=math.radians(self.config.push_turn))
        if body is not None:
            self.held_radius = body_reach(*body)
        return cost

    # ---- acting ----------------------------------------------------------------------------
    def plan(self, frame: RGBDFrame, state: np.ndarray, obs: dict[str, torch.Tensor]) -> ActionChunk:
        """The `sample` hook of `select_action`: bring the obstacles up to date, sample a chunk from the policy's
        window `obs` (guided, checked or guided when needed, as configured), record it in `chunks`, and return
        it with the n_action_steps actions to execute."""
        self.update_obstacles(frame, state)
        started = time.perf_counter()
        cfg = self.config
        start = self.policy_config.n_obs_steps - 1  # "now" in the horizon
        # the actions to execute, from the horizon rather than chunk.actions, which holds only the policy's own
        # n_action_steps: the runner's may be more
        execute = slice(start, start + self.n_action_steps)
        guidance = cfg.guidance if cfg.guided and self.obstacle_cost is not None else None
        cost = self.obstacle_cost

        def sample(guide: GuidanceConfig | None):
            chunk = self.policy.predict_action_chunk(
                obs, guidance=guide, position_cost=cost if guide is not None else None,
                scheduler=cfg.scheduler, num_inference_steps=cfg.num_inference_steps, generator=self.generator)
            return chunk

        sample_started = time.perf_counter()
        record = ChunkRecord(step=self.step_count, latency_s=0.0, sample_s=0.0)
        if cfg.checked is not None and cost is not None:
            check = CheckConfig(**{**asdict(cfg.checked), "n_execute": self.n_action_steps})
            position = obs["state"][:, -1, :3]  # the EE now: the first executed segment starts there

            def sample_fn(guide: GuidanceConfig):
                chunk = sample(guide if guide.mode is not GuidanceMode.NONE else None)
                return chunk.trajectory[:, start:, :3].float(), chunk

            result = checked_sample(sample_fn, cost, guidance, check, start_position=position)
            chunk = result.payload
            record.tries = result.tries
            record.scale = result.guidance.scale if result.guidance.mode is not GuidanceMode.NONE else 0.0
            record.clear = result.success
            record.predicted_clearance = float(result.min_clearance.min())
        else:
            chunk = None
            if guidance is not None and cfg.guide_when_needed:
                # the policy's own chunk, kept when its whole horizon already clears every obstacle by the
                # margin: guidance then never bends a grasp that was not heading for the obstacle
                plain = sample(None)
                with torch.no_grad():
                    gap = float(cost.clearance(plain.trajectory[:, start:, :3].float()).min())
                if gap >= self.config.obstacle.margin:
                    chunk, guidance = plain, None
                record.tries = 1 if chunk is not None else 2
            if chunk is None:
                chunk = sample(guidance)
            record.scale = guidance.scale if guidance is not None else 0.0
        guided = cost is not None and cfg.guided and record.scale > 0
        # the path the arm will take through this chunk, which the repair and the cut below are checked on
        path_cost = self.executed_path_cost(state, chunk.trajectory[0, execute]) if guided and (
            cfg.repair_steps or cfg.hold_unclear) else None
        if path_cost is not None and cfg.repair_steps:
            chunk, record.repaired = self.push_chunk_clear(chunk, start, path_cost)
        if cost is not None and (cfg.checked is None or record.repaired):
            with torch.no_grad():
                executed = chunk.trajectory[:, execute, :3].float()
                record.predicted_clearance = float((path_cost or cost).clearance(executed).min())
        record.sample_s = time.perf_counter() - sample_started
        actions = chunk.trajectory[:, execute]
        if path_cost is not None and cfg.hold_unclear:
            actions = self.cut_to_clear(actions, state, path_cost)
            record.executed = actions.shape[1] if actions.shape[1] < self.n_action_steps else None
            if actions.shape[1] == 0:  # nothing of it is clear: hold the present pose, with the chunk's gripper
                actions = chunk.trajectory[:, start:start + 1].clone()
                actions[0, 0, :9] = torch.as_tensor(np.asarray(state[:9]), dtype=actions.dtype)
                if cfg.escape_when_inside:
                    actions[0, 0, :3] = self.retreat(state, path_cost).to(actions.dtype)
                self.held_in_a_row += 1
            else:
                self.held_in_a_row = 0
            if cfg.follow_when_stuck:
                actions = self.follow_obstacles(actions, state, path_cost, chunk.trajectory[:, start:start + 1],
                                                chunk.trajectory[0, -1, :3].detach().cpu().numpy())
        chunk = ActionChunk(actions, chunk.trajectory)
        record.trajectory = chunk.trajectory[0].detach().cpu().numpy().astype(np.float32)
        record.latency_s = time.perf_counter() - started
        self.chunks.append(record)
        if not record.clear and cfg.on_unclear == "stop":
            self.stopped_reason = "no collision-free chunk"
            raise ClosedLoopError(f"no collision-free chunk at step {self.step_count} after {record.tries} tries "
                                  f"(up to rho={record.scale:g}); predicted clearance "
                                  f"{record.predicted_clearance:.3f} m")
        return chunk

    def executed_path_cost(self, state: np.ndarray, waypoints: torch.Tensor) -> ExecutedPath:
        """The cost on the path the arm will take from its present pose through `waypoints` ((T, 10) metric
        actions): the body as the guidance cost measured it, posed by each waypoint's rotation (a held object's
        ball turns with the hand), under the arm's step limit."""
        rotations = [np.asarray(state[3:9], dtype=np.float64)] + list(waypoints[:, 3:9].detach().cpu().double().numpy())
        model = self.config.obstacle
        if model.body == "swept":
            now = rot6d_to_matrix(rotations[0])
            held = self._held_ball if self._held_ball is not None and state[GRASP_FLAG] >= 0.5 else None
            poses, radii = [], None
            for rotation in rotations:
                offsets, radii = model.hand_balls(rotation)
                if held is not None:  # measured in world axes now: turn it with the hand
                    offsets = np.vstack([offsets, rot6d_to_matrix(rotation) @ now.T @ held[0]])
                    radii = np.append(radii, held[1])
                poses.append(offsets)
            node_offsets = np.stack(poses)
        else:  # the "sphere" body: the obstacles carry the held radius; one ball of radius 0 at the EE point
            node_offsets, radii = np.zeros((len(rotations), 1, 3)), np.zeros(1)
        step_limit = None if self.config.step_limit is None else self.config.step_limit * self.time_stride
        return ExecutedPath(self.guided_obstacles(), state[:3], node_offsets, radii, step_limit=step_limit,
                            densify=max(self.config.densify, 2), margin=model.margin)

    def push_chunk_clear(self, chunk: ActionChunk, start: int, cost: PositionCost) -> tuple[ActionChunk, int]:
        """`chunk` with its waypoints from horizon index `start` pushed to the margin from every obstacle along
        `cost` (the executed path's, in metres) by plain descent (`guidance.push_clear`, at most `repair_steps`
        1 cm steps), and the steps taken."""
        trajectory = chunk.trajectory.detach().clone()
        executed = slice(start, start + len(cost.node_offsets) - 1)
        moved, steps = push_clear(cost, trajectory[:, executed, :3].double(), clearance=self.config.obstacle.margin,
                                  iterations=self.config.repair_steps)
        if steps == 0:
            return chunk, 0
        trajectory[:, executed, :3] = moved.to(trajectory.dtype)
        return ActionChunk(trajectory[:, start:start + chunk.actions.shape[1]], trajectory), steps

    def cut_to_clear(self, actions: torch.Tensor, state: np.ndarray, cost: PositionCost) -> torch.Tensor:
        """The start of `actions` (B, T, 10) whose executed path keeps half the margin from every obstacle
        (`guidance.clear_prefix`); the last kept action may be moved part of the way to its waypoint."""
        start = torch.as_tensor(np.asarray(state[:3], dtype=np.float64))[None]
        required = self.config.obstacle.margin / 2
        if self.config.escape_when_inside:
            # a hand already inside (a moving obstacle came at it) may move where it gets no closer: holding
            # still there let the obstacle walk into it
            required = min(required, cost.present_clearance())
        kept = clear_prefix(cost, actions[:, :, :3].double(), start, clearance=required)
        if kept.shape[1] == actions.shape[1]:
            return actions
        cut = actions[:, :kept.shape[1]].clone()
        cut[:, :, :3] = kept.to(cut.dtype)
        return cut

    def retreat(self, state: np.ndarray, cost: ExecutedPath) -> torch.Tensor:
        """(3,) where a hand already inside half the margin steps to when no chunk start keeps it from going
        deeper: straight out along the executed-path cost, a few 1 cm steps of plain descent; its present
        position when it is not inside (an ordinary hold). A moving obstacle traced on a table scene held a hand
        3 cm inside it for 48 chunks, every chunk's first step leading deeper."""
        here = torch.as_tensor(np.asarray(state[:3], dtype=np.float64))
        required = self.config.obstacle.margin / 2
        deficit = required - cost.present_clearance()
        if deficit <= 0:
            return here
        steps = min(math.ceil(deficit / 0.01) + 1, 5)  # at most 5 cm: the arm's step limit, re-planned after
        moved, _ = push_clear(cost, here[None, None], clearance=required, iterations=steps)
        return moved[0, 0]

    def follow_obstacles(self, actions: torch.Tensor, state: np.ndarray, cost: ExecutedPath, first: torch.Tensor,
                         goal: np.ndarray) -> torch.Tensor:
        """Bug-algorithm boundary following: a hand held still for FOLLOW_AFTER_HOLDS chunks in a row (a blocked
        way: two obstacles, or the wall across their gap, between it and its target, the network aiming
        through) steps FOLLOW_STEP_M at a time along the nearest obstacle, on the side of the chunk's end
        (`goal`), until the chunk's start runs and the straight way from the hand to its end keeps half the
        margin (FOLLOW_MAX_STEPS steps at a time). `actions`: what the chunk would run, returned when not
        following; `first`: its first action, whose gripper a step keeps."""
        margin = self.config.obstacle.margin
        if self._following is None:
            if self.held_in_a_row < FOLLOW_AFTER_HOLDS or cost.present_clearance() < margin / 2:
                return actions
            self._following = (None, 0)
        here = torch.as_tensor(np.asarray(state[:3], dtype=np.float64))
        # the straight way to the chunk's end, as waypoints the path cost can pose the body at
        fractions = torch.arange(1, len(cost.node_offsets), dtype=torch.float64)[:, None] / (len(cost.node_offsets) - 1)
        way = here + fractions * (torch.as_tensor(goal, dtype=torch.float64) - here)
        with torch.no_grad():
            way_clear = float(cost.clearance(way[None]).min()) >= margin / 2
        if (way_clear and self.held_in_a_row == 0) or self._following[1] >= FOLLOW_MAX_STEPS:
            self._following = None
            return actions

        def clearance_at(offset_xy: np.ndarray) -> float:
            target = here.clone()
            target[:2] += torch.as_tensor(offset_xy)
            with torch.no_grad():
                return float(cost.clearance(target[None, None]).min())

        # away from the nearest obstacle: the clearance's gradient, by central differences over 5 mm
        probe = 0.005
        away = np.array([clearance_at(np.array([probe, 0.0])) - clearance_at(np.array([-probe, 0.0])),
                         clearance_at(np.array([0.0, probe])) - clearance_at(np.array([0.0, -probe]))])
        if np.linalg.norm(away) < 1e-9:
            self._following = None
            return actions
        away /= np.linalg.norm(away)
        tangent = np.array([-away[1], away[0]])
        side = self._following[0]
        if side is None:
            side = 1.0 if tangent @ (np.asarray(goal[:2]) - here[:2].numpy()) >= 0 else -1.0
        # hug the boundary at the margin: drift out when closer, in when farther; bend out more round a tight curve
        drift = 0.3 if cost.present_clearance() < margin else -0.3
        for bend in (0.0, 0.5, 1.0):
            step = side * tangent + (drift + bend) * away
            step = FOLLOW_STEP_M * step / np.linalg.norm(step)
            if clearance_at(step) >= FOLLOW_CLEARANCE * margin:
                break
        else:
            self._following = None
            return actions
        self._following = (side, self._following[1] + 1)
        self.followed_steps += 1
        moved = first.clone()
        moved[0, 0, :9] = torch.as_tensor(np.asarray(state[:9]), dtype=moved.dtype)
        moved[0, 0, :2] += torch.as_tensor(step, dtype=moved.dtype)
        return moved

    def act(self, frame: RGBDFrame, state: np.ndarray) -> np.ndarray:
        """Observe, let the policy re-plan (through `plan`) when its queue is empty, and return the next (10,)
        absolute EE action.

        Call it every env step. With a time stride S it observes only every S-th env step, so the window holds
        frames S env steps apart as the training windows held recorded steps, and each policy action becomes S
        env actions interpolated from the last commanded one (`interpolate_action`).
        """
        if not self.env_actions:
            action = self.policy.select_action(self.policy_input(frame, state), sample=partial(self.plan, frame, state))
            target = action[0].detach().cpu().numpy().astype(np.float32)
            if self.time_stride == 1:
                self.env_actions.append(target)
            else:
                # at an episode's start nothing was commanded: lead from the EE's pose, the gripper as asked
                previous = self.commanded if self.commanded is not None else np.concatenate(
                    [np.asarray(state, dtype=np.float32)[:9], target[9:]])
                self.env_actions.extend(interpolate_action(previous, target, self.time_stride))
        self.step_count += 1
        self.commanded = self.env_actions.popleft()
        return self.commanded


@dataclass
class EpisodeResult:
    """What one closed-loop episode measured.

    Attributes:
        seed: the env reset seed.
        success: the task's success check held at some step.
        steps: env steps taken.
        collided: the robot or held object touched an obstacle (simulator contact events).
        n_collision_steps: steps with at least one obstacle contact.
        min_clearance: smallest true distance (m) between robot/held object and any obstacle, from the
            simulator (None when the env reports none, e.g. no obstacle).
        path_length: EE path length (m), from the robot state.
        chunk_latency_s: planning time of every chunk (`ChunkRecord.latency_s`), seconds.
        chunk_tries: samples drawn per chunk (checked execution).
        chunk_repaired: plain cost-descent steps taken after sampling, per chunk (`RuntimeConfig.repair_steps`).
        chunk_executed: per chunk, the actions kept when it was cut short to its predicted-clear start (0: held
            still), or None when it ran whole (`RuntimeConfig.hold_unclear`).
        chunk_predicted_clearance: per chunk, the runner's own clearance estimate of the executed waypoints.
        ee_path: (steps + 1, 3) EE positions, metres (kept for plots; dropped from JSON by default).
        obstacles: the fitted obstacle shapes the runner guided against (see `describe_obstacle`).
        gap_walls: walls across gaps too narrow to pass that it guided against too (`RuntimeConfig.bridge_gaps`).
        held_radius: m, the held extent used in Q*.
        held_clouds: target clouds carried over from the previous frame because the target was hidden.
        partly_hidden: targets whose first-frame cloud came from the few points an obstacle left in view.
        seen_from_other_views: targets and obstacles the observation camera could not see in the first frame,
            found in the env's other views.
        stale_obstacle_fits: re-fits (`refit_every_chunk`) that kept the last fit because the camera saw too little
            of an obstacle.
        followed_steps: steps the runtime took along obstacle boundaries (`PolicyRunner.follow_obstacles`).
        targets: phrase -> centroid (m) of each target's cloud in the first frame (object policies).
        error: why the episode ended early (perception failure, no clear chunk), or None.
        wall_s: wall time of the episode, seconds.
        stages: the task's stages in order -> reached during the episode (the env's last info["stages"];
            empty when the env reports none).
        stage: the furthest stage reached, or None.
    """

    seed: int
    success: bool
    steps: int
    collided: bool
    n_collision_steps: int
    min_clearance: float | None
    path_length: float
    chunk_latency_s: list[float]
    chunk_tries: list[int]
    chunk_predicted_clearance: list[float | None]
    ee_path: np.ndarray
    obstacles: list[dict[str, Any]] = field(default_factory=list)
    gap_walls: list[dict[str, Any]] = field(default_factory=list)
    chunk_repaired: list[int] = field(default_factory=list)
    chunk_executed: list[int | None] = field(default_factory=list)
    held_radius: float | None = None
    held_clouds: int = 0
    partly_hidden: list[str] = field(default_factory=list)
    seen_from_other_views: list[str] = field(default_factory=list)
    stale_obstacle_fits: int = 0
    followed_steps: int = 0
    targets: dict[str, list[float]] = field(default_factory=dict)
    error: str | None = None
    wall_s: float = 0.0
    info: dict[str, Any] = field(default_factory=dict)
    stages: dict[str, bool] = field(default_factory=dict)
    stage: str | None = None

    def to_dict(self, include_path: bool = False) -> dict[str, Any]:
        data = asdict(self)
        data["ee_path"] = self.ee_path.round(5).tolist() if include_path else None
        if not include_path:
            data.pop("ee_path")
        return data


def path_length(positions: np.ndarray) -> float:
    """Sum of segment lengths of a (T, 3) path, metres."""
    positions = np.asarray(positions, dtype=np.float64)
    if len(positions) < 2:
        return 0.0
    return float(np.linalg.norm(np.diff(positions, axis=0), axis=1).sum())


def _obstacle_contact(info: Mapping[str, Any]) -> bool:
    """Whether this step's info reports contact with an obstacle (a list of contact events)."""
    return len(info.get("obstacle_contacts", ())) > 0


def _clearance(info: Mapping[str, Any]) -> float | None:
    value = info.get("min_obstacle_clearance")
    return None if value is None or not np.isfinite(value) else float(value)


def rollout(env, runner: PolicyRunner, *, seed: int, options: Mapping[str, Any] | None = None,
            max_steps: int | None = None, on_frame: Callable[[RGBDFrame, Mapping[str, Any]], None] | None = None,
            on_reset: Callable[[PolicyRunner, RGBDFrame, Mapping[str, Any]], None] | None = None,
            stop_on_success: bool = True) -> EpisodeResult:
    """Run one closed-loop episode and measure it.

    Args:
        env: meets the simulator protocol; `info` may carry "success" (bool), "obstacle_contacts"
            (this step's contact events with obstacles) and "min_obstacle_clearance" (m; inf without obstacles).
        runner: the controller; it is reset here with `seed`.
        seed: env reset seed (and the runner's sampling seed).
        max_steps: step limit (default: the env's own truncation).
        on_frame: called with every frame and info (videos).
        on_reset: called after the env reset with (runner, first frame, info), e.g. to name this scene's
            targets and obstacles (`runner.set_objects`).
        stop_on_success: end the episode at the first step whose info says success.
    """
    started = time.perf_counter()
    runner.reset(seed, other_views=getattr(env, "other_views", None))
    obs, info = env.reset(seed=seed, options=dict(options or {}))
    frame, state = observe(env, obs)
    if on_reset is not None:
        on_reset(runner, frame, info)
    positions = [state[:3].copy()]
    success = bool(info.get("success", False))
    collided = _obstacle_contact(info)
    n_collision_steps = int(collided)
    clearances = [c for c in [_clearance(info)] if c is not None]
    if on_frame is not None:
        on_frame(frame, info)
    steps, error = 0, None
    while not (success and stop_on_success):
        if max_steps is not None and steps >= max_steps:
            break
        try:
            action = runner.act(frame, state)
        except Lano3dpError as failure:  # perception or checked execution: the episode fails, the eval goes on
            error = f"{type(failure).__name__}: {failure}"
            break
        obs, _reward, terminated, truncated, info = env.step(action)
        steps += 1
        frame, state = observe(env, obs)
        positions.append(state[:3].copy())
        success = success or bool(info.get("success", False))
        contact = _obstacle_contact(info)
        collided = collided or contact
        n_collision_steps += int(contact)
        if (clearance := _clearance(info)) is not None:
            clearances.append(clearance)
        if on_frame is not None:
            on_frame(frame, info)
        if terminated or truncated:
            break
    ee_path = np.asarray(positions, dtype=np.float32)
    return EpisodeResult(
        seed=int(seed), success=success, steps=steps, collided=collided, n_collision_steps=n_collision_steps,
        min_clearance=float(min(clearances)) if clearances else None, path_length=path_length(ee_path),
        chunk_latency_s=[round(c.latency_s, 5) for c in runner.chunks],
        chunk_tries=[c.tries for c in runner.chunks],
        chunk_repaired=[c.repaired for c in runner.chunks],
        chunk_executed=[c.executed for c in runner.chunks],
        chunk_predicted_clearance=[None if c.predicted_clearance is None else round(c.predicted_clearance, 5)
                                   for c in runner.chunks],
        ee_path=ee_path,
        obstacles=([describe_obstacle(o, runner.config.obstacle.shape) for o in runner.obstacles]
                   if runner.obstacles is not None else []),
        gap_walls=[describe_obstacle(wall, "box") for wall in runner.gap_walls],
        held_radius=runner.held_radius, held_clouds=runner.held_clouds, partly_hidden=list(runner.partly_hidden),
        seen_from_other_views=list(runner.seen_from_other_views), stale_obstacle_fits=runner.stale_obstacle_fits,
        followed_steps=runner.followed_steps,
        targets=dict(runner.initial_targets), error=error,
        wall_s=time.perf_counter() - started,
        # The env latches stages, so its last info holds every stage reached in the episode.
        stages={stage: bool(flag) for stage, flag in (info.get("stages") or {}).items()}, stage=info.get("stage"),
    )
