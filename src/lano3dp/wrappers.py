"""Env wrappers that adapt a user's environment to the policy's action contract.

lano3dp policies (and the experts they learn from) emit absolute end-effector actions, (10,): position (3, m,
world frame), rotation 6D (6, the first two columns of the rotation matrix), gripper (1, 0 open .. 1 closed).
Many simulators and robot drivers take a step's change instead; `AbsoluteActions` computes that change from
the state the env last reported (obs["state"] (11,): EE position, rotation 6D, gripper opening, grasp flag).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal

import numpy as np

from lano3dp.geometry.rotations import matrix_to_rot6d, rot6d_to_matrix


def rotation_to_axis_angle(rotation: np.ndarray) -> np.ndarray:
    """(3, 3) rotation -> (3,) axis * angle (rad), angle in [0, pi] (the matrix logarithm)."""
    rotation = np.asarray(rotation, dtype=np.float64)
    cos = np.clip((np.trace(rotation) - 1.0) / 2.0, -1.0, 1.0)
    angle = float(np.arccos(cos))
    skew = np.array([rotation[2, 1] - rotation[1, 2], rotation[0, 2] - rotation[2, 0], rotation[1, 0] - rotation[0, 1]])
    if angle < 1e-6:
        return skew / 2.0  # first order: R = I + [w]x
    if np.pi - angle < 1e-4:  # near a half turn the skew part vanishes: the axis is R + I's largest column
        column = rotation + np.eye(3)
        axis = column[:, int(np.argmax(np.linalg.norm(column, axis=0)))]
        return axis / np.linalg.norm(axis) * angle
    return skew / (2.0 * np.sin(angle)) * angle


class AbsoluteActions:
    """Drive an env that takes delta actions with the absolute (10,) actions a lano3dp policy emits.

    The delta sent is target - current from the latest obs["state"]: position target - position (3, m) and the
    rotation taking the current orientation to the target's, as axis-angle (3, rad) or 6D (6); the gripper value
    passes through `gripper`. All other attributes (frame, control_hz, max_steps, ...) are the wrapped env's.

    Args:
        env: an env whose step takes [position delta, rotation delta, gripper] and whose obs holds "state" (11,).
        rotation: "axis_angle" (3 values), "rot6d" (6 values) or "none" (the env takes no rotation).
        frame: "world" (deltas in the world frame) or "ee" (in the end effector's current frame).
        position_scale, rotation_scale: the delta is multiplied by these (an env that takes a normalised
            command, e.g. metres / 0.05).
        max_position_delta: m; a longer position delta is shortened to this (None: as computed).
        gripper: maps the policy's gripper value (0 open .. 1 closed) to the env's (default: unchanged).
    """

    def __init__(self, env, *, rotation: Literal["axis_angle", "rot6d", "none"] = "axis_angle",
                 frame: Literal["world", "ee"] = "world", position_scale: float = 1.0, rotation_scale: float = 1.0,
                 max_position_delta: float | None = None, gripper: Callable[[float], float] | None = None):
        if rotation not in ("axis_angle", "rot6d", "none"):
            raise ValueError(f"rotation must be 'axis_angle', 'rot6d' or 'none', got {rotation!r}")
        if frame not in ("world", "ee"):
            raise ValueError(f"frame must be 'world' or 'ee', got {frame!r}")
        self.env = env
        self.rotation, self.frame = rotation, frame
        self.position_scale, self.rotation_scale = float(position_scale), float(rotation_scale)
        self.max_position_delta = max_position_delta
        self.gripper = gripper
        self._state: np.ndarray | None = None

    def __getattr__(self, name: str):
        if name == "env":  # not set yet (unpickling): no recursion
            raise AttributeError(name)
        return getattr(self.env, name)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._state = self._read_state(obs, "reset()")
        return obs, info

    def step(self, action):
        if self._state is None:
            raise RuntimeError("AbsoluteActions: call reset() before step()")
        obs, reward, terminated, truncated, info = self.env.step(self.delta(action))
        self._state = self._read_state(obs, "step()")
        return obs, reward, terminated, truncated, info

    def delta(self, action) -> np.ndarray:
        """The wrapped env's action for an absolute (10,) one, from the last state: (3 + 3|6|0 + 1,) float32."""
        action = np.asarray(action, dtype=np.float64)
        if action.shape != (10,):
            raise ValueError(f"AbsoluteActions takes (10,) absolute actions (position, rotation 6D, gripper), "
                             f"got {action.shape}")
        current = rot6d_to_matrix(self._state[3:9])
        position = action[:3] - self._state[:3]
        if self.max_position_delta is not None:
            length = np.linalg.norm(position)
            if length > self.max_position_delta:
                position *= self.max_position_delta / length
        turn = rot6d_to_matrix(action[3:9]) @ current.T  # world frame: target = turn @ current
        if self.frame == "ee":
            position, turn = current.T @ position, current.T @ turn @ current
        parts = [position * self.position_scale]
        if self.rotation == "axis_angle":
            parts.append(rotation_to_axis_angle(turn) * self.rotation_scale)
        elif self.rotation == "rot6d":
            parts.append(matrix_to_rot6d(turn))
        grip = float(action[9]) if self.gripper is None else self.gripper(float(action[9]))
        parts.append(np.atleast_1d(grip))
        return np.concatenate(parts).astype(np.float32)

    @staticmethod
    def _read_state(obs, call: str) -> np.ndarray:
        state = obs.get("state") if hasattr(obs, "get") else getattr(obs, "state", None)
        if state is None:
            raise KeyError(f"AbsoluteActions: the env's {call} observation has no 'state' (11,)")
        state = np.asarray(state, dtype=np.float64)
        if state.shape != (11,):
            raise ValueError(f"AbsoluteActions: obs['state'] must be (11,), got {state.shape}")
        return state

    def close(self) -> None:
        close = getattr(self.env, "close", None)
        if callable(close):
            close()
