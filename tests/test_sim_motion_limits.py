"""The simulated arm moves no faster than a real one, whatever the actions; the experts never need more."""

from __future__ import annotations

import numpy as np
import pytest

from lano3dp.geometry.rotations import quat_to_matrix
from lano3dp.sim import TabletopEnv
from lano3dp.sim.env import MotionLimits
from lano3dp.sim.experts import rotation_angle
from lano3dp.sim.tasks import TASKS
from simulator_versions import skip_if_mujoco_too_old

LIMITS = MotionLimits()
STEP_DISTANCE = LIMITS.linear / 10.0  # metres per 10 Hz control step
STEP_ANGLE = LIMITS.angular / 10.0


def random_action(rng: np.random.Generator) -> np.ndarray:
    """Anywhere in (and beyond) the workspace, any orientation, any gripper command."""
    position = rng.uniform([-0.2, -0.8, -0.2], [1.2, 0.8, 0.9])
    columns = rng.normal(size=6)
    return np.concatenate([position, columns, [rng.uniform(-0.5, 1.5)]])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_no_action_sequence_moves_the_hand_faster_than_the_limits(seed):
    rng = np.random.default_rng(seed)
    env = TabletopEnv("close_microwave", image_size=16, render_rgb=False)
    try:
        env.reset(seed=seed)
        previous_target = env._target_pos.copy(), quat_to_matrix(env._target_quat)
        previous_hand = env.gripper.ee_pose(env.data)
        limited = 0
        for _ in range(30):
            # Alternate far jumps with small steps, so both the bounded and the free case are exercised.
            action = random_action(rng) if rng.random() < 0.7 else np.concatenate(
                [previous_target[0] + rng.normal(scale=0.01, size=3), previous_target[1][:, :2].T.reshape(-1), [0]])
            *_, info = env.step(action)
            target = env._target_pos.copy(), quat_to_matrix(env._target_quat)
            hand = env.gripper.ee_pose(env.data)
            assert np.linalg.norm(target[0] - previous_target[0]) <= STEP_DISTANCE + 1e-9
            assert rotation_angle(previous_target[1], target[1]) <= STEP_ANGLE + 1e-6
            # The hand follows its target through a stiff weld: it may lag, never overshoot by much.
            assert np.linalg.norm(hand[0] - previous_hand[0]) <= 1.5 * STEP_DISTANCE
            limited += info["motion_limited"]
            previous_target, previous_hand = target, hand
        assert limited >= 10  # the random jumps really hit the limit
    finally:
        env.close()


def test_a_target_within_the_limits_is_reached_in_one_step():
    env = TabletopEnv("bowl_pour", image_size=16, render_rgb=False)
    try:
        env.reset(seed=0)
        start = env._target_pos.copy()
        action = np.concatenate([start + [0.03, -0.02, 0.01], [1, 0, 0, 0, -1, 0], [0.0]])
        *_, info = env.step(action)
        assert not info["motion_limited"]
        np.testing.assert_allclose(env._target_pos, action[:3])
    finally:
        env.close()


@pytest.mark.parametrize("task", sorted(TASKS))
def test_every_expert_succeeds_without_meeting_the_limits(task):
    skip_if_mujoco_too_old(task)
    env = TabletopEnv(task, image_size=16, render_rgb=False)
    try:
        for seed in (0, 1):
            env.reset(seed=seed)
            actions = env.expert_plan().actions()
            actions = np.concatenate([actions, np.repeat(actions[-1:], 15, axis=0)])
            success, limited = False, 0
            for action in actions:
                *_, terminated, truncated, info = env.step(action)
                limited += info["motion_limited"]
                if terminated or truncated:
                    success = bool(info["success"])
                    break
            assert success, f"{task} seed {seed}: the expert failed under the motion limits"
            assert limited == 0, f"{task} seed {seed}: the expert needed {limited} steps beyond the limits"
    finally:
        env.close()
