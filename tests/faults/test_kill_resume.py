"""A run killed (SIGKILL) at any point resumes, and the resumed result equals the uninterrupted one: training
(killed half-way through writing a checkpoint), collection (killed at a random moment), evaluation (killed after
an episode, with a line cut short). Resuming keeps what a run was made with."""

from __future__ import annotations

import json
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from faults_common import EXAMPLE_ENV, subprocess_env
from lano3dp.data import EpisodeStore
from lano3dp.locking import lock_path
from lano3dp.policy.checkpoint import load_training_state
from lano3dp.train import Trainer, TrainingConfigError, train
from test_train import micro_config, write_reach_store


def kill(process: subprocess.Popen) -> str:
    process.send_signal(signal.SIGKILL)
    output = process.communicate()[0]
    assert process.returncode == -signal.SIGKILL, output
    return output


def wait_for(condition, process: subprocess.Popen, seconds: float = 120) -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        assert process.poll() is None, process.communicate()[0]
        assert time.monotonic() < deadline, "the process never got there"
        time.sleep(0.01)


# ---- training ----------------------------------------------------------------------------------------------
# Runs `python -m lano3dp.train` with its second checkpoint write held open half-way (the EMA policy written, the
# training state not yet): the kill lands inside atomic_directory, the worst moment for a checkpoint.
KILL_IN_CHECKPOINT = """
import sys, time
import lano3dp.train as train
real, calls = train.save_training_state, []
def held(*args, **kwargs):
    calls.append(1)
    if len(calls) == 2:
        print("writing", flush=True)
        time.sleep(120)
    real(*args, **kwargs)
train.save_training_state = held
sys.exit(train.main(["--config", sys.argv[1]]))
"""


def test_training_killed_while_writing_a_checkpoint_resumes_to_the_uninterrupted_weights(tmp_path):
    """With the recent options on: a time stride, object pose features and their skew, EMA and validation."""
    data = write_reach_store(tmp_path / "reach.zarr", episodes=6, length=24)
    options = dict(steps=9, ckpt_every=3, val_ratio=0.2, val_every=3, time_stride=2)

    def config(out: Path):
        made = micro_config(data, out, **options)
        made.policy = made.policy.replace(object_pose_features=True, object_pose_skew=True)
        return made

    killed = config(tmp_path / "killed")
    (tmp_path / "train.json").write_text(killed.to_json())
    process = subprocess.Popen([sys.executable, "-c", KILL_IN_CHECKPOINT, str(tmp_path / "train.json")],
                               env=subprocess_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines = []
    while (line := process.stdout.readline()) and line.strip() != "writing":  # (validation losses come first)
        lines.append(line)
    assert line.strip() == "writing", "".join(lines)
    checkpoints = tmp_path / "killed" / "checkpoints"
    kill(process)
    half = [p.name for p in checkpoints.iterdir() if p.name.startswith(".step_0000006.tmp-")]
    assert len(half) == 1 and (checkpoints / half[0] / "model.safetensors").exists()  # killed mid-write
    assert (checkpoints / "last").resolve().name == "step_0000003"

    trainer = Trainer(killed)
    assert trainer.step == 3 and not any(p.name.startswith(".step_") for p in checkpoints.iterdir())
    final = trainer.run()
    unbroken = train(config(tmp_path / "unbroken"))
    assert final.name == unbroken.name == "step_0000009"
    resumed_state, unbroken_state = load_training_state(final), load_training_state(unbroken)
    for key, value in unbroken_state.model.items():
        assert torch.allclose(resumed_state.model[key], value, atol=1e-6), key
    assert json.loads((final / "progress.json").read_text())["step"] == 9


def test_resuming_with_another_learning_rate_or_batch_is_refused_naming_old_and_new(reach_data, tmp_path):
    train(micro_config(reach_data, tmp_path / "run", steps=2, ckpt_every=2, val_ratio=0.0))
    with pytest.raises(TrainingConfigError, match=r"batch_size: 8 -> 4; lr: 0\.001 -> 0\.0005"):
        Trainer(micro_config(reach_data, tmp_path / "run", steps=2, val_ratio=0.0, lr=5e-4, batch_size=4))
    other = micro_config(reach_data, tmp_path / "run", steps=2, val_ratio=0.0)
    other.policy = other.policy.replace(point_encoder="mlp")
    with pytest.raises(TrainingConfigError, match=r"point_encoder: 'residual' -> 'mlp'"):
        Trainer(other)


def test_extending_a_run_applies_the_new_step_count_and_records_it(reach_data, tmp_path):
    train(micro_config(reach_data, tmp_path / "run", steps=2, ckpt_every=2, val_ratio=0.0))
    final = train(micro_config(reach_data, tmp_path / "run", steps=4, ckpt_every=2, val_ratio=0.0))
    assert final.name == "step_0000004"
    recorded = json.loads((final / "train_config.json").read_text())["extra"]["resume_changes"]
    assert recorded == [{"at_step": 2, "field": "steps", "old": 2, "new": 4}]


# ---- collection --------------------------------------------------------------------------------------------
SLOW_EXPERT = '''
import os, time

import numpy as np

ROT6D = np.array([1, 0, 0, 0, 1, 0], np.float32)
DELAY = float(os.environ.get("EXPERT_DELAY_S", "0"))  # only the killed run is slowed: the actions are the same


def reach(env, obs, info):
    time.sleep(DELAY)
    block = env.scene.boxes[0]
    return np.r_[block.center_xy, block.size[2] + 0.02, ROT6D, 0.0].astype(np.float32)
'''


def test_collection_killed_at_a_random_moment_resumes_to_the_uninterrupted_dataset(tmp_path):
    from lano3dp.collect import collect_from_env

    (tmp_path / "experts.py").write_text(SLOW_EXPERT)
    env, expert, episodes = f"{EXAMPLE_ENV}:make_env", f"{tmp_path / 'experts.py'}:reach", 8
    out = tmp_path / "d.zarr"
    args = ["collect", "--env", env, "--expert", expert, "--slots", "block", "--episodes", str(episodes),
            "--image-size", "48", "--follow-through", "0", "--no-progress", "--out", str(out)]
    process = subprocess.Popen([sys.executable, "-c", "from lano3dp.cli import main; main()", *args],
                               env=subprocess_env() | {"EXPERT_DELAY_S": "0.03"}, stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)

    def committed() -> int:
        try:
            return EpisodeStore.open(out).n_episodes
        except Exception:  # not created yet, or caught between two writes: look again
            return 0

    wait_for(lambda: committed() >= 1, process)
    time.sleep(random.Random(38).uniform(0.0, 0.25))  # anywhere in the next episode or its append
    kill(process)
    held = committed()
    assert 1 <= held < episodes

    options = dict(slots=["block"], image_size=48, follow_through_s=0.0, progress=False)
    result = collect_from_env(env, expert, episodes, out, **options)
    assert result.added == episodes - held and not lock_path(out).exists()
    collect_from_env(env, expert, episodes, tmp_path / "unbroken.zarr", **options)
    resumed, unbroken = EpisodeStore.open(out), EpisodeStore.open(tmp_path / "unbroken.zarr")
    assert resumed.attrs["episode_seeds"] == unbroken.attrs["episode_seeds"] == list(range(episodes))
    for index in range(episodes):
        for key, value in unbroken.get_episode(index).items():
            np.testing.assert_array_equal(resumed.get_episode(index)[key], value, err_msg=f"{key} of {index}")


# ---- evaluation --------------------------------------------------------------------------------------------
def _without_timing(value):
    """Drop wall-clock measurements (latencies, timings): the only things two equal runs may differ in."""
    if isinstance(value, dict):
        return {k: _without_timing(v) for k, v in value.items()
                if not (k.endswith("_s") or k in ("timing", "command", "out", "provenance"))}
    if isinstance(value, list):
        return [_without_timing(v) for v in value]
    return value


def test_a_killed_eval_resumes_and_equals_an_uninterrupted_one(reach_checkpoint, tmp_path):
    from lano3dp.evaluation import EvalConfig, episode_log_path, evaluate

    episodes, out, env = 4, tmp_path / "killed.json", f"{EXAMPLE_ENV}:make_env"
    args = ["eval", "--checkpoint", str(reach_checkpoint), "--env", env, "--episodes", str(episodes),
            "--max-steps", "6", "--out", str(out)]
    process = subprocess.Popen([sys.executable, "-c", "from lano3dp.cli import main; main()", *args],
                               env=subprocess_env(), stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT, text=True)
    log = episode_log_path(out)
    wait_for(lambda: log.exists() and log.read_text().count("\n") >= 2, process)  # the header and one episode
    kill(process)
    assert not out.exists(), "killed before the end: no results JSON yet"
    with open(log, "a") as handle:
        handle.write('{"index": 3, "epis')  # a line cut short by the kill
    logged = log.read_text().count("\n") - 1
    assert 1 <= logged < episodes

    config = dict(checkpoint=str(reach_checkpoint), env=env, episodes=episodes, max_steps=6)
    ran = []
    resumed = evaluate(EvalConfig(**config, out=str(out)), progress=lambda done, total, record: ran.append(done))
    assert resumed["timing"]["resumed_episodes"] == logged and len(ran) == episodes
    evaluate(EvalConfig(**config, out=str(tmp_path / "unbroken.json")))
    assert [e["seed"] for e in resumed["episodes"]] == list(range(1_000_000, 1_000_000 + episodes))
    assert _without_timing(json.loads(out.read_text())) == _without_timing(
        json.loads((tmp_path / "unbroken.json").read_text()))
    assert not lock_path(out).exists()
