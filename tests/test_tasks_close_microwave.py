"""close_microwave: the door's kinematics as the expert assumes them, and the success threshold."""

from __future__ import annotations

import numpy as np
import pytest

from lano3dp.sim.objects.articulated import MicrowaveParts
from lano3dp.sim.robot import rot_z
from lano3dp.sim.tasks.close_microwave import CLOSED_ANGLE, door_point
from test_tasks_common import make_env, set_joint


@pytest.fixture
def env():
    env = make_env("close_microwave")
    env.reset(seed=0)
    yield env
    env.close()


def parts_of(env) -> MicrowaveParts:
    layout = env.episode.layout
    return MicrowaveParts.of(layout.names["microwave"], layout.objects["microwave"].scale)


def test_door_starts_open_at_the_sampled_angle(env):
    angle = env.episode.layout.objects["microwave"].params["door_angle"]
    assert 0.8 <= angle <= 1.4
    assert env.sim.joint_qpos(parts_of(env).joint) == pytest.approx(angle, abs=0.01)


@pytest.mark.parametrize("angle", [0.0, 0.7, 1.5])
def test_door_panel_follows_the_kinematics_the_expert_plans_with(env, angle):
    """The panel's centre is half a door width from the hinge along (sin q, cos q) in the box frame."""
    parts = parts_of(env)
    set_joint(env, parts.joint, angle)
    box = env.episode.layout.objects["microwave"]
    expected, _ = door_point(parts, np.asarray(box.position), rot_z(box.yaw), angle, parts.door_width / 2, 0.0)
    panel = env.data.geom_xpos[env.model.geom(f"{parts.name}/panel").id]
    np.testing.assert_allclose(panel[:2], expected[:2], atol=1e-6)


def test_success_needs_the_door_within_a_tenth_of_a_radian_of_closed(env):
    parts = parts_of(env)
    set_joint(env, parts.joint, CLOSED_ANGLE + 0.02)
    assert not env.task.is_success(env.sim, env.episode.layout)
    set_joint(env, parts.joint, CLOSED_ANGLE - 0.02)
    assert env.task.is_success(env.sim, env.episode.layout)
