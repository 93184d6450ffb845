"""The obstacle shapes as costs: one small protocol (`PositionCost`), one class per shape, and sets of them."""

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

