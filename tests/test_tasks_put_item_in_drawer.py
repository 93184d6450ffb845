"""put_item_in_drawer: the block counts as stored only when it rests on the drawer's floor."""

from __future__ import annotations

import numpy as np
import pytest

from lano3dp.sim.objects.articulated import DrawerParts
from lano3dp.sim.tasks.bottle_in_drawer import drawer_slot_centre
from lano3dp.sim.tasks.put_item_in_drawer import BLOCK_HALF
from test_tasks_common import make_env, teleport


@pytest.fixture
def env():
    env = make_env("put_item_in_drawer")
    env.reset(seed=0)
    yield env
    env.close()


def test_block_is_registered_with_the_slot_word(env):
    """The oracle grounds "the block" by kind, so the cube must carry the slot word, not "cube"."""
    assert env.objects["block"].kind == "block"
    assert env.objects["block"].body_names == ("block",)


def test_block_in_the_drawer_is_a_success_and_on_the_cabinet_is_not(env):
    layout = env.episode.layout
    parts = DrawerParts.of(layout.names["drawer"], layout.objects["drawer"].scale)
    origin, rotation = env.sim.body_position(parts.cabinet), env.sim.body_rotation(parts.cabinet)
    slot = drawer_slot_centre(parts, origin, rotation, env.sim.joint_qpos(parts.joint))
    teleport(env, "block", slot + [0, 0, BLOCK_HALF + 0.002])
    assert env.task.is_success(env.sim, env.episode.layout)
    on_top = origin + np.array([0.0, 0.0, parts.height + BLOCK_HALF + 0.002])
    teleport(env, "block", on_top)
    assert not env.task.is_success(env.sim, env.episode.layout)
