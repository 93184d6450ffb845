"""Which simulator results depend on the MuJoCo version (docs/simulator-versions.md): a task's expert is only
asserted to succeed on a MuJoCo at least as new as its `reliable_from_mujoco`."""

import pytest

from lano3dp.sim.env import mujoco_version
from lano3dp.sim.tasks import make_task


def skip_if_mujoco_too_old(task: str) -> None:
    needed = make_task(task).reliable_from_mujoco
    if mujoco_version() < tuple(needed):
        pytest.skip(f"{task}'s contacts need MuJoCo >= {needed[0]}.{needed[1]} (docs/simulator-versions.md)")
