"""Training runs: checkpoints and logs, kill-and-resume, torchrun data-parallel, corrupt inputs."""

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from safetensors.torch import load_file

from lano3dp.data import EpisodeStore
from lano3dp.errors import CorruptFileError
from lano3dp.policy import DiffusionPolicy, PolicyConfig
from lano3dp.policy.checkpoint import load_training_state
from lano3dp.train import (
    TrainConfig,
    Trainer,
    TrainingConfigError,
    cosine_with_warmup,
    policy_config_for_dataset,
    train,
    training_progress,
)

ROT6D = np.array([1, 0, 0, 0, 1, 0], np.float32)
# A model small enough that a step costs a few milliseconds: these tests check the machinery, not learning.
MICRO = dict(down_dims=(8, 16), diffusion_step_embed_dim=8, n_groups=4, point_hidden_dims=(8, 16), encoder_out=8,
             state_feature_dim=8, horizon=8, n_action_steps=4)


def write_reach_store(path: Path, episodes: int = 8, length: int = 10, points: int = 16, seed: int = 0) -> Path:
    """Episodes that move the end effector from a start pose to a point above a one-slot marker cloud."""
    rng = np.random.default_rng(seed)
    store = EpisodeStore.create(path, {"skill": "reach_marker", "object_names": ["marker"]})
    for _ in range(episodes):
        marker = np.array([rng.uniform(-0.2, 0.2), rng.uniform(-0.1, 0.1), 0.0], np.float32)
        cloud = marker + rng.uniform([-0.03, -0.03, 0.0], [0.03, 0.03, 0.1], (points, 3)).astype(np.float32)
        start = np.array([0.0, -0.3, 0.2], np.float32)
        fraction = np.clip(np.arange(1, length + 1) / (length - 2), 0, 1)[:, None].astype(np.float32)
        positions = start + fraction * (marker + [0, 0, 0.1] - start)
        action = np.concatenate([positions, np.tile(ROT6D, (length, 1)), fraction.round()], 1).astype(np.float32)
        ee = np.concatenate([start[None], positions[:-1]])
        state = np.concatenate([ee, np.tile(ROT6D, (length, 1)), np.full((length, 2), [0.04, 0.0])], 1)
        store.append_episode({"action": action, "state": state.astype(np.float32),
                              "object_clouds": np.tile(cloud, (length, 1, 1, 1))})
    return path


def micro_config(data: Path, out: Path, **changes) -> TrainConfig:
    policy = changes.pop("policy", None) or policy_config_for_dataset(data, **MICRO)
    return TrainConfig(**(dict(data=str(data), out=str(out), policy=policy, steps=6, batch_size=8, lr=1e-3,
                               warmup_steps=2, val_ratio=0.25, val_every=3, ckpt_every=3, log_every=1,
                               progress=False) | changes))


@pytest.fixture(scope="module")
def reach_data(tmp_path_factory) -> Path:
    return write_reach_store(tmp_path_factory.mktemp("data") / "reach.zarr")


def _subprocess_env() -> dict:
    return os.environ | {"OMP_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1"}


# ---- configuration -------------------------------------------------------------------------
def test_train_config_round_trips_through_json(reach_data, tmp_path):
    config = micro_config(reach_data, tmp_path / "run", bf16=True, betas=(0.9, 0.99))
    again = TrainConfig.from_dict(json.loads(config.to_json()))
    assert again == config and isinstance(again.policy, PolicyConfig) and again.betas == (0.9, 0.99)
    with pytest.raises(ValueError, match="steps"):
        micro_config(reach_data, tmp_path, steps=0)


def test_default_policy_config_takes_slots_and_points_from_the_dataset(reach_data):
    config = policy_config_for_dataset(reach_data)
    assert config.object_names == ("marker",) and config.n_points == 16
    assert config.extra == {"skill": "reach_marker", "observation": {}}  # this store records no camera or crop


# ---- a run ---------------------------------------------------------------------------------
def test_a_run_writes_ema_checkpoints_logs_and_a_last_pointer(reach_data, tmp_path):
    out = tmp_path / "run"
    final = train(micro_config(reach_data, out))
    checkpoints = out / "checkpoints"
    assert final == checkpoints / "step_0000006"
    assert sorted(p.name for p in checkpoints.iterdir()) == ["last", "step_0000003", "step_0000006"]
    assert (checkpoints / "last").resolve() == final.resolve()
    # The EMA policy is what from_pretrained loads; the raw weights sit in the training state.
    policy = DiffusionPolicy.from_pretrained(out)  # a run folder resolves to checkpoints/last
    state = load_training_state(final)
    assert state.step == 6 and state.extra["world_size"] == 1
    assert state.ema["optimization_step"] == 6
    ema_weights = load_file(str(final / "model.safetensors"))
    assert any(not torch.equal(ema_weights[k], v) for k, v in state.model.items() if v.is_floating_point())
    assert all(torch.equal(policy.state_dict()[k], v) for k, v in ema_weights.items())
    # Only the newest checkpoint keeps the (large) training state; older ones keep their policy.
    assert not (checkpoints / "step_0000003" / "training_state.safetensors").exists()
    assert (checkpoints / "step_0000003" / "model.safetensors").exists()
    assert json.loads((final / "train_config.json").read_text())["steps"] == 6
    # TensorBoard scalars: loss and lr every step, validation loss every 3 steps.
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(out / "tensorboard"))
    events.Reload()
    assert [e.step for e in events.Scalars("loss")] == [1, 2, 3, 4, 5, 6]
    assert [e.step for e in events.Scalars("val_loss")] == [3, 6]
    learning_rates = [e.value for e in events.Scalars("lr")]
    assert learning_rates[:3] == pytest.approx([0.0, 5e-4, 1e-3])  # linear warm-up over 2 steps
    assert learning_rates[2:] == sorted(learning_rates[2:], reverse=True) and learning_rates[-1] < 2e-4  # cosine
    # Training again on a finished run does nothing and returns the same checkpoint.
    assert train(micro_config(reach_data, out)) == final


@pytest.mark.parametrize("obs_type", ["scene", "image"])
def test_the_baselines_train_through_the_same_loop(tmp_path, obs_type):
    rng = np.random.default_rng(0)
    store = EpisodeStore.create(tmp_path / "baseline.zarr", {"skill": "reach_marker"})
    for _ in range(3):
        length = 9
        visual = (rng.uniform(-0.3, 0.3, (length, 64, 3)).astype(np.float32) if obs_type == "scene"
                  else rng.integers(0, 256, (length, 32, 32, 3), dtype=np.uint8))
        store.append_episode({"action": rng.normal(size=(length, 10)).astype(np.float32),
                              "state": rng.normal(size=(length, 11)).astype(np.float32),
                              ("scene_cloud" if obs_type == "scene" else "rgb"): visual})
    policy = policy_config_for_dataset(tmp_path / "baseline.zarr", obs_type=obs_type, **MICRO)
    assert (policy.scene_points, policy.image_size) == ((64, 96) if obs_type == "scene" else (512, 32))
    config = micro_config(tmp_path / "baseline.zarr", tmp_path / "run", policy=policy, steps=2, ckpt_every=2,
                          val_ratio=0.0)
    loaded = DiffusionPolicy.from_pretrained(train(config))
    assert loaded.config.obs_type == obs_type
    obs = {key: value[None] for key, value in store.get_episode(0, [policy.visual_key, "state"]).items()}
    assert loaded.predict_action_chunk(obs, num_inference_steps=2).actions.shape == (1, 4, 10)


def test_a_policy_can_train_on_fewer_points_than_the_dataset_holds(reach_data, tmp_path):
    policy = policy_config_for_dataset(reach_data, **MICRO, n_points=8)  # the dataset holds 16
    trainer = Trainer(micro_config(reach_data, tmp_path / "run", policy=policy, steps=3, val_ratio=0.0))
    seen = []
    trainer.policy.obs_encoder.visual.register_forward_pre_hook(lambda module, args: seen.append(args[0].clone()))
    trainer.run()
    assert [tuple(clouds.shape[-2:]) for clouds in seen] == [(8, 3)] * 3
    assert not torch.equal(seen[0], seen[1])  # a fresh subset every step
    too_many = policy_config_for_dataset(reach_data, **MICRO, n_points=32)
    with pytest.raises(TrainingConfigError, match="holds 16 points per cloud"):
        Trainer(micro_config(reach_data, tmp_path / "other", policy=too_many))


def test_bf16_autocast_trains(reach_data, tmp_path):
    final = train(micro_config(reach_data, tmp_path / "run", bf16=True, steps=2, ckpt_every=2, val_ratio=0.0))
    assert load_training_state(final).step == 2


def test_augmented_training_trains_and_records_the_augmentation(reach_data, tmp_path):
    from lano3dp.augment import AugmentConfig

    final = train(micro_config(reach_data, tmp_path / "run", augment=AugmentConfig(), steps=2, ckpt_every=2,
                               val_ratio=0.0))
    assert load_training_state(final).step == 2
    saved = json.loads((final / "train_config.json").read_text())
    assert saved["augment"]["shift"] == AugmentConfig().shift


def test_a_lifted_training_widens_the_normalisers_heights_by_the_lift(reach_data, tmp_path):
    from lano3dp.augment import AugmentConfig
    from lano3dp.policy import DiffusionPolicy

    plain = DiffusionPolicy.from_pretrained(train(micro_config(reach_data, tmp_path / "plain", steps=1,
                                                               val_ratio=0.0))).normalizer_stats()
    lifted = DiffusionPolicy.from_pretrained(train(micro_config(
        reach_data, tmp_path / "lifted", augment=AugmentConfig(lift=0.03), steps=1, val_ratio=0.0))).normalizer_stats()
    for key in ("action", "state", "object_clouds"):
        np.testing.assert_allclose(lifted[key]["min"][2], plain[key]["min"][2] - 0.03, atol=1e-6)
        np.testing.assert_allclose(lifted[key]["max"][2], plain[key]["max"][2] + 0.03, atol=1e-6)
        np.testing.assert_array_equal(np.delete(lifted[key]["min"], 2), np.delete(plain[key]["min"], 2))


def test_resuming_with_another_policy_configuration_is_refused(reach_data, tmp_path):
    train(micro_config(reach_data, tmp_path / "run", steps=1, val_ratio=0.0))
    other = micro_config(reach_data, tmp_path / "run", steps=2)
    other.policy = other.policy.replace(point_encoder="mlp")
    with pytest.raises(TrainingConfigError, match="another policy configuration"):
        Trainer(other)


def test_a_batch_larger_than_the_dataset_is_a_clear_error(reach_data, tmp_path):
    with pytest.raises(TrainingConfigError, match="lower --batch-size"):
        Trainer(micro_config(reach_data, tmp_path / "run", batch_size=10_000))


# ---- kill and resume -----------------------------------------------------------------------
def test_a_killed_run_resumes_where_its_checkpoint_left_off(reach_data, tmp_path):
    """SIGKILL a training process after its first checkpoint, resume, and end where an unbroken run ends."""
    steps = 150
    config = micro_config(reach_data, tmp_path / "killed", steps=steps, ckpt_every=10, val_ratio=0.0, log_every=50)
    config_path = tmp_path / "train.json"
    config_path.write_text(config.to_json())
    process = subprocess.Popen([sys.executable, "-m", "lano3dp.train", "--config", str(config_path)],
                               env=_subprocess_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    last = tmp_path / "killed" / "checkpoints" / "last"
    deadline = time.monotonic() + 120
    while not last.exists() and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    process.send_signal(signal.SIGKILL)
    output = process.communicate()[0].decode()
    assert process.returncode == -signal.SIGKILL, output
    saved = load_training_state(last.resolve())
    assert 10 <= saved.step < steps, "the run must be killed between its first checkpoint and its end"

    trainer = Trainer(config)  # resumes from the newest checkpoint
    assert trainer.step == saved.step and trainer.resumed_from == last.resolve()
    assert all(torch.equal(trainer.policy.state_dict()[k], v) for k, v in saved.model.items())
    optimizer_state = trainer.optimizer.state_dict()["state"]
    for index, entries in saved.optimizer["state"].items():
        for name, value in entries.items():
            assert torch.equal(optimizer_state[index][name], value), f"optimizer {index}.{name} not restored"
    ema_saved = load_file(str(last.resolve() / "model.safetensors"))
    assert all(torch.equal(trainer.ema.model.state_dict()[k], v) for k, v in ema_saved.items())
    assert trainer.ema.optimization_step == saved.step
    assert trainer.lr_scheduler.last_epoch == saved.step
    final = trainer.run()
    assert final.name == f"step_{steps:07d}" and load_training_state(final).step == steps

    # Randomness is a function of (seed, rank, step), so the resumed run equals an unbroken one.
    unbroken = train(micro_config(reach_data, tmp_path / "unbroken", steps=steps, ckpt_every=steps, val_ratio=0.0))
    resumed_weights, unbroken_weights = load_training_state(final).model, load_training_state(unbroken).model
    for key, value in unbroken_weights.items():
        assert torch.allclose(resumed_weights[key], value, atol=1e-6), key


def test_the_learning_rate_schedule_follows_whichever_ends_first_steps_or_cpu_budget():
    # 1000 planned steps, 60 CPU-s budget: at step 100 with 30 CPU-s spent, the budget is half gone.
    assert training_progress(100, 1000, 30.0, 1.0) == pytest.approx(0.5)
    assert training_progress(800, 1000, 30.0, 1.0) == pytest.approx(0.8)  # steps ahead of the budget
    assert training_progress(100, 1000, 30.0, None) == pytest.approx(0.1)  # no budget: steps alone
    assert training_progress(100, 1000, 90.0, 1.0) == 1.0
    assert cosine_with_warmup(0.0, 5, 10, 1000) == pytest.approx(0.5)  # warm-up counts steps
    assert cosine_with_warmup(0.5, 500, 0, 1000) == pytest.approx(0.5)
    assert cosine_with_warmup(1.0, 600, 0, 1000) == pytest.approx(0.0)


def test_a_run_its_budget_stops_early_still_ends_with_the_learning_rate_decayed(reach_data, tmp_path):
    """A probe that under-priced the steps (a machine that got busier) must not leave the final weights
    trained at a high rate: the cosine follows the CPU budget and reaches 0 where the budget ends."""
    config = micro_config(reach_data, tmp_path / "budget", steps=1_000_000, warmup_steps=5, cpu_minutes=2 / 60,
                          ckpt_every=1_000_000, val_ratio=0.0, log_every=1)
    trainer = Trainer(config)
    rates = []
    open_writer = trainer._writer

    def recording_writer():  # the run logs the rate each step used
        writer = open_writer()
        log = writer.add_scalar
        writer.add_scalar = lambda name, value, step: (rates.append(value) if name == "lr" else None,
                                                       log(name, value, step))
        return writer

    trainer._writer = recording_writer
    trainer.run()
    assert trainer.stopped_by_budget and trainer.step < 0.01 * config.steps
    assert max(rates) == pytest.approx(config.lr, rel=0.05), "the rate must reach its peak after warm-up"
    assert rates[-1] < 0.05 * config.lr, f"last step at {rates[-1]:.2e}, not decayed"
    middle = rates[len(rates) // 2]
    assert 0.2 * config.lr < middle < 0.8 * config.lr, "half-way through the budget the cosine is half-way down"


# ---- torchrun ------------------------------------------------------------------------------
DDP_SCRIPT = textwrap.dedent("""
    import json, sys
    from safetensors.torch import save_file
    from lano3dp.train import TrainConfig, Trainer

    config = TrainConfig.from_dict(json.load(open(sys.argv[1])))
    trainer = Trainer(config)
    first_batch = trainer._batches(0, 0)[0]
    trainer.run()
    state = {k: v.contiguous() for k, v in trainer.policy.state_dict().items()}
    save_file(state, f"{config.out}/rank{trainer.rank}.safetensors")
    json.dump({"world_size": trainer.world_size, "step": trainer.step, "first_batch": first_batch},
              open(f"{config.out}/rank{trainer.rank}.json", "w"))
""")


def test_torchrun_two_cpu_processes_train_one_model(reach_data, tmp_path):
    out = tmp_path / "ddp"
    config = micro_config(reach_data, out, steps=4, batch_size=4, ckpt_every=4, val_ratio=0.0)
    (tmp_path / "train.json").write_text(config.to_json())
    (tmp_path / "ddp_train.py").write_text(DDP_SCRIPT)
    result = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2",
                             str(tmp_path / "ddp_train.py"), str(tmp_path / "train.json")],
                            env=_subprocess_env(), capture_output=True, text=True, timeout=240)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    ranks = [json.loads((out / f"rank{r}.json").read_text()) for r in (0, 1)]
    assert [r["world_size"] for r in ranks] == [2, 2] and [r["step"] for r in ranks] == [4, 4]
    assert not set(ranks[0]["first_batch"]) & set(ranks[1]["first_batch"]), "ranks must see different windows"
    weights = [load_file(str(out / f"rank{r}.safetensors")) for r in (0, 1)]
    assert all(torch.equal(weights[0][k], weights[1][k]) for k in weights[0]), "ranks ended with different weights"
    # Rank 0 alone wrote the checkpoint, and it holds the shared weights.
    state = load_training_state(out / "checkpoints" / "step_0000004")
    assert state.extra["world_size"] == 2
    assert all(torch.equal(state.model[k], weights[0][k]) for k in weights[0])
    initial = DiffusionPolicy(config.policy)
    assert any(not torch.equal(initial.state_dict()[k], v) for k, v in weights[0].items()
               if k.startswith("unet.")), "training must have changed the weights"


# ---- corrupt inputs ------------------------------------------------------------------------
def test_a_corrupt_dataset_is_a_corrupt_file_error_naming_it(reach_data, tmp_path):
    import shutil

    data = tmp_path / "broken.zarr"
    shutil.copytree(reach_data, data)
    chunk = next(p for p in (data / "data" / "action").rglob("*") if p.is_file() and p.name != "zarr.json")
    chunk.write_bytes(chunk.read_bytes()[:7])
    with pytest.raises(CorruptFileError, match="broken.zarr"):
        Trainer(micro_config(data, tmp_path / "run"))
    (data / "zarr.json").write_text("{ garbage")
    with pytest.raises(CorruptFileError, match="broken.zarr"):
        Trainer(micro_config(data, tmp_path / "run"))


def test_a_truncated_checkpoint_is_named_when_resuming(reach_data, tmp_path):
    out = tmp_path / "run"
    final = train(micro_config(reach_data, out, steps=2, ckpt_every=2, val_ratio=0.0))
    state_file = final / "training_state.safetensors"
    state_file.write_bytes(state_file.read_bytes()[:1000])
    with pytest.raises(CorruptFileError, match="training_state.safetensors"):
        Trainer(micro_config(reach_data, out, steps=4, val_ratio=0.0))
    train(micro_config(reach_data, tmp_path / "run2", steps=2, ckpt_every=2, val_ratio=0.0))
    weights = tmp_path / "run2" / "checkpoints" / "step_0000002" / "model.safetensors"
    weights.write_bytes(weights.read_bytes()[:-10])
    with pytest.raises(CorruptFileError, match="model.safetensors"):
        Trainer(micro_config(reach_data, tmp_path / "run2", steps=4, val_ratio=0.0))
