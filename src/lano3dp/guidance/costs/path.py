"""The path the arm will really take through a chunk, and what checks and repairs a chunk on it; the one recipe from
fitted obstacles to the guidance cost."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch

from lano3dp.guidance.costs.obstacles import ObstacleSet, PositionCost, _check_positions
from lano3dp.guidance.costs.wrappers import (
    AnchoredPath,
    Densified,
    MetricGradient,
    SweptBody,
    TurnedPush,
    densify,
    obstacle_axis_xy,
    reached_positions,
)
from lano3dp.guidance.settings import SAFETY_MARGIN


class ExecutedPath:
    """An obstacle cost on the path the arm will really take through a sampled chunk, for checking and
    repairing the chunk before it runs (beyond the paper).

    The guidance cost sees straight segments between waypoints and the body at the hand's present rotation.
    Traces of touching episodes showed two gaps (bottle_in_drawer, tuning seeds): a guided chunk whose
    waypoints zig-zag 10-25 cm apart is not executed along its segments, since the simulator's arm moves at
    most 5 cm a step and chases each waypoint from where the last step left it, cutting across the obstacle
    the segments went round; and the held object turns with the hand within a chunk. Here the path starts at
    the hand, follows `reached_positions` under the arm's step limit, and each reached position carries the
    body at its own waypoint's rotation; a segment carries the bodies of both its ends (the hand turns
    between them).

    Args:
        obstacles: the bare fitted obstacles (held radius 0; with the "sphere" body, their held radius).
        start: (3,) the EE's present position, m.
        node_offsets: (1 + T, K, 3) body-ball offsets from the EE point, world axes, at the hand's present
            rotation and at each of the T waypoints' rotations.
        radii: (K,) ball radii, m.
        step_limit: metres the EE moves at most per policy step (None: it reaches every waypoint).
        densify: points per segment.
        margin: where the cost starts pushing (m); default the obstacles' margin.
    """

    def __init__(self, obstacles: Sequence[PositionCost], start, node_offsets, radii, *,
                 step_limit: float | None = None, densify: int = 4, margin: float | None = None):
        self.obstacles = list(obstacles)
        self.start = torch.as_tensor(np.asarray(start, dtype=np.float64).reshape(3))
        self.node_offsets = torch.as_tensor(np.asarray(node_offsets, dtype=np.float64))
        self.radii = torch.as_tensor(np.asarray(radii, dtype=np.float64).reshape(-1))
        if self.node_offsets.ndim != 3 or self.node_offsets.shape[1:] != (len(self.radii), 3):
            raise ValueError(f"node_offsets must be (1 + T, K, 3) with K = {len(self.radii)} radii, "
                             f"got {tuple(self.node_offsets.shape)}")
        if densify < 1 or (step_limit is not None and step_limit <= 0):
            raise ValueError(f"need densify >= 1 and step_limit > 0 or None, got {densify}, {step_limit}")
        self.step_limit, self.densify = step_limit, int(densify)
        if margin is None:
            margin = getattr(self.obstacles[0], "margin", SAFETY_MARGIN) if self.obstacles else SAFETY_MARGIN
        self.margin = float(margin)

    def _gaps(self, positions: torch.Tensor) -> list[torch.Tensor]:
        """(B, T, 3) waypoints (T at most the nodes') -> per obstacle (B, M) gaps of the body along the path,
        M = T * densify + 1, the hand's present pose first."""
        _check_positions(positions)
        batch, steps, _ = positions.shape
        if steps + 1 > len(self.node_offsets):
            raise ValueError(f"{steps} waypoints but body poses for {len(self.node_offsets) - 1}")
        start = self.start.to(positions).expand(batch, 1, 3)
        nodes = torch.cat([start, reached_positions(self.start, positions, self.step_limit)], 1)
        offsets = self.node_offsets[:steps + 1].to(positions)
        points = densify(nodes, self.densify)  # (B, M, 3)
        both_ends = torch.cat([offsets[:-1], offsets[1:]], 1).repeat_interleave(self.densify, 0)
        both_ends = torch.cat([both_ends, offsets[-1:].repeat(1, 2, 1)], 0)  # (M, 2K, 3)
        balls = points[:, :, None] + both_ends  # (B, M, 2K, 3)
        radii = self.radii.to(positions).repeat(2)
        return [(obstacle.clearance(balls.flatten(1, 2)).reshape(balls.shape[:3]) - radii).min(-1).values
                for obstacle in self.obstacles]

    def present_clearance(self) -> float:
        """The body's gap (m) at the hand's present pose, to the nearest obstacle (inf without obstacles)."""
        with torch.no_grad():
            gaps = self._gaps(self.start[None, None])
        return min((float(gap[0, 0]) for gap in gaps), default=math.inf)

    def clearance(self, positions: torch.Tensor) -> torch.Tensor:
        """(B, T, 3) -> (B, T * densify): the smallest gap along the executed path, the hand's present pose
        excluded (no waypoint can change it)."""
        gaps = self._gaps(positions)
        if not gaps:
            return positions.new_full((positions.shape[0], positions.shape[1] * self.densify), math.inf)
        return torch.stack(gaps).min(0).values[:, 1:]

    def __call__(self, positions: torch.Tensor) -> torch.Tensor:
        return sum((torch.relu(self.margin - gap).sum(-1) for gap in self._gaps(positions)),
                   positions.new_zeros(positions.shape[0]))

    def __repr__(self):
        return (f"ExecutedPath({len(self.obstacles)} obstacles, {len(self.radii)} balls, "
                f"step_limit={self.step_limit}, densify={self.densify})")


def push_clear(cost: PositionCost, positions: torch.Tensor, *, clearance: float, step: float = 0.01,
               iterations: int = 20) -> tuple[torch.Tensor, int]:
    """Move waypoints down `cost` by plain gradient steps (no network) until `cost.clearance` is at least
    `clearance` everywhere, or `iterations` steps were taken (beyond the paper).

    Guidance pushes a sample while the network pulls it back towards the demonstrations, so a guided chunk can
    end inside the margin; this finishes the push on the sample itself. Every waypoint the cost pushes moves
    `step` metres per iteration along its own descent direction, so a deep waypoint is not flung far in one
    go. (B, T, 3) metric positions -> (the moved positions, iterations taken).
    """
    _check_positions(positions)
    moved = positions.detach().clone()
    for taken in range(iterations):
        if float(min_clearance(cost, moved).min()) >= clearance:
            return moved, taken
        with torch.enable_grad():
            variable = moved.clone().requires_grad_(True)
            (gradient,) = torch.autograd.grad(cost(variable).sum(), variable)
        norm = gradient.norm(dim=-1, keepdim=True)
        moved = moved - step * gradient / norm.clamp_min(1e-12) * (norm > 1e-12)
    return moved, iterations


def clear_prefix(cost: PositionCost, positions: torch.Tensor, start: torch.Tensor, *, clearance: float,
                 fractions: Sequence[float] = (0.75, 0.5, 0.25, 0.1)) -> torch.Tensor:
    """The longest start of a chunk that `cost` predicts keeps `clearance` (m) from every obstacle: whole
    waypoints while they do, then the farthest of `fractions` of the way to the next one (beyond the paper).

    (B, T, 3) waypoints and (B, 3) the EE now -> (B, k, 3), k <= T; k = 0 when even the first tenth of the
    first step does not keep clear. Executing only this part and re-planning is safer than running a chunk
    that guidance and the repair left on course for the obstacle.
    """
    _check_positions(positions)
    with torch.no_grad():
        def clear(candidate: torch.Tensor) -> bool:
            return float(min_clearance(cost, candidate).min()) >= clearance

        if clear(positions):
            return positions
        kept, previous = positions[:, :0], start.to(positions)
        for index in range(positions.shape[1]):
            target = positions[:, index]
            if clear(torch.cat([kept, target[:, None]], 1)):
                kept, previous = torch.cat([kept, target[:, None]], 1), target
                continue
            for fraction in fractions:
                shortened = torch.cat([kept, (previous + fraction * (target - previous))[:, None]], 1)
                if clear(shortened):
                    return shortened
            return kept
        return kept


def obstacle_guidance_cost(obstacles: Sequence[PositionCost], *, body: tuple[np.ndarray, np.ndarray] | None = None,
                           densify: int = 1, action_scale=None, start=None, turn: float = 0.0) -> PositionCost:
    """The one recipe from fitted obstacles to the cost guidance descends (runtime, `guidance-figures`, benches).

    Args:
        obstacles: fitted obstacle costs (their safety distance already holds any held radius).
        body: (K, 3) offsets from the EE point and (K,) radii of what moves with it (`SweptBody`); None: the EE
            point alone.
        densify: points per path segment the cost sees (`Densified`; 1: the waypoints only, the paper's).
        action_scale: the normaliser's position scale s (1/m) for an isotropic push in metres (`MetricGradient`);
            None: the paper's push in normalised units.
        start: (3,) the EE's present position, to cost the path from it through the waypoints (`AnchoredPath`);
            None: the waypoints alone (the paper's).
        turn: radians each obstacle's push is turned round it (`TurnedPush`; needs `start`); 0: straight away.
    """
    axes = [obstacle_axis_xy(obstacle) for obstacle in obstacles] if turn > 0 and start is not None else None
    if body is not None:
        obstacles = [SweptBody(obstacle, *body) for obstacle in obstacles]
    if axes is not None:
        obstacles = [cost if axis is None else TurnedPush(cost, axis, start, turn)
                     for cost, axis in zip(obstacles, axes, strict=True)]
    cost: PositionCost = ObstacleSet(list(obstacles))
    if densify > 1:
        cost = Densified(cost, densify)
    if start is not None:
        cost = AnchoredPath(cost, start)
    if action_scale is not None:
        cost = MetricGradient(cost, action_scale)
    return cost


def min_clearance(cost: PositionCost, positions: torch.Tensor) -> torch.Tensor:
    """(B, T, 3) -> (B,) the smallest clearance (m) along each trajectory, without gradients."""
    with torch.no_grad():
        return cost.clearance(positions).min(-1).values
