"""Obstacle costs plug into DiffusionPolicy.predict_action_chunk (a tiny untrained network, DDIM-10)."""

import numpy as np
import torch

from lano3dp.guidance import Cylinder, Densified, GuidanceConfig, GuidanceMode, MetricGradient
from lano3dp.policy import DiffusionPolicy, PolicyConfig

TINY = dict(object_names=("target",), down_dims=(16, 32), diffusion_step_embed_dim=16, n_groups=4,
            point_hidden_dims=(16, 32), encoder_out=16, state_feature_dim=16, n_points=16,
            action_frame="absolute")  # the action range below is world positions
# demonstrations spanning 8 cm sideways (x) and 60 cm along the path (y), as in bench/bench_guidance.py
ACTION_MIN = np.array([-0.04, -0.3, 0.1, *[-1.0] * 6, 0.0])
ACTION_MAX = np.array([0.04, 0.3, 0.2, *[1.0] * 6, 1.0])


def make_policy() -> DiffusionPolicy:
    torch.manual_seed(0)
    policy = DiffusionPolicy(PolicyConfig(**TINY))
    policy.set_normalizer({"action": {"min": ACTION_MIN, "max": ACTION_MAX},
                           "state": {"min": -np.ones(11), "max": np.ones(11)},
                           "object_clouds": {"min": np.array([-0.5, -0.5, 0.0]), "max": np.array([0.5, 0.5, 0.3])}})
    return policy


def observation(batch: int) -> dict:
    rng = np.random.default_rng(0)
    return {"object_clouds": rng.uniform(-0.1, 0.1, (batch, 2, 1, 16, 3)).astype(np.float32),
            "state": rng.uniform(-1, 1, (batch, 2, 11)).astype(np.float32)}


def chunk(policy, guidance=None, cost=None, batch=32):
    return policy.predict_action_chunk(observation(batch), guidance=guidance, position_cost=cost, scheduler="ddim",
                                       num_inference_steps=10, generator=torch.Generator().manual_seed(0))


def test_rho_zero_through_the_policy_reproduces_the_unguided_chunk():
    policy = make_policy()
    obstacle = Cylinder((0.0, 0.0), 0.03, held_radius=0.03)
    unguided = chunk(policy)
    guided = chunk(policy, GuidanceConfig(GuidanceMode.CLEAN, 0.0, 100), obstacle)
    assert torch.equal(guided.trajectory, unguided.trajectory)


def test_guidance_on_a_0k_moves_the_policys_waypoints_out_of_the_obstacle():
    policy = make_policy()
    obstacle = Cylinder((0.0, 0.0), 0.08, held_radius=0.03)
    cost = MetricGradient(Densified(obstacle, 4), policy.normalizer.scale("action")[:3])
    unguided = chunk(policy).trajectory[..., :3]
    guided = chunk(policy, GuidanceConfig(GuidanceMode.CLEAN, 0.02, 100), cost).trajectory[..., :3]
    inside = lambda positions: (obstacle.clearance(positions) < 0).float().mean().item()  # noqa: E731
    assert inside(unguided) > 0.05  # an untrained net scatters waypoints over the demo range, many inside
    assert inside(guided) < inside(unguided) / 3
    assert obstacle.clearance(guided).mean() > obstacle.clearance(unguided).mean()
