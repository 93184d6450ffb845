"""Differentiable obstacle costs on metric end-effector positions (the paper's D, Eq. 4).

Every obstacle shares one small protocol:

    clearance(positions (B, T, 3)) -> (B, T)   signed gap in metres between what the gripper holds
                                                (a sphere of `held_radius` around the EE point) and the
                                                obstacle surface; < 0 means collision
    __call__(positions (B, T, 3))  -> (B,)     sum over waypoints of relu(margin - clearance)

so the cost, and its gradient, is non-zero only for waypoints closer than the safety distance
(Eq. 4), and descending it pushes exactly those waypoints away from the obstacle. An obstacle
object therefore plugs straight into `DiffusionPolicy.predict_action_chunk(position_cost=...)`.

The paper's cost is `Cylinder`: the xy distance d_i from each waypoint to the obstacle centre,
hinged at the safety distance

    Q* = obstacle radius + held radius + margin          (`Cylinder.safety_distance`)

so that relu(Q* - d_i) = relu(margin - clearance_i). The paper's bowl-pouring setup used
Q* = bowl diameter + obstacle radius. For the other shapes the same hinge is applied to a signed
distance function, i.e. the safety distance is measured from the obstacle surface.

Positions may be float32 or float64 and live on any device; obstacle parameters follow them.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import numpy as np
import torch

from lano3dp.errors import EmptyCloudError
from lano3dp.guidance.settings import SAFETY_MARGIN

# sqrt has an infinite derivative at 0; a waypoint exactly on an obstacle's axis gets a zero
# (not NaN) gradient instead. The offset, 1e-10 m once square-rooted, is far below float32 resolution
# of positions around a metre, and still a normal float32 number.
_SQRT_EPS = 1e-20


def _safe_norm(x: torch.Tensor, dim: int = -1) -> torch.Tensor:
    return torch.sqrt((x * x).sum(dim) + _SQRT_EPS)


def _check_positions(positions: torch.Tensor) -> None:
    if positions.ndim != 3 or positions.shape[-1] != 3:
        raise ValueError(f"positions must be (B, T, 3) metric EE positions, got shape {tuple(positions.shape)}")


@runtime_checkable
class PositionCost(Protocol):
    """What `predict_action_chunk(position_cost=...)` and the checked execution accept."""

    def clearance(self, positions: torch.Tensor) -> torch.Tensor: ...

    def __call__(self, positions: torch.Tensor) -> torch.Tensor: ...


class Obstacle(ABC):
    """Base of every obstacle cost.

    Args:
        held_radius: radius (m) of a sphere around the EE point that must stay clear of the obstacle:
            the gripper plus whatever it holds (the paper used the bowl's diameter).
        margin: extra distance (m) beyond contact at which the cost starts pushing.
        xy_only: measure distances in the horizontal plane only (the paper's setting), i.e. treat
            the obstacle as an infinite vertical prism; z is ignored.
    """

    def __init__(self, *, held_radius: float = 0.0, margin: float = SAFETY_MARGIN, xy_only: bool = False):
        if held_radius < 0 or margin < 0:
            raise ValueError(f"held_radius and margin must be >= 0, got {held_radius}, {margin}")
        self.held_radius = float(held_radius)
        self.margin = float(margin)
        self.xy_only = bool(xy_only)

    @abstractmethod
    def surface_distance(self, positions: torch.Tensor) -> torch.Tensor:
        """Signed distance (B, T) in metres from each point to the obstacle surface (< 0 inside)."""

    def clearance(self, positions: torch.Tensor) -> torch.Tensor:
        """(B, T, 3) metric positions -> (B, T) signed gap (m) of the held sphere; < 0 is a collision."""
        _check_positions(positions)
        return self.surface_distance(positions) - self.held_radius

    def waypoint_cost(self, positions: torch.Tensor) -> torch.Tensor:
        """(B, T) per-waypoint hinge relu(margin - clearance); its gradient is zero beyond the margin."""
        return torch.relu(self.margin - self.clearance(positions))

    def __call__(self, positions: torch.Tensor) -> torch.Tensor:
        """(B, T, 3) metric positions -> (B,) cost, the sum over waypoints of the hinge."""
        return self.waypoint_cost(positions).sum(-1)

    def __add__(self, other: PositionCost) -> ObstacleSet:
        return ObstacleSet([self, other])


class Cylinder(Obstacle):
    """A vertical cylinder; with `xy_only` (default, the paper) an infinite vertical column.

    Args:
        center: (x, y) of the axis, m.
        radius: m.
        z_min, z_max: vertical extent (m) used when `xy_only` is False (a finite cylinder, 3D).
    """

    def __init__(self, center: Sequence[float], radius: float, *, z_min: float = -math.inf,
                 z_max: float = math.inf, xy_only: bool = True, held_radius: float = 0.0,
                 margin: float = SAFETY_MARGIN):
        super().__init__(held_radius=held_radius, margin=margin, xy_only=xy_only)
        if len(center) != 2:
            raise ValueError(f"Cylinder center is (x, y), got {center!r}")
        if radius <= 0 or not z_min < z_max:
            raise ValueError(f"Cylinder needs radius > 0 and z_min < z_max, got {radius}, {z_min}, {z_max}")
        self.center = torch.tensor([float(c) for c in center], dtype=torch.float64)
        self.radius, self.z_min, self.z_max = float(radius), float(z_min), float(z_max)

    @property
    def safety_distance(self) -> float:
        """Q* of Eq. 4: the xy distance from the axis below which a waypoint is pushed (m)."""
        return self.radius + self.held_radius + self.margin

    def surface_distance(self, positions):
        radial = _safe_norm(positions[..., :2] - self.center.to(positions)) - self.radius
        if self.xy_only or (math.isinf(self.z_min) and math.isinf(self.z_max)):
            return radial
        mid, half = (self.z_min + self.z_max) / 2, (self.z_max - self.z_min) / 2
        vertical = (positions[..., 2] - mid).abs() - half
        return _sdf_from_axis_gaps(torch.stack([radial, vertical], -1))

    def __repr__(self):
        return (f"Cylinder(center={self.center.tolist()}, radius={self.radius:.4f}, z=[{self.z_min}, {self.z_max}], "
                f"xy_only={self.xy_only}, Q*={self.safety_distance:.4f})")


class Sphere(Obstacle):
    """A ball; with `xy_only` a disc in the horizontal plane (an infinite vertical cylinder)."""

    def __init__(self, center: Sequence[float], radius: float, *, xy_only: bool = False,
                 held_radius: float = 0.0, margin: float = SAFETY_MARGIN):
        super().__init__(held_radius=held_radius, margin=margin, xy_only=xy_only)
        if len(center) != 3 or radius <= 0:
            raise ValueError(f"Sphere needs a center (x, y, z) and radius > 0, got {center!r}, {radius}")
        self.center = torch.tensor([float(c) for c in center], dtype=torch.float64)
        self.radius = float(radius)

    @property
    def safety_distance(self) -> float:
        """Distance from the centre below which a waypoint is pushed (m)."""
        return self.radius + self.held_radius + self.margin

    def surface_distance(self, positions):
        dims = 2 if self.xy_only else 3
        return _safe_norm(positions[..., :dims] - self.center[:dims].to(positions)) - self.radius

    def __repr__(self):
        return f"Sphere(center={self.center.tolist()}, radius={self.radius:.4f}, xy_only={self.xy_only})"


def _sdf_from_axis_gaps(gaps: torch.Tensor) -> torch.Tensor:
    """Exact signed distance of a convex product shape from per-axis gaps (..., n) (q = |p| - half)."""
    outside = _safe_norm(torch.relu(gaps))
    inside = torch.clamp(gaps.max(-1).values, max=0.0)
    # where every gap is <= 0 the point is inside and `outside` is 0; else `inside` is 0
    return torch.where(gaps.max(-1).values > 0, outside, inside)


class OrientedBox(Obstacle):
    """A box rotated about the vertical axis by `yaw` (rad); signed distance to its surface.

    Args:
        center: (x, y, z) of the box centre, m.
        half_extents: half sizes along the box's own x, y, z axes, m.
        yaw: rotation about world z, rad.
        xy_only: ignore z (an infinite vertical prism with the box's footprint).
    """

    def __init__(self, center: Sequence[float], half_extents: Sequence[float], yaw: float = 0.0, *,
                 xy_only: bool = False, held_radius: float = 0.0, margin: float = SAFETY_MARGIN):
        super().__init__(held_radius=held_radius, margin=margin, xy_only=xy_only)
        if len(center) != 3 or len(half_extents) != 3 or min(half_extents) <= 0:
            raise ValueError(f"OrientedBox needs center (3,) and positive half_extents (3,), got "
                             f"{center!r}, {half_extents!r}")
        self.center = torch.tensor([float(c) for c in center], dtype=torch.float64)
        self.half_extents = torch.tensor([float(h) for h in half_extents], dtype=torch.float64)
        self.yaw = float(yaw)

    def to_local(self, positions: torch.Tensor) -> torch.Tensor:
        """World (..., 3) -> box frame (..., 3)."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        rel = positions - self.center.to(positions)
        x = c * rel[..., 0] + s * rel[..., 1]
        y = -s * rel[..., 0] + c * rel[..., 1]
        return torch.stack([x, y, rel[..., 2]], -1)

    def surface_distance(self, positions):
        gaps = self.to_local(positions).abs() - self.half_extents.to(positions)
        return _sdf_from_axis_gaps(gaps[..., :2] if self.xy_only else gaps)

    def corners_xy(self) -> np.ndarray:
        """(4, 2) footprint corners in the world frame (for plots)."""
        hx, hy = self.half_extents[:2].tolist()
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        local = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]])
        rot = np.array([[c, -s], [s, c]])
        return local @ rot.T + self.center[:2].numpy()

    def __repr__(self):
        return (f"OrientedBox(center={self.center.tolist()}, half_extents={self.half_extents.tolist()}, "
                f"yaw={self.yaw:.3f}, xy_only={self.xy_only})")


class PointCloudObstacle(Obstacle):
    """An obstacle given directly by its segmented points: distance to the nearest point.

    Unlike the fitted shapes it needs no shape assumption, but it only knows the surface the
    camera saw: a thin shell, not a solid, so `point_radius` (m) should cover the point spacing
    and waypoints can "tunnel" between sparse points. Cost O(B T N) per call.

    Args:
        points: (N, 3) world frame, m (numpy or torch).
        point_radius: each point is treated as a ball of this radius.
        xy_only: nearest-point distance in the horizontal plane (the points become vertical lines).
    """

    def __init__(self, points, *, point_radius: float = 0.01, xy_only: bool = True, min_points: int = 1,
                 held_radius: float = 0.0, margin: float = SAFETY_MARGIN):
        super().__init__(held_radius=held_radius, margin=margin, xy_only=xy_only)
        points = torch.as_tensor(np.asarray(points, dtype=np.float32))
        if points.ndim != 2 or points.shape[-1] != 3:
            raise ValueError(f"obstacle points must be (N, 3), got shape {tuple(points.shape)}")
        points = points[torch.isfinite(points).all(-1)]
        if len(points) < max(min_points, 1):
            raise EmptyCloudError(f"obstacle cloud has {len(points)} finite points, need at least {max(min_points, 1)}")
        self.points = points
        self.point_radius = float(point_radius)

    def surface_distance(self, positions):
        dims = 2 if self.xy_only else 3
        diff = positions[..., None, :dims] - self.points[:, :dims].to(positions)  # (B, T, N, dims)
        return _safe_norm(diff).min(-1).values - self.point_radius

    def __repr__(self):
        return (f"PointCloudObstacle({len(self.points)} points, point_radius={self.point_radius}, "
                f"xy_only={self.xy_only})")


class ObstacleSet:
    """Several obstacles: the cost is the sum of their costs, the clearance the smallest of theirs."""

    def __init__(self, obstacles: Sequence[PositionCost]):
        flat: list[PositionCost] = []
        for obstacle in obstacles:
            flat.extend(obstacle.obstacles if isinstance(obstacle, ObstacleSet) else [obstacle])
        if not flat:
            raise ValueError("ObstacleSet needs at least one obstacle")
        self.obstacles = flat

    def clearance(self, positions: torch.Tensor) -> torch.Tensor:
        return torch.stack([o.clearance(positions) for o in self.obstacles], 0).min(0).values

    def __call__(self, positions: torch.Tensor) -> torch.Tensor:
        return torch.stack([o(positions) for o in self.obstacles], 0).sum(0)

    def __add__(self, other: PositionCost) -> ObstacleSet:
        return ObstacleSet([self, other])

    def __iter__(self):
        return iter(self.obstacles)

    def __len__(self):
        return len(self.obstacles)

    def __repr__(self):
        return f"ObstacleSet({self.obstacles!r})"


def body_reach(offsets, radii) -> float:
    """Farthest surface (m) from the EE point of a body of balls: (K, 3) offsets, (K,) radii."""
    return float((np.linalg.norm(np.asarray(offsets, dtype=np.float64), axis=-1) + np.asarray(radii)).max())


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
