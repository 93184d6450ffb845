"""A goal-conditioned MuJoCo task of the test suite's own: move the hand to a goal drawn anew every episode.

The goal is a site, which renders nothing, so no camera frame shows it: the env hands it over as obs["goal"] (3,),
metres, world frame, as Gymnasium-Robotics' Fetch tasks and Meta-World do. A grey base block sits on the table for
the policy's one object slot. The hand (a mocap point) moves at most 5 cm a step towards the absolute action's
position; the episode succeeds when it is within 4 cm of the goal.
"""

from __future__ import annotations

import mujoco
import numpy as np

from lano3dp.geometry.rotations import matrix_to_rot6d
from lano3dp.mujoco_frame import mujoco_frame

SCENE = """
<mujoco>
  <visual><global offwidth="64" offheight="64"/></visual>
  <worldbody>
    <light pos="0 0 1.5" dir="0 0 -1"/>
    <camera name="front" pos="0.6 0 0.6" xyaxes="0 1 0 -0.707 0 0.707" fovy="55"/>
    <geom name="table" type="box" size="0.4 0.4 0.02" pos="0 0 -0.02" rgba="0.8 0.7 0.6 1"/>
    <body name="base" pos="0.05 0.25 0.04"><geom type="box" size="0.06 0.06 0.04" rgba="0.5 0.5 0.5 1"/></body>
    <body name="hand" mocap="true" pos="0 0 0.3">
      <geom type="sphere" size="0.015" rgba="0.2 0.2 0.2 1" contype="0" conaffinity="0"/>
    </body>
    <site name="goal" pos="0 0 0.2" size="0.02" rgba="0 1 0 0.5"/>
  </worldbody>
</mujoco>
"""
GOAL_LOW, GOAL_HIGH = np.array([-0.1, -0.15, 0.05]), np.array([0.15, 0.15, 0.25])
STEP, REACHED = 0.05, 0.04  # m


class GoalReachEnv:
    """reset(seed) -> (obs, info); step(action (10,) absolute: position (m), rotation 6D, gripper)."""

    control_hz = 10.0

    def __init__(self, image_size: int = 32, max_steps: int = 20):
        self.model = mujoco.MjModel.from_xml_string(SCENE)
        self.data = mujoco.MjData(self.model)
        self.renderer = mujoco.Renderer(self.model, image_size, image_size)
        self.image_size, self.max_steps, self.steps = image_size, max_steps, 0

    @property
    def goal(self) -> np.ndarray:
        return self.model.site("goal").pos.copy()

    def reset(self, *, seed=None, options=None):
        rng = np.random.default_rng(seed)
        mujoco.mj_resetData(self.model, self.data)
        self.model.site("goal").pos[:] = rng.uniform(GOAL_LOW, GOAL_HIGH)
        self.data.mocap_pos[0] = rng.uniform([-0.05, -0.1, 0.2], [0.1, 0.1, 0.3])
        mujoco.mj_forward(self.model, self.data)
        self.steps = 0
        return self.observation(), self.info()

    def step(self, action):
        move = np.asarray(action[:3], dtype=np.float64) - self.data.mocap_pos[0]
        self.data.mocap_pos[0] += move * min(1.0, STEP / (np.linalg.norm(move) + 1e-12))
        mujoco.mj_forward(self.model, self.data)
        self.steps += 1
        info = self.info()
        return self.observation(), 0.0, False, self.steps >= self.max_steps, info

    def info(self) -> dict:
        return {"success": bool(np.linalg.norm(self.data.mocap_pos[0] - self.goal) < REACHED)}

    def observation(self) -> dict:
        state = np.r_[self.data.mocap_pos[0], matrix_to_rot6d(np.eye(3)), 0.08, 0.0].astype(np.float32)
        frame = mujoco_frame(self.model, self.data, "front", {"base": ["base"]}, self.image_size, self.image_size,
                             self.renderer, rgb=False)
        return {"state": state, "frame": frame, "goal": self.goal.astype(np.float32)}

    def close(self):
        self.renderer.close()


def make_env(image_size=32, max_steps=None, **options):
    return GoalReachEnv(image_size, max_steps or 20)


def reach_expert(env, obs, info):
    """Closed loop: 4 cm a step straight at the goal the observation holds."""
    hand, goal = obs["state"][:3], obs["goal"]
    way = goal - hand
    way *= min(1.0, 0.04 / (np.linalg.norm(way) + 1e-12))
    return np.r_[hand + way, matrix_to_rot6d(np.eye(3)), 0.0].astype(np.float32)
