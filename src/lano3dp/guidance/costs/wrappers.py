"""What turns fitted obstacles into the cost guidance descends: the body swept along the path, the path densified and
anchored at the hand, the push in metres and turned round each obstacle."""

from __future__ import annotations

import math

import numpy as np
import torch

from lano3dp.guidance.costs.obstacles import _SQRT_EPS, PointCloudObstacle, PositionCost, _check_positions, body_reach
from lano3dp.guidance.settings import SAFETY_MARGIN


class SweptBody:
    """An obstacle cost on everything that moves with the end effector, not on the EE point alone.

    The body is a few balls rigidly offset from the EE point (the hand's span, the held object's
    centre), each with its own radius. Every waypoint carries the whole body, so the cost sees the
    volume the body sweeps along the path: a bowl held by its rim is pushed clear on the side it
    hangs, instead of a ball of its diameter round the EE pushing the EE away on every side (which
    kept a guided bowl ~19 cm from the obstacle's axis and out of reach of a pan beside it).

    The offsets are world-frame and fixed over one chunk (the runner re-measures them before each
    chunk from the current EE rotation and the held object's cloud), so a rotation inside one chunk
    is not modelled.

    Args:
        obstacle: the bare obstacle (held_radius 0): its clearance is the distance to its surface.
        offsets: (K, 3) ball centres relative to the EE point, world axes, m.
        radii: (K,) ball radii, m.
        margin: distance (m) beyond contact at which the cost starts pushing; default the obstacle's.
    """

    def __init__(self, obstacle: PositionCost, offsets, radii, *, margin: float | None = None):
        offsets = torch.as_tensor(np.asarray(offsets, dtype=np.float64).reshape(-1, 3))
        radii = torch.as_tensor(np.asarray(radii, dtype=np.float64).reshape(-1))
        if len(offsets) == 0 or len(offsets) != len(radii) or bool((radii < 0).any()):
            raise ValueError(f"SweptBody needs K offsets (K, 3) and K radii >= 0, got {tuple(offsets.shape)}, "
                             f"{tuple(radii.shape)}")
        self.obstacle, self.offsets, self.radii = obstacle, offsets, radii
        self.margin = float(getattr(obstacle, "margin", SAFETY_MARGIN) if margin is None else margin)

    @property
    def reach(self) -> float:
        """Farthest body surface from the EE point (m): the radius of the ball the older model used."""
        return body_reach(self.offsets.numpy(), self.radii.numpy())

    def clearance(self, positions: torch.Tensor) -> torch.Tensor:
        """(B, T, 3) EE positions -> (B, T) smallest gap (m) of any body ball to the obstacle."""
        _check_positions(positions)
        batch, steps, _ = positions.shape
        carried = positions[:, :, None, :] + self.offsets.to(positions)  # (B, T, K, 3)
        gaps = self.obstacle.clearance(carried.reshape(batch, -1, 3)).reshape(batch, steps, -1)
        return (gaps - self.radii.to(positions)).min(-1).values

    def __call__(self, positions: torch.Tensor) -> torch.Tensor:
        # The nearest ball alone is pushed, so a body of many balls is pushed as hard as one point.
        return torch.relu(self.margin - self.clearance(positions)).sum(-1)

    def __repr__(self):
        return f"SweptBody({self.obstacle!r}, {len(self.radii)} balls, reach={self.reach:.3f})"


def densify(positions: torch.Tensor, factor: int) -> torch.Tensor:
    """Linearly interpolate `factor - 1` points inside every segment.

    Waypoints 3 cm apart can straddle a thin obstacle while every waypoint is clear; checking
    (or costing) the densified path checks the segments too. (B, T, 3) -> (B, (T - 1) * factor + 1, 3).
    """
    if factor < 1:
        raise ValueError(f"densify factor must be >= 1, got {factor}")
    if factor == 1 or positions.shape[-2] < 2:
        return positions
    fractions = torch.arange(factor, dtype=positions.dtype, device=positions.device) / factor
    start, end = positions[..., :-1, None, :], positions[..., 1:, None, :]
    inner = start + (end - start) * fractions[:, None]  # (B, T-1, factor, 3)
    return torch.cat([inner.flatten(-3, -2), positions[..., -1:, :]], -2)


class Densified:
    """A cost evaluated on the densified path (see `densify`), so segments are pushed out too."""

    def __init__(self, cost: PositionCost, factor: int = 4):
        self.cost, self.factor = cost, int(factor)

    def clearance(self, positions):
        return self.cost.clearance(densify(positions, self.factor))

    def __call__(self, positions):
        return self.cost(densify(positions, self.factor))

    def __repr__(self):
        return f"Densified({self.cost!r}, factor={self.factor})"


class _MapGradient(torch.autograd.Function):
    """Identity forward; the backward passes the positions' gradient through `map_gradient` (the metric push
    reweights its axes, the turned push rotates it), so a cost's value stays and only its push changes."""

    @staticmethod
    def forward(ctx, positions, map_gradient):
        ctx.map_gradient = map_gradient
        return positions.view_as(positions)

    @staticmethod
    def backward(ctx, grad):
        return ctx.map_gradient(grad), None


class MetricGradient:
    """A cost whose guidance push is isotropic in metres (beyond the paper).

    Guidance differentiates with respect to the *normalised* trajectory. With Diffusion Policy's
    per-axis min-max normaliser a = s * x + o, a push -rho * dD/da moves a waypoint by
    -rho * s_d^-2 * dD/dx_d along axis d: demonstrations that span 8 cm in x and 55 cm in y resist a
    sideways push (s_x = 25/m) about 50 times more than one along the path (s_y = 3.6/m), so the
    paper's cost slides waypoints along the path instead of around the obstacle. Scaling the gradient
    that reaches the positions by s_d^2 cancels that: each guided step then moves a waypoint by about
    rho metres down the metric cost gradient (exactly so where d A_0|k / d A_k is the identity), so
    rho reads in metres per guided step. The cost value and the clearance are unchanged.

    Args:
        cost: any PositionCost.
        action_scale: (3,) the normaliser's scale s of the position dims (1/m), i.e.
            `policy.normalizer.scale("action")[:3]`, so the guidance sees the same floors as the policy.
    """

    def __init__(self, cost: PositionCost, action_scale):
        self.cost = cost
        self.weight = torch.as_tensor(np.asarray(action_scale, dtype=np.float64)) ** 2
        if self.weight.shape != (3,) or not bool((self.weight > 0).all()):
            raise ValueError(f"action_scale must be 3 positive numbers, got {action_scale!r}")

    def clearance(self, positions):
        return self.cost.clearance(positions)

    def __call__(self, positions):
        weight = self.weight.to(positions)
        return self.cost(_MapGradient.apply(positions, lambda grad: grad * weight))

    def __repr__(self):
        return f"MetricGradient({self.cost!r}, weight={self.weight.tolist()})"


class AnchoredPath:
    """A cost on the path the hand will take: from the EE's present position through the waypoints (beyond the
    paper).

    The sampled horizon starts at the first action, not at the hand; a cost on the waypoints alone never sees
    the segment from the hand to that first action, and a guided chunk could leap across an obstacle in one
    step with every waypoint clear (a traced bottle_in_drawer touch: 18 cm from the hand to a first waypoint
    beyond the obstacle).

    Args:
        cost: the obstacles (an `ObstacleSet`, `Densified`, ...), on metric positions.
        start: (3,) the EE's present position, m.
    """

    def __init__(self, cost: PositionCost, start):
        self.cost = cost
        self.start = torch.as_tensor(np.asarray(start, dtype=np.float64).reshape(3))

    def path(self, positions: torch.Tensor) -> torch.Tensor:
        """(B, T, 3) waypoints -> (B, 1 + T, 3): the present position, then the waypoints."""
        _check_positions(positions)
        return torch.cat([self.start.to(positions).expand(positions.shape[0], 1, 3), positions], 1)

    def clearance(self, positions: torch.Tensor) -> torch.Tensor:
        """Along the path from the hand, but not at the hand itself: where it is now no waypoint can change, and
        a check or a push that counted it would never finish while the hand is inside the margin."""
        return self.cost.clearance(self.path(positions))[:, 1:]

    def __call__(self, positions: torch.Tensor) -> torch.Tensor:
        return self.cost(self.path(positions))

    def __repr__(self):
        return f"AnchoredPath({self.cost!r}, start={self.start.tolist()})"


def _turn_horizontal(grad: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    """(B, T, 3) gradients with each row's horizontal part turned by its (B,) angle (rad, about +z)."""
    cos, sin = torch.cos(angle).to(grad)[:, None], torch.sin(angle).to(grad)[:, None]
    turned = grad.clone()
    turned[..., 0] = cos * grad[..., 0] - sin * grad[..., 1]
    turned[..., 1] = sin * grad[..., 0] + cos * grad[..., 1]
    return turned


def obstacle_axis_xy(obstacle) -> torch.Tensor | None:
    """(2,) the horizontal middle of a fitted obstacle (a cylinder's axis, a box's or a cloud's centre), m; None
    for a shape that has none."""
    if isinstance(obstacle, PointCloudObstacle):
        return obstacle.points[:, :2].double().mean(0)
    center = getattr(obstacle, "center", None)
    return None if center is None else torch.as_tensor(center, dtype=torch.float64).reshape(-1)[:2]


class TurnedPush:
    """An obstacle's push turned sideways, round the obstacle, on the side the chunk already passes (beyond the
    paper).

    The hinge pushes each waypoint straight away from the obstacle. A chunk headed straight at it is then pushed
    back along its own way, while the network pulls it forward again: a traced bowl_pour episode guided round a
    phantom obstacle held the bowl 21-25 cm from its axis for 80 steps before going round, and timed out. Here the
    descent direction is turned by `angle` towards the side of the line from the hand to the chunk's end that
    the obstacle is not on, so the push carries the path round the obstacle (a circulation field, as in
    potential-field navigation); the side is re-read from each call's positions, so it stays put while the hand
    goes round. The cost and its clearance are unchanged; only its gradient is turned.

    Args:
        cost: one obstacle's cost (a `SweptBody`, or the obstacle itself) on metric positions.
        axis_xy: (2,) the obstacle's horizontal middle, m.
        start: (3,) the EE's present position, m.
        angle: the turn, radians (0: the plain push; below pi / 2, so part of the push still points away).
    """

    def __init__(self, cost: PositionCost, axis_xy, start, angle: float):
        if not 0.0 <= angle < math.pi / 2:
            raise ValueError(f"the push's turn must be in [0, pi/2) radians, got {angle}")
        self.cost, self.angle = cost, float(angle)
        self.axis_xy = torch.as_tensor(np.asarray(axis_xy, dtype=np.float64).reshape(2))
        self.start = torch.as_tensor(np.asarray(start, dtype=np.float64).reshape(3))

    def turns(self, positions: torch.Tensor) -> torch.Tensor:
        """(B, T, 3) -> (B,) the signed turn: counter-clockwise (seen from above) when the obstacle lies left of
        the way from the hand to the chunk's end, so the push goes round its right, and clockwise otherwise."""
        start = self.start[:2].to(positions)
        way = positions[:, -1, :2].detach() - start
        towards = self.axis_xy.to(positions) - start
        left = way[:, 0] * towards[1] - way[:, 1] * towards[0]
        return torch.where(left >= 0, 1.0, -1.0).to(positions) * self.angle

    def clearance(self, positions: torch.Tensor) -> torch.Tensor:
        return self.cost.clearance(positions)

    def __call__(self, positions: torch.Tensor) -> torch.Tensor:
        if self.angle == 0.0:
            return self.cost(positions)
        angle = self.turns(positions)
        return self.cost(_MapGradient.apply(positions, lambda grad: _turn_horizontal(grad, angle)))

    def __repr__(self):
        return f"TurnedPush({self.cost!r}, angle={self.angle:.3f})"


def reached_positions(start: torch.Tensor, waypoints: torch.Tensor, step_limit: float | None) -> torch.Tensor:
    """Where a motion-limited arm is after each control step: it chases each commanded waypoint, moving at most
    `step_limit` metres a step, and chases the next one from wherever it got. (3,) start and (B, T, 3) waypoints
    -> (B, T, 3); None: every waypoint is reached. Differentiable in the waypoints."""
    if step_limit is None:
        return waypoints
    position = start.to(waypoints).expand(waypoints.shape[0], 3)
    reached = []
    for index in range(waypoints.shape[1]):
        offset = waypoints[:, index] - position
        length = torch.sqrt((offset**2).sum(-1, keepdim=True) + _SQRT_EPS)
        position = position + offset * torch.clamp(step_limit / length, max=1.0)
        reached.append(position)
    return torch.stack(reached, 1)

