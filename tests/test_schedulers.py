"""The own DDPM and DDIM steps (lano3dp.guidance.schedulers) against diffusers', the reference they replace.

diffusers is a test dependency only: the policy imports none of it (it cost ~1.8 CPU-s per process).
"""

import subprocess
import sys

import pytest
import torch

from lano3dp.guidance.schedulers import (
    DDIMScheduler,
    DDPMScheduler,
    SchedulerConfig,
    draw_normal,
)

diffusers = pytest.importorskip("diffusers")

PROCESS = dict(num_train_timesteps=100, beta_schedule="squaredcos_cap_v2", clip_sample=True,
               prediction_type="epsilon")


def reference(kind: str, **overrides):
    """The diffusers schedulers exactly as the policy configured them before (policy/modeling.py)."""
    if kind == "ddpm":
        return diffusers.DDPMScheduler(variance_type="fixed_small", **{**PROCESS, **overrides})
    return diffusers.DDIMScheduler(set_alpha_to_one=True, steps_offset=0, **{**PROCESS, **overrides})


def own(kind: str, **overrides):
    return {"ddpm": DDPMScheduler, "ddim": DDIMScheduler}[kind](SchedulerConfig(**{**PROCESS, **overrides}))


def test_the_cosine_schedule_is_diffusers_own():
    for steps in (100, 1000):
        ours, theirs = own("ddpm", num_train_timesteps=steps), reference("ddpm", num_train_timesteps=steps)
        torch.testing.assert_close(ours.betas, theirs.betas, rtol=0, atol=1e-6)
        torch.testing.assert_close(ours.alphas_cumprod, theirs.alphas_cumprod, rtol=0, atol=1e-6)
        assert ours.alphas_cumprod.dtype == torch.float32
    assert float(own("ddpm").betas.max()) == pytest.approx(0.999)  # the cap of the last step


@pytest.mark.parametrize("kind", ["ddpm", "ddim"])
def test_every_spacing_visits_the_timesteps_diffusers_visits(kind):
    ours, theirs = own(kind), reference(kind)
    for steps in (1, 3, 7, 10, 16, 33, 50, 99, 100):
        ours.set_timesteps(steps)
        theirs.set_timesteps(steps)
        assert ours.timesteps.tolist() == theirs.timesteps.tolist()
    ours.set_timesteps(10)
    assert ours.timesteps.tolist() == [90, 80, 70, 60, 50, 40, 30, 20, 10, 0]


@pytest.mark.parametrize("kind,steps", [("ddim", 10), ("ddim", 7), ("ddpm", 100), ("ddpm", 10)])
@pytest.mark.parametrize("clip", [True, False])
def test_a_whole_reverse_chain_matches_diffusers_to_1e_6(kind, steps, clip):
    """Same x_T, same eps per step, same generator for DDPM's z: every x_t' and x_0 estimate agree."""
    ours, theirs = own(kind, clip_sample=clip), reference(kind, clip_sample=clip)
    ours.set_timesteps(steps)
    theirs.set_timesteps(steps)
    ours_generator, theirs_generator = torch.Generator().manual_seed(3), torch.Generator().manual_seed(3)
    sample = 1.5 * torch.randn(4, 16, 10, generator=torch.Generator().manual_seed(0))
    ours_sample = theirs_sample = sample
    for t in ours.timesteps.tolist():
        noise = torch.randn(4, 16, 10, generator=torch.Generator().manual_seed(100 + t))
        mine = ours.step(noise, t, ours_sample, generator=ours_generator)
        reference_step = theirs.step(noise, t, theirs_sample, generator=theirs_generator)
        torch.testing.assert_close(mine.prev_sample, reference_step.prev_sample, rtol=0, atol=1e-6)
        torch.testing.assert_close(mine.pred_original_sample, reference_step.pred_original_sample, rtol=0, atol=1e-6)
        ours_sample, theirs_sample = mine.prev_sample, reference_step.prev_sample
    if clip:
        assert float(ours_sample.abs().max()) <= 1.0 + 1e-6  # the last step returns the clipped x_0
    # DDPM drew one z per step but the last, exactly as diffusers: the generators are at the same place
    assert torch.equal(torch.rand(3, generator=ours_generator), torch.rand(3, generator=theirs_generator))


def test_a_wider_clip_range_is_the_same_process_with_another_range():
    wide = DDIMScheduler.from_config(own("ddim").config, clip_sample_range=3.0)
    theirs = reference("ddim", clip_sample_range=3.0)
    wide.set_timesteps(10)
    theirs.set_timesteps(10)
    sample = 4.0 * torch.randn(2, 16, 3, generator=torch.Generator().manual_seed(0))
    noise = torch.zeros_like(sample)
    mine = wide.step(noise, 90, sample)
    assert float(mine.pred_original_sample.abs().max()) == pytest.approx(3.0)
    torch.testing.assert_close(mine.prev_sample, theirs.step(noise, 90, sample).prev_sample, rtol=0, atol=1e-6)


def test_add_noise_is_the_forward_process_diffusers_trains_with():
    clean = torch.randn(8, 16, 10, generator=torch.Generator().manual_seed(0))
    noise = torch.randn(8, 16, 10, generator=torch.Generator().manual_seed(1))
    timesteps = torch.tensor([0, 1, 5, 20, 50, 80, 98, 99])
    torch.testing.assert_close(own("ddpm").add_noise(clean, noise, timesteps),
                               reference("ddpm").add_noise(clean, noise, timesteps), rtol=0, atol=1e-6)


def test_a_float64_sample_steps_in_float64():
    scheduler = own("ddpm")
    scheduler.set_timesteps(100)
    sample = torch.randn(2, 16, 3, dtype=torch.float64)
    stepped = scheduler.step(torch.zeros_like(sample), 50, sample, generator=torch.Generator().manual_seed(0))
    assert stepped.prev_sample.dtype == stepped.pred_original_sample.dtype == torch.float64
    assert own("ddim").add_noise(sample, sample, torch.tensor([3, 4])).dtype == torch.float64


def test_one_generator_per_sample_gives_each_sample_its_own_noise():
    alone = [draw_normal((1, 16, 10), torch.Generator().manual_seed(seed), "cpu", torch.float32) for seed in (7, 8)]
    together = draw_normal((2, 16, 10), [torch.Generator().manual_seed(7), torch.Generator().manual_seed(8)], "cpu",
                           torch.float32)
    assert torch.equal(together, torch.cat(alone))
    with pytest.raises(ValueError, match="2 generators for a batch of 3"):
        draw_normal((3, 16, 10), [torch.Generator(), torch.Generator()], "cpu", torch.float32)


def test_the_scheduler_errors_say_what_to_do():
    with pytest.raises(ValueError, match="run set_timesteps before step"):
        own("ddim").step(torch.zeros(1, 16, 3), 90, torch.zeros(1, 16, 3))
    with pytest.raises(ValueError, match="num_inference_steps must be in 1..100"):
        own("ddpm").set_timesteps(101)
    with pytest.raises(ValueError, match="prediction_type 'sample' is not implemented"):
        SchedulerConfig(prediction_type="sample")
    with pytest.raises(ValueError, match="beta_schedule 'linear' is not implemented"):
        SchedulerConfig(beta_schedule="linear")


def test_loading_a_policy_imports_neither_diffusers_nor_torch_dynamo():
    """diffusers pulls torch._dynamo (~1.8 CPU-s per process): the policy, its sampler and its guidance do not."""
    code = ("import sys\n"
            "from lano3dp.policy import DiffusionPolicy\n"
            "from lano3dp.policy.pretrained import packaged_checkpoint\n"
            "import lano3dp.guidance.sampler, lano3dp.guidance.costs\n"
            "DiffusionPolicy.from_pretrained(packaged_checkpoint('bowl_pour'))\n"
            "print(sorted(name for name in ('diffusers', 'torch._dynamo') if name in sys.modules))\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert result.stdout.strip() == "[]"
