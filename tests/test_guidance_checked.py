"""Checked execution: re-sample with a larger rho until the executed part is clear, or say it failed."""

import pytest
import torch

from lano3dp.guidance import (
    CheckConfig,
    CollisionError,
    Cylinder,
    Densified,
    GuidanceConfig,
    GuidanceMode,
    checked_sample,
    denoise,
)
from lano3dp.guidance.analytic import GaussianPathPrior, straight_line
from lano3dp.guidance.checked import NO_CLEAR_CHUNK
from lano3dp.guidance.schedulers import DDIMScheduler

HORIZON = 16
LINE = straight_line([0.0, -0.8, 0.0], [0.0, 0.8, 0.0], HORIZON)
OBSTACLE = Cylinder((0.0, 0.0), 0.15, margin=0.05)


def make_sample_fn(obstacle, batch=8, seed=0):
    """A policy stand-in: DDIM-10 on the analytic prior; records the guidance of every call."""
    scheduler = DDIMScheduler(num_train_timesteps=100, beta_schedule="squaredcos_cap_v2", prediction_type="epsilon")
    prior = GaussianPathPrior(LINE, 0.05, scheduler.alphas_cumprod)
    generator = torch.Generator().manual_seed(seed)
    calls = []

    def sample_fn(guidance):
        calls.append(guidance)
        positions = denoise(prior, scheduler, (batch, HORIZON, 3), num_inference_steps=10, generator=generator,
                            guidance=guidance, cost_fn=obstacle)
        return positions, {"call": len(calls)}

    return sample_fn, calls


def test_escalates_rho_until_the_chunk_is_clear():
    sample_fn, calls = make_sample_fn(OBSTACLE)
    result = checked_sample(sample_fn, OBSTACLE, GuidanceConfig(GuidanceMode.CLEAN, 0.02, 100),
                            CheckConfig(max_tries=6, growth=2.0, densify=1))
    assert result.success and result.message == "ok"
    assert result.tries > 1  # rho = 0.02 is too weak on this prior (see test_guidance_sampler)
    assert [g.scale for g in calls] == pytest.approx([0.02 * 2**i for i in range(result.tries)])
    assert result.final_scale == calls[-1].scale == result.guidance.scale
    assert (result.min_clearance >= 0).all()
    assert OBSTACLE.clearance(result.positions).min() >= 0
    assert result.payload == {"call": result.tries}
    assert [a.guidance for a in result.attempts] == calls
    assert result.raise_if_failed() is result


def test_an_unguided_first_try_switches_to_clean_guidance():
    sample_fn, calls = make_sample_fn(OBSTACLE)
    result = checked_sample(sample_fn, OBSTACLE, None, CheckConfig(max_tries=4, initial_scale=0.3, densify=1))
    assert calls[0].mode is GuidanceMode.NONE
    assert calls[1].mode is GuidanceMode.CLEAN and calls[1].scale == 0.3
    assert result.success


def test_reports_failure_when_the_obstacle_blocks_every_path():
    wall = Cylinder((0.0, 0.0), 5.0)  # covers the whole workspace: no chunk can be clear
    sample_fn, calls = make_sample_fn(wall)
    result = checked_sample(sample_fn, wall, GuidanceConfig(GuidanceMode.CLEAN, 0.01, 100),
                            CheckConfig(max_tries=3, growth=4.0))
    assert not result.success
    assert result.message == NO_CLEAR_CHUNK == "no collision-free chunk found"
    assert result.tries == 3 and [g.scale for g in calls] == pytest.approx([0.01, 0.04, 0.16])
    assert result.final_scale == pytest.approx(0.16)
    assert (result.min_clearance < 0).all()
    with pytest.raises(CollisionError, match="no collision-free chunk found: after 3 tries up to rho=0.16"):
        result.raise_if_failed()


def test_only_the_executed_part_must_be_clear():
    sample_fn, calls = make_sample_fn(OBSTACLE)
    # the obstacle sits mid-path (waypoints 6-9); executing the first 4 waypoints is safe without guidance
    result = checked_sample(sample_fn, OBSTACLE, None, CheckConfig(n_execute=4))
    assert result.success and result.tries == 1 and calls[0].mode is GuidanceMode.NONE
    assert OBSTACLE.clearance(result.positions).min() < 0  # the un-executed rest would collide


def test_max_scale_stops_escalating_instead_of_repeating_the_same_try():
    wall = Cylinder((0.0, 0.0), 5.0)
    sample_fn, calls = make_sample_fn(wall)
    result = checked_sample(sample_fn, wall, GuidanceConfig(GuidanceMode.CLEAN, 0.1, 100),
                            CheckConfig(max_tries=10, max_scale=0.4))
    assert [g.scale for g in calls] == pytest.approx([0.1, 0.2, 0.4])
    assert not result.success and result.tries == 3


def test_the_segment_from_the_current_position_is_checked_too():
    pole = Cylinder((0.0, 0.0), 0.02, margin=0.0)

    def sample_fn(guidance):
        return torch.tensor([[[0.0, 0.1, 0.0], [0.0, 0.2, 0.0]]]), None

    assert checked_sample(sample_fn, pole, config=CheckConfig(max_tries=1)).success
    start = torch.tensor([[0.0, -0.1, 0.0]])  # the move from here to the first waypoint crosses the pole
    assert not checked_sample(sample_fn, pole, config=CheckConfig(max_tries=1), start_position=start).success


def test_the_densified_check_catches_neighbouring_waypoints_pushed_to_opposite_sides():
    """Per-waypoint guidance pushes each waypoint out on its own side of a symmetric obstacle; two
    neighbours can end on opposite sides, every waypoint clear, the segment between them not."""
    sample_fn, _ = make_sample_fn(OBSTACLE, batch=32)
    positions, _ = sample_fn(GuidanceConfig(GuidanceMode.CLEAN, 0.64, 100))
    waypoint_clearance = OBSTACLE.clearance(positions).min(-1).values
    segment_clearance = Densified(OBSTACLE, 8).clearance(positions).min(-1).values
    assert (waypoint_clearance >= 0).all()
    split_rate = (segment_clearance < 0).float().mean().item()
    assert split_rate > 0.2
    # guiding on the densified path as well splits fewer (this prior has no smoothness of its own to help)
    dense_fn, _ = make_sample_fn(Densified(OBSTACLE, 4), batch=32)
    dense_positions, _ = dense_fn(GuidanceConfig(GuidanceMode.CLEAN, 0.64, 100))
    assert (Densified(OBSTACLE, 8).clearance(dense_positions).min(-1).values < 0).float().mean() < split_rate / 2
