"""One denoising loop for DDPM and DDIM, with optional cost guidance.

Algorithm 1 of the paper (Lan-o3dp), in this loop's names:

    A_k         sample            the noisy trajectory at diffusion step k (normalised units)
    eps_theta   noise             the network's noise estimate eps_theta(A_k, k, O)
    mu_k+s_k z  scheduler.step    the DDPM/DDIM posterior step A_{k-1} (guidance.schedulers)
    A_0|k       clean_estimate    (A_k - sqrt(1 - abar_k) eps_theta) / sqrt(abar_k)       (Eq. 2)
    D           cost_fn           obstacle cost of a trajectory, in metric units
    S           last_steps        guide only while k <= S (k = diffusers timestep + 1)
    rho         scale             A_{k-1} <- A_{k-1} - rho * grad_{A_k} D(.)             (Eq. 3)

The switch `mode` picks what D is evaluated on: nothing (no guidance), the noisy A_k (the
prior methods the paper contrasts with), or the clean estimate A_0|k (the paper).

Guiding on A_k needs no gradient through the network (D(A_k) depends on A_k directly), so that
mode costs one extra cost evaluation per step; guiding on A_0|k back-propagates through eps_theta.

DDIM. `last_steps` S is measured in training-scale steps for every scheduler: DDIM-10 over 100
training steps visits t = 90, 80, ..., 0, so S = 10 guides only its last step and S = 100 guides
all ten. Each guided step applies one push of rho (the paper's Algorithm 1, per step), so the same
rho pushes DDIM-10 with S = 100 about as often as DDPM-100 with S = 10. With `per_train_step`,
rho is multiplied by the stride (training steps per inference step) instead, which keeps the total
push across a window of S training steps the same as DDPM's; measured in bench/bench_guidance.py.

Push weighting. With eps_theta held fixed, a push delta on A_{k-1} reaches the final sample
amplified by 1 / sqrt(abar_{k-1}) (later steps rescale it like signal), and the gradient itself
carries d A_0|k / d A_k = 1 / sqrt(abar_k). Late DDPM steps have abar > 0.97, so the paper's
constant rho is fine for S = 10 of 100; DDIM-10 guided on every step starts at abar_90 = 0.020,
abar_80 = 0.085, where this linear estimate puts the same rho ~25x stronger (the trained network
absorbs part of an early push, so less in practice). `push_weight="alpha_bar"` multiplies each push
by sqrt(abar_k * abar_{k-1}) (0.041 on DDIM's first step, 1.0 on its last), so every guided step
moves the final sample by about rho * grad (FreeDoM scales by sqrt(abar_k) for the same reason).

clip_sample. Diffusion Policy's schedulers clip their x_0 estimate to [-1, 1], the normaliser's
range of the demonstrations. The cost always sees the unclipped A_0|k, so clipping never zeroes the
gradient. But a detour around an obstacle the demonstrations never saw often has to leave that range,
and then each clipped step pulls the pushed sample back inside, so only the very last push survives
(tests/test_guidance_sampler.py). `guided_clip_range` r lets guided steps clip to [-r, r] instead.
Switching clipping off altogether (r = inf) is only safe for the last few steps: with S = 100 the
early, noisy x_0 estimates run away (a trained policy's goal error went from 5 cm to 88 m), hence a
finite widening such as r = 3 (a detour may leave the demonstrated range by one range on each side).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum

import torch

from lano3dp.guidance.exceptions import GuidanceError
from lano3dp.guidance.schedulers import Generators, draw_normal
from lano3dp.guidance.settings import PUSH_WEIGHTS

NoiseFn = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]
CostFn = Callable[[torch.Tensor], torch.Tensor]


class GuidanceMode(StrEnum):
    NONE = "none"
    NOISY = "noisy"  # D(A_k): guidance on the noisy sample
    CLEAN = "clean"  # D(A_0|k): the paper's guidance


@dataclass(frozen=True)
class GuidanceConfig:
    """Cost-guidance settings.

    Attributes:
        mode: what the cost is evaluated on (see GuidanceMode).
        scale: rho, the step along -grad; in normalised action units per unit of cost.
        last_steps: S; guide only while the training-scale step k = t + 1 <= S (100 = every step).
        per_train_step: multiply rho by the scheduler stride (num_train_timesteps / num_inference_steps),
            so fewer, longer inference steps push as much in total as DDPM-100 (see the module docstring).
        guided_clip_range: on guided steps clip the x_0 estimate to [-r, r] (normalised units) instead of the
            scheduler's range; None keeps the scheduler's, inf disables clipping (see the module docstring).
        push_weight: "constant" (the paper: every guided step pushes by rho * grad) or "alpha_bar" (each push
            times sqrt(abar_k * abar_{k-1}), so every step moves the final sample about equally; for DDIM).
    """

    mode: GuidanceMode = GuidanceMode.CLEAN
    scale: float = 1.0
    last_steps: int = 10
    per_train_step: bool = False
    guided_clip_range: float | None = None
    push_weight: str = "constant"

    def __post_init__(self):
        object.__setattr__(self, "mode", GuidanceMode(self.mode))
        if self.scale < 0:
            raise ValueError(f"guidance scale rho must be >= 0, got {self.scale}")
        if self.last_steps < 0:
            raise ValueError(f"last_steps S must be >= 0, got {self.last_steps}")
        if self.guided_clip_range is not None and not self.guided_clip_range > 0:
            raise ValueError(f"guided_clip_range must be > 0 or None, got {self.guided_clip_range}")
        if self.push_weight not in PUSH_WEIGHTS:
            raise ValueError(f"push_weight must be one of {PUSH_WEIGHTS}, got {self.push_weight!r}")

    def active(self, timestep: int) -> bool:
        return self.mode is not GuidanceMode.NONE and timestep + 1 <= self.last_steps

    @property
    def enabled(self) -> bool:
        """True if this config can change a sample at all."""
        return self.mode is not GuidanceMode.NONE and self.scale > 0 and self.last_steps > 0


@dataclass
class DenoiseStep:
    """What `on_step` sees after each step: the input A_k, its clean estimate A_0|k, the output A_{k-1}.

    `gradient` (grad_{A_k} D, normalised units) and `cost` (B,) are set on guided steps only.
    """

    timestep: int
    sample: torch.Tensor
    clean_estimate: torch.Tensor
    next_sample: torch.Tensor
    guided: bool
    gradient: torch.Tensor | None = None
    cost: torch.Tensor | None = None


def clean_estimate(sample: torch.Tensor, noise: torch.Tensor, alpha_bar: torch.Tensor) -> torch.Tensor:
    """Eq. 2: A_0|k = (A_k - sqrt(1 - abar_k) eps) / sqrt(abar_k)."""
    return (sample - (1.0 - alpha_bar).sqrt() * noise) / alpha_bar.sqrt()


def denoise(
    noise_fn: NoiseFn,
    scheduler,
    shape: tuple[int, ...],
    *,
    num_inference_steps: int | None = None,
    generator: Generators = None,
    guidance: GuidanceConfig | None = None,
    cost_fn: CostFn | None = None,
    initial_noise: torch.Tensor | None = None,
    on_step: Callable[[DenoiseStep], None] | None = None,
    device: torch.device | str | None = None,
    dtype: torch.dtype = torch.float32,
) -> torch.Tensor:
    """Sample trajectories by reverse diffusion, optionally cost-guided.

    Args:
        noise_fn: eps_theta(sample (B, H, D), timestep (B,) long) -> (B, H, D); conditioning is closed over.
        scheduler: a `guidance.schedulers` DDPMScheduler or DDIMScheduler (or a diffusers one) configured for
            epsilon prediction. Its timesteps are reset here.
        shape: (B, H, D) of the normalised trajectory.
        num_inference_steps: defaults to the scheduler's number of training steps.
        generator: seeds the initial noise and the DDPM noise z; or one generator per sample (B of them),
            so that each sample gets the noise it would get alone. A CPU generator draws on the CPU and the
            noise is moved to `device`: a seed gives the same sample on any device.
        guidance: None or mode NONE samples without guidance.
        cost_fn: normalised trajectory (B, H, D) -> per-sample cost (B,); required when guiding.
        initial_noise: A_T, to reproduce a run exactly (else drawn from `generator`).
        on_step: called after each step (diagnostics; Fig. 5 of the paper).
        device, dtype: of every tensor made here (A_T, the timestep batch, the schedule): the network's
            (default device: initial_noise's, else the CPU).

    Returns:
        (B, H, D) A_0, normalised units.
    """
    guidance = guidance or GuidanceConfig(mode=GuidanceMode.NONE)
    if guidance.mode is not GuidanceMode.NONE and cost_fn is None:
        raise ValueError("guidance needs a cost_fn; pass obstacles, or guidance mode 'none'")
    if getattr(scheduler.config, "prediction_type", "epsilon") != "epsilon":
        raise ValueError("guided sampling needs an epsilon-prediction scheduler "
                         f"(got {scheduler.config.prediction_type!r})")
    num_inference_steps = num_inference_steps or scheduler.config.num_train_timesteps
    scheduler.set_timesteps(num_inference_steps)
    stride = scheduler.config.num_train_timesteps / num_inference_steps
    step_scale = guidance.scale * (stride if guidance.per_train_step else 1.0)
    guided_scheduler = scheduler
    if guidance.enabled and guidance.guided_clip_range is not None and getattr(scheduler.config, "clip_sample", False):
        clip_range = guidance.guided_clip_range
        guided_scheduler = type(scheduler).from_config(scheduler.config, clip_sample=not math.isinf(clip_range),
                                                       clip_sample_range=1.0 if math.isinf(clip_range) else clip_range)
        guided_scheduler.set_timesteps(num_inference_steps)
    if device is None:
        device = initial_noise.device if initial_noise is not None else torch.device("cpu")
    alphas_cumprod = scheduler.alphas_cumprod.to(device=device, dtype=dtype)
    if initial_noise is not None:
        sample = initial_noise.to(device=device, dtype=dtype).clone()
    else:
        sample = draw_normal(shape, generator, device, dtype)
    batch = sample.shape[0]
    for timestep in scheduler.timesteps:
        t = int(timestep)
        t_batch = torch.full((batch,), t, dtype=torch.long, device=device)
        alpha_bar = alphas_cumprod[t]
        guided = guidance.active(t) and step_scale > 0
        gradient = cost = None
        if guided and guidance.mode is GuidanceMode.CLEAN:
            # Eq. 3: the gradient of D(A_0|k) flows back through eps_theta to A_k.
            with torch.enable_grad():
                sample_var = sample.detach().requires_grad_(True)
                noise = noise_fn(sample_var, t_batch)
                estimate = clean_estimate(sample_var, noise, alpha_bar)
                cost = cost_fn(estimate)
                gradient = _cost_gradient(cost, sample_var)
            noise, estimate, cost = noise.detach(), estimate.detach(), cost.detach()
        else:
            with torch.no_grad():
                noise = noise_fn(sample, t_batch)
            estimate = clean_estimate(sample, noise, alpha_bar)
            if guided:  # D(A_k): the cost of the noisy sample itself, no network in the graph
                with torch.enable_grad():
                    sample_var = sample.detach().requires_grad_(True)
                    cost = cost_fn(sample_var)
                    gradient = _cost_gradient(cost, sample_var)
                cost = cost.detach()
        step_scheduler = guided_scheduler if guided else scheduler
        next_sample = step_scheduler.step(noise, t, sample, generator=generator).prev_sample
        if guided:
            weight = 1.0
            if guidance.push_weight == "alpha_bar":
                previous = t - int(round(stride))
                alpha_bar_previous = alphas_cumprod[previous] if previous >= 0 else alphas_cumprod.new_ones(())
                weight = (alpha_bar * alpha_bar_previous).sqrt()
            next_sample = next_sample - step_scale * weight * gradient  # Algorithm 1, line 7
        if on_step is not None:
            on_step(DenoiseStep(t, sample, estimate, next_sample, guided, gradient, cost))
        sample = next_sample
    return sample


def _cost_gradient(cost: torch.Tensor, sample_var: torch.Tensor) -> torch.Tensor:
    if cost.shape != sample_var.shape[:1]:
        raise GuidanceError(f"cost_fn must return one cost per sample, shape ({sample_var.shape[0]},); "
                            f"got {tuple(cost.shape)}")
    if not cost.requires_grad:  # the cost does not depend on the sample (e.g. a constant): nothing to push
        return torch.zeros_like(sample_var)
    (gradient,) = torch.autograd.grad(cost.sum(), sample_var)
    if not torch.isfinite(gradient).all():
        raise GuidanceError("the guidance gradient is not finite; check the cost function and the normaliser "
                            "(a zero-range action dimension makes the metric positions blow up)")
    return gradient.detach()
