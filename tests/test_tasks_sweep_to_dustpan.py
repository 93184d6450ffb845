"""sweep_to_dustpan: the dirt starts in front of the dustpan's mouth, the expert sweeps it in
while holding the broom, and success wants 3 of the 4 dirt cubes inside the pan."""

from __future__ import annotations

import numpy as np
import pytest

from lano3dp.geometry.rotations import rot6d_to_matrix
from lano3dp.sim.experts import OPEN
from lano3dp.sim.objects.articulated import BroomParts, DustpanParts
from lano3dp.sim.robot import TOP_DOWN
from lano3dp.sim.tasks.sweep_to_dustpan import DIRT_HALF, MIN_SWEPT, N_DIRT
from test_tasks_common import make_env, teleport


@pytest.fixture
def env():
    env = make_env("sweep_to_dustpan")
    env.reset(seed=0)
    yield env
    env.close()


def pan_frame(env) -> tuple[DustpanParts, np.ndarray, np.ndarray]:
    pan = env.episode.layout.objects["dustpan"]
    parts = DustpanParts.of(env.episode.layout.names["dustpan"], pan.scale)
    return parts, env.sim.body_position(parts.body), env.sim.body_rotation(parts.body)


def test_dirt_starts_in_front_of_the_mouth(env):
    _, origin, rotation = pan_frame(env)
    for i in range(N_DIRT):
        local = rotation.T @ (env.sim.body_position(f"dirt{i}") - origin)
        assert -0.14 < local[0] < -0.05  # outside the pan, ~10 cm before the mouth
        assert abs(local[1]) < 0.05


@pytest.mark.parametrize("n_in_pan", [MIN_SWEPT - 1, MIN_SWEPT])
def test_success_counts_the_dirt_inside_the_pan(env, n_in_pan):
    parts, origin, rotation = pan_frame(env)
    for i in range(n_in_pan):
        local = np.array([parts.depth * (0.3 + 0.15 * i), 0.02 * (i - 1), DIRT_HALF + 0.001])
        teleport(env, f"dirt{i}", origin + rotation @ local, settle_steps=0)
    teleport(env, "dirt3", env.sim.body_position("dirt3"), settle_steps=100)
    assert env.task.is_success(env.sim, env.episode.layout) == (n_in_pan >= MIN_SWEPT)


def test_expert_sweeps_holding_the_broom(env):
    held = []
    for action in env.expert_plan().actions():
        env.step(action)
        held.append(env.sim.held_object())
    assert held[-1] == "broom"
    assert env.task.is_success(env.sim, env.episode.layout)


def test_expert_holds_the_head_on_the_same_side_of_the_hand():
    """Of the two symmetric grasps across the handle the expert takes the one with the head along the hand's +x,
    whichever way the broom lies, so every demonstration sweeps with the hand turned to the sweep direction."""
    env = make_env("sweep_to_dustpan")
    try:
        for seed in range(12):
            env.reset(seed=seed)
            layout = env.episode.layout
            broom = env.sim.body_rotation(BroomParts.of(layout.names["broom"], layout.objects["broom"].scale).body)
            actions = env.expert_plan().actions()
            grasp = actions[int(np.argmax(actions[:, 9] > OPEN)) - 1]
            head_in_hand = rot6d_to_matrix(grasp[3:9]).T @ broom[:, 0]
            assert head_in_hand[0] > 0.99, seed
            sweep = rot6d_to_matrix(actions[-1, 3:9]) @ TOP_DOWN.T  # rot_z(yaw) for a top-down hand
            angle = layout.params["sweep_angle"]
            assert np.allclose(sweep[:2, 0], [np.cos(angle), np.sin(angle)], atol=1e-3), seed
    finally:
        env.close()
