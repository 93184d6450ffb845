"""A checkpoint acts without its dataset, refuses another skill's task, and ships as fp16 package data."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import torch
from safetensors import safe_open
from typer.testing import CliRunner

from lano3dp.cli import app
from lano3dp.evaluation import EvalConfig, PolicyBundle, PolicyTaskMismatchError, evaluate
from lano3dp.evaluation.episodes import EpisodeRunner
from lano3dp.guidance.settings import guidance_preset
from lano3dp.policy import DiffusionPolicy, pretrained
from lano3dp.policy.pretrained import PackagedCheckpointNotFoundError, export_fp16, packaged_checkpoint

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def moved_checkpoint(tmp_path_factory):
    """A tiny bowl_pour policy whose training dataset was deleted after training."""
    from lano3dp.collect import collect
    from lano3dp.train import TrainConfig, policy_config_for_dataset, train

    root = tmp_path_factory.mktemp("pretrained")
    data = root / "bowl_pour.zarr"
    collect("bowl_pour", 2, data, image_size=48, n_points=32, progress=False, crop_low=(0.0, -0.5, 0.01),
            crop_high=(0.9, 0.5, 0.5))
    policy = policy_config_for_dataset(data, down_dims=(16, 32), point_hidden_dims=(16,), encoder_out=16,
                                       state_feature_dim=16, diffusion_step_embed_dim=16, n_groups=4)
    trained = train(TrainConfig(data=str(data), out=str(root / "run"), policy=policy, steps=4, batch_size=8,
                                 warmup_steps=1, val_ratio=0.0, progress=False))
    before = evaluate(EvalConfig(checkpoint=str(trained), task="bowl_pour", episodes=2, max_steps=12))
    checkpoint = root / "copied"  # a new folder; the run and the dataset are then gone
    shutil.copytree(trained, checkpoint)
    shutil.rmtree(root / "run")
    shutil.rmtree(data)
    return root, checkpoint, before


def episodes_without_timing(result: dict) -> list[dict]:
    return [{key: value for key, value in episode.items() if "latency" not in key and not key.endswith("_s")}
            for episode in result["episodes"]]


def test_a_copied_checkpoint_without_its_dataset_evaluates_exactly_as_before(moved_checkpoint):
    _, checkpoint, before = moved_checkpoint
    after = evaluate(EvalConfig(checkpoint=str(checkpoint), task="bowl_pour", episodes=2, max_steps=12))
    assert episodes_without_timing(after) == episodes_without_timing(before)


def test_a_checkpoint_keeps_its_observation_settings_when_the_dataset_is_gone(moved_checkpoint):
    _, checkpoint, _ = moved_checkpoint
    bundle = PolicyBundle.load(checkpoint)
    settings = bundle.observation
    assert bundle.task == "bowl_pour" and settings.image_size == 48 and settings.n_points == 32
    assert settings.crop_low == (0.0, -0.5, 0.01) and settings.crop_high == (0.9, 0.5, 0.5)


def test_a_checkpoint_refuses_a_task_of_another_skill(moved_checkpoint):
    _, checkpoint, _ = moved_checkpoint
    with pytest.raises(PolicyTaskMismatchError, match="trained for skill 'bowl_pour'.*not 'open_drawer'"):
        EpisodeRunner(EvalConfig(checkpoint=str(checkpoint), task="open_drawer", episodes=1), guidance_preset("none"))
    result = CliRunner().invoke(app, ["eval", "--checkpoint", str(checkpoint), "--task", "open_drawer",
                                      "--episodes", "1", "--out", str(moved_checkpoint[0] / "wrong.json")])
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert "trained for skill 'bowl_pour'" in result.output


def test_fp16_export_halves_the_weights_and_keeps_the_statistics_exact(moved_checkpoint, tmp_path):
    root, checkpoint, _ = moved_checkpoint
    out = export_fp16(checkpoint, tmp_path / "bowl_pour", record={"success_rate": 0.0})
    with safe_open(str(out / "model.safetensors"), "pt") as weights:
        dtypes = {name: weights.get_slice(name).get_dtype() for name in weights.keys()}
    assert {d for n, d in dtypes.items() if not n.startswith("normalizer.")} == {"F16"}
    assert {d for n, d in dtypes.items() if n.startswith("normalizer.")} == {"F32", "BOOL"}  # stats, fitted flag
    full, half = DiffusionPolicy.from_pretrained(checkpoint), DiffusionPolicy.from_pretrained(out)
    for key, value in full.normalizer.state_dict().items():
        assert torch.equal(value, half.normalizer.state_dict()[key])
    rng = np.random.default_rng(0)
    obs = {"object_clouds": rng.uniform(-0.2, 0.4, (1, 1, 2, 32, 3)).astype(np.float32),
           "state": rng.uniform(-0.1, 0.4, (1, 1, 11)).astype(np.float32)}
    noise = torch.randn(1, 16, 10, generator=torch.Generator().manual_seed(0))
    a = full.predict_action_chunk(obs, initial_noise=noise).trajectory
    b = half.predict_action_chunk(obs, initial_noise=noise).trajectory
    assert float((a - b).abs().max()) < 5e-3  # metres / rotation units: fp16 rounding of the weights only
    assert json.loads((out / "record.json").read_text()) == {"success_rate": 0.0}


def test_eval_finds_the_packaged_policy_by_task_name(moved_checkpoint, tmp_path, monkeypatch):
    root, checkpoint, _ = moved_checkpoint
    monkeypatch.setattr(pretrained, "PACKAGED_ROOT", tmp_path / "checkpoints")
    export_fp16(checkpoint, tmp_path / "checkpoints" / "bowl_pour")
    assert packaged_checkpoint("bowl_pour") == tmp_path / "checkpoints" / "bowl_pour"
    with pytest.raises(PackagedCheckpointNotFoundError, match="no packaged policy for 'open_drawer'.*bowl_pour"):
        packaged_checkpoint("open_drawer")
    out = tmp_path / "packaged.json"
    result = CliRunner().invoke(app, ["eval", "--task", "bowl_pour", "--episodes", "1", "--max-steps", "8",
                                      "--out", str(out)])
    assert result.exit_code == 0, result.output + repr(result.exception)
    assert json.loads(out.read_text())["summary"]["episodes"] == 1
    result = CliRunner().invoke(app, ["eval", "--task", "open_drawer", "--episodes", "1"])
    assert result.exit_code == 1 and "no packaged policy for 'open_drawer'" in result.output
