"""An expert from outside (`collect --env ... --expert module:callable`) is checked at its boundary: one that
raises, returns NaN, the wrong shape or not numbers at all is one line naming the expert, the seed and step and
what was expected, and nothing is written half: a first collection leaves no dataset, a later one leaves the
dataset as it was."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from faults_common import EXAMPLE_ENV, assert_one_line
from lano3dp.cli import app

EXPERTS = '''
import numpy as np

ROT6D = np.array([1, 0, 0, 0, 1, 0], np.float32)


def reach(env, obs, info):
    """Straight to 2 cm above the block's top: the example env's task."""
    block = env.scene.boxes[0]
    return np.r_[block.center_xy, block.size[2] + 0.02, ROT6D, 0.0].astype(np.float32)


def raises(env, obs, info):
    raise ZeroDivisionError("division by zero in my controller")


def nan_gripper(env, obs, info):
    action = reach(env, obs, info)
    action[9] = np.nan
    return action


def position_only(env, obs, info):
    return reach(env, obs, info)[:3]


def words(env, obs, info):
    return "go to the block"


class NanFromTheSecondEpisode:
    """Good for one episode, then a NaN: the dataset must keep the good episode as it was."""

    def __init__(self):
        self.episodes = 0

    def reset(self, env, obs, info):
        self.episodes += 1

    def __call__(self, env, obs, info):
        action = reach(env, obs, info)
        if self.episodes >= 2:
            action[1] = np.nan
        return action
'''


@pytest.fixture(scope="module")
def experts(tmp_path_factory):
    path = tmp_path_factory.mktemp("experts") / "experts.py"
    path.write_text(EXPERTS)
    return path


def collect_with(expert: str, out, episodes: int = 2):
    return CliRunner().invoke(app, ["collect", "--env", f"{EXAMPLE_ENV}:make_env", "--expert", expert, "--slots",
                                    "block", "--episodes", str(episodes), "--image-size", "48", "--follow-through",
                                    "0", "--no-progress", "--out", str(out)])


@pytest.mark.parametrize("name, texts", [
    ("raises", ["raised ZeroDivisionError: division by zero in my controller (seed 0, step 0)"]),
    ("nan_gripper", ["returned nan at action[9] (seed 0, step 0); it must be (10,) finite numbers"]),
    ("position_only", ["returned an action of shape (3,) (seed 0, step 0); it must be (10,) finite numbers: "
                       "position (m), rotation 6D, gripper"]),
    ("words", ["returned str 'go to the block' (seed 0, step 0); it must be (10,) finite numbers"]),
])
def test_a_bad_expert_is_one_line_naming_it_and_leaves_no_dataset(experts, tmp_path, name, texts):
    spec = f"{experts}:{name}"
    out = tmp_path / "d.zarr"
    result = collect_with(spec, out)
    assert_one_line(result, 1, f"--expert {spec} ", *texts)
    assert list(tmp_path.iterdir()) == []  # no store, no lock file


def test_an_expert_failing_in_a_later_episode_leaves_every_complete_episode_as_it_was(experts, tmp_path):
    from lano3dp.data.store import EpisodeStore

    out, unbroken = tmp_path / "d.zarr", tmp_path / "unbroken.zarr"
    assert collect_with(f"{experts}:reach", out, episodes=1).exit_code == 0
    assert collect_with(f"{experts}:reach", unbroken, episodes=2).exit_code == 0
    spec = f"{experts}:NanFromTheSecondEpisode"  # adds episode 1 as `reach` would, then a NaN in episode 2
    result = collect_with(spec, out, episodes=3)
    assert_one_line(result, 1, f"--expert {spec} returned nan at action[1] (seed 2, step 0)")
    store, expected = EpisodeStore.open(out), EpisodeStore.open(unbroken)
    assert store.n_episodes == 2 and store.attrs["episode_seeds"] == [0, 1]
    for index in range(2):
        for key, value in expected.get_episode(index).items():
            np.testing.assert_array_equal(store.get_episode(index)[key], value)
