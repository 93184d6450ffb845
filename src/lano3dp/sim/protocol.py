"""What a simulator or a real robot must provide to stand in for `TabletopEnv`.

The evaluation and runtime layers only use this surface, so a user's own simulator or robot
plugs in by implementing it (structural typing: no inheritance needed).

    obs, info = env.reset(seed=0)
    frame = env.frame()                         # RGBDFrame: rgb, depth, calibrated camera
    state = obs["state"]                        # (11,) EE position, rotation 6D, opening (m), grasp flag
    obs, reward, terminated, truncated, info = env.step(action)   # action (10,) absolute EE pose + gripper

Real robots without ground-truth segmentation leave `frame.segmentation` None and use an
open-vocabulary segmenter; `info` should carry "success" when the robot can tell (else False).

The grasp flag, state[10]: 1.0 while the gripper holds an object, else 0.0 (the built-in simulator: an object
touched by both finger pads while the gripper is commanded closed). It is used twice: the policy sees it as part
of the state (the paper's gripper feedback: it tells a grasp that held from one that slipped), and guided runs
add the held object (the runner's `held_object`) to the body kept clear of obstacles while it is set (>= 0.5).
An env that cannot tell gives 0.0 at every step, in its demonstrations and at evaluation alike: the policy then
learns nothing from it (a constant input), and guidance keeps the hand clear but not a carried object. Where the
env can tell (finger contacts, a gripper's object-detection bit, the task's own "grasped" check), give that: it
must mean the same in the demonstrations and in evaluation.

Optional: obs["goal"] (D,) or another registered task input (`lano3dp.policy.observations.vector`): a goal the
episode draws that no camera shows; `collect` records it and a policy trained on it receives it every step.

Optional: `max_ee_step`, the metres the end effector moves at most in one step. Guided runs then predict the
path the arm really takes through a chunk (it chases each waypoint at that pace) when they check and repair
the chunk; without it every waypoint is assumed reached.

Optional: `other_views()`, this moment seen from the env's other calibrated cameras (a list of RGBDFrame). The
runtime asks for them only when the observation camera cannot see a target or an obstacle in an episode's first
frame (an obstacle in front of it), and takes that object's cloud from the view that sees most of it.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

from lano3dp.geometry import RGBDFrame


@runtime_checkable
class SimulatorProtocol(Protocol):
    """Gymnasium-style control loop over absolute end-effector actions (see the module docstring)."""

    control_hz: float
    max_steps: int

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict[str, Any], dict]:
        """Start an episode; obs holds at least "state" (11,) float32 (and "goal" (D,) in a goal-conditioned task)."""
        ...

    def step(self, action: np.ndarray) -> tuple[dict[str, Any], float, bool, bool, dict]:
        """Execute one (10,) action: position (3, m), rotation 6D (6), gripper (1, 0 open .. 1 closed)."""
        ...

    def frame(self) -> RGBDFrame:
        """The latest camera frame with intrinsics and camera-to-world extrinsics."""
        ...

    def close(self) -> None: ...
