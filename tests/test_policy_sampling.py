"""Sampling a shipped policy: the own DDPM/DDIM steps give the chunks diffusers gave, and every tensor the sampler
makes follows the policy's device and dtype."""

import numpy as np
import pytest
import torch

from lano3dp.guidance import Cylinder, GuidanceConfig, GuidanceMode, denoise, obstacle_guidance_cost
from lano3dp.guidance.schedulers import DDIMScheduler, DDPMScheduler
from lano3dp.policy import DiffusionPolicy
from lano3dp.policy.pretrained import packaged_checkpoint


@pytest.fixture(scope="module")
def policy():
    return DiffusionPolicy.from_pretrained(packaged_checkpoint("bowl_pour"))


def observation(policy, seed: int, batch: int = 1) -> dict[str, np.ndarray]:
    """Object clouds round random centres in the workspace and a state inside the training range."""
    rng = np.random.default_rng(seed)
    config = policy.config
    stats = policy.normalizer_stats()["state"]
    state = rng.uniform(stats["min"], stats["max"], size=(batch, 1, config.state_dim))
    centres = rng.uniform([0.3, -0.3, 0.05], [0.7, 0.3, 0.15], size=(batch, 1, config.n_slots, 1, 3))
    clouds = centres + rng.normal(0, 0.03, size=(batch, 1, config.n_slots, config.n_points, 3))
    return {"object_clouds": clouds.astype(np.float32), "state": state.astype(np.float32)}


def guided_sampling(plain_trajectory: torch.Tensor, kind: str) -> dict:
    """Guidance that moves the chunk: a cylinder just beside the middle of an unguided trajectory (1, H, D)."""
    middle = plain_trajectory[0, 8, :2].double().cpu().numpy()
    cost = obstacle_guidance_cost([Cylinder(middle + 0.01, 0.04)])
    guidance = GuidanceConfig(GuidanceMode.CLEAN, scale=1.0, last_steps=100 if kind == "ddim" else 10,
                              guided_clip_range=3.0)
    return dict(guidance=guidance, position_cost=cost)


@pytest.mark.parametrize("kind,steps,seeds", [("ddim", 10, (0, 1)), ("ddpm", 100, (0,))])
def test_the_shipped_policy_samples_the_chunks_diffusers_sampled(policy, kind, steps, seeds):
    """Same policy, same seeds, the scheduler swapped for diffusers' (what the policy used before): equal to 1e-6,
    unguided and guided (the guided sampler reads the scheduler's abar and clipping)."""
    diffusers = pytest.importorskip("diffusers")
    process = dict(num_train_timesteps=100, beta_schedule="squaredcos_cap_v2", clip_sample=True,
                   prediction_type="epsilon")
    reference = (diffusers.DDPMScheduler(variance_type="fixed_small", **process) if kind == "ddpm"
                 else diffusers.DDIMScheduler(set_alpha_to_one=True, steps_offset=0, **process))

    def sample(obs, seed, scheduler, **options):
        return policy.predict_action_chunk(obs, scheduler=scheduler, num_inference_steps=steps,
                                           generator=torch.Generator().manual_seed(seed), **options).trajectory

    for seed in seeds:
        obs = observation(policy, seed)
        plain = sample(obs, seed, kind)
        torch.testing.assert_close(plain, sample(obs, seed, reference), rtol=0, atol=1e-6)
        guided = guided_sampling(plain, kind)
        pushed = sample(obs, seed, kind, **guided)
        torch.testing.assert_close(pushed, sample(obs, seed, reference, **guided), rtol=0, atol=1e-6)
        assert float((pushed - plain)[..., :3].norm(dim=-1).max()) > 0.01  # guidance acted (metres)


@pytest.mark.parametrize("kind", ["ddim", "ddpm"])
def test_a_float64_policy_samples_in_float64(policy, kind):
    """Noise, timesteps, schedule and anchor all follow the weights' dtype, guided or not. DDIM from the same A_T
    lands where the float32 policy does (DDPM's z drawn in float64 are other numbers, so only its dtype is checked)."""
    obs = observation(policy, 0)
    wide = DiffusionPolicy.from_pretrained(packaged_checkpoint("bowl_pour")).to(torch.float64)
    initial = torch.randn(1, 16, 10, generator=torch.Generator().manual_seed(5))
    plain = policy.predict_action_chunk(obs, scheduler="ddim", generator=torch.Generator().manual_seed(0))
    for options in ({}, guided_sampling(plain.trajectory, kind)):
        double = wide.predict_action_chunk(obs, scheduler=kind, num_inference_steps=10,
                                           generator=torch.Generator().manual_seed(0), **options)
        assert double.trajectory.dtype == double.actions.dtype == torch.float64
        if kind == "ddim":
            single = policy.predict_action_chunk(obs, scheduler=kind, initial_noise=initial, **options)
            double = wide.predict_action_chunk(obs, scheduler=kind, initial_noise=initial, **options)
            assert float((double.trajectory - single.trajectory.double()).abs().max()) < 1e-4


@pytest.mark.parametrize("scheduler", [DDIMScheduler(), DDPMScheduler()], ids=["ddim", "ddpm"])
def test_every_tensor_the_sampler_makes_is_on_the_networks_device(scheduler):
    """On the meta device (shapes only, no data): a tensor made on the CPU would reach the network and fail here."""
    seen = []

    def noise_fn(sample, timesteps):
        seen.append((sample.device.type, timesteps.device.type, sample.dtype))
        return torch.zeros_like(sample)

    out = denoise(noise_fn, scheduler, (2, 16, 10), num_inference_steps=10, device="meta", dtype=torch.float64,
                  generator=torch.Generator().manual_seed(0))
    assert (out.device.type, out.dtype) == ("meta", torch.float64)
    assert set(seen) == {("meta", "meta", torch.float64)} and len(seen) == 10


def test_a_cpu_generator_gives_the_same_first_noise_on_any_device():
    """A_T is drawn on the generator's device and moved: the sampler's seed means the same on CPU and elsewhere."""
    captured = {}

    def noise_fn(sample, timesteps):
        captured.setdefault(sample.device.type, sample)
        return torch.zeros_like(sample)

    scheduler = DDIMScheduler()
    denoise(noise_fn, scheduler, (1, 16, 10), num_inference_steps=1, generator=torch.Generator().manual_seed(4))
    assert torch.equal(captured["cpu"], torch.randn(1, 16, 10, generator=torch.Generator().manual_seed(4)))


def test_one_generator_per_observation_samples_each_as_it_would_be_alone(policy):
    """What batched rollouts need: an episode's chunk does not depend on the episodes batched with it."""
    obs = observation(policy, 3, batch=2)
    for kind in ("ddim", "ddpm"):
        together = policy.predict_action_chunk(obs, scheduler=kind, num_inference_steps=10,
                                               generator=[torch.Generator().manual_seed(s) for s in (11, 12)])
        for row, seed in enumerate((11, 12)):
            alone = policy.predict_action_chunk({key: value[row:row + 1] for key, value in obs.items()},
                                                scheduler=kind, num_inference_steps=10,
                                                generator=torch.Generator().manual_seed(seed))
            torch.testing.assert_close(together.trajectory[row:row + 1], alone.trajectory, rtol=0, atol=1e-5)


