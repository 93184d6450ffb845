"""The guided denoising loop (Algorithm 1) on an exact Gaussian prior: no training needed.

The prior is a straight path through a cylinder, so unguided samples collide and guidance has
something to do.
"""

import pytest
import torch

from lano3dp.guidance import Cylinder, GuidanceConfig, GuidanceError, GuidanceMode, denoise
from lano3dp.guidance.analytic import GaussianPathPrior, straight_line
from lano3dp.guidance.schedulers import DDIMScheduler, DDPMScheduler

BATCH, HORIZON = 32, 16
SHAPE = (BATCH, HORIZON, 3)
LINE = straight_line([0.0, -0.8, 0.0], [0.0, 0.8, 0.0], HORIZON)
OBSTACLE = Cylinder((0.0, 0.0), 0.15, margin=0.05)


def make_scheduler(kind: str, clip_sample: bool = True):
    cls = DDPMScheduler if kind == "ddpm" else DDIMScheduler
    return cls(num_train_timesteps=100, beta_schedule="squaredcos_cap_v2", clip_sample=clip_sample,
               prediction_type="epsilon")


STEPS = {"ddpm": 100, "ddim": 10}


def sample(kind, guidance=None, cost=OBSTACLE, seed=0, prior_mean=LINE, on_step=None, clip_sample=True):
    scheduler = make_scheduler(kind, clip_sample)
    prior = GaussianPathPrior(prior_mean, 0.05, scheduler.alphas_cumprod)
    generator = torch.Generator().manual_seed(seed)
    return denoise(prior, scheduler, SHAPE, num_inference_steps=STEPS[kind], generator=generator,
                   guidance=guidance, cost_fn=cost, on_step=on_step)


def collision_rate(positions, obstacle=OBSTACLE):
    return (obstacle.clearance(positions).min(-1).values < 0).float().mean().item()


@pytest.mark.parametrize("kind", ["ddpm", "ddim"])
@pytest.mark.parametrize("mode", [GuidanceMode.CLEAN, GuidanceMode.NOISY])
def test_rho_zero_reproduces_the_unguided_samples_exactly(kind, mode):
    unguided = sample(kind)
    assert collision_rate(unguided) == 1.0  # the prior runs straight through the obstacle
    assert torch.equal(sample(kind, GuidanceConfig(mode, scale=0.0, last_steps=100)), unguided)


@pytest.mark.parametrize("kind", ["ddpm", "ddim"])
def test_guidance_with_nothing_in_range_reproduces_the_unguided_samples(kind):
    far_away = Cylinder((5.0, 5.0), 0.1)
    guided = sample(kind, GuidanceConfig(GuidanceMode.CLEAN, scale=1.0, last_steps=100), cost=far_away)
    torch.testing.assert_close(guided, sample(kind), rtol=0, atol=1e-6)


@pytest.mark.parametrize("kind,last_steps,rho", [("ddpm", 10, 0.1), ("ddim", 100, 0.3)])
def test_guidance_on_the_clean_estimate_clears_the_obstacle(kind, last_steps, rho):
    unguided = sample(kind)
    guided = sample(kind, GuidanceConfig(GuidanceMode.CLEAN, scale=rho, last_steps=last_steps))
    assert collision_rate(unguided) == 1.0
    assert collision_rate(guided) == 0.0
    assert (OBSTACLE.clearance(guided).min(-1).values > OBSTACLE.clearance(unguided).min(-1).values).all()
    # only waypoints near the obstacle move: start and goal stay where the prior puts them
    torch.testing.assert_close(guided[:, [0, -1]], unguided[:, [0, -1]], rtol=0, atol=1e-5)


def test_guidance_steps_follow_s_in_training_steps_for_ddpm_and_ddim():
    def guided_timesteps(kind, last_steps):
        seen = []
        sample(kind, GuidanceConfig(GuidanceMode.CLEAN, 0.1, last_steps), on_step=lambda s: seen.append(s))
        return [s.timestep for s in seen if s.guided]

    assert guided_timesteps("ddpm", 10) == list(range(9, -1, -1))
    assert guided_timesteps("ddim", 10) == [0]  # DDIM-10 visits t = 90, 80, ..., 0
    assert guided_timesteps("ddim", 100) == list(range(90, -1, -10))
    assert guided_timesteps("ddpm", 0) == []


def test_the_push_is_rho_times_the_gradient_and_per_train_step_scales_it_by_the_stride():
    """DDIM-10 with S = 10 guides only its last step, so the guided and unguided outputs differ by
    exactly the last push: rho * grad (paper), or rho * 10 * grad with per_train_step."""
    unguided = sample("ddim")
    for per_train_step, factor in ((False, 1.0), (True, 10.0)):
        steps = []
        guidance = GuidanceConfig(GuidanceMode.CLEAN, 0.01, 10, per_train_step=per_train_step)
        guided = sample("ddim", guidance, on_step=steps.append)
        gradient = steps[-1].gradient
        assert gradient.abs().max() > 0
        torch.testing.assert_close(guided, unguided - 0.01 * factor * gradient, rtol=0, atol=1e-6)


def test_noisy_guidance_differentiates_the_cost_of_the_noisy_sample_itself():
    steps = []
    sample("ddpm", GuidanceConfig(GuidanceMode.NOISY, 0.1, 10), on_step=steps.append)
    guided = [s for s in steps if s.guided]
    assert len(guided) == 10
    for step in guided:
        sample_var = step.sample.clone().requires_grad_(True)
        (expected,) = torch.autograd.grad(OBSTACLE(sample_var).sum(), sample_var)
        torch.testing.assert_close(step.gradient, expected)
        torch.testing.assert_close(step.cost, OBSTACLE(step.sample))


def test_clip_sample_does_not_zero_the_gradient_and_a_wider_guided_clip_keeps_the_push():
    """The cost must see the unclipped A_0|k: clamping it to [-1, 1] would make its gradient zero for a
    path that the normaliser maps outside [-1, 1]. With the scheduler's clip on guided steps, each step
    pulls the pushed sample back inside [-1, 1] and only the last push survives; widening the guided
    steps' clip range keeps every push."""
    outside = straight_line([1.4, -0.8, 0.0], [1.4, 0.8, 0.0], HORIZON)
    obstacle = Cylinder((1.2, 0.0), 0.45, margin=0.05)
    steps = []
    unguided = sample("ddpm", prior_mean=outside, cost=obstacle)
    clipped = sample("ddpm", GuidanceConfig(GuidanceMode.CLEAN, 0.3, 10), prior_mean=outside, cost=obstacle,
                     on_step=steps.append)
    guided_steps = [s for s in steps if s.guided]
    assert all(s.clean_estimate[..., 0].max() > 1.0 for s in guided_steps)
    assert all(s.gradient.abs().sum() > 0 for s in guided_steps)
    assert collision_rate(unguided, obstacle) == 1.0
    assert 0.3 <= collision_rate(clipped, obstacle) < 1.0  # the gradient acts, but clipping undoes most of it
    for clip_range in (3.0, float("inf")):
        widened = sample("ddpm", GuidanceConfig(GuidanceMode.CLEAN, 0.3, 10, guided_clip_range=clip_range),
                         prior_mean=outside, cost=obstacle)
        assert collision_rate(widened, obstacle) == 0.0


def test_alpha_bar_push_weight_scales_each_push_by_the_noise_level():
    """DDIM-10, S = 100: the last step (t = 0, abar_prev = 1) keeps its push; earlier pushes shrink."""
    for push_weight in ("constant", "alpha_bar"):
        steps = []
        sample("ddim", GuidanceConfig(GuidanceMode.CLEAN, 0.01, 100, push_weight=push_weight), on_step=steps.append)
        first, last = steps[0], steps[-1]
        scheduler = make_scheduler("ddim")
        abar = scheduler.alphas_cumprod
        expected_first = 1.0 if push_weight == "constant" else float((abar[90] * abar[80]).sqrt())
        expected_last = 1.0 if push_weight == "constant" else float(abar[0].sqrt())
        # the guided output minus what the scheduler alone would give is -rho * weight * gradient
        for step, expected in ((first, expected_first), (last, expected_last)):
            scheduler.set_timesteps(10)
            prior = GaussianPathPrior(LINE, 0.05, scheduler.alphas_cumprod)
            plain = scheduler.step(prior(step.sample, torch.full((BATCH,), step.timestep)), step.timestep,
                                   step.sample).prev_sample
            push = plain - step.next_sample
            torch.testing.assert_close(push, 0.01 * expected * step.gradient, rtol=1e-4, atol=1e-7)
    assert expected_first < 0.05


def test_guidance_errors_name_the_problem():
    with pytest.raises(ValueError, match="needs a cost_fn"):
        sample("ddim", GuidanceConfig(GuidanceMode.CLEAN, 0.1, 10), cost=None)
    with pytest.raises(GuidanceError, match="one cost per sample"):
        sample("ddim", GuidanceConfig(GuidanceMode.CLEAN, 0.1, 10), cost=lambda a: a.sum())
    with pytest.raises(GuidanceError, match="not finite"):
        sample("ddim", GuidanceConfig(GuidanceMode.CLEAN, 0.1, 10), cost=lambda a: a.sqrt().sum((1, 2)))
    with pytest.raises(ValueError, match="rho must be >= 0"):
        GuidanceConfig(GuidanceMode.CLEAN, -1.0)
    diffusers = pytest.importorskip("diffusers")  # denoise also takes diffusers' schedulers: not theirs for x_0
    sample_scheduler = diffusers.DDIMScheduler(num_train_timesteps=100, prediction_type="sample")
    with pytest.raises(ValueError, match="epsilon-prediction"):
        denoise(lambda a, t: a, sample_scheduler, SHAPE, num_inference_steps=10)
