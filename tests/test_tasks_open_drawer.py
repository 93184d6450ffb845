"""open_drawer: the drawer's initial state, the success threshold and what the expert achieves."""

from __future__ import annotations

import numpy as np
import pytest

from lano3dp.sim.objects.articulated import DrawerParts
from lano3dp.sim.tasks.open_drawer import OPEN_FRACTION
from test_tasks_common import make_env, set_joint


@pytest.fixture
def env():
    env = make_env("open_drawer")
    yield env
    env.close()


def parts_of(env) -> DrawerParts:
    layout = env.episode.layout
    return DrawerParts.of(layout.names["drawer"], layout.objects["drawer"].scale)


def test_reset_restores_the_sampled_initial_opening(env):
    for seed in (0, 1):
        env.reset(seed=seed)
        parts = parts_of(env)
        opening = env.episode.layout.objects["drawer"].params["opening"]
        assert 0.0 <= opening <= 0.15 * parts.travel
        assert env.sim.joint_qpos(parts.joint) == pytest.approx(opening, abs=1e-3)


def test_success_needs_the_drawer_out_by_sixty_percent_of_its_travel(env):
    env.reset(seed=2)
    parts = parts_of(env)
    set_joint(env, parts.joint, (OPEN_FRACTION - 0.05) * parts.travel)
    assert not env.task.is_success(env.sim, env.episode.layout)
    set_joint(env, parts.joint, (OPEN_FRACTION + 0.02) * parts.travel)
    assert env.task.is_success(env.sim, env.episode.layout)


def test_expert_pulls_the_drawer_nearly_fully_out_and_lets_go(env):
    env.reset(seed=3)
    parts = parts_of(env)
    for action in env.expert_plan().actions():
        env.step(action)
    assert env.sim.joint_qpos(parts.joint) > 0.8 * parts.travel
    assert env.sim.held_object() is None
    assert env.gripper.opening(env.data) > 0.08  # open again after the pull


def test_handle_site_sits_on_the_bar_in_front_of_the_drawer(env):
    env.reset(seed=4)
    parts = parts_of(env)
    model, data = env.model, env.data
    handle = data.site_xpos[model.site(parts.handle_site).id]
    bar = data.geom_xpos[model.geom(f"{parts.name}/handle_bar").id]
    np.testing.assert_allclose(handle, bar, atol=1e-9)
    cabinet = env.sim.body_position(parts.cabinet)
    forward = env.sim.body_rotation(parts.cabinet)[:, 0]
    expected = parts.handle_x + env.sim.joint_qpos(parts.joint)
    assert np.dot(handle - cabinet, forward) == pytest.approx(expected, abs=1e-6)
