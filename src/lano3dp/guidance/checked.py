"""Checked execution: never execute a chunk that collides (beyond the paper).

Guidance lowers the chance of a collision but guarantees nothing: the push is a fixed number of
gradient steps of size rho. So after sampling, the part of the chunk that will be executed is
checked against every obstacle; if any waypoint (or, with `densify`, any point on a segment) is
closer than `min_clearance`, the chunk is re-sampled with a larger rho, a bounded number of times.
If no try is clear the result says so, and the caller must not execute the chunk.

The sampler is passed in as a callable so this module knows nothing of the policy:

    def sample_fn(guidance: GuidanceConfig) -> tuple[Tensor (B, H, 3) metric positions, payload]

`payload` is whatever the caller needs back (e.g. the policy's ActionChunk).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import torch

from lano3dp.guidance.costs import PositionCost, densify
from lano3dp.guidance.exceptions import CollisionError
from lano3dp.guidance.sampler import GuidanceConfig, GuidanceMode
from lano3dp.guidance.settings import CostSettings

SampleFn = Callable[[GuidanceConfig], tuple[torch.Tensor, Any]]

NO_CLEAR_CHUNK = "no collision-free chunk found"


@dataclass(frozen=True)
class CheckConfig:
    """How chunks are checked and how guidance escalates.

    Attributes:
        n_execute: how many leading waypoints of the returned chunk will be executed and so must be clear
            (None: all of them; pass the policy's actions and leave None, or its trajectory and n_action_steps).
        min_clearance: required gap (m) between the held sphere and every obstacle; 0 = no contact.
        max_tries: samples drawn at most, the first included.
        growth: rho is multiplied by this after each colliding try.
        initial_scale: rho used on the first escalation when the caller's guidance is off (mode none or rho 0).
        max_scale: rho never exceeds this (large pushes throw the sample off the data manifold).
        densify: also check `densify - 1` points inside each segment (see costs.densify).
    """

    n_execute: int | None = None
    min_clearance: float = 0.0
    max_tries: int = 4
    growth: float = 2.0
    initial_scale: float = 0.1
    max_scale: float = float("inf")
    densify: int = CostSettings.densify

    def __post_init__(self):
        if self.max_tries < 1 or self.growth < 1 or self.densify < 1 or self.initial_scale <= 0:
            raise ValueError(f"invalid CheckConfig {self}")


@dataclass(frozen=True)
class Attempt:
    """One try: the guidance it used, its smallest clearance per sample (m), and its time (s)."""

    guidance: GuidanceConfig
    min_clearance: torch.Tensor
    seconds: float


@dataclass
class CheckedResult:
    """Outcome of `checked_sample`.

    Attributes:
        success: every sample's executed part keeps at least `min_clearance` from every obstacle.
        tries: how many samples were drawn.
        guidance: the guidance of the returned try (on success, the last one).
        min_clearance: (B,) smallest clearance (m) of the returned chunk's executed part.
        positions: (B, H, 3) metric positions of the returned chunk.
        payload: what `sample_fn` returned with them.
        attempts: every try, in order.
        message: "ok" or why it failed.
    """

    success: bool
    tries: int
    guidance: GuidanceConfig
    min_clearance: torch.Tensor
    positions: torch.Tensor
    payload: Any
    attempts: list[Attempt] = field(default_factory=list)
    message: str = "ok"

    @property
    def final_scale(self) -> float:
        """rho of the last try (the largest one tried)."""
        return self.attempts[-1].guidance.scale if self.attempts else self.guidance.scale

    def raise_if_failed(self) -> CheckedResult:
        if not self.success:
            raise CollisionError(f"{self.message}: after {self.tries} tries up to rho={self.final_scale:g}, "
                                 f"min clearance {self.min_clearance.min().item():.4f} m")
        return self


def executed_clearance(cost: PositionCost, positions: torch.Tensor, config: CheckConfig,
                       start_position: torch.Tensor | None = None) -> torch.Tensor:
    """(B, H, 3) metric positions -> (B,) smallest clearance (m) of the executed part.

    With `start_position` (B, 3), the segment from the current EE position to the first waypoint is
    checked as well.
    """
    executed = positions[:, : config.n_execute] if config.n_execute is not None else positions
    if start_position is not None:
        executed = torch.cat([start_position[:, None].to(executed), executed], 1)
    with torch.no_grad():
        return cost.clearance(densify(executed, config.densify)).min(-1).values


def escalate(guidance: GuidanceConfig, config: CheckConfig) -> GuidanceConfig:
    """The next try's guidance: switch guidance on (A_0|k) if it was off, else multiply rho by `growth`."""
    if not guidance.enabled:
        return dataclasses.replace(guidance, mode=GuidanceMode.CLEAN, scale=min(config.initial_scale, config.max_scale),
                                   last_steps=max(guidance.last_steps, 1))
    return dataclasses.replace(guidance, scale=min(guidance.scale * config.growth, config.max_scale))


def checked_sample(sample_fn: SampleFn, cost: PositionCost, guidance: GuidanceConfig | None = None,
                   config: CheckConfig | None = None, *, start_position: torch.Tensor | None = None) -> CheckedResult:
    """Sample, check the executed part against `cost.clearance`, re-sample with larger rho until clear.

    Args:
        sample_fn: guidance -> ((B, H, 3) metric positions, payload).
        cost: the obstacles (anything with `clearance`, e.g. an ObstacleSet).
        guidance: the first try's guidance (None: unguided first, then escalate).
        config: see CheckConfig.
        start_position: (B, 3) current EE position, to check the first segment too.

    Returns:
        CheckedResult; on failure `success` is False, `message` is "no collision-free chunk found" and the
        returned chunk is the try with the largest clearance (for diagnostics only: do not execute it).
    """
    config = config or CheckConfig()
    guidance = guidance or GuidanceConfig(mode=GuidanceMode.NONE)
    attempts: list[Attempt] = []
    best = None
    for attempt_index in range(config.max_tries):
        if attempt_index:
            next_guidance = escalate(guidance, config)
            if next_guidance == guidance:  # rho is at max_scale: another try would repeat the same push
                break
            guidance = next_guidance
        started = time.perf_counter()
        positions, payload = sample_fn(guidance)
        clearance = executed_clearance(cost, positions, config, start_position)
        attempts.append(Attempt(guidance, clearance, time.perf_counter() - started))
        result = CheckedResult(bool((clearance >= config.min_clearance).all()), len(attempts), guidance,
                               clearance, positions, payload, attempts)
        if result.success:
            return result
        if best is None or clearance.min() > best.min_clearance.min():
            best = result
    best.tries, best.attempts, best.success = len(attempts), attempts, False
    best.message = NO_CLEAR_CHUNK
    return best
