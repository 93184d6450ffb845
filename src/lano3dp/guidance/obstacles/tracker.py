"""ObstacleTracker: the obstacles of one episode, from phrases to fitted shapes, and the body kept clear of them.

Obstacles become costs as in the paper: segment each obstacle and fit a vertical cylinder to its points
(`guidance.fitting.fit_cylinder`; `ObstacleSettings.shape` picks another registered shape). Every instance a
phrase matches is its own obstacle ("avoid the mugs" fits one cylinder per mug). What must keep clear is, by
default, the swept body: the hand as a row of balls along its finger axis plus the held object as a ball at its
fitted centre, re-measured before each chunk. The paper's model (`body="sphere"`) hinges the xy distance of every
waypoint at Q* = obstacle radius + held-object extent + margin, the extent measured from the held object's cloud.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from lano3dp.errors import EmptyCloudError
from lano3dp.geometry.frame import RGBDFrame
from lano3dp.guidance.costs import ObstacleSet, PositionCost, body_reach
from lano3dp.guidance.fitting import bridge_narrow_gaps, fit_cylinder
from lano3dp.guidance.obstacles.body import fit_obstacle_shape, hand_balls, passable_gap
from lano3dp.guidance.settings import ObstacleSettings
from lano3dp.perception.exceptions import PerceptionError
from lano3dp.perception.observer import ObjectObserver
from lano3dp.perception.views import OtherViews

GRASP_FLAG = 10  # index of the grasp flag in the 11-D robot state


class ObstacleTracker:
    """The fitted obstacles of one episode, the walls across gaps between them, and the body kept clear.

    Args:
        observer: segments the obstacles (and the held object) in a frame.
        settings: the shape, margin, body model, re-fitting and gap walls.
        views: the env's other cameras, where an obstacle hidden at its first fit is looked for.
    """

    def __init__(self, observer: ObjectObserver | None, settings: ObstacleSettings, views: OtherViews | None = None):
        self.observer = observer
        self.settings = settings
        self.views = views
        self.phrases: tuple[str, ...] = ()
        self.held_object: str | None = None
        self.reset()

    def reset(self) -> None:
        """Forget what was fitted and measured (a new episode, or new objects)."""
        self.obstacles: ObstacleSet | None = None
        self.walls: list[PositionCost] = []  # across gaps too narrow for the body (`settings.bridge_gaps`)
        self.held_radius: float | None = None  # m: the sphere's radius, or the swept body's reach
        self.held_ball: tuple[np.ndarray, float] | None = None  # (offset from the EE, radius) of the held object
        self.stale_fits = 0  # re-fits that kept the last fit because the camera saw too little of an obstacle

    def set_objects(self, phrases: Sequence[str], held_object: str | None) -> None:
        if phrases and self.observer is None:
            raise ValueError(f"obstacles {tuple(phrases)} need an observer to segment them")
        self.phrases, self.held_object = tuple(phrases), held_object or None
        self.obstacles, self.walls = None, []

    @property
    def guided(self) -> list[PositionCost]:
        """The fitted obstacles and the walls across gaps too narrow to pass: what guidance keeps clear of."""
        return list(self.obstacles) + self.walls

    def update(self, frame: RGBDFrame, step: int) -> None:
        """Before a chunk: fit the obstacles if not yet fitted, or re-fit them with `settings.refit` (keeping the
        last fit, counted in `stale_fits`, when the arm hides one now)."""
        if not self.phrases:
            return
        if self.obstacles is not None and not self.settings.refit:
            return
        try:
            self.obstacles = self._fit(frame, step)
        except (PerceptionError, EmptyCloudError):
            if self.obstacles is None:
                raise
            self.stale_fits += 1
            return
        self.walls = bridge_narrow_gaps(list(self.obstacles), passable_gap(self.settings, self.held_radius or 0.0)) \
            if self.settings.bridge_gaps else []

    def _fit(self, frame: RGBDFrame, step: int) -> ObstacleSet:
        """Segment every obstacle phrase and fit its shape. With the "sphere" body the shapes carry the held
        radius; with "swept" they are bare and the cost adds the body."""
        sphere = self.settings.body == "sphere"
        if sphere:
            self.held_radius = self._measure_held_radius(frame, step)
        try:
            clouds = list(self.observer.observe_instances(frame, self.phrases).points)
        except PerceptionError:
            if self.obstacles is not None:
                raise  # a re-fit: the caller keeps the last fit
            # the first fit: an obstacle hidden behind another is looked for in the other views
            clouds = [points for phrase in self.phrases
                      for points in self._observe_anywhere(frame, phrase, step, instances=True).points]
        return ObstacleSet([fit_obstacle_shape(self.settings, points, self.held_radius if sphere else 0.0)
                            for points in clouds])

    def _observe_anywhere(self, frame: RGBDFrame, phrase: str, step: int, instances: bool = False):
        if self.views is None:
            return (self.observer.observe_instances(frame, [phrase]) if instances
                    else self.observer.observe(frame, [phrase]))
        return self.views.observe_anywhere(frame, phrase, step=step, instances=instances)

    def _measure_held_radius(self, frame: RGBDFrame, step: int) -> float:
        """("sphere") metres around the EE point to keep clear: the held object's extent, at least the gripper's;
        measured before the grasp, when the obstacle may stand in front of it."""
        if self.settings.held_radius is not None:
            return float(self.settings.held_radius)
        if not self.held_object:
            return self.settings.gripper_radius
        points = self._observe_anywhere(frame, self.held_object, step).points[0]
        return max(self.settings.gripper_radius, self.settings.held_extent * fit_cylinder(points).radius)

    def body(self, frame: RGBDFrame, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """("swept") (K, 3) world offsets from the EE point and (K,) radii of what moves with it now: the hand,
        and the held object while the grasp flag is set (its last seen ball when the hand hides it)."""
        offsets, radii = hand_balls(self.settings, state[3:9])
        if not self.held_object or state[GRASP_FLAG] < 0.5:
            self.held_ball = None
        else:
            try:
                held = fit_cylinder(self.observer.observe(frame, [self.held_object]).points[0])
                offset = np.array([*held.center.tolist(), (held.z_min + held.z_max) / 2]) - state[:3]
                # a flag set while the named object is nowhere near the hand (another object is held, or the
                # env's flag is stale) must not drag a ball across the table with the hand
                near = np.linalg.norm(offset) - held.radius <= self.settings.hand_half_span
                self.held_ball = (offset, held.radius) if near else None
            except (PerceptionError, EmptyCloudError):
                pass  # keep the ball measured before the hand covered the object
            if self.held_ball is not None:
                offsets, radii = np.vstack([offsets, self.held_ball[0]]), np.append(radii, self.held_ball[1])
        self.held_radius = body_reach(offsets, radii)
        return offsets, radii
