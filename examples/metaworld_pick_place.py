"""Meta-World's pick-place-v3 in `lano3dp collect / train / eval`: a goal drawn every episode, as obs["goal"].

    python -m venv .venv-metaworld && . .venv-metaworld/bin/activate
    pip install lano3dp metaworld        # Meta-World pins mujoco==3.3.0, which lano3dp supports
    # (CPU-only torch: add --extra-index-url https://download.pytorch.org/whl/cpu)
    lano3dp collect --env examples/metaworld_pick_place.py:make_env --expert examples/metaworld_pick_place.py:expert \
        --slots puck --task pick_place --episodes 40 --out mw.zarr
    lano3dp train --data mw.zarr --out runs/mw --minutes 10 --time-stride 4   # 80 Hz env: plan at 20 Hz
    lano3dp eval --env examples/metaworld_pick_place.py:make_env --checkpoint runs/mw --episodes 20

The Sawyer's hand moves by deltas of at most 1 cm a step (`AbsoluteActions`), its gripper by an effort in
[-1 open, 1 closed]. The object slot "puck" is the body "obj" seen by a free camera; the goal is a site,
which no camera frame shows, so it comes in as obs["goal"]. Success is Meta-World's own info["success"]. The
expert is Meta-World's scripted policy, its delta actions read back as absolute targets. The policy trained on
the episodes takes obs["goal"] as they recorded it.
"""

import mujoco
import numpy as np
from metaworld.env_dict import ALL_V3_ENVIRONMENTS_GOAL_OBSERVABLE
from metaworld.policies import SawyerPickPlaceV3Policy

from lano3dp.geometry.rotations import matrix_to_rot6d
from lano3dp.mujoco_frame import mujoco_frame
from lano3dp.wrappers import AbsoluteActions

STEP = 0.01  # m of hand motion per unit of action (Meta-World's action_scale)


class PickPlace:
    control_hz = 80.0  # 5 physics steps of 2.5 ms

    def __init__(self, image_size=96, max_steps=200):
        self.env = ALL_V3_ENVIRONMENTS_GOAL_OBSERVABLE["pick-place-v3-goal-observable"]()
        self.env.max_path_length, self.max_steps, self.size = max_steps, max_steps, image_size
        self.camera = mujoco.MjvCamera()  # across the table from the robot, closer than the model's cameras
        self.camera.lookat, self.camera.distance, self.camera.azimuth, self.camera.elevation = [0, 0.7, 0.1], 0.9, \
            -90.0, -45.0
        self.env.model.vis.quality.offsamples = 0  # no multisampling: ~10x faster offscreen frames on a CPU
        self.renderer = mujoco.Renderer(self.env.model, image_size, image_size)

    def observation(self, raw):
        self.raw = raw  # the expert reads Meta-World's own (39,) observation
        model, data = self.env.model, self.env.data
        hand = data.body("hand").xmat.reshape(3, 3)
        state = np.r_[raw[:3], matrix_to_rot6d(hand), 0.1 * raw[3], 0.0].astype(np.float32)  # no grasp flag: 0
        frame = mujoco_frame(model, data, self.camera, {"puck": ["obj"]}, self.size, self.size, self.renderer)
        return {"state": state, "frame": frame, "goal": self.env._target_pos.astype(np.float32)}

    def reset(self, *, seed=None, options=None):
        self.env._freeze_rand_vec, self.env.seeded_rand_vec = False, True  # a new object and goal per seed
        self.env.seed(seed)
        raw, _ = self.env.reset()
        return self.observation(raw), {"success": False}

    def step(self, action):
        raw, reward, terminated, truncated, info = self.env.step(np.clip(action, -1, 1))
        return self.observation(raw), reward, terminated, truncated, {"success": bool(info["success"])}

    def close(self):
        self.renderer.close()
        self.env.close()


def make_env(image_size=96, max_steps=None, **options):
    return AbsoluteActions(PickPlace(image_size, max_steps or 200), rotation="none", position_scale=1 / STEP,
                           max_position_delta=STEP, gripper=lambda g: 2 * g - 1)


def expert(env, obs, info, policy=SawyerPickPlaceV3Policy()):
    delta = np.clip(policy.get_action(env.raw), -1, 1)
    return np.r_[obs["state"][:3] + STEP * delta[:3], obs["state"][3:9], (delta[3] + 1) / 2].astype(np.float32)
