"""Drawing one chunk from the policy, as `SamplerSettings.strategy` says.

    always        one sample, guided against the obstacles when there are any (the paper)
    when_needed   the policy's own chunk first; guided only when its horizon comes within the margin of an
                  obstacle, so guidance never bends a chunk that was not heading for one (one extra sample)
    checked       re-sample with a larger rho while the executed part collides (`guidance.checked`)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch

from lano3dp.guidance.checked import CheckConfig, checked_sample
from lano3dp.guidance.costs import PositionCost
from lano3dp.guidance.sampler import GuidanceConfig, GuidanceMode
from lano3dp.guidance.settings import GuidanceSettings
from lano3dp.policy.modeling import ActionChunk


@dataclass
class Drawn:
    """A drawn chunk: the policy's ActionChunk, samples drawn, the rho it was guided with (0: unguided), whether
    checked execution found it clear, and checked execution's clearance of its executed part (m)."""

    chunk: ActionChunk
    tries: int = 1
    scale: float = 0.0
    clear: bool = True
    checked_clearance: float | None = None


def guidance_config(settings: GuidanceSettings) -> GuidanceConfig | None:
    """The sampler's parameters for guided sampling (None when the settings never guide)."""
    sampler = settings.sampler
    if not settings.guided or sampler.rho <= 0:
        return None
    return GuidanceConfig(mode=GuidanceMode(sampler.mode), scale=sampler.rho, last_steps=sampler.last_steps,
                          per_train_step=sampler.per_train_step, guided_clip_range=sampler.clip_range,
                          push_weight=sampler.push_weight)


class ChunkSampler:
    """Draws chunks for one runner.

    Args:
        sample: (guidance or None, cost or None) -> ActionChunk, the policy's sampler with the window bound.
        settings: the sampler, cost and obstacle sections are read.
        start: index of "now" in the horizon; n_execute: actions a chunk runs.
    """

    def __init__(self, settings: GuidanceSettings, *, start: int, n_execute: int):
        self.strategy = settings.sampler.strategy
        self.guidance = guidance_config(settings)
        self.margin = settings.obstacles.margin
        self.start, self.n_execute = start, n_execute
        # checked execution escalates from rho (at least 1 mm, so an unguided first try can escalate at all)
        self.check = CheckConfig(initial_scale=max(settings.sampler.rho, 1e-3), densify=settings.cost.densify,
                                 n_execute=n_execute) if self.strategy == "checked" else None

    def draw(self, sample: Callable[[GuidanceConfig | None], ActionChunk], cost: PositionCost | None,
             position: torch.Tensor) -> Drawn:
        """One chunk; `sample(guidance)` draws from the policy (guided against `cost` when guidance is given),
        `position` (1, 3) is the EE now (checked execution checks the step to the first action too)."""
        if cost is None:
            return Drawn(sample(None))
        if self.check is not None:
            return self._checked(sample, cost, position)
        if self.guidance is None:
            return Drawn(sample(None))
        if self.strategy == "when_needed":
            plain = sample(None)
            with torch.no_grad():
                gap = float(cost.clearance(plain.trajectory[:, self.start:, :3].float()).min())
            if gap >= self.margin:
                return Drawn(plain)
            return Drawn(sample(self.guidance), tries=2, scale=self.guidance.scale)
        return Drawn(sample(self.guidance), scale=self.guidance.scale)

    def _checked(self, sample, cost: PositionCost, position: torch.Tensor) -> Drawn:
        def sample_fn(guide: GuidanceConfig):
            chunk = sample(guide if guide.mode is not GuidanceMode.NONE else None)
            return chunk.trajectory[:, self.start:, :3].float(), chunk

        result = checked_sample(sample_fn, cost, self.guidance, self.check, start_position=position)
        scale = result.guidance.scale if result.guidance.mode is not GuidanceMode.NONE else 0.0
        return Drawn(result.payload, tries=result.tries, scale=scale, clear=result.success,
                     checked_clearance=float(result.min_clearance.min()))
