"""Shared motion primitives for scripted experts: timed waypoints turned into absolute actions.

An expert is a `MotionPlan`: a start pose plus segments (move to a pose, hold), each
lasting a number of control steps derived from a speed limit. `plan.actions()` gives the
(T, 10) absolute actions (position, rotation 6D, gripper) the env consumes, and
`plan.path()` the waypoint positions (the expert's nominal path, used to place obstacles
on it). Positions follow a smoothstep profile inside each segment (zero velocity at every
waypoint, so a grasped object is never jerked); rotations are slerped.

Typical pick:

    plan = MotionPlan(HOME_POSITION, top_down())
    plan.grasp(grasp_position, grasp_rotation)           # above, descend, close, lift
    plan.move_to(place_position + [0, 0, 0.1])
    plan.move_to(place_position).release().retreat()
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lano3dp.geometry.rotations import matrix_to_quat, matrix_to_rot6d, quat_to_matrix, slerp

CONTROL_HZ = 10.0
OPEN, CLOSED = 0.0, 1.0


def rotation_angle(r0: np.ndarray, r1: np.ndarray) -> float:
    """Angle (rad) of the relative rotation r0^T r1."""
    cos = (np.trace(r0.T @ r1) - 1.0) / 2.0
    return float(np.arccos(np.clip(cos, -1.0, 1.0)))


@dataclass
class Segment:
    position: np.ndarray  # (3,) target at the end of the segment, metres
    rotation: np.ndarray  # (3, 3)
    gripper: float
    steps: int


class MotionPlan:
    """Piecewise-smooth EE trajectory with a gripper command, at `control_hz`."""

    def __init__(self, position, rotation, gripper: float = OPEN, control_hz: float = CONTROL_HZ,
                 speed: float = 0.25, angular_speed: float = 1.5):
        self.start = Segment(np.asarray(position, float), np.asarray(rotation, float), gripper, 0)
        self.segments: list[Segment] = []
        self.control_hz = control_hz
        self.speed = speed                  # m/s
        self.angular_speed = angular_speed  # rad/s

    @property
    def last(self) -> Segment:
        return self.segments[-1] if self.segments else self.start

    def move_to(self, position, rotation=None, gripper: float | None = None, speed: float | None = None,
                min_steps: int = 2) -> MotionPlan:
        """Move in a straight line (smoothstep) to `position`, keeping rotation/gripper unless given."""
        last = self.last
        position = np.asarray(position, float)
        rotation = last.rotation if rotation is None else np.asarray(rotation, float)
        gripper = last.gripper if gripper is None else gripper
        duration = max(np.linalg.norm(position - last.position) / (speed or self.speed),
                       rotation_angle(last.rotation, rotation) / self.angular_speed)
        steps = max(min_steps, int(np.ceil(duration * self.control_hz * 1.5)))  # 1.5: smoothstep peak speed
        self.segments.append(Segment(position, rotation, gripper, steps))
        return self

    def hold(self, steps: int, gripper: float | None = None) -> MotionPlan:
        last = self.last
        self.segments.append(Segment(last.position, last.rotation, last.gripper if gripper is None else gripper,
                                     int(steps)))
        return self

    def grasp(self, position, rotation, approach: float = 0.10, lift: float = 0.12, close_steps: int = 6,
              descend_speed: float = 0.15) -> MotionPlan:
        """Go above `position` with the gripper open, descend along the approach axis, close, lift."""
        position, rotation = np.asarray(position, float), np.asarray(rotation, float)
        above = position - rotation[:, 2] * approach
        self.move_to(above, rotation, gripper=OPEN)
        self.move_to(position, speed=descend_speed)
        self.hold(close_steps, gripper=CLOSED)
        self.move_to(position + np.array([0.0, 0.0, lift]), speed=descend_speed)
        return self

    def release(self, steps: int = 5) -> MotionPlan:
        return self.hold(steps, gripper=OPEN)

    def retreat(self, height: float = 0.10) -> MotionPlan:
        """Back off along the approach axis (up for a top-down grasp)."""
        last = self.last
        return self.move_to(last.position - last.rotation[:, 2] * height, gripper=OPEN)

    # ---- outputs -------------------------------------------------------------------------
    def actions(self) -> np.ndarray:
        """(T, 10) float32 absolute actions: position (3), rotation 6D (6), gripper (1)."""
        rows = []
        previous = self.start
        for segment in self.segments:
            q0, q1 = matrix_to_quat(previous.rotation), matrix_to_quat(segment.rotation)
            for k in range(1, segment.steps + 1):
                u = k / segment.steps
                s = u * u * (3 - 2 * u)
                position = previous.position + s * (segment.position - previous.position)
                rotation = quat_to_matrix(slerp(q0, q1, s))
                rows.append(np.concatenate([position, matrix_to_rot6d(rotation), [segment.gripper]]))
            previous = segment
        return np.asarray(rows, dtype=np.float32)

    def path(self) -> np.ndarray:
        """(M, 3) waypoint positions including the start: the expert's nominal path."""
        return np.array([self.start.position] + [s.position for s in self.segments])

    def __len__(self) -> int:
        return sum(s.steps for s in self.segments)


class PlanFollower:
    """Replays a plan's actions; after the last one it keeps repeating it (the env decides when to stop)."""

    def __init__(self, plan: MotionPlan):
        self.plan = plan
        self._actions = plan.actions()
        self._t = 0

    def __call__(self, observation=None) -> np.ndarray:
        action = self._actions[min(self._t, len(self._actions) - 1)]
        self._t += 1
        return action.copy()

    @property
    def done(self) -> bool:
        return self._t >= len(self._actions)
