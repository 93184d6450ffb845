"""Faults: bad input, damaged files, kills and concurrent writers give the right result or one clear line.

One section per class of issue 13: dataset completeness, checkpoint integrity, resume honesty, the CLI's
error boundary, results written as they are made (a killed eval resumes), and one writer per output.
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
import zarr
from typer.testing import CliRunner

from lano3dp.cli import app
from lano3dp.data import EpisodeStore
from lano3dp.data.sequence import NonFiniteDataError
from lano3dp.errors import CorruptFileError
from lano3dp.evaluate import (
    EvalConfig,
    PolicyTaskMismatchError,
    check_task_matches_policy,
    episode_log_path,
    evaluate,
)
from lano3dp.locking import LockedError, WriteLock, lock_path
from lano3dp.policy import DiffusionPolicy, PolicyConfig
from lano3dp.train import Trainer, TrainingConfigError, train
from test_policy import TINY, make_policy, stats_for
from test_train import micro_config, write_reach_store


def tree_digest(folder: Path) -> str:
    digest = hashlib.sha256()
    for path in sorted(Path(folder).rglob("*")):
        if path.is_file():
            digest.update(str(path.relative_to(folder)).encode() + path.read_bytes())
    return digest.hexdigest()


def subprocess_env() -> dict:
    return os.environ | {"OMP_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1", "MUJOCO_GL": "egl"}


@pytest.fixture(scope="module")
def reach_data(tmp_path_factory) -> Path:
    return write_reach_store(tmp_path_factory.mktemp("faults") / "reach.zarr")


# ---- 1. datasets are complete and finite --------------------------------------------------------
def test_a_missing_chunk_file_is_refused_naming_key_and_episode(tmp_path):
    data = write_reach_store(tmp_path / "d.zarr", episodes=3)
    (data / "data" / "action" / "c" / "0" / "0").unlink()
    with pytest.raises(CorruptFileError, match=r"d\.zarr: data/action is missing chunk 0/0 \(rows 0-29, episode 0\)"):
        EpisodeStore.open(data)


def test_arrays_shorter_than_episode_ends_are_refused_naming_the_episode(tmp_path):
    data = write_reach_store(tmp_path / "d.zarr", episodes=3, length=10)
    zarr.open_group(str(data), mode="r+")["data/state"].resize((25, 11))
    with pytest.raises(CorruptFileError, match=r"data/state has 25 rows, but meta/episode_ends says episode 2 ends "
                                               r"at row 30"):
        EpisodeStore.open(data)


def test_an_all_zero_episode_is_stored_and_reads_back(tmp_path):
    store = EpisodeStore.create(tmp_path / "z.zarr")
    store.append_episode({"action": np.zeros((5, 2), np.float32)})  # every chunk is written, even a zero one
    assert EpisodeStore.open(tmp_path / "z.zarr").get_episode(0)["action"].shape == (5, 2)


def test_nan_in_a_validation_episode_is_refused_before_training_and_the_data_is_unchanged(tmp_path):
    data = write_reach_store(tmp_path / "d.zarr", episodes=4)
    state = zarr.open_group(str(data), mode="r+")["data/state"]
    state[33, 2] = np.nan  # episode 3, step 3
    before = tree_digest(data)
    with pytest.raises(NonFiniteDataError, match=r"data/state holds NaN or inf in episode 3 \(step 3"):
        Trainer(micro_config(data, tmp_path / "run", val_ratio=0.25))
    assert tree_digest(data) == before and not (tmp_path / "run" / "checkpoints" / "last").exists()


# ---- 2. checkpoints know their bytes and their skill --------------------------------------------
def _flip_weight_bytes(path: Path) -> None:
    raw = bytearray(path.read_bytes())
    raw[-64:-56] = b"\xff" * 8  # inside the tensor data: the header still parses
    path.write_bytes(bytes(raw))


def test_overwritten_weight_bytes_are_refused_naming_the_file(tmp_path):
    folder = make_policy().save_pretrained(tmp_path / "ckpt")
    DiffusionPolicy.from_pretrained(folder)  # intact: loads
    _flip_weight_bytes(folder / "model.safetensors")
    with pytest.raises(CorruptFileError, match=r"ckpt/model\.safetensors: the weights do not match the checksum"):
        DiffusionPolicy.from_pretrained(folder)


def test_an_fp16_export_loads_and_its_damage_is_named(tmp_path):
    from lano3dp.policy.pretrained import export_fp16

    folder = make_policy(extra={"observation": {"image_size": 128}}).save_pretrained(tmp_path / "ckpt")
    exported = export_fp16(folder, tmp_path / "fp16")
    loaded = DiffusionPolicy.from_pretrained(exported)
    original = DiffusionPolicy.from_pretrained(folder)
    weight = "unet.final_conv.1.weight"
    assert torch.allclose(loaded.state_dict()[weight], original.state_dict()[weight], atol=1e-3)
    _flip_weight_bytes(exported / "model.safetensors")
    with pytest.raises(CorruptFileError, match=r"fp16/model\.safetensors: the weights do not match the checksum"):
        DiffusionPolicy.from_pretrained(exported)


def test_a_checkpoint_refuses_a_task_of_another_skill_and_accepts_its_own():
    config = PolicyConfig(**({"object_names": ("drawer",), "extra": {"skill": "open_drawer", "task": "open_drawer"}}
                             | TINY))
    check_task_matches_policy("open_drawer", config)
    with pytest.raises(PolicyTaskMismatchError, match="trained for skill 'open_drawer'.*not 'close_microwave'"):
        check_task_matches_policy("close_microwave", config)


# ---- 3. resuming keeps what the run was made with ----------------------------------------------
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


# ---- 4. the CLI: one line and an exit code ------------------------------------------------------
@pytest.fixture(scope="module")
def tiny_checkpoint(tmp_path_factory):
    """An untrained tiny open_drawer policy: evaluation needs a checkpoint, not a good one."""
    torch.manual_seed(0)
    policy = DiffusionPolicy(PolicyConfig(**({"object_names": ("drawer",),
                                              "extra": {"skill": "open_drawer", "task": "open_drawer"}} | TINY)))
    policy.set_normalizer(stats_for(policy.config))
    return policy.save_pretrained(tmp_path_factory.mktemp("tiny") / "policy")


def _bad_invocations(tmp: Path, checkpoint: Path, data: Path) -> list[tuple[list[str], int, str]]:
    a_file = tmp / "a_file"
    a_file.write_text("x")
    corrupt = tmp / "corrupt"
    corrupt.mkdir()
    (corrupt / "config.json").write_text("{not json")
    (corrupt / "model.safetensors").write_bytes((checkpoint / "model.safetensors").read_bytes())
    cuda = [] if torch.cuda.is_available() else [(["train", "--data", str(data), "--out", str(tmp / "r"),
                                                    "--device", "cuda"], 2, "CUDA is not available")]
    return [
        (["collect", "--task", "open_drawer", "--episodes", "-3", "--out", str(tmp / "c.zarr")], 2, "--episodes"),
        (["collect", "--task", "open_drawer", "--n-points", "0", "--out", str(tmp / "c.zarr")], 2, "--n-points"),
        (["collect", "--task", "no_such_task", "--out", str(tmp / "c.zarr")], 2, "unknown task 'no_such_task'"),
        (["collect", "--task", "open_drawer", "--variation", "bogus", "--out", str(tmp / "c.zarr")], 2, "bogus"),
        (["collect", "--task", "open_drawer", "--out", str(a_file / "c.zarr")], 2, "a_file is a file"),
        (["video", "--task", "open_drawer", "--out", str(tmp / "v.txt")], 2, "must end in .mp4 or .gif"),
        (["train", "--data", str(tmp / "missing.zarr"), "--out", str(tmp / "r")], 2, "missing.zarr does not exist"),
        (["train", "--data", str(data), "--out", str(a_file / "run")], 2, "a_file is a file"),
        (["train", "--data", str(checkpoint), "--out", str(tmp / "r2")], 1, "policy: unreadable dataset"),
        *cuda,
        (["eval", "--checkpoint", str(checkpoint), "--guidance", "bogus"], 2, "'bogus' is not one of none, noisy"),
        (["eval", "--checkpoint", str(checkpoint), "--task", "nope"], 2, "unknown task 'nope'"),
        (["eval", "--checkpoint", str(checkpoint), "--out", str(a_file / "r.json")], 2, "a_file is a file"),
        (["eval", "--checkpoint", str(corrupt), "--task", "open_drawer", "--out", str(tmp / "r.json")], 1,
         "corrupt/config.json: not a valid policy config"),
        (["eval", "--checkpoint", str(data), "--task", "open_drawer", "--out", str(tmp / "r.json")], 1,
         "no policy checkpoint in"),
        (["eval", "--checkpoint", str(checkpoint), "--task", "close_microwave", "--out", str(tmp / "r.json")], 1,
         "trained for skill 'open_drawer'"),
        (["run", "open the drawer", "--guidance", "bogus"], 2, "'bogus' is not one of"),
        (["run", "open the drawer", "--out", str(a_file)], 2, "is a file; give a folder"),
        (["demo", "--task", "nope", "--out", str(tmp / "demo")], 2, "unknown task 'nope'"),
        (["demo", "--guidance-preset", "fast", "--out", str(tmp / "demo")], 2, "'fast' is not one of"),
        (["guidance-figures", "--analytic", "--obstacle", "0", "0", "0.1", "--out", str(tmp / "g"), "--scheduler",
          "bogus"], 2, "'bogus' is not one of ddpm, ddim"),
        (["plan", "open the drawer", "--registry", str(tmp / "missing.json")], 1, "missing.json"),
    ]


def test_every_command_reports_bad_options_in_one_line_with_its_exit_code(tiny_checkpoint, reach_data, tmp_path):
    runner = CliRunner()
    for args, code, text in _bad_invocations(tmp_path, tiny_checkpoint, reach_data):
        result = runner.invoke(app, args)
        lines = [line for line in result.stderr.splitlines() if line.strip()]
        errors = [line for line in lines if line.startswith("error: ")]
        assert result.exit_code == code, (args, result.output, result.exception)
        assert len(errors) == 1 and text in errors[0], (args, result.stderr)
        assert "Traceback" not in result.output, args
    assert not (tmp_path / "c.zarr").exists() and not (tmp_path / "r.json").exists()  # refused before any work


def test_debug_shows_the_traceback_of_a_user_error(tiny_checkpoint, tmp_path):
    result = CliRunner().invoke(app, ["--debug", "eval", "--checkpoint", str(tiny_checkpoint), "--task",
                                      "close_microwave", "--out", str(tmp_path / "r.json")])
    assert result.exit_code == 1 and isinstance(result.exception, PolicyTaskMismatchError)


def test_the_env_refuses_a_step_after_close():
    from lano3dp.sim import TabletopEnv
    from lano3dp.sim.env import EnvClosedError

    env = TabletopEnv("open_drawer", image_size=32, render_rgb=False)
    env.reset(seed=0)
    env.close()
    with pytest.raises(EnvClosedError, match="closed; make a new one"):
        env.step(np.zeros(10, np.float32))


# ---- 5. a killed evaluation resumes -------------------------------------------------------------
def _without_timing(value):
    """Drop wall-clock measurements (latencies, timings): the only things two equal runs may differ in."""
    if isinstance(value, dict):
        return {k: _without_timing(v) for k, v in value.items()
                if not (k.endswith("_s") or k in ("timing", "command", "out"))}
    if isinstance(value, list):
        return [_without_timing(v) for v in value]
    return value


def test_a_killed_eval_resumes_and_equals_an_uninterrupted_one(tiny_checkpoint, tmp_path):
    episodes, out = 5, tmp_path / "killed.json"
    args = ["eval", "--checkpoint", str(tiny_checkpoint), "--task", "open_drawer", "--episodes", str(episodes),
            "--max-steps", "12", "--out", str(out)]
    process = subprocess.Popen([sys.executable, "-c", "from lano3dp.cli import main; main()", *args],
                               env=subprocess_env(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    log = episode_log_path(out)
    deadline = time.monotonic() + 120
    while process.poll() is None and time.monotonic() < deadline:
        if log.exists() and log.read_text().count("\n") >= 2:  # the header and one finished episode
            break
        time.sleep(0.01)
    process.send_signal(signal.SIGKILL)
    stderr = process.communicate()[1].decode()
    assert process.returncode == -signal.SIGKILL, stderr
    assert not out.exists(), "killed before the end: no results JSON yet"
    with open(log, "a") as handle:
        handle.write('{"index": 4, "epis')  # a line cut short by the kill
    logged = log.read_text().count("\n") - 1
    assert 1 <= logged < episodes

    config = dict(checkpoint=str(tiny_checkpoint), task="open_drawer", episodes=episodes, max_steps=12)
    ran = []
    resumed = evaluate(EvalConfig(**config, out=str(out)), progress=lambda done, total, record: ran.append(done))
    assert resumed["timing"]["resumed_episodes"] == logged and len(ran) == episodes
    evaluate(EvalConfig(**config, out=str(tmp_path / "unbroken.json")))
    assert [e["seed"] for e in resumed["episodes"]] == list(range(1_000_000, 1_000_000 + episodes))
    assert _without_timing(json.loads(out.read_text())) == _without_timing(
        json.loads((tmp_path / "unbroken.json").read_text()))
    assert not lock_path(out).exists()


# ---- 6. one writer per output -------------------------------------------------------------------
HOLD_LOCK = "import sys, time; from lano3dp.locking import WriteLock; lock = WriteLock(sys.argv[1]).acquire(); " \
            "print('held', flush=True); time.sleep(120)"


def _hold_lock(target: Path) -> subprocess.Popen:
    process = subprocess.Popen([sys.executable, "-c", HOLD_LOCK, str(target)], env=subprocess_env(),
                               stdout=subprocess.PIPE, text=True)
    assert process.stdout.readline().strip() == "held"
    return process


def test_a_second_writer_is_refused_with_the_holders_pid(reach_data, tiny_checkpoint, tmp_path):
    from lano3dp.collect import collect

    dataset, run, results = tmp_path / "d.zarr", tmp_path / "run", tmp_path / "r.json"
    holders = [_hold_lock(target) for target in (dataset, run, results)]
    try:
        for holder, attempt in zip(holders, [
            lambda: collect("open_drawer", 1, dataset, progress=False),
            lambda: Trainer(micro_config(reach_data, run)),
            lambda: evaluate(EvalConfig(checkpoint=str(tiny_checkpoint), task="open_drawer", episodes=1,
                                        out=str(results))),
        ], strict=True):
            with pytest.raises(LockedError, match=rf"is being written by process {holder.pid} "):
                attempt()
        assert not dataset.exists() and not run.exists() and not results.exists()  # nothing written
        result = CliRunner().invoke(app, ["train", "--data", str(reach_data), "--out", str(run)])
        assert result.exit_code == 1 and f"being written by process {holders[1].pid}" in result.stderr
    finally:
        for holder in holders:
            holder.kill()
            holder.wait()


def test_a_stale_lock_after_sigkill_does_not_block_the_next_writer(reach_data, tmp_path):
    run = tmp_path / "run"
    holder = _hold_lock(run)
    holder.send_signal(signal.SIGKILL)
    holder.wait()
    assert lock_path(run).read_text().strip() == str(holder.pid)  # the dead writer's lock file is still there
    final = train(micro_config(reach_data, run, steps=1, val_ratio=0.0))
    assert final.name == "step_0000001" and not lock_path(run).exists()
    with WriteLock(run) as lock:
        assert lock.held and lock_path(run).read_text().strip() == str(os.getpid())
