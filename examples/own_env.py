"""Your own environment in `lano3dp eval` and `lano3dp run`: a toy "reach the block" scene, no lano3dp.sim.

    lano3dp eval --env examples/own_env.py:make_env --checkpoint RUN --episodes 5 --out own.json

The scene is plain numpy: a hand (a point that moves at most 5 cm a step), a red block and a grey post on a
table, seen by one calibrated camera ray-cast with `lano3dp.perception.synthetic.render_boxes` (depth, colour
and a ground-truth instance map, so the "sim" segmenter works; with a real camera use `--segmenter open-vocab`).
The episode succeeds when the hand is within 4 cm of the block's top. Replace the scene with your simulator or
robot driver; what lano3dp needs is below the GLUE line.
"""

from __future__ import annotations

import numpy as np

from lano3dp.geometry import RGBDFrame
from lano3dp.geometry.rotations import matrix_to_rot6d
from lano3dp.perception.synthetic import Box, render_boxes, top_down_camera


class ReachBlockScene:
    """A point hand over a table with a block to reach and a post to avoid (the user's own simulator).

    Args:
        image_size: camera resolution, pixels (square).
        max_steps: steps before the episode is cut off.
    """

    control_hz = 10.0
    step_limit = 0.05  # m per step, as a real arm's velocity limit
    block_size = (0.10, 0.10, 0.05)
    post_size = (0.06, 0.06, 0.25)

    def __init__(self, image_size: int = 64, max_steps: int = 30):
        self.camera = top_down_camera(size=image_size, height=0.9, fovy_deg=55.0, tilt_deg=25.0)
        self.max_steps = max_steps
        self.hand = np.zeros(3)
        self.gripper = 0.0
        self.boxes: list[Box] = []
        self.steps = 0

    def start(self, seed: int | None) -> None:
        rng = np.random.default_rng(seed)
        block_xy = (rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.15))
        post_xy = (block_xy[0] + rng.choice([-0.2, 0.2]), block_xy[1])
        self.boxes = [Box("block", block_xy, self.block_size, {"kind": "block", "color": "red"}),
                      Box("post", post_xy, self.post_size, {"kind": "post", "color": "grey", "role": "obstacle"})]
        self.hand = np.array([rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2), 0.3])
        self.gripper, self.steps = 0.0, 0

    def move(self, target: np.ndarray, gripper: float) -> None:
        delta = np.asarray(target, dtype=np.float64) - self.hand
        distance = np.linalg.norm(delta)
        if distance > self.step_limit:
            delta *= self.step_limit / distance
        self.hand = np.clip(self.hand + delta, [-0.5, -0.5, 0.0], [0.5, 0.5, 0.6])
        self.gripper = float(np.clip(gripper, 0.0, 1.0))
        self.steps += 1

    def reached(self) -> bool:
        block = self.boxes[0]
        top = np.array([*block.center_xy, block.size[2]])
        return bool(np.linalg.norm(self.hand - top) < 0.04)

    def post_clearance(self) -> float:
        """Distance (m) from the hand to the post's box."""
        post = self.boxes[1]
        return float(np.linalg.norm(np.maximum(np.maximum(post.low - self.hand, self.hand - post.high), 0.0)))

    def render(self) -> RGBDFrame:
        return render_boxes(self.camera, self.boxes)


# ---- GLUE: what lano3dp needs, the protocol of lano3dp.sim.protocol -------------------------------
class ReachBlockEnv:
    """reset(seed, options) -> (obs, info); step(action (10,)) -> (obs, reward, terminated, truncated, info)."""

    def __init__(self, scene: ReachBlockScene):
        self.scene, self.control_hz, self.max_steps = scene, scene.control_hz, scene.max_steps

    def observation(self) -> dict:
        state = np.r_[self.scene.hand, matrix_to_rot6d(np.eye(3)), 0.08 * (1 - self.scene.gripper), 0.0]
        return {"state": state.astype(np.float32), "frame": self.scene.render()}  # (11,), RGBDFrame

    def info(self) -> dict:
        clearance = self.scene.post_clearance()
        return {"success": self.scene.reached(), "min_obstacle_clearance": clearance,
                "obstacle_contacts": ["hand-post"] if clearance < 0.005 else []}

    def reset(self, *, seed=None, options=None):
        self.scene.start(seed)
        return self.observation(), self.info()

    def step(self, action):
        self.scene.move(action[:3], action[9])  # absolute position (m); the toy hand ignores rotation
        info = self.info()
        return self.observation(), 0.0, info["success"], self.scene.steps >= self.max_steps, info

    def close(self):
        pass


def make_env(task=None, image_size=64, max_steps=None, **options):
    return ReachBlockEnv(ReachBlockScene(image_size=image_size, max_steps=max_steps or 30))
