"""An environment from outside (`--env module:factory`) is checked at its boundary: a factory that raises or makes
something that is not an env, and a first observation that breaks the protocol (keys, shapes, dtypes, finite
values) are one line naming the factory, the key and what was expected. A NaN in the middle of an episode ends
that episode with a recorded error, not the evaluation."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from faults_common import EXAMPLE_ENV, assert_one_line
from lano3dp.cli import app

BAD_ENVS = '''
import sys

import numpy as np

sys.path.insert(0, {examples!r})
from own_env import make_env as make_reach_env


class Twisted:
    """The example env with one fault: `reset_obs` / `step_obs` rewrite its observations, `step_reply` its step
    reply."""

    def __init__(self, env, reset_obs=None, step_obs=None, step_reply=None):
        self.env, self.max_steps, self.control_hz = env, env.max_steps, env.control_hz
        self.reset_obs, self.step_obs, self.step_reply = reset_obs, step_obs, step_reply
        self.seed, self.steps = None, 0

    def __getattr__(self, name):  # the scene, for an expert that reads it
        return getattr(self.__dict__["env"], name)

    def reset(self, *, seed=None, options=None):
        self.seed, self.steps = seed, 0
        obs, info = self.env.reset(seed=seed)
        return (self.reset_obs(obs) if self.reset_obs else obs), info

    def step(self, action):
        self.steps += 1
        reply = self.env.step(action)
        if self.step_reply:
            return self.step_reply(reply)
        obs = self.step_obs(self, reply[0]) if self.step_obs else reply[0]
        return (obs, *reply[1:])


def with_state(obs, state):
    return {{**obs, "state": state}}


def broken(**options):
    raise RuntimeError("robot not connected")


def not_an_env(**options):
    return {{"state": np.zeros(11)}}


def nothing(**options):
    return None


def no_state(**options):
    return Twisted(make_reach_env(**options), reset_obs=lambda obs: {{"frame": obs["frame"]}})


def short_state(**options):
    return Twisted(make_reach_env(**options), reset_obs=lambda obs: with_state(obs, obs["state"][:7]))


def text_state(**options):
    return Twisted(make_reach_env(**options), reset_obs=lambda obs: with_state(obs, np.array(list("abcdefghijk"))))


def nan_at_reset(**options):
    return Twisted(make_reach_env(**options),
                   reset_obs=lambda obs: with_state(obs, np.r_[obs["state"][:3], np.nan, obs["state"][4:]]))


def frame_not_a_frame(**options):
    return Twisted(make_reach_env(**options), reset_obs=lambda obs: {{**obs, "frame": {{"rgb": None}}}})


def depth_in_millimetres(**options):
    def images(obs):
        frame = obs["frame"]
        return {{"state": obs["state"], "rgb": frame.rgb, "depth": (frame.depth * 1000).astype(np.uint16),
                 "intrinsics": frame.camera.K, "cam_to_world": frame.camera.cam_to_world}}
    return Twisted(make_reach_env(**options), reset_obs=images)


def four_values_from_step(**options):
    return Twisted(make_reach_env(**options), step_reply=lambda reply: reply[:4])


def short_state_after_a_step(**options):
    return Twisted(make_reach_env(**options), step_obs=lambda env, obs: with_state(obs, obs["state"][:10]))


def nan_on_even_seeds(**options):
    """Blows up (NaN hand position) at the second step of every episode with an even seed."""
    def step_obs(env, obs):
        if env.seed % 2 == 0 and env.steps >= 2:
            return with_state(obs, np.r_[np.nan, obs["state"][1:]].astype(np.float32))
        return obs
    return Twisted(make_reach_env(**options), step_obs=step_obs)
'''


@pytest.fixture(scope="module")
def bad_envs(tmp_path_factory):
    path = tmp_path_factory.mktemp("envs") / "bad_envs.py"
    path.write_text(BAD_ENVS.format(examples=str(EXAMPLE_ENV.parent)))
    return path


def evaluate_with(env: str, checkpoint, out, episodes: int = 1):
    return CliRunner().invoke(app, ["eval", "--env", env, "--checkpoint", str(checkpoint), "--episodes",
                                    str(episodes), "--max-steps", "4", "--out", str(out)])


@pytest.mark.parametrize("factory, texts", [
    ("broken", ["calling it with (", "raised RuntimeError: robot not connected"]),
    ("not_an_env", ["the factory returned a dict, which has no reset() and no step()"]),
    ("nothing", ["the factory returned a NoneType, which has no reset() and no step()"]),
    ("no_state", ["reset()'s observation has no 'state' (11,", "its keys: frame"]),
    ("short_state", ["reset()'s observation 'state' must be (11,) finite numbers", "got float32 of shape (7,)"]),
    ("text_state", ["reset()'s observation 'state' must be (11,) finite numbers", "got <U1 of shape (11,)"]),
    ("nan_at_reset", ["reset()'s observation 'state' holds nan at index 3"]),
    ("frame_not_a_frame", ["reset()'s observation does not make a camera frame",
                           "'frame' must be an RGBDFrame, got dict"]),
    ("depth_in_millimetres", ["reset()'s observation 'depth' must be (H, W) float; got uint16 of shape (48, 48)"]),
    ("four_values_from_step", ["step() must return (obs, reward, terminated, truncated, info), got a tuple of 4"]),
    ("short_state_after_a_step", ["step 1's observation 'state' must be (11,)", "got float32 of shape (10,)"]),
])
def test_an_env_that_breaks_the_protocol_is_one_line_naming_it_the_key_and_what_was_expected(
        bad_envs, reach_checkpoint, tmp_path, factory, texts):
    spec = f"{bad_envs}:{factory}"
    out = tmp_path / "r.json"
    result = evaluate_with(spec, reach_checkpoint, out)
    assert_one_line(result, 1, f"--env {spec}: ", *texts)
    assert not out.exists()


def test_a_nan_mid_episode_ends_that_episode_with_its_error_and_the_evaluation_goes_on(bad_envs, reach_checkpoint,
                                                                                        tmp_path):
    out = tmp_path / "r.json"
    result = evaluate_with(f"{bad_envs}:nan_on_even_seeds", reach_checkpoint, out, episodes=2)
    assert result.exit_code == 0, (result.output, result.exception)
    first, second = json.loads(out.read_text())["episodes"]
    assert (first["seed"], first["steps"]) == (1_000_000, 1)  # the NaN came back from its second step
    assert first["error"].startswith("NonFiniteObservationError: ")
    assert "step 2's observation 'state' holds nan at index 0" in first["error"]
    assert second["seed"] == 1_000_001 and second["error"] is None and second["steps"] == 4
    assert "episodes ended by errors: NonFiniteObservationError" in result.stderr


def test_a_nan_while_collecting_is_one_line_naming_the_env_and_seed_and_records_nothing(bad_envs, tmp_path):
    from test_kill_resume import SLOW_EXPERT

    (tmp_path / "experts.py").write_text(SLOW_EXPERT)
    spec, out = f"{bad_envs}:nan_on_even_seeds", tmp_path / "d.zarr"
    result = CliRunner().invoke(app, ["collect", "--env", spec, "--expert", f"{tmp_path / 'experts.py'}:reach",
                                      "--slots", "block", "--episodes", "2", "--image-size", "48", "--no-progress",
                                      "--out", str(out)])
    assert_one_line(result, 1, f"--env {spec}: step 2's observation 'state' holds nan at index 0", "(seed 0)")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["experts.py"]


def test_a_checked_env_passes_a_good_env_through_unchanged():
    from lano3dp.env_factory import make_env

    env = make_env(f"{EXAMPLE_ENV}:make_env", task="reach_block", image_size=48)
    obs, info = env.reset(seed=0)
    state = obs["state"].copy()
    obs, reward, terminated, truncated, info = env.step(np.r_[state[:3], state[3:9], 0.0].astype(np.float32))
    assert obs["state"].shape == (11,) and env.steps == 1 and env.reports_success


def test_the_env_refuses_a_step_after_close():
    from lano3dp.sim import TabletopEnv
    from lano3dp.sim.env import EnvClosedError

    env = TabletopEnv("open_drawer", image_size=32, render_rgb=False)
    env.reset(seed=0)
    env.close()
    with pytest.raises(EnvClosedError, match="closed; make a new one"):
        env.step(np.zeros(10, np.float32))
