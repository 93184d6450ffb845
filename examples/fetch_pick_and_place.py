"""Gymnasium-Robotics' FetchPickAndPlace-v4 in `lano3dp collect / train / eval`: the goal as obs["goal"].

    python -m venv .venv-fetch && . .venv-fetch/bin/activate
    pip install lano3dp gymnasium-robotics "mujoco==3.3.0"   # Gymnasium-Robotics 1.4.2 fails on 3.17 and 4.x
    # (CPU-only torch: add --extra-index-url https://download.pytorch.org/whl/cpu)
    lano3dp collect --env examples/fetch_pick_and_place.py:make_env --expert examples/fetch_pick_and_place.py:expert \
        --slots block --task fetch_pick_place --episodes 40 --out fetch.zarr
    lano3dp train --data fetch.zarr --out runs/fetch --minutes 10
    lano3dp eval --env examples/fetch_pick_and_place.py:make_env --checkpoint runs/fetch --episodes 20

Fetch moves its gripper by deltas of at most 5 cm a step (action * 0.05 m, `AbsoluteActions`) and opens it with a
positive command. The block is the geom "object0", seen by a free camera across the table; the goal
("target0") is a site that no camera frame shows, so it comes in as obs["goal"]. Success is Fetch's own
info["is_success"] (the block within 5 cm of the goal). docs/own-environment-fetch.md walks through this file.
"""

import gymnasium as gym
import gymnasium_robotics
import mujoco
import numpy as np

from lano3dp.geometry.rotations import matrix_to_rot6d
from lano3dp.mujoco_frame import mujoco_frame
from lano3dp.wrappers import AbsoluteActions

gym.register_envs(gymnasium_robotics)


class FetchPickAndPlace:
    control_hz = 25.0

    def __init__(self, image_size=96, max_steps=50):
        self.env = gym.make("FetchPickAndPlace-v4", max_episode_steps=max_steps)
        self.model, self.data = self.env.unwrapped.model, self.env.unwrapped.data
        self.max_steps, self.size = max_steps, image_size
        self.camera = mujoco.MjvCamera()  # the model's cameras ride on the robot: look at the table from across it
        self.camera.lookat, self.camera.distance, self.camera.azimuth, self.camera.elevation = [1.3, 0.75, 0.5], 1.0, \
            180.0, -45.0
        self.renderer = mujoco.Renderer(self.model, image_size, image_size)

    def observation(self, raw):
        grip = self.data.site("robot0:grip").xmat.reshape(3, 3)
        state = np.r_[raw["observation"][:3], matrix_to_rot6d(grip), raw["observation"][9:11].sum(), 0.0]
        frame = mujoco_frame(self.model, self.data, self.camera, {"block": ["object0"]}, self.size, self.size,
                             self.renderer)
        return {"state": state.astype(np.float32), "frame": frame, "goal": raw["desired_goal"].astype(np.float32)}

    def reset(self, *, seed=None, options=None):
        raw, _ = self.env.reset(seed=seed)
        return self.observation(raw), {"success": False}

    def step(self, action):
        raw, reward, terminated, truncated, info = self.env.step(np.clip(action, -1, 1))
        return self.observation(raw), reward, terminated, truncated, {"success": bool(info["is_success"])}

    def close(self):
        self.renderer.close()
        self.env.close()


def make_env(image_size=96, max_steps=None, **options):
    return AbsoluteActions(FetchPickAndPlace(image_size, max_steps or 50), rotation="none", position_scale=20.0,
                           max_position_delta=0.05, gripper=lambda g: 1 - 2 * g)


def expert(env, obs, info):
    """Closed loop: above the block, down, close, then carry it to the goal."""
    grip, opening, goal = obs["state"][:3], obs["state"][9], obs["goal"]
    block = env.data.body("object0").xpos
    if opening < 0.06 and np.linalg.norm(block - grip) < 0.03:  # closed on the block: carry it
        target, closed = goal, 1.0
    elif np.linalg.norm(block[:2] - grip[:2]) > 0.01:  # over the block first, 6 cm above it
        target, closed = block + [0, 0, 0.06], 0.0
    else:  # down to it, closing once there
        target, closed = block, float(abs(grip[2] - block[2]) < 0.01)
    return np.r_[target, obs["state"][3:9], closed].astype(np.float32)
