"""Augmentation moves clouds, hand and actions as one rigid scene; jitter and dropout touch clouds only."""

from __future__ import annotations

import json
import math

import pytest
import torch

from lano3dp.augment import AugmentConfig, augment_batch
from lano3dp.geometry import rot6d_to_matrix


def random_batch(batch: int = 8, steps: int = 2, horizon: int = 16) -> dict:
    generator = torch.Generator().manual_seed(0)
    angle = torch.rand(batch, horizon, generator=generator) * 3
    rotation = torch.stack([angle.cos(), angle.sin(), torch.zeros_like(angle),
                            angle.sin(), -angle.cos(), torch.zeros_like(angle)], dim=-1)  # a top-down yaw
    actions = torch.cat([torch.rand(batch, horizon, 3, generator=generator), rotation,
                         torch.rand(batch, horizon, 1, generator=generator)], dim=-1)
    state = torch.cat([actions[:, :steps, :9], torch.rand(batch, steps, 2, generator=generator)], dim=-1)
    clouds = torch.rand(batch, steps, 2, 32, 3, generator=generator)
    return {"obs": {"object_clouds": clouds, "state": state}, "action": actions}


def test_the_scene_moves_rigidly_and_the_hand_with_it():
    batch = random_batch()
    config = AugmentConfig(shift=0.05, yaw=math.radians(20), jitter=0.0, dropout=0.0)
    moved = augment_batch(batch, "object_clouds", config, torch.Generator().manual_seed(1))
    clouds, moved_clouds = batch["obs"]["object_clouds"], moved["obs"]["object_clouds"]
    # distances from every action position to every cloud point are kept: one rigid motion per sample
    before = torch.cdist(batch["action"][:, :, :3], clouds.flatten(1, 3))
    after = torch.cdist(moved["action"][:, :, :3], moved_clouds.flatten(1, 3))
    torch.testing.assert_close(before, after, atol=1e-5, rtol=0)
    # heights, grippers and the grasp flag do not change; rotations stay rotations
    torch.testing.assert_close(moved["action"][..., 2], batch["action"][..., 2])
    torch.testing.assert_close(moved["action"][..., 9], batch["action"][..., 9])
    torch.testing.assert_close(moved["obs"]["state"][..., 9:], batch["obs"]["state"][..., 9:])
    matrices = rot6d_to_matrix(moved["action"][..., 3:9])
    torch.testing.assert_close(matrices.transpose(-1, -2) @ matrices, torch.eye(3).expand_as(matrices), atol=1e-5,
                               rtol=0)
    shift = (moved_clouds - clouds).mean(dim=(1, 2, 3))[:, :2].abs()
    assert float(shift.max()) > 0.005  # it really moved


def test_jitter_and_dropout_keep_the_cloud_shape_and_leave_actions_alone():
    batch = random_batch()
    config = AugmentConfig(shift=0.0, yaw=0.0, jitter=0.002, dropout=0.5)
    moved = augment_batch(batch, "object_clouds", config, torch.Generator().manual_seed(2))
    assert moved["obs"]["object_clouds"].shape == batch["obs"]["object_clouds"].shape
    torch.testing.assert_close(moved["action"], batch["action"])
    # every point is within a few jitter sigmas of some original point of its own cloud
    original = batch["obs"]["object_clouds"].flatten(0, 2)
    nearest = torch.cdist(moved["obs"]["object_clouds"].flatten(0, 2), original).amin(dim=-1)
    assert float(nearest.max()) < 0.002 * 6


def test_bad_magnitudes_are_refused():
    with pytest.raises(ValueError, match="dropout must be < 1"):
        AugmentConfig(dropout=1.0)


def test_a_training_config_round_trips_its_augmentation():
    from lano3dp.train import TrainConfig

    config = TrainConfig(data="d.zarr", out="run", augment=AugmentConfig(shift=0.01))
    again = TrainConfig.from_dict(json.loads(config.to_json()))
    assert again.augment == AugmentConfig(shift=0.01)
    assert TrainConfig(data="d.zarr", out="run").augment is None
