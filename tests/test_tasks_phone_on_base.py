"""phone_on_base: the phone must lie flat in the base's recess, not on its rim or the table."""

from __future__ import annotations

import numpy as np
import pytest

from lano3dp.geometry import matrix_to_quat
from lano3dp.sim.objects.articulated import PHONE_THICKNESS, PhoneBaseParts
from lano3dp.sim.robot import rot_z
from test_tasks_common import make_env, teleport


@pytest.fixture
def env():
    env = make_env("phone_on_base")
    env.reset(seed=0)
    yield env
    env.close()


def test_recess_fits_the_phone_with_clearance(env):
    base = PhoneBaseParts.of("base", 1.0)
    assert base.inner_length - 0.13 == pytest.approx(0.05)
    assert base.inner_width - 0.06 == pytest.approx(0.05)


def test_phone_flat_in_the_recess_is_a_success(env):
    base = env.episode.layout.objects["base"]
    parts = PhoneBaseParts.of("base", base.scale)
    aligned = matrix_to_quat(rot_z(base.yaw))
    teleport(env, "phone/body", [*base.position[:2], parts.plate + PHONE_THICKNESS / 2 + 0.002], aligned)
    assert env.task.is_success(env.sim, env.episode.layout)


def test_phone_across_the_rim_or_on_the_table_is_not_a_success(env):
    base = env.episode.layout.objects["base"]
    parts = PhoneBaseParts.of("base", base.scale)
    across = matrix_to_quat(rot_z(base.yaw + np.pi / 2))  # long axis across the recess: rests on the rim
    teleport(env, "phone/body", [*base.position[:2], parts.plate + parts.rim_height + PHONE_THICKNESS / 2 + 0.002],
             across)
    assert not env.task.is_success(env.sim, env.episode.layout)
    beside = np.asarray(base.position[:2]) + rot_z(base.yaw)[:2, 0] * (parts.inner_length / 2 + 0.12)
    teleport(env, "phone/body", [*beside, PHONE_THICKNESS / 2 + 0.002], matrix_to_quat(rot_z(base.yaw)))
    assert not env.task.is_success(env.sim, env.episode.layout)
