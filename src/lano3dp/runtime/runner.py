"""PolicyRunner: observe -> update the obstacles -> sample a chunk -> run the chunk filters -> act.

The policy owns the observation window and the action queue (`select_action`, receding horizon as Diffusion
Policy); the runner turns each frame into the policy's input (its observation type's `runtime_input`: object
clouds through `perception.TargetClouds`, a scene cloud, an image), keeps the obstacles up to date
(`guidance.obstacles.ObstacleTracker`), builds the cost (`guidance.recipe.CostRecipe`), draws each chunk
(`runtime.sampling`), passes a guided chunk through the chunk filters (`guidance.execution`) and records it.
A policy trained with a time stride S observes and acts every S env steps, each action spread over S env steps.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np
import torch

from lano3dp.errors import Lano3dpError
from lano3dp.geometry.frame import RGBDFrame
from lano3dp.geometry.rotations import quat_to_rot6d, rot6d_to_quat, slerp
from lano3dp.guidance.execution import FilterContext, Proposal, build_filters, run_filters
from lano3dp.guidance.obstacles import ObstacleTracker
from lano3dp.guidance.recipe import CostRecipe
from lano3dp.guidance.settings import GuidanceSettings, guidance_preset
from lano3dp.perception.targets import TargetClouds
from lano3dp.perception.views import OtherViews
from lano3dp.policy.modeling import ActionChunk
from lano3dp.policy.observations import task_inputs_of
from lano3dp.runtime.sampling import ChunkSampler

_UNCHANGED = object()  # set_objects' "leave as is", since None means "nothing held"


class ClosedLoopError(Lano3dpError, RuntimeError):
    """The closed loop cannot continue (e.g. no collision-free chunk under checked execution with on_unclear stop)."""


@dataclass
class ChunkRecord:
    """One planning call: the env step it was planned at, its wall time (sampling, tries and filters; s) and
    sampling's alone, samples drawn, the rho of the executed sample (0: unguided), whether checked execution
    found it clear, the runner's predicted clearance (m) of its executed waypoints (None without obstacles), the
    actions kept when cut short (0: held still; None: it ran whole), each filter's note, and (H, 10) the
    sampled horizon (metric)."""

    step: int
    latency_s: float = 0.0
    sample_s: float = 0.0
    tries: int = 1
    scale: float = 0.0
    clear: bool = True
    predicted_clearance: float | None = None
    executed: int | None = None
    notes: dict[str, Any] = field(default_factory=dict)
    trajectory: np.ndarray | None = None


def interpolate_action(previous: np.ndarray, target: np.ndarray, steps: int) -> np.ndarray:
    """(steps, 10) env actions from the `previous` commanded (10,) action to the (10,) `target`, the last one
    `target` itself: position and gripper linearly, rotation by slerp."""
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
    """Receding-horizon controller around a policy (`policy.ControlPolicy`: a DiffusionPolicy, or any chunk
    sampler with `policy.ChunkedControl`).

    Args:
        policy: the policy; its action normaliser gives the push in metres.
        observer: an `ObjectObserver` (segmenter + FPS), for object policies and obstacles.
        guidance: the settings tree (default: the "none" preset, unguided).
        n_action_steps: actions executed per chunk (None: the policy's).
        step_limit: metres the end effector moves at most per env step (the env's `max_ee_step`).
        seed: seeds the sampling noise (one generator per runner, re-seeded on reset).
        target_phrases: words naming the policy's object slots in this scene, in slot order (default: its
            `object_names`); obstacle_phrases: objects to avoid; held_object: phrase of what the gripper carries.
        visual_fn: frame -> one step of visual input, overriding the observation type's.
    """

    def __init__(self, policy, observer=None, guidance: GuidanceSettings | None = None, *,
                 n_action_steps: int | None = None, step_limit: float | None = None, seed: int = 0,
                 target_phrases: Sequence[str] | None = None, obstacle_phrases: Sequence[str] = (),
                 held_object: str | None = None, visual_fn: Callable[[RGBDFrame], np.ndarray] | None = None):
        self.policy, self.policy_config, self.observer = policy, policy.config, observer
        self.guidance = guidance = guidance if guidance is not None else guidance_preset("none")
        pc = self.policy_config
        self.time_stride = pc.time_stride
        self.n_action_steps = int(n_action_steps or pc.n_action_steps)
        if self.n_action_steps > pc.horizon - pc.n_obs_steps + 1:
            raise ValueError(f"n_action_steps {self.n_action_steps} exceeds what one chunk holds "
                             f"(horizon {pc.horizon} - n_obs_steps {pc.n_obs_steps} + 1)")
        if pc.observation.object_slots and observer is None and visual_fn is None:
            raise ValueError(f"an {pc.obs_type!r} policy needs an observer (segmenter) to build its object clouds")
        self.start = pc.n_obs_steps - 1  # "now" in the horizon
        self.views = OtherViews(observer)
        self.targets = TargetClouds(observer, self.views)
        self.tracker = ObstacleTracker(observer, guidance.obstacles, self.views)
        self.recipe = CostRecipe(guidance, lambda: policy.normalizer.scale("action")[:3], step_limit=step_limit,
                                 time_stride=self.time_stride)
        self.sampler = ChunkSampler(guidance, start=self.start, n_execute=self.n_action_steps)
        self.filters = build_filters(guidance.execution)
        self.target_phrases = tuple(pc.object_names)
        self.visual_fn = visual_fn or (lambda frame: pc.observation.runtime_input(self, frame))
        self._own_visual = visual_fn is None  # the observation types' inputs: frame by frame (objects: `targets`)
        self.seed = seed
        self.set_objects(target_phrases, obstacle_phrases, held_object)
        self.reset()

    def reset(self, seed: int | None = None, other_views: Callable[[], Sequence[RGBDFrame]] | None = None) -> None:
        """Start an episode: the policy's window and queue, what was perceived and fitted, the filters' memory,
        and the sampling noise (re-seeded). `other_views`: the env's other cameras, if it has them."""
        self.policy.reset()
        self.views.reset(other_views)
        self.targets.reset()
        self.tracker.reset()
        for chunk_filter in self.filters:
            chunk_filter.reset()
        self.env_actions: deque[np.ndarray] = deque()  # the env steps of the policy action being executed
        self.commanded: np.ndarray | None = None  # the last action handed to the env
        self.chunks: list[ChunkRecord] = []
        self.step_count = 0
        self.generator = torch.Generator().manual_seed(self.seed if seed is None else int(seed))
        start_episode = getattr(getattr(self.observer, "segmenter", None), "start_episode", None)
        if start_episode is not None:  # per-episode perception state: a tracker's memory, an error model's draws
            start_episode(self.seed if seed is None else int(seed))

    def set_objects(self, target_phrases: Sequence[str] | None = None, obstacle_phrases: Sequence[str] | None = None,
                    held_object: str | None | object = _UNCHANGED) -> None:
        """What this episode's scene calls the targets (slot order), the objects to avoid, and what the gripper
        carries (None: nothing); an argument left out stays as it was."""
        pc = self.policy_config
        if target_phrases is not None:
            if pc.observation.object_slots and len(target_phrases) != len(pc.object_names):
                raise ValueError(f"the policy has {len(pc.object_names)} object slots {tuple(pc.object_names)} but "
                                 f"{len(target_phrases)} target phrases were given: {tuple(target_phrases)}")
            self.target_phrases = tuple(target_phrases)
        self.tracker.set_objects(self.tracker.phrases if obstacle_phrases is None else obstacle_phrases,
                                 self.tracker.held_object if held_object is _UNCHANGED else held_object)

    def object_clouds(self, frame: RGBDFrame) -> np.ndarray:
        """(K, N, 3) target clouds in slot order (for the "objects" observation type)."""
        return self.targets(frame, self.target_phrases, step=self.step_count)

    def policy_input(self, frame: RGBDFrame, state: np.ndarray,
                     obs: Mapping[str, Any] | None = None) -> dict[str, np.ndarray]:
        """One observation as `select_action` takes it: {visual key: (1, ...), "state": (1, 11)}, and each of the
        policy's task inputs (1, D) taken from the env's observation, e.g. obs["goal"]."""
        visual = np.asarray(self.visual_fn(frame))
        task_inputs = task_inputs_of(obs or {}, list(self.policy_config.task_inputs)) \
            if self.policy_config.task_inputs else {}
        return {self.policy_config.visual_key: visual[None], "state": np.asarray(state, dtype=np.float32)[None],
                **{key: value[None] for key, value in task_inputs.items()}}

    def plan(self, frame: RGBDFrame, state: np.ndarray, obs: dict[str, torch.Tensor]) -> ActionChunk:
        """The `sample` hook of `select_action`: update the obstacles, draw a chunk from the policy's window
        `obs`, pass a guided one through the filters, record it, and return it with the actions to execute."""
        self.tracker.update(frame, self.step_count)
        started = time.perf_counter()
        cost = self.recipe.guidance_cost(self.tracker, frame, state) if self.tracker.phrases else None
        execute = slice(self.start, self.start + self.n_action_steps)

        def sample(guide):
            return self.policy.predict_action_chunk(
                obs, guidance=guide, position_cost=cost if guide is not None else None,
                scheduler=self.guidance.sampler.scheduler, num_inference_steps=self.guidance.sampler.steps,
                generator=self.generator)

        drawn = self.sampler.draw(sample, cost, obs["state"][:, -1, :3])
        record = ChunkRecord(step=self.step_count, tries=drawn.tries, scale=drawn.scale, clear=drawn.clear,
                             predicted_clearance=drawn.checked_clearance)
        proposal = Proposal(drawn.chunk.trajectory, drawn.chunk.trajectory[:, execute])
        path = None
        if cost is not None and drawn.scale > 0 and self.filters:
            path = self.recipe.executed_path(self.tracker, state, drawn.chunk.trajectory[0, execute])
            context = FilterContext(np.asarray(state), self.start, self.n_action_steps, path,
                                    self.guidance.obstacles.margin)
            proposal, record.notes = run_filters(self.filters, proposal, context)
        # checked execution measured the chunk as drawn: measure again only what a filter moved
        if cost is not None and (self.sampler.check is None or proposal.trajectory is not drawn.chunk.trajectory):
            with torch.no_grad():
                executed = proposal.trajectory[:, execute, :3].float()
                record.predicted_clearance = float((path or cost).clearance(executed).min())
        record.sample_s = record.latency_s = time.perf_counter() - started
        record.executed = proposal.executed
        record.trajectory = proposal.trajectory[0].detach().cpu().numpy().astype(np.float32)
        self.chunks.append(record)
        if not record.clear and self.guidance.sampler.on_unclear == "stop":
            raise ClosedLoopError(f"no collision-free chunk at step {self.step_count} after {record.tries} tries "
                                  f"(up to rho={record.scale:g}); predicted clearance "
                                  f"{record.predicted_clearance:.3f} m")
        return ActionChunk(proposal.actions, proposal.trajectory)

    def act(self, frame: RGBDFrame | Callable[[], RGBDFrame], state: np.ndarray,
            obs: Mapping[str, Any] | None = None) -> np.ndarray:
        """Observe, let the policy re-plan (through `plan`) when its queue is empty, and return the next (10,)
        absolute EE action. Call it every env step; with a time stride S it observes every S-th step and spreads
        each policy action over S env actions (`interpolate_action`).

        `frame` may be a callable that renders it (`TabletopEnv.frame_later`): a frame no sampled window will hold
        is then not rendered, and not perceived unless a later frame needs it (`TargetClouds.defer`)."""
        if not self.env_actions:
            if self._observation_unused():
                later = frame if callable(frame) else (lambda: frame)
                if self.policy_config.observation.object_slots:
                    self.targets.defer(later, self.step_count)
                action = self.policy.select_queued_action()
            else:
                frame = frame() if callable(frame) else frame
                action = self.policy.select_action(self.policy_input(frame, state, obs),
                                                   sample=partial(self.plan, frame, state))
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

    def reads_frame(self) -> bool:
        """Whether the next `act` looks at its frame at all (with a time stride S, one step in S does)."""
        return not self.env_actions

    def _observation_unused(self) -> bool:
        """This step's observation reaches no sampled window and building it changes nothing later."""
        needed = getattr(self.policy, "observation_needed", None)  # a policy without `ChunkedControl` observes always
        if needed is None or needed() or not self._own_visual:
            return False
        return not self.policy_config.observation.object_slots or self.targets.can_defer(self.target_phrases)

    def episode_facts(self) -> dict[str, Any]:
        """What the runner knows of the episode so far, for `EpisodeResult`."""
        tracker, targets = self.tracker, self.targets
        return {"held_radius": tracker.held_radius, "stale_obstacle_fits": tracker.stale_fits,
                "held_clouds": targets.held_clouds, "partly_hidden": list(targets.partly_hidden),
                "seen_from_other_views": list(self.views.seen), "targets": dict(targets.initial_targets),
                "filters": {f.name: note for f in self.filters if (note := f.episode_note())}}
