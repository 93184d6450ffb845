"""A goal-conditioned task: the env hands the policy a goal no camera shows (obs["goal"]), `collect` records it, the
policy normalises, encodes and saves it like its other inputs, and reaches goals it never saw.

The task (tests/goal_reach_env.py): a MuJoCo hand moves to a goal drawn anew every episode; the goal is a site, which
renders nothing. The expert sees obs["goal"]; so does the policy, through its task inputs.
"""

import json
import time

import numpy as np
import pytest
import torch

from goal_reach_env import make_env, reach_expert
from lano3dp import EvalConfig, evaluate
from lano3dp.collect import collect_from_env
from lano3dp.data import EpisodeStore
from lano3dp.policy import DiffusionPolicy, PolicyConfig
from lano3dp.policy.observations import task_inputs_of
from lano3dp.train import TrainConfig, TrainingConfigError, policy_config_for_dataset, train

TINY = dict(down_dims=(32, 64), diffusion_step_embed_dim=16, n_groups=4, point_hidden_dims=(8,), encoder_out=8,
            state_feature_dim=32, n_obs_steps=1, horizon=8, n_action_steps=4)
HELD_OUT_SEED = 10_000  # evaluation goals: seeds no training episode used


@pytest.fixture(scope="module")
def goal_data(tmp_path_factory):
    out = tmp_path_factory.mktemp("goal") / "goal.zarr"
    started = time.process_time()
    result = collect_from_env(make_env, reach_expert, 120, out, slots=["base"], task="reach_goal", n_points=16,
                              image_size=32, follow_through_s=0.5, progress=False)
    assert result.total == 120 and result.failed_seeds == []
    return out, time.process_time() - started


def test_collect_records_the_goal_the_env_hands_over(goal_data):
    store = EpisodeStore.open(goal_data[0])
    episode = store.get_episode(0)
    length = len(episode["action"])
    assert episode["goal"].shape == (length, 3) and episode["goal"].dtype == np.float32
    assert np.all(episode["goal"] == episode["goal"][0])  # one goal per episode ...
    assert not np.allclose(store.get_episode(1)["goal"][0], episode["goal"][0])  # ... drawn anew each
    # the expert ends on the goal; the camera shows only the base block (a site renders nothing)
    assert np.linalg.norm(episode["action"][-1, :3] - episode["goal"][0]) < 0.04
    assert np.abs(episode["object_clouds"][0, 0].mean(0) - [0.05, 0.25, 0.04]).max() < 0.07


def test_a_policy_trained_on_them_reaches_goals_it_never_saw(goal_data, tmp_path):
    data, collect_cpu_s = goal_data
    started = time.process_time()
    policy = policy_config_for_dataset(data, **TINY)
    assert policy.task_inputs == {"goal": 3} and policy.obs_keys == ("object_clouds", "state", "goal")
    checkpoint = train(TrainConfig(data=str(data), out=str(tmp_path / "run"), policy=policy, steps=1500,
                                   batch_size=32, lr=3e-3, warmup_steps=20, val_ratio=0.0, ckpt_every=1500,
                                   val_every=1500, progress=False))
    # the goal is part of the checkpoint's observation spec: its length, its normaliser range, its encoder
    config = json.loads((checkpoint / "config.json").read_text())
    assert config["task_inputs"] == {"goal": 3}
    stats = json.loads((checkpoint / "normalizer.json").read_text())["goal"]
    assert np.all(np.array(stats["min"]) >= [-0.1, -0.15, 0.05])
    assert np.all(np.array(stats["max"]) <= [0.15, 0.15, 0.25])
    assert any(key.startswith("obs_encoder.task_inputs.goal.") for key in DiffusionPolicy.from_pretrained(checkpoint)
               .state_dict())

    report = evaluate(EvalConfig(checkpoint=str(checkpoint), env=make_env, episodes=20, seed=HELD_OUT_SEED))
    held_out = {int(e["seed"]) for e in report["episodes"]}
    assert held_out.isdisjoint(EpisodeStore.open(data).attrs["episode_seeds"])
    assert report["summary"]["success_rate"] >= 0.8, [(e["seed"], e["success"]) for e in report["episodes"]]
    assert collect_cpu_s + time.process_time() - started < 90  # CPU seconds: ~60 when the machine is quiet


def test_a_policy_without_the_goal_it_was_trained_with_says_which_key_is_missing():
    config = PolicyConfig(object_names=("base",), task_inputs={"goal": 3}, **TINY)
    assert config.obs_keys == ("object_clouds", "state", "goal")
    with pytest.raises(KeyError, match=r"takes obs\['goal'\] \(a task input\) but the env's observation has no "
                                       r"'goal' \(it holds frame, state\)"):
        task_inputs_of({"state": np.zeros(11), "frame": None}, ["goal"])
    with pytest.raises(ValueError, match="task_inputs: unknown obs_type 'door'"):
        PolicyConfig(object_names=("base",), task_inputs={"door": 1})
    with pytest.raises(ValueError, match="obs_type 'goal' is a task input"):
        PolicyConfig(obs_type="goal", object_names=("base",))
    policy = DiffusionPolicy(config)
    policy.set_normalizer({"action": {"min": -np.ones(10), "max": np.ones(10)},
                           "state": {"min": -np.ones(11), "max": np.ones(11)},
                           "object_clouds": {"min": -np.ones(3), "max": np.ones(3)},
                           "goal": {"min": -np.ones(3), "max": np.ones(3)}})
    window = {"object_clouds": torch.zeros(1, 1, 1, 16, 3), "state": torch.zeros(1, 1, 11)}
    with pytest.raises(KeyError, match="missing 'goal'"):
        policy.predict_action_chunk(window)
    chunk = policy.predict_action_chunk(window | {"goal": torch.zeros(1, 1, 3)})
    assert chunk.actions.shape == (1, 4, 10)


def test_augmentation_is_refused_for_a_policy_with_task_inputs(goal_data, tmp_path):
    from lano3dp.augment import AugmentConfig

    policy = policy_config_for_dataset(goal_data[0], **TINY)
    with pytest.raises(TrainingConfigError, match=r"--augment moves the scene but not the task inputs \['goal'\]"):
        train(TrainConfig(data=str(goal_data[0]), out=str(tmp_path / "run"), policy=policy, steps=1,
                          batch_size=4, augment=AugmentConfig(), progress=False))
