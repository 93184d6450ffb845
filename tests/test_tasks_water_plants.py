"""water_plants: the water starts in the can, and the plant counts as watered once at least 3 of
the 4 water spheres rest in its pot."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from lano3dp.sim.objects.articulated import CAN_RADIUS, POT_RADIUS, SOIL_HEIGHT
from lano3dp.sim.tasks.water_plants import MIN_WATERED, N_WATER
from test_tasks_common import make_env, teleport


@pytest.fixture
def env():
    env = make_env("water_plants")
    env.reset(seed=0)
    yield env
    env.close()


def test_water_starts_inside_the_can(env):
    can = env.sim.body_position("watering can")
    for i in range(N_WATER):
        water = env.sim.body_position(f"water{i}")
        assert np.linalg.norm(water[:2] - can[:2]) < CAN_RADIUS
        assert water[2] < 0.03


@pytest.mark.parametrize("n_in_pot", [MIN_WATERED - 1, MIN_WATERED])
def test_plant_is_watered_once_three_spheres_rest_in_the_pot(env, n_in_pot):
    pot = env.sim.body_position("plant")
    for i in range(n_in_pot):
        offset = 0.025 * np.array([np.cos(2 * np.pi * i / N_WATER), np.sin(2 * np.pi * i / N_WATER)])
        teleport(env, f"water{i}", [*(pot[:2] + offset), SOIL_HEIGHT + 0.015], settle_steps=0)
    mujoco.mj_step(env.model, env.data, nstep=150)  # let them come to rest on the soil
    for i in range(n_in_pot):
        assert np.linalg.norm(env.sim.body_position(f"water{i}")[:2] - pot[:2]) < POT_RADIUS
    assert env.task.is_success(env.sim, env.episode.layout) == (n_in_pot >= MIN_WATERED)
