"""bottle_in_drawer: the drawer starts open and the success check wants the bottle upright,
released and resting on the drawer's floor."""

from __future__ import annotations

import numpy as np
import pytest

from lano3dp.geometry import matrix_to_quat
from lano3dp.sim.objects.articulated import DrawerParts
from lano3dp.sim.objects.primitives import BOTTLE_BODY_HALF
from lano3dp.sim.robot import rot_axis
from lano3dp.sim.tasks.bottle_in_drawer import drawer_slot_centre
from test_tasks_common import make_env, teleport


@pytest.fixture
def env():
    env = make_env("bottle_in_drawer")
    env.reset(seed=0)
    yield env
    env.close()


def drawer_state(env) -> tuple[DrawerParts, np.ndarray, np.ndarray, float]:
    layout = env.episode.layout
    parts = DrawerParts.of(layout.names["drawer"], layout.objects["drawer"].scale)
    return (parts, env.sim.body_position(parts.cabinet), env.sim.body_rotation(parts.cabinet),
            env.sim.joint_qpos(parts.joint))


def test_drawer_starts_open_and_bottle_starts_upright_on_the_table(env):
    parts, _, _, opening = drawer_state(env)
    assert opening >= 0.85 * parts.travel - 1e-3
    assert env.sim.body_rotation("bottle")[2, 2] > 0.999
    assert env.sim.body_position("bottle")[2] == pytest.approx(BOTTLE_BODY_HALF, abs=2e-3)


def test_upright_bottle_resting_in_the_drawer_is_a_success(env):
    parts, origin, rotation, opening = drawer_state(env)
    slot = drawer_slot_centre(parts, origin, rotation, opening)
    teleport(env, "bottle", slot + [0, 0, BOTTLE_BODY_HALF + 0.002])
    assert env.task.is_success(env.sim, env.episode.layout)


def test_bottle_lying_in_the_drawer_or_standing_beside_it_is_not_a_success(env):
    parts, origin, rotation, opening = drawer_state(env)
    slot = drawer_slot_centre(parts, origin, rotation, opening)
    lying = matrix_to_quat(rot_axis(rotation[:, 0], np.pi / 2))  # axis along the drawer's width
    teleport(env, "bottle", slot + [0, 0, 0.03], lying)
    assert not env.task.is_success(env.sim, env.episode.layout)
    beside = slot + rotation @ np.array([0.0, parts.width / 2 + 0.06, 0.0])
    teleport(env, "bottle", [beside[0], beside[1], BOTTLE_BODY_HALF + 0.002])
    assert not env.task.is_success(env.sim, env.episode.layout)
