"""A time stride S: training windows whose steps are S recorded steps apart, carried by the checkpoint, and a
runtime that observes every S env steps and spreads each policy action over S env steps (issue 12, item 3).

Tiny models and synthetic stores only: this checks the bookkeeping, not what a strided policy learns.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from lano3dp.cli import app
from lano3dp.data import EpisodeStore, SequenceDataset
from lano3dp.data.sequence import window_indices
from lano3dp.geometry.camera import PinholeCamera
from lano3dp.geometry.frame import RGBDFrame
from lano3dp.geometry.rotations import matrix_to_rot6d, rot6d_to_matrix
from lano3dp.migrate import migrate
from lano3dp.policy import ChunkedControl, DiffusionPolicy, PolicyConfig
from lano3dp.runtime import PolicyRunner, interpolate_action, rollout
from lano3dp.sim.protocol import SimulatorProtocol
from lano3dp.train import TrainConfig, Trainer, TrainingConfigError, train
from test_train import ROT6D, micro_config, write_reach_store


def write_counting_store(path, lengths) -> EpisodeStore:
    """Every value is its (episode, step), so a window shows which recorded steps it took."""
    store = EpisodeStore.create(path)
    for episode, length in enumerate(lengths):
        steps = np.arange(length, dtype=np.float32)
        store.append_episode({"action": np.stack([np.full(length, episode, np.float32), steps], -1),
                              "object_clouds": np.broadcast_to(steps[:, None, None, None], (length, 1, 4, 3)).copy()})
    return store


def window_steps(dataset: SequenceDataset) -> list[tuple[int, list[int], list[int]]]:
    """(episode, observation steps, action steps) of every window."""
    return [(int(item["action"][0, 0]), item["obs"]["object_clouds"][:, 0, 0, 0].astype(int).tolist(),
             item["action"][:, 1].astype(int).tolist()) for item in (dataset[i] for i in range(len(dataset)))]


# ---- windows ----------------------------------------------------------------------------------
def test_stride_2_windows_take_every_second_step_with_edge_padding_at_both_ends(tmp_path):
    store = write_counting_store(tmp_path / "d.zarr", [6, 4])
    dataset = SequenceDataset(store, ["object_clouds"], n_obs_steps=2, horizon=4, n_action_steps=2, time_stride=2)
    # a window starts at every recorded step from 2 x (To - 1) before the episode to where its last action step
    # lies 2 x (Ta - 1) after it; steps outside the episode repeat its first or last frame
    assert window_steps(dataset) == [
        (0, [0, 0], [0, 0, 2, 4]),  # steps -2, 0, 2, 4
        (0, [0, 1], [0, 1, 3, 5]),  # -1, 1, 3, 5
        (0, [0, 2], [0, 2, 4, 5]),  # 0, 2, 4, 6
        (0, [1, 3], [1, 3, 5, 5]),  # 1, 3, 5, 7
        (1, [0, 0], [0, 0, 2, 3]),  # -2, 0, 2, 4 of the 4-step episode: windows never mix episodes
        (1, [0, 1], [0, 1, 3, 3]),  # -1, 1, 3, 5
    ]
    with pytest.raises(ValueError, match="time_stride"):
        SequenceDataset(store, ["object_clouds"], time_stride=0)


def _old_window_indices(episode_ends, episodes, horizon, pad_before, pad_after):
    """window_indices and SequenceDataset._window as they were before the stride, the reference for stride 1."""
    rows = []
    for episode in episodes:
        start = 0 if episode == 0 else int(episode_ends[episode - 1])
        length = int(episode_ends[episode]) - start
        for offset in range(-pad_before, length - horizon + pad_after + 1):
            buffer_start = max(offset, 0) + start
            buffer_end = min(offset + horizon, length) + start
            sample_start = buffer_start - (offset + start)
            rows.append((buffer_start, buffer_end, sample_start, sample_start + buffer_end - buffer_start))
    return np.asarray(rows, dtype=np.int64).reshape(-1, 4)


def _old_window(values, row, length, horizon):
    buffer_start, buffer_end, sample_start, sample_end = row
    values = values[buffer_start:buffer_end]
    if sample_start == 0 and sample_end == horizon:
        return values[:length]
    return values[np.clip(np.arange(length) - sample_start, 0, len(values) - 1)]


@pytest.mark.parametrize("n_obs_steps,horizon,n_action_steps", [(1, 8, 4), (2, 4, 2), (3, 8, 6), (2, 16, 8)])
def test_a_stride_1_dataset_gives_exactly_the_windows_it_gave_before(tmp_path, n_obs_steps, horizon, n_action_steps):
    store = write_counting_store(tmp_path / "d.zarr", [1, 3, 9, 20, 5])
    episodes = [0, 2, 3, 4]
    dataset = SequenceDataset(store, ["object_clouds"], n_obs_steps=n_obs_steps, horizon=horizon,
                              n_action_steps=n_action_steps, episodes=episodes)
    expected = _old_window_indices(store.episode_ends, episodes, horizon, n_obs_steps - 1, n_action_steps - 1)
    np.testing.assert_array_equal(dataset.indices, expected)
    np.testing.assert_array_equal(window_indices(store.episode_ends, episodes, horizon, n_obs_steps - 1,
                                                 n_action_steps - 1, stride=1), expected)
    for index, row in enumerate(expected):
        item = dataset[index]
        for key, length, got in (("object_clouds", n_obs_steps, item["obs"]["object_clouds"]),
                                 ("action", horizon, item["action"])):
            want = _old_window(dataset.data[key], row, length, horizon)
            assert got.dtype == want.dtype and np.array_equal(got, want)


# ---- training and the checkpoint ---------------------------------------------------------------
@pytest.fixture(scope="module")
def strided_run(tmp_path_factory):
    """A stride-2 run on its own copy of a reach store (the test below deletes the store)."""
    root = tmp_path_factory.mktemp("strided")
    data = write_reach_store(root / "reach.zarr", episodes=4, length=12)
    config = micro_config(data, root / "run", time_stride=2, steps=2, ckpt_every=2, val_ratio=0.0, batch_size=4)
    config.policy = config.policy.replace(n_obs_steps=2)  # a window of two frames, to see how far apart they are
    return data, train(config)


def test_a_checkpoint_trained_with_a_stride_carries_it_and_acts_without_its_dataset(strided_run):
    data, final = strided_run
    assert json.loads((final / "config.json").read_text())["extra"]["observation"]["time_stride"] == 2
    assert json.loads((final / "train_config.json").read_text())["time_stride"] == 2
    shutil.rmtree(data)  # the checkpoint is self-contained: nothing below reads the store
    policy = DiffusionPolicy.from_pretrained(final)
    assert policy.config.time_stride == 2
    env, recorder = CountingEnv(max_steps=20), RecordingPolicy(policy)
    assert isinstance(env, SimulatorProtocol)
    runner = PolicyRunner(recorder, visual_fn=lambda frame: np.zeros((1, 16, 3), np.float32))
    result = rollout(env, runner, seed=0, success_at="end")

    assert result.steps == 20 and len(env.actions) == 20
    # Ta = 4 policy actions of 2 env steps each per chunk: a chunk every 8 env steps
    assert [c.step for c in runner.chunks] == [0, 8, 16]
    # the window's two frames are 2 env steps apart (the state's opening counts env steps); the first repeats
    assert [call["obs_steps"] for call in recorder.calls] == [[0, 0], [6, 8], [14, 16]]
    # each policy action is the env action that ends its 2 steps; the step before is half-way to it
    targets = np.concatenate([call["actions"] for call in recorder.calls])[:10]
    sent = np.stack(env.actions)
    np.testing.assert_array_equal(sent[1::2], targets)
    previous = np.concatenate([[CountingEnv.START], targets[:-1, :3]])
    np.testing.assert_allclose(sent[0::2, :3], (previous + targets[:, :3]) / 2, atol=1e-6)
    np.testing.assert_allclose(sent[2::2, 9], (targets[:-1, 9] + targets[1:, 9]) / 2, atol=1e-6)
    assert sent[0, 9] == targets[0, 9]  # nothing commanded the gripper before the first action


def test_a_stride_1_checkpoint_carries_no_stride_and_steps_once_per_action(tmp_path):
    data = write_reach_store(tmp_path / "reach.zarr", episodes=4)
    final = train(micro_config(data, tmp_path / "run", steps=1, ckpt_every=1, val_ratio=0.0, batch_size=4))
    # config.json as before the stride existed
    assert "time_stride" not in json.loads((final / "config.json").read_text())["extra"]["observation"]
    policy = DiffusionPolicy.from_pretrained(final)
    env, recorder = CountingEnv(max_steps=9), RecordingPolicy(policy)
    rollout(env, PolicyRunner(recorder, visual_fn=lambda frame: np.zeros((1, 16, 3), np.float32)), seed=0,
            success_at="end")
    np.testing.assert_array_equal(np.stack(env.actions), np.concatenate([c["actions"] for c in recorder.calls])[:9])


def test_a_run_given_no_policy_configuration_strides_its_default_one(tmp_path):
    data = write_reach_store(tmp_path / "reach.zarr", episodes=2, length=48)  # a 16-step horizon spans 46 steps
    trainer = Trainer(TrainConfig(data=str(data), out=str(tmp_path / "run"), batch_size=4, val_ratio=0.0,
                                  time_stride=3, progress=False))
    trainer.close()
    assert trainer.policy.config.time_stride == 3 and trainer.train_set.time_stride == 3


def test_a_resumed_run_with_another_stride_is_refused(tmp_path):
    data = write_reach_store(tmp_path / "reach.zarr", episodes=4)
    train(micro_config(data, tmp_path / "run", steps=1, ckpt_every=1, val_ratio=0.0, batch_size=4))
    with pytest.raises(TrainingConfigError, match=r"time_stride: 1 -> 2"):
        Trainer(micro_config(data, tmp_path / "run", steps=2, val_ratio=0.0, batch_size=4, time_stride=2))
    strided = tmp_path / "strided"
    train(micro_config(data, strided, steps=1, ckpt_every=1, val_ratio=0.0, batch_size=4, time_stride=2))
    with pytest.raises(TrainingConfigError, match=r"time_stride: 2 -> 1"):
        Trainer(micro_config(data, strided, steps=2, val_ratio=0.0, batch_size=4))
    # the same stride resumes; so does a run whose train_config.json predates the field (trained with stride 1),
    # once `lano3dp migrate` has stated it
    Trainer(micro_config(data, strided, steps=2, val_ratio=0.0, batch_size=4, time_stride=2)).close()
    run = tmp_path / "run"
    for path in {run / "train_config.json", *(p.resolve() for p in run.glob("checkpoints/*/train_config.json"))}:
        saved = json.loads(path.read_text())
        del saved["time_stride"]
        path.write_text(json.dumps(saved))
    assert migrate([run])
    Trainer(micro_config(data, tmp_path / "run", steps=2, val_ratio=0.0, batch_size=4)).close()


def test_the_stride_is_checked_where_it_is_given(tmp_path):
    data = write_reach_store(tmp_path / "reach.zarr", episodes=4)
    for bad in (0, -1, 1.5, True):
        with pytest.raises(ValueError, match="time_stride"):
            micro_config(data, tmp_path / "run", time_stride=bad)
    with pytest.raises(ValueError, match="time_stride"):
        PolicyConfig(object_names=("a",), extra={"observation": {"time_stride": 0}})
    # a policy configuration that names another stride than the training one: which was meant is unclear
    config = micro_config(data, tmp_path / "run", time_stride=2)
    config.policy = config.policy.replace(extra={**config.policy.extra, "observation": {"time_stride": 3}})
    with pytest.raises(TrainingConfigError, match="give one stride"):
        Trainer(config)


def test_the_train_command_takes_a_time_stride(tmp_path):
    data = write_reach_store(tmp_path / "reach.zarr", episodes=4, length=12)
    result = CliRunner().invoke(app, ["train", "--data", str(data), "--out", str(tmp_path / "run"), "--steps", "1",
                                      "--batch-size", "2", "--warmup-steps", "1", "--horizon", "8",
                                      "--n-action-steps", "4", "--val-ratio", "0", "--time-stride", "2",
                                      "--no-progress"])
    assert result.exit_code == 0, result.output
    assert DiffusionPolicy.from_pretrained(tmp_path / "run").config.time_stride == 2
    result = CliRunner().invoke(app, ["train", "--data", str(data), "--out", str(tmp_path / "other"),
                                      "--time-stride", "0"])
    assert result.exit_code == 2
    help_text = CliRunner().invoke(app, ["train", "--help"]).output
    assert "--time-stride" in help_text


# ---- execution ---------------------------------------------------------------------------------
def test_interpolation_is_linear_in_position_and_gripper_and_slerps_the_rotation():
    quarter_turn = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    previous = np.concatenate([[0.0, 0, 0], ROT6D, [0.0]]).astype(np.float32)
    target = np.concatenate([[0.4, 0, 0.2], matrix_to_rot6d(quarter_turn), [1.0]]).astype(np.float32)
    steps = interpolate_action(previous, target, 4)
    assert steps.shape == (4, 10) and steps.dtype == np.float32
    np.testing.assert_array_equal(steps[-1], target)
    np.testing.assert_allclose(steps[:, 0], [0.1, 0.2, 0.3, 0.4], atol=1e-6)
    np.testing.assert_allclose(steps[:, 9], [0.25, 0.5, 0.75, 1.0], atol=1e-6)
    # a yaw of 22.5, 45, 67.5 degrees on the way to 90
    yaws = [np.degrees(np.arctan2(m[1, 0], m[0, 0])) for m in rot6d_to_matrix(steps[:, 3:9].astype(np.float64))]
    np.testing.assert_allclose(yaws, [22.5, 45, 67.5, 90], atol=1e-4)
    np.testing.assert_array_equal(interpolate_action(previous, target, 1), target[None])


class CountingEnv:
    """The simulator protocol at its smallest: the EE goes where it is told, the state's opening counts steps."""

    START = np.array([0.0, -0.3, 0.2], np.float32)
    control_hz = 80.0

    def __init__(self, max_steps: int):
        self.max_steps = max_steps
        camera = PinholeCamera(4, 4, np.array([[4.0, 0, 2], [0, 4, 2], [0, 0, 1]]))
        self._frame = RGBDFrame(rgb=np.zeros((4, 4, 3), np.uint8), depth=np.ones((4, 4), np.float32), camera=camera)
        self.actions: list[np.ndarray] = []

    def _obs(self):
        state = np.concatenate([self.position, ROT6D, [float(self.steps), 0.0]]).astype(np.float32)
        return {"frame": self._frame, "state": state}

    def reset(self, *, seed=None, options=None):
        self.position, self.steps, self.actions = self.START.copy(), 0, []
        return self._obs(), {}

    def step(self, action):
        self.actions.append(np.array(action, np.float32))
        self.position, self.steps = np.asarray(action[:3], np.float32), self.steps + 1
        return self._obs(), 0.0, False, self.steps >= self.max_steps, {}

    def frame(self) -> RGBDFrame:
        return self._frame

    def close(self) -> None:
        pass


class RecordingPolicy(ChunkedControl):
    """A real policy whose every chunk is recorded with the env steps its observation window came from."""

    def __init__(self, policy: DiffusionPolicy):
        self.policy, self.config, self.normalizer, self.device = policy, policy.config, policy.normalizer, policy.device
        self.calls: list[dict] = []
        self.reset()

    def predict_action_chunk(self, obs, **options):
        with torch.no_grad():
            chunk = self.policy.predict_action_chunk(obs, **options)
        actions = chunk.actions[0, : self.config.n_action_steps].cpu().numpy().astype(np.float32)
        self.calls.append({"obs_steps": torch.as_tensor(obs["state"])[0, :, 9].int().tolist(), "actions": actions})
        return chunk
