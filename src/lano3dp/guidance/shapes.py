"""Obstacle shapes as a registry: one object per shape owns how it is fitted, described and drawn.

    fit(points (N, 3) m, *, held_radius, margin, xy_only) -> a `costs.Obstacle` (None: too few points)
    describe(obstacle)                                    -> one line (str) for results and logs
    plot_data(obstacle)                                   -> plain numbers (dict) for results JSON and for draw()
    draw(ax, data, *, label=None)                         -> the artists it added to a top-view (x, y) Axes

`draw` takes the plain data, not the cost, because top views are drawn from results (`report.plot_top_view`), also
from results JSON read back later. Built in: "cylinder" (the paper), "box" and "points". A new shape is one class
and one call, from any module imported before it is used (for `lano3dp eval`/`run`: e.g. the `--env` module, which
the CLI imports before it checks `--obstacle-shape`):

    class Ball(ObstacleShape):
        def fit(self, points, *, held_radius, margin, xy_only): ...
    register_obstacle_shape("ball", Ball())     # then --set guidance.obstacles.shape=ball

This module imports neither torch nor matplotlib when it is imported (the built-in shapes do inside their methods),
so the CLI can list the registered names in its --help cheaply.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping
from typing import Any

from lano3dp.errors import EmptyCloudError
from lano3dp.guidance.exceptions import GuidanceError
from lano3dp.guidance.settings import SAFETY_MARGIN
from lano3dp.registry import Registry

OBSTACLE_COLOR = "tab:red"


class UnknownObstacleShapeError(GuidanceError):
    """No obstacle shape is registered under that name."""


class ObstacleShape(ABC):
    """One obstacle shape. Subclass it, implement `fit`, and usually `plot_data` and `draw`; register an instance.

    The defaults describe an obstacle by its repr, record no numbers and draw nothing (as the "points" shape).
    """

    @abstractmethod
    def fit(self, points, *, held_radius: float, margin: float, xy_only: bool):
        """(N, 3) world-frame points (m) -> an obstacle cost whose safety distance includes `held_radius` and
        `margin` (m), distances in the horizontal plane only when `xy_only`; None when the points are too few."""

    def describe(self, obstacle) -> str:
        """One line saying what was fitted (results JSON, logs)."""
        return repr(obstacle)

    def plot_data(self, obstacle) -> dict[str, Any]:
        """Plain JSON numbers (m) of a fitted obstacle: what `draw` needs to draw it again from saved results."""
        return {}

    def draw(self, ax, data: Mapping[str, Any], *, label: str | None = None) -> list:
        """Draw one obstacle, from `plot_data`'s numbers, on a top-view (x, y) Axes; returns the artists added.
        `label` names the obstacle in the legend (given to the first obstacle only)."""
        return []


def _rounded(values) -> list[float]:
    return [round(float(v), 5) for v in values]


class CylinderShape(ObstacleShape):
    """The paper's: a vertical cylinder (circle fit of the xy points, radius covering all of them)."""

    def fit(self, points, *, held_radius, margin, xy_only):
        from lano3dp.guidance.fitting import fit_cylinder

        return fit_cylinder(points, held_radius=held_radius, margin=margin, xy_only=xy_only)

    def describe(self, obstacle) -> str:
        x, y = obstacle.center.tolist()
        return (f"vertical cylinder at ({x:.3f}, {y:.3f}) m, radius {100 * obstacle.radius:.1f} cm, "
                f"Q* {100 * obstacle.safety_distance:.1f} cm")

    def plot_data(self, obstacle) -> dict[str, Any]:
        return {"center": _rounded(obstacle.center), "radius": round(obstacle.radius, 5),
                "safety_distance": round(obstacle.safety_distance, 5)}

    def draw(self, ax, data, *, label=None) -> list:
        from matplotlib.patches import Circle

        center = data["center"][:2]
        body = Circle(center, data["radius"], color=OBSTACLE_COLOR, alpha=0.45, label=label)
        # one dashed circle at Q*, so a plot shows how close guidance lets the held object come
        safety = Circle(center, data["safety_distance"], fill=False, ls="--", color=OBSTACLE_COLOR,
                        label="safety distance Q*" if label is not None else None)
        return [ax.add_patch(body), ax.add_patch(safety)]


class BoxShape(ObstacleShape):
    """A yaw-oriented box: the minimum-area footprint rectangle and the points' z range."""

    def fit(self, points, *, held_radius, margin, xy_only):
        from lano3dp.guidance.fitting import fit_box

        return fit_box(points, held_radius=held_radius, margin=margin, xy_only=xy_only)

    def describe(self, obstacle) -> str:
        x, y = obstacle.center[:2].tolist()
        hx, hy, _ = obstacle.half_extents.tolist()
        return (f"box at ({x:.3f}, {y:.3f}) m, footprint {200 * hx:.1f} x {200 * hy:.1f} cm, "
                f"yaw {math.degrees(obstacle.yaw):.0f} deg")

    def plot_data(self, obstacle) -> dict[str, Any]:
        return {"center": _rounded(obstacle.center[:2]), "corners": obstacle.corners_xy().tolist(),
                "half_extents": _rounded(obstacle.half_extents)}

    def draw(self, ax, data, *, label=None) -> list:
        import numpy as np
        from matplotlib.patches import Polygon

        return [ax.add_patch(Polygon(np.asarray(data["corners"]), color=OBSTACLE_COLOR, alpha=0.45, label=label))]


class PointsShape(ObstacleShape):
    """No shape assumed: the distance to the nearest segmented point. Too many numbers for results, so none are
    kept and top views draw nothing for it."""

    def fit(self, points, *, held_radius, margin, xy_only):
        from lano3dp.guidance.costs import PointCloudObstacle

        return PointCloudObstacle(points, held_radius=held_radius, margin=margin, xy_only=xy_only)

    def describe(self, obstacle) -> str:
        return f"{len(obstacle.points)} segmented points, each a ball of {100 * obstacle.point_radius:.1f} cm"


_REGISTRY: Registry[ObstacleShape] = Registry("obstacle shape", UnknownObstacleShapeError,
                                              ("fit", "describe", "plot_data", "draw"),
                                              "lano3dp.guidance.ObstacleShape")
for _name, _shape in (("cylinder", CylinderShape()), ("box", BoxShape()), ("points", PointsShape())):
    _REGISTRY.register(_name, _shape)
BUILTIN_OBSTACLE_SHAPES = _REGISTRY.mark_builtin()
# The cost classes the built-in shapes fit: an obstacle described without naming its shape gets the one of its class.
_BUILTIN_BY_COST = {"Cylinder": "cylinder", "OrientedBox": "box", "PointCloudObstacle": "points"}


def register_obstacle_shape(name: str, shape, *, replace: bool = False) -> ObstacleShape:
    """Make `shape` (an ObstacleShape, or a class of one taking no arguments) available as `name`: to
    `ObstacleSettings(shape=name)` and `--set guidance.obstacles.shape=name` (same-class re-registration
    replaces; another class needs `replace=True`)."""
    return _REGISTRY.register(name, shape, replace=replace)


def unregister_obstacle_shape(name: str) -> None:
    """Remove a registered shape (the built-in ones stay: configs default to them)."""
    _REGISTRY.unregister(name)


def obstacle_shape_names() -> tuple[str, ...]:
    """Registered names, built-in ones first, then in the order they were registered."""
    return _REGISTRY.names()


def get_obstacle_shape(name: str) -> ObstacleShape:
    """The shape registered as `name`; UnknownObstacleShapeError naming the registered ones otherwise."""
    return _REGISTRY.get(name)


def shape_for_workers(name: str) -> dict[str, bytes]:
    """{name: pickled shape} for a user's shape, {} for a built-in one (spawned workers know the built-ins)."""
    return _REGISTRY.worker_payload(name)


def fit_obstacle(name: str, points, *, held_radius: float = 0.0, margin: float = SAFETY_MARGIN, xy_only: bool = True):
    """Fit the shape registered as `name` to (N, 3) world points (m) and check what it returns.

    Raises:
        EmptyCloudError: the shape found too few points (it returned None, or raised it itself), which the
            runner handles as it handles a cloud perception lost (keep the last fit, or end the episode).
        TypeError: the shape returned something that is not a position cost.
    """
    from lano3dp.guidance.costs import PositionCost

    cost = get_obstacle_shape(name).fit(points, held_radius=held_radius, margin=margin, xy_only=xy_only)
    if cost is None:
        raise EmptyCloudError(f"obstacle shape {name!r} cannot fit an obstacle to {len(points)} points")
    if not isinstance(cost, PositionCost):
        raise TypeError(f"obstacle shape {name!r} fitted a {type(cost).__name__}, not a cost with clearance() and "
                        "__call__() (see lano3dp.guidance.costs.Obstacle)")
    return cost


def describe_obstacle(obstacle, shape: str | None = None) -> dict[str, Any]:
    """A fitted obstacle as plain data (results JSON and top views): its cost class ("shape"), repr, the numbers
    its shape keeps (centre, size, safety distance; m), the registered shape ("kind") and a one-line
    "description". `shape` None: the built-in shape that fits the obstacle's class, if any."""
    data: dict[str, Any] = {"shape": type(obstacle).__name__, "repr": repr(obstacle)}
    name = shape if shape is not None else _BUILTIN_BY_COST.get(type(obstacle).__name__)
    if name is None:
        return {**data, "description": repr(obstacle)}
    owner = get_obstacle_shape(name)
    return {**data, **owner.plot_data(obstacle), "kind": name, "description": owner.describe(obstacle)}


def shape_of(data: Mapping[str, Any]) -> ObstacleShape | None:
    """The shape that draws `describe_obstacle` data: the registered one its "kind" names (None for data without
    one, or a shape this process has not registered: a plug-in not imported is not guessed at). Descriptions saved
    before obstacles named their kind are converted by `lano3dp migrate`."""
    kind = data.get("kind")
    return _REGISTRY.get(kind) if kind in _REGISTRY.names() else None


def draw_obstacle(ax, data: Mapping[str, Any], *, label: str | None = None) -> list:
    """Draw one `describe_obstacle` result on a top-view Axes with its shape's `draw` (nothing when no registered
    shape knows it); returns the artists added."""
    shape = shape_of(data)
    return [] if shape is None else list(shape.draw(ax, data, label=label) or [])
