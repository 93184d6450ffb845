"""open_wine_bottle: the cap stays on until pulled, the pull does not lift the bottle, and the
success check wants the cap 3 cm up with the bottle still standing."""

from __future__ import annotations

import pytest

from lano3dp.sim.objects.articulated import WineBottleParts
from lano3dp.sim.tasks.open_wine_bottle import OFF_HEIGHT
from test_tasks_common import make_env, set_joint


@pytest.fixture
def env():
    env = make_env("open_wine_bottle")
    env.reset(seed=0)
    yield env
    env.close()


def parts_of(env) -> WineBottleParts:
    layout = env.episode.layout
    return WineBottleParts.of(layout.names["bottle"], layout.objects["bottle"].scale)


def test_cap_stays_on_and_the_bottle_stands_after_settling(env):
    parts = parts_of(env)
    assert env.sim.joint_qpos(parts.joint) == pytest.approx(0.0, abs=1e-3)
    assert env.sim.body_rotation(parts.body)[2, 2] > 0.999


def test_expert_pulls_the_cap_off_without_lifting_the_bottle(env):
    parts = parts_of(env)
    for action in env.expert_plan().actions():
        env.step(action)
        assert env.sim.body_position(parts.body)[2] < 0.005  # the bottle never leaves the table
    assert env.sim.joint_qpos(parts.joint) > 0.04
    assert env.sim.held_object() is None


def test_success_threshold_on_the_cap_height(env):
    parts = parts_of(env)
    set_joint(env, parts.joint, OFF_HEIGHT - 0.005)
    assert not env.task.is_success(env.sim, env.episode.layout)
    set_joint(env, parts.joint, OFF_HEIGHT + 0.005)
    assert env.task.is_success(env.sim, env.episode.layout)
