"""Fit simple obstacle shapes to an obstacle's segmented point cloud (world frame, metres).

A single camera sees only the near side of an obstacle, so the centroid of its points is biased
toward the camera. The cylinder fit therefore fits a circle to the xy points (algebraic least
squares, Kasa 1976), which finds the axis from a partial arc, and then grows the radius until it
covers every point: a conservative shape is the safe one for collision avoidance. The box fit
takes the yaw of the minimum-area footprint rectangle, so it covers what was seen, never more.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from lano3dp.errors import EmptyCloudError
from lano3dp.guidance.costs import Cylinder, OrientedBox, obstacle_axis_xy
from lano3dp.guidance.settings import SAFETY_MARGIN


def _finite_points(points, min_points: int) -> np.ndarray:
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[-1] != 3:
        raise ValueError(f"obstacle points must be (N, 3), got shape {points.shape}")
    points = points[np.isfinite(points).all(-1)]
    if len(points) < min_points:
        raise EmptyCloudError(f"cannot fit an obstacle to {len(points)} finite points; need at least {min_points}")
    return points


def fit_circle_xy(xy: np.ndarray) -> tuple[np.ndarray, float] | None:
    """Least-squares circle through (N, 2) points; None when the points are (nearly) collinear."""
    design = np.column_stack([xy, np.ones(len(xy))])
    target = -(xy**2).sum(-1)
    solution, _, rank, singular = np.linalg.lstsq(design, target, rcond=None)
    if rank < 3 or singular[-1] < 1e-9 * singular[0]:
        return None
    center = -solution[:2] / 2
    radius_sq = center @ center - solution[2]
    return (center, float(np.sqrt(radius_sq))) if radius_sq > 0 else None


def fit_cylinder(points, *, min_points: int = 10, held_radius: float = 0.0, margin: float = SAFETY_MARGIN,
                 xy_only: bool = True, coverage: float = 1.0) -> Cylinder:
    """A vertical cylinder around an obstacle's points.

    Args:
        points: (N, 3) world frame, m.
        min_points: fewer finite points raise EmptyCloudError.
        coverage: fraction of points the radius must cover (1.0 = all; 0.98 drops stray outliers).

    Returns:
        Cylinder with the axis from a circle fit (or the centroid when the points do not look like an
        arc), radius covering `coverage` of the points, z range from the points' min to max.
    """
    points = _finite_points(points, min_points)
    xy = points[:, :2]
    centroid = xy.mean(0)
    spread = np.linalg.norm(xy - centroid, axis=1).max()
    center = centroid
    circle = fit_circle_xy(xy)
    # A flat face or a blob gives a circle far larger than the cloud or centred far from it; only
    # trust the fit when it is the size of the cloud.
    if circle is not None and circle[1] <= 2 * spread + 1e-6 and np.linalg.norm(circle[0] - centroid) <= 2 * spread:
        center = circle[0]
    radius = float(np.quantile(np.linalg.norm(xy - center, axis=1), coverage))
    radius = max(radius, 1e-3)  # a single column of points still has some size
    # A camera that sees only a flat top gives no height; as in fit_box, keep at least 2 mm.
    z_mid, z_half = (points[:, 2].max() + points[:, 2].min()) / 2, max(np.ptp(points[:, 2]) / 2, 1e-3)
    return Cylinder(center.tolist(), radius, z_min=float(z_mid - z_half), z_max=float(z_mid + z_half),
                    xy_only=xy_only, held_radius=held_radius, margin=margin)


def fit_box(points, *, min_points: int = 10, held_radius: float = 0.0, margin: float = SAFETY_MARGIN,
            xy_only: bool = False, angle_resolution_deg: float = 0.5) -> OrientedBox:
    """A yaw-only oriented box: the minimum-area footprint rectangle and the points' z range.

    A brute-force search over yaw in [0, 90) degrees (a rectangle repeats every 90); at 0.5 degree
    resolution that is 180 projections of N points, cheap next to segmentation, and simpler and
    sturdier than rotating calipers on a hull.
    """
    points = _finite_points(points, min_points)
    xy = points[:, :2]
    angles = np.deg2rad(np.arange(0.0, 90.0, angle_resolution_deg))
    cos, sin = np.cos(angles), np.sin(angles)
    # coordinates of every point in every candidate box frame: (A, N)
    u = cos[:, None] * xy[None, :, 0] + sin[:, None] * xy[None, :, 1]
    v = -sin[:, None] * xy[None, :, 0] + cos[:, None] * xy[None, :, 1]
    areas = (u.max(1) - u.min(1)) * (v.max(1) - v.min(1))
    best = int(np.argmin(areas))
    yaw = float(angles[best])
    u_mid, v_mid = (u[best].max() + u[best].min()) / 2, (v[best].max() + v[best].min()) / 2
    half = np.array([(u[best].max() - u[best].min()) / 2, (v[best].max() - v[best].min()) / 2,
                     (points[:, 2].max() - points[:, 2].min()) / 2])
    half = np.maximum(half, 1e-3)
    center_xy = np.array([np.cos(yaw) * u_mid - np.sin(yaw) * v_mid, np.sin(yaw) * u_mid + np.cos(yaw) * v_mid])
    center = [float(center_xy[0]), float(center_xy[1]), float((points[:, 2].max() + points[:, 2].min()) / 2)]
    return OrientedBox(center, half.tolist(), yaw, xy_only=xy_only, held_radius=held_radius, margin=margin)


def bridge_narrow_gaps(obstacles, passable: float) -> list[OrientedBox]:
    """Walls across every gap narrower than `passable` (m) between two fitted obstacles (beyond the paper).

    Each obstacle pushes a path straight away from itself, so in the gap between two close ones the pushes
    cancel: the network keeps aiming through a gap the hand cannot pass and the runtime holds the hand still at
    its mouth (most two-obstacle failures were this "path blocked" hold). A wall from one axis to the other,
    no wider than the thinner obstacle, fills that gap and nothing else (it lies inside the pair's hull), so the
    push carries the path out of the gap and, turned (`TurnedPush`), round the pair's end. Only obstacles
    measured in the horizontal plane are bridged: a 3-D one may be passed over.

    Args:
        obstacles: fitted obstacle costs with an `xy_only` flag and a horizontal middle (`obstacle_axis_xy`).
        passable: the narrowest gap between two obstacle surfaces the moving body can pass, m.

    Returns:
        One `OrientedBox` (xy_only) per bridged pair, carrying the smaller held radius and margin of the two.
    """
    walls = []
    axes = [(o, obstacle_axis_xy(o)) for o in obstacles if getattr(o, "xy_only", False)]
    flat = [(o, axis.double()) for o, axis in axes if axis is not None]
    for index, (first, axis_a) in enumerate(flat):
        for second, axis_b in flat[index + 1:]:
            between = float(torch.linalg.norm(axis_b - axis_a))
            if between < 1e-6:
                continue
            # each obstacle's reach towards the other along the line of axes (a cylinder's: its radius)
            reach_a = between - float(first.surface_distance(torch.cat([axis_b, axis_b.new_zeros(1)])[None]))
            reach_b = between - float(second.surface_distance(torch.cat([axis_a, axis_a.new_zeros(1)])[None]))
            if between - reach_a - reach_b >= passable:
                continue
            half_width = min(reach_a, reach_b)
            if half_width <= 0:
                continue
            middle = (axis_a + axis_b) / 2
            direction = axis_b - axis_a
            walls.append(OrientedBox([float(middle[0]), float(middle[1]), 0.0], [between / 2, half_width, 1.0],
                                     math.atan2(float(direction[1]), float(direction[0])), xy_only=True,
                                     held_radius=min(first.held_radius, second.held_radius),
                                     margin=min(first.margin, second.margin)))
    return walls
