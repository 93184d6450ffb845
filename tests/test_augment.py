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


def test_a_lift_moves_clouds_hand_and_actions_up_or_down_together_and_nothing_else():
    batch = random_batch()
    config = AugmentConfig(shift=0.0, yaw=0.0, jitter=0.0, dropout=0.0, lift=0.03)
    moved = augment_batch(batch, "object_clouds", config, torch.Generator().manual_seed(3))
    dz = moved["action"][:, 0, 2] - batch["action"][:, 0, 2]  # one lift per window
    assert float(dz.abs().max()) <= 0.03 and float(dz.abs().max()) > 0.01 and bool((dz < 0).any() and (dz > 0).any())
    torch.testing.assert_close(moved["action"][..., 2] - batch["action"][..., 2], dz[:, None].expand(-1, 16))
    torch.testing.assert_close(moved["obs"]["state"][..., 2] - batch["obs"]["state"][..., 2], dz[:, None].expand(-1, 2))
    clouds_dz = moved["obs"]["object_clouds"][..., 2] - batch["obs"]["object_clouds"][..., 2]
    torch.testing.assert_close(clouds_dz, dz.view(-1, 1, 1, 1).expand_as(clouds_dz))
    for key in ("action",):
        torch.testing.assert_close(moved[key][..., [0, 1, *range(3, 10)]], batch[key][..., [0, 1, *range(3, 10)]])


def test_without_a_lift_the_random_stream_is_the_one_recipes_were_trained_with():
    batch = random_batch()
    before = augment_batch(batch, "object_clouds", AugmentConfig(), torch.Generator().manual_seed(4))
    after = augment_batch(batch, "object_clouds", AugmentConfig(lift=0.0), torch.Generator().manual_seed(4))
    torch.testing.assert_close(before["action"], after["action"])
    torch.testing.assert_close(before["obs"]["object_clouds"], after["obs"]["object_clouds"])


def test_the_normaliser_range_covers_what_a_lift_reaches():
    import numpy as np

    from lano3dp.augment import widened_stats

    stats = {key: {"min": np.zeros(dim), "max": np.ones(dim)} for key, dim in
             (("action", 10), ("state", 11), ("object_clouds", 3))}
    wide = widened_stats(stats, AugmentConfig(lift=0.03), "object_clouds")
    for key in stats:
        assert wide[key]["min"][2] == -0.03 and wide[key]["max"][2] == 1.03
        np.testing.assert_array_equal(np.delete(wide[key]["min"], 2), np.delete(stats[key]["min"], 2))
    assert stats["action"]["min"][2] == 0.0  # the caller's statistics are not changed
    assert widened_stats(stats, AugmentConfig(), "object_clouds") is stats


def test_a_stretch_scales_every_height_about_the_table_by_one_factor_per_window():
    batch = random_batch()
    config = AugmentConfig(shift=0.0, yaw=0.0, jitter=0.0, dropout=0.0, stretch=0.2)
    moved = augment_batch(batch, "object_clouds", config, torch.Generator().manual_seed(5))
    factor = moved["action"][:, 0, 2] / batch["action"][:, 0, 2]
    assert float((factor - 1).abs().max()) <= 0.2 and float((factor - 1).abs().max()) > 0.05
    torch.testing.assert_close(moved["action"][..., 2], batch["action"][..., 2] * factor[:, None])
    torch.testing.assert_close(moved["obs"]["state"][..., 2], batch["obs"]["state"][..., 2] * factor[:, None])
    torch.testing.assert_close(moved["obs"]["object_clouds"][..., 2],
                               batch["obs"]["object_clouds"][..., 2] * factor.view(-1, 1, 1, 1))
    torch.testing.assert_close(moved["action"][..., :2], batch["action"][..., :2])  # nothing moves sideways


def test_the_normaliser_range_covers_what_a_stretch_reaches():
    import numpy as np

    from lano3dp.augment import widened_stats

    stats = {key: {"min": np.full(dim, 0.06), "max": np.full(dim, 0.30)} for key, dim in
             (("action", 10), ("state", 11), ("object_clouds", 3))}
    wide = widened_stats(stats, AugmentConfig(stretch=0.2), "object_clouds")
    assert wide["action"]["min"][2] == pytest.approx(0.048) and wide["action"]["max"][2] == pytest.approx(0.36)
