"""One closed-loop episode with a `PolicyRunner` in any env meeting the simulator protocol, and what it measured."""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from lano3dp.env_factory import NonFiniteObservationError
from lano3dp.errors import Lano3dpError
from lano3dp.geometry.frame import RGBDFrame, observe, observed_state
from lano3dp.guidance.shapes import describe_obstacle
from lano3dp.runtime.runner import PolicyRunner

SUCCESS_AT = ("first", "end")  # success at any step (the episode stops there), or at the episode's last step


@dataclass
class EpisodeResult:
    """What one closed-loop episode measured.

    Attributes:
        seed: the env reset seed.
        success: the task's success check held (at some step, or at the last step with success_at "end").
        steps: env steps taken.
        collided: the robot or held object touched an obstacle (the env's contact events).
        n_collision_steps: steps with at least one obstacle contact.
        min_clearance: smallest true distance (m) between robot/held object and any obstacle, from the env (None
            when it reports none, e.g. no obstacle).
        path_length: EE path length (m), from the robot state.
        chunk_latency_s, chunk_tries, chunk_predicted_clearance, chunk_executed, chunk_notes: per chunk, from its
            `ChunkRecord` (latency, samples drawn, predicted clearance, actions kept when cut short, filter notes).
        ee_path: (steps + 1, 3) EE positions, metres (for plots; dropped from JSON by default).
        obstacles, gap_walls: the fitted obstacle shapes and the walls across gaps guided against
            (`describe_obstacle`).
        held_radius: m, the held extent in Q* ("sphere") or the swept body's reach.
        held_clouds, partly_hidden, seen_from_other_views, targets: what perception did (`TargetClouds`,
            `OtherViews`): clouds carried over while hidden (in the frames perceived: one the policy does not
            observe is perceived only when a later frame needs it), targets taken from a few points, objects
            found only in other views, each target's first centroid (m).
        stale_obstacle_fits: re-fits that kept the last fit because the camera saw too little of an obstacle.
        filters: per chunk filter, what it did over the episode (e.g. {"follow": {"steps": 3}}).
        error: why the episode ended early (perception failure, no clear chunk), or None.
        wall_s: wall time of the episode, s.
        stages: the task's stages in order -> reached (the env's last info["stages"]); stage: the furthest.
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
    chunk_executed: list[int | None] = field(default_factory=list)
    chunk_notes: list[dict[str, Any]] = field(default_factory=list)
    obstacles: list[dict[str, Any]] = field(default_factory=list)
    gap_walls: list[dict[str, Any]] = field(default_factory=list)
    held_radius: float | None = None
    held_clouds: int = 0
    partly_hidden: list[str] = field(default_factory=list)
    seen_from_other_views: list[str] = field(default_factory=list)
    stale_obstacle_fits: int = 0
    filters: dict[str, dict[str, Any]] = field(default_factory=dict)
    targets: dict[str, list[float]] = field(default_factory=dict)
    error: str | None = None
    wall_s: float = 0.0
    stages: dict[str, bool] = field(default_factory=dict)
    stage: str | None = None

    def to_dict(self, include_path: bool = False) -> dict[str, Any]:
        data = asdict(self)
        if include_path:
            data["ee_path"] = self.ee_path.round(5).tolist()
        else:
            data.pop("ee_path")
        return data


def path_length(positions: np.ndarray) -> float:
    """Sum of segment lengths of a (T, 3) path, metres."""
    positions = np.asarray(positions, dtype=np.float64)
    if len(positions) < 2:
        return 0.0
    return float(np.linalg.norm(np.diff(positions, axis=0), axis=1).sum())


def scene_obstacles(frame: RGBDFrame) -> list[str]:
    """Names of the objects the simulator marks as obstacles (ground truth; for evaluation defaults)."""
    return sorted(name for name, attributes in frame.instance_attributes.items()
                  if attributes.get("role") == "obstacle")


def _obstacle_contact(info: Mapping[str, Any]) -> bool:
    return len(info.get("obstacle_contacts", ())) > 0


def _clearance(info: Mapping[str, Any]) -> float | None:
    value = info.get("min_obstacle_clearance")
    return None if value is None or not np.isfinite(value) else float(value)


def rollout(env, runner: PolicyRunner, *, seed: int, options: Mapping[str, Any] | None = None,
            max_steps: int | None = None, on_frame: Callable[[RGBDFrame, Mapping[str, Any]], None] | None = None,
            on_reset: Callable[[PolicyRunner, RGBDFrame, Mapping[str, Any]], None] | None = None,
            success_at: str = "first") -> EpisodeResult:
    """Run one closed-loop episode and measure it.

    Args:
        env: meets the simulator protocol; `info` may carry "success" (bool), "obstacle_contacts" (this step's
            contact events with obstacles) and "min_obstacle_clearance" (m; inf without obstacles).
        runner: the controller; it is reset here with `seed`.
        seed: env reset seed (and the runner's sampling seed).
        max_steps: step limit (default: the env's own truncation).
        on_frame: called with every frame and info (videos, recordings).
        on_reset: called after the env reset with (runner, first frame, info), e.g. to name this scene's targets
            and obstacles (`runner.set_objects`).
        success_at: "first": success at any step ends the episode (the built-in tasks); "end": the episode runs to
            its end and succeeds when the last step's info says so (benchmarks such as Gymnasium-Robotics Fetch).
    """
    if success_at not in SUCCESS_AT:
        raise ValueError(f"success_at must be one of {', '.join(SUCCESS_AT)}, got {success_at!r}")
    # An env that can render a moment later (the built-in simulator) renders only the frames the runner looks at;
    # every frame when a callback wants each one.
    later = getattr(env, "frame_later", None) if on_frame is None else None
    if later is not None:
        env.defer_images(True)
    try:
        return _rollout(env, runner, seed, options, max_steps, on_frame, on_reset, success_at, later)
    finally:
        if later is not None:
            env.defer_images(False)


def _rollout(env, runner: PolicyRunner, seed: int, options, max_steps, on_frame, on_reset, success_at: str,
             later: Callable[[], Callable[[], RGBDFrame]] | None) -> EpisodeResult:
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
    while not (success and success_at == "first"):
        if max_steps is not None and steps >= max_steps:
            break
        if frame is None and runner.reads_frame():
            frame = later()  # rendered if the runner's policy observes it, or a later frame needs it
        try:
            action = runner.act(frame, state, obs)
        except Lano3dpError as failure:  # perception or checked execution: the episode fails, the eval goes on
            error = f"{type(failure).__name__}: {failure}"
            break
        try:
            obs, _reward, terminated, truncated, info = env.step(action)
        except NonFiniteObservationError as failure:  # the env blew up (NaN): this episode fails, the eval goes on
            error = f"{type(failure).__name__}: {failure}"
            break
        steps += 1
        if later is not None:
            frame, state = None, observed_state(obs)  # the frame is made when the runner asks for it
        else:
            frame, state = observe(env, obs)
        positions.append(state[:3].copy())
        reported = bool(info.get("success", False))
        success = reported if success_at == "end" else success or reported
        contact = _obstacle_contact(info)
        collided = collided or contact
        n_collision_steps += int(contact)
        if (clearance := _clearance(info)) is not None:
            clearances.append(clearance)
        if on_frame is not None:
            on_frame(frame, info)
        if terminated or truncated:
            break
    if error is not None and success_at == "end":
        success = False  # it did not reach its end
    ee_path = np.asarray(positions, dtype=np.float32)
    tracker, chunks = runner.tracker, runner.chunks
    return EpisodeResult(
        seed=int(seed), success=success, steps=steps, collided=collided, n_collision_steps=n_collision_steps,
        min_clearance=float(min(clearances)) if clearances else None, path_length=path_length(ee_path),
        chunk_latency_s=[round(c.latency_s, 5) for c in chunks], chunk_tries=[c.tries for c in chunks],
        chunk_predicted_clearance=[None if c.predicted_clearance is None else round(c.predicted_clearance, 5)
                                   for c in chunks],
        chunk_executed=[c.executed for c in chunks], chunk_notes=[c.notes for c in chunks],
        ee_path=ee_path,
        obstacles=([describe_obstacle(o, tracker.settings.shape) for o in tracker.obstacles]
                   if tracker.obstacles is not None else []),
        gap_walls=[describe_obstacle(wall, "box") for wall in tracker.walls],
        error=error, wall_s=time.perf_counter() - started,
        # The env latches stages, so its last info holds every stage reached in the episode.
        stages={stage: bool(flag) for stage, flag in (info.get("stages") or {}).items()}, stage=info.get("stage"),
        **runner.episode_facts(),
    )
