"""bowl_pour and bottle_upright: layouts are seeded, experts succeed, success is not trivially true."""

import numpy as np
import pytest

from lano3dp.sim import TabletopEnv, make_task
from lano3dp.sim.variations import Variation
from simulator_versions import skip_if_mujoco_too_old


def run_expert(env, seed):
    obs, info = env.reset(seed=seed)
    assert not info["success"], "a fresh scene must not already count as solved"
    actions = env.expert_plan().actions()
    for t in range(env.max_steps):
        obs, reward, terminated, truncated, info = env.step(actions[min(t, len(actions) - 1)])
        if terminated or truncated:
            return info["success"], t + 1
    return False, env.max_steps


@pytest.mark.parametrize("task,seeds", [("bowl_pour", [10, 11, 12]), ("bottle_upright", [10, 11, 12])])
def test_expert_succeeds_on_fresh_seeds(task, seeds):
    skip_if_mujoco_too_old(task)
    env = TabletopEnv(task, image_size=32, render_rgb=False)
    try:
        results = [run_expert(env, seed) for seed in seeds]
    finally:
        env.close()
    assert all(success for success, _ in results), results
    assert all(steps < env.max_steps for _, steps in results)


def test_layout_is_a_function_of_the_seed():
    task = make_task("bowl_pour")
    a = task.sample_layout(np.random.default_rng(7), Variation())
    b = task.sample_layout(np.random.default_rng(7), Variation())
    c = task.sample_layout(np.random.default_rng(8), Variation())
    np.testing.assert_array_equal(a.objects["bowl"].position, b.objects["bowl"].position)
    assert not np.allclose(a.objects["bowl"].position, c.objects["bowl"].position)


def test_bowl_pour_items_start_in_the_bowl_and_the_pan_is_far_enough():
    task = make_task("bowl_pour")
    for seed in range(20):
        layout = task.sample_layout(np.random.default_rng(seed), Variation())
        bowl, pan = layout.objects["bowl"].position, layout.objects["pan"].position
        assert np.linalg.norm(bowl[:2] - pan[:2]) >= 0.30
        for key, item in layout.objects.items():
            if item.kind == "item":
                assert np.linalg.norm(item.position[:2] - bowl[:2]) < 0.04, key


def test_dropping_the_bowl_into_the_pan_is_not_success():
    """Items still inside the bowl do not count, even when the bowl sits in the pan."""
    env = TabletopEnv("bowl_pour", image_size=32, render_rgb=False)
    try:
        env.reset(seed=0)
        model, data = env.model, env.data
        pan = env.sim.body_position("pan")
        bowl_qpos = model.joint("bowl/free").qposadr[0]
        shift = np.array([pan[0], pan[1], 0.02]) - data.qpos[bowl_qpos:bowl_qpos + 3]
        data.qpos[bowl_qpos:bowl_qpos + 3] += shift
        for i in range(3):
            adr = model.joint(f"item{i}/free").qposadr[0]
            data.qpos[adr:adr + 3] += shift
        import mujoco

        mujoco.mj_step(model, data, nstep=200)
        assert not env.task.is_success(env.sim, env.episode.layout)
    finally:
        env.close()


def test_bottle_lying_is_not_upright_and_an_upright_bottle_is():
    env = TabletopEnv("bottle_upright", image_size=32, render_rgb=False)
    try:
        env.reset(seed=0)
        assert not env.task.is_success(env.sim, env.episode.layout)
        model, data = env.model, env.data
        adr = model.joint("bottle/free").qposadr[0]
        data.qpos[adr + 2] = 0.06 + 0.001
        data.qpos[adr + 3:adr + 7] = [1, 0, 0, 0]
        data.qvel[:] = 0
        import mujoco

        mujoco.mj_step(model, data, nstep=100)
        assert env.task.is_success(env.sim, env.episode.layout)
    finally:
        env.close()
