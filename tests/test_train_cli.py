"""`lano3dp train` on the command line."""

import json
import math

import pytest
from typer.testing import CliRunner

from lano3dp.cli import app
from lano3dp.policy import DiffusionPolicy


def _reach_store(tmp_path):
    from test_train import write_reach_store

    return write_reach_store(tmp_path / "reach.zarr", episodes=4)


def test_train_command_trains_a_loadable_policy(tmp_path):
    data = _reach_store(tmp_path)
    result = CliRunner().invoke(app, ["train", "--data", str(data), "--out", str(tmp_path / "run"), "--steps", "2",
                                      "--batch-size", "4", "--warmup-steps", "1", "--horizon", "8",
                                      "--n-action-steps", "4", "--encoder", "mlp", "--val-ratio", "0",
                                      "--ckpt-every", "2", "--no-progress", "--seed", "3"])
    assert result.exit_code == 0, result.output
    assert "step_0000002" in result.output
    policy = DiffusionPolicy.from_pretrained(tmp_path / "run")
    assert policy.config.point_encoder == "mlp" and policy.config.down_dims == (48, 96, 192)
    assert policy.config.object_names == ("marker",) and policy.config.horizon == 8
    saved = json.loads((tmp_path / "run" / "train_config.json").read_text())
    assert saved["seed"] == 3 and saved["steps"] == 2


@pytest.mark.parametrize("skew", [False, True])
def test_train_command_pose_features_reach_the_policy(tmp_path, skew):
    data = _reach_store(tmp_path)
    result = CliRunner().invoke(app, ["train", "--data", str(data), "--out", str(tmp_path / "run"), "--steps", "1",
                                      "--batch-size", "4", "--warmup-steps", "0", "--horizon", "8",
                                      "--n-action-steps", "4", "--val-ratio", "0", "--no-progress",
                                      "--pose-features"] + (["--pose-skew"] if skew else []))
    assert result.exit_code == 0, result.output
    config = DiffusionPolicy.from_pretrained(tmp_path / "run").config
    assert config.object_pose_features and config.object_pose_skew is skew


def test_train_command_reports_a_dataset_that_lacks_the_observation(tmp_path):
    data = _reach_store(tmp_path)
    result = CliRunner().invoke(app, ["train", "--data", str(data), "--out", str(tmp_path / "run"),
                                      "--obs-type", "scene", "--no-progress"])
    assert result.exit_code == 1
    assert "scene_cloud" in result.output


def test_train_command_rejects_more_points_than_the_dataset_has(tmp_path):
    data = _reach_store(tmp_path)
    result = CliRunner().invoke(app, ["train", "--data", str(data), "--out", str(tmp_path / "run"),
                                      "--n-points", "64", "--no-progress"])
    assert result.exit_code == 1 and "holds 16 points per cloud" in result.output


def test_train_help_lists_the_options():
    result = CliRunner().invoke(app, ["train", "--help"])
    assert result.exit_code == 0
    for option in ("--data", "--out", "--size", "--obs-type", "--encoder", "--n-points", "--bf16", "--ckpt-every"):
        assert option in result.output


def test_train_command_turns_the_augmentation_by_the_yaw_asked(tmp_path):
    data = _reach_store(tmp_path)
    base = ["train", "--data", str(data), "--out", str(tmp_path / "run"), "--steps", "1", "--batch-size", "4",
            "--warmup-steps", "0", "--horizon", "8", "--n-action-steps", "4", "--val-ratio", "0", "--no-progress"]
    refused = CliRunner().invoke(app, base + ["--augment-yaw", "45"])
    assert refused.exit_code == 2 and "--augment-yaw needs --augment" in refused.output
    result = CliRunner().invoke(app, base + ["--augment", "--augment-yaw", "45"])
    assert result.exit_code == 0, result.output
    saved = json.loads((tmp_path / "run" / "train_config.json").read_text())
    assert saved["augment"]["yaw"] == pytest.approx(math.radians(45))
