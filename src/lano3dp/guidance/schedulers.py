"""DDPM and DDIM steps for the policy's diffusion process, written here rather than imported from diffusers.

Why not diffusers: importing it pulls in torch._dynamo and huggingface_hub, about 1.8 CPU-s per process,
most of a short evaluation's start-up, for some thirty lines of arithmetic. These classes reproduce, operation
for operation, the two configurations the policy used from diffusers 0.42: `DDPMScheduler(beta_schedule=
"squaredcos_cap_v2", variance_type="fixed_small", clip_sample, prediction_type="epsilon")` and `DDIMScheduler(
set_alpha_to_one=True, steps_offset=0, eta=0, ...)`, both with "leading" timestep spacing. In float32 on the CPU
they give the same bits as diffusers (tests/test_schedulers.py checks them against it to 1e-6, and the shipped
policies' chunks for equality), so checkpoints trained with diffusers sample as before.

Symbols (Ho et al. 2020, DDPM; Song et al. 2021, DDIM) and their names here, as in diffusers:

    T              num_train_timesteps          training diffusion steps; t runs T-1 .. 0
    beta_t         betas[t]                     noise added by forward step t (Nichol & Dhariwal's cosine schedule)
    abar_t         alphas_cumprod[t]            prod_{s<=t} (1 - beta_s)
    t'             previous_timestep(t)         the next timestep visited: t - T // n for n inference steps
    eps_theta      model_output                 the network's noise estimate
    x_0            pred_original_sample         (x_t - sqrt(1 - abar_t) eps_theta) / sqrt(abar_t), clipped
    mu_t           pred_prev_sample (DDPM)      the posterior mean of x_t' given x_t and x_0
    sigma_t        variance ** 0.5 (DDPM)       the posterior standard deviation ("fixed_small")

Device and dtype: the schedule is built once in float32 on the CPU, exactly as diffusers builds it, and each
step uses a copy on the sample's device in the sample's dtype, so a float64 or CUDA policy samples without a
silent float32 or CPU detour. DDPM's noise z is drawn from the given torch.Generator on the generator's
device and then moved to the sample's (diffusers' `randn_tensor` does the same): a CPU generator gives the
same noise whatever device the policy runs on.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import torch

BETA_SCHEDULES = ("squaredcos_cap_v2",)
PREDICTION_TYPES = ("epsilon",)
# one generator for the batch, or one per sample (see draw_normal)
Generators = torch.Generator | Sequence[torch.Generator] | None


@dataclass(frozen=True)
class SchedulerConfig:
    """The diffusion process a scheduler steps through (the names are diffusers' config keys).

    Attributes:
        num_train_timesteps: T, the training diffusion steps.
        beta_schedule: "squaredcos_cap_v2" (the cosine schedule, betas capped at 0.999).
        prediction_type: "epsilon": the network predicts the added noise.
        clip_sample: clip the x_0 estimate to [-clip_sample_range, clip_sample_range] before stepping.
        clip_sample_range: see clip_sample (normalised action units; the normaliser maps the demonstrations
            to [-1, 1]).
    """

    num_train_timesteps: int = 100
    beta_schedule: str = "squaredcos_cap_v2"
    prediction_type: str = "epsilon"
    clip_sample: bool = True
    clip_sample_range: float = 1.0

    def __post_init__(self):
        if self.num_train_timesteps < 1:
            raise ValueError(f"num_train_timesteps must be >= 1, got {self.num_train_timesteps}")
        if self.beta_schedule not in BETA_SCHEDULES:
            raise ValueError(f"beta_schedule {self.beta_schedule!r} is not implemented; use one of {BETA_SCHEDULES}")
        if self.prediction_type not in PREDICTION_TYPES:
            raise ValueError(f"prediction_type {self.prediction_type!r} is not implemented; use one of "
                             f"{PREDICTION_TYPES}")
        if not self.clip_sample_range > 0:
            raise ValueError(f"clip_sample_range must be > 0, got {self.clip_sample_range}")


class SchedulerOutput(NamedTuple):
    """prev_sample: x_t' (B, ...); pred_original_sample: the clipped x_0 estimate (B, ...)."""

    prev_sample: torch.Tensor
    pred_original_sample: torch.Tensor


def cosine_betas(num_train_timesteps: int, max_beta: float = 0.999) -> torch.Tensor:
    """betas (T,) float32 of the cosine schedule abar(s) = cos((s + 0.008) / 1.008 * pi / 2)^2 (Nichol & Dhariwal
    2021, Eq. 17), beta_t = min(1 - abar((t+1)/T) / abar(t/T), max_beta); in Python floats, as diffusers does."""

    def alpha_bar(s: float) -> float:
        return math.cos((s + 0.008) / 1.008 * math.pi / 2) ** 2

    betas = [min(1 - alpha_bar((t + 1) / num_train_timesteps) / alpha_bar(t / num_train_timesteps), max_beta)
             for t in range(num_train_timesteps)]
    return torch.tensor(betas, dtype=torch.float32)


class DiffusionScheduler:
    """What DDPM and DDIM share: the schedule, the visited timesteps, the forward process (add_noise).

    Call `set_timesteps(n)` before `step`; `timesteps` then holds the n visited timesteps, T-1 side first
    ("leading" spacing: 0, T//n, 2 T//n, ... reversed).
    """

    def __init__(self, config: SchedulerConfig | None = None, **fields):
        self.config = dataclasses.replace(config, **fields) if config is not None else SchedulerConfig(**fields)
        self.betas = cosine_betas(self.config.num_train_timesteps)
        self.alphas = 1.0 - self.betas
        self.alphas_cumprod = torch.cumprod(self.alphas, dim=0)
        self.num_inference_steps: int | None = None
        self.timesteps = torch.arange(self.config.num_train_timesteps - 1, -1, -1)
        self._on: dict[tuple[torch.device, torch.dtype], torch.Tensor] = {}

    @classmethod
    def from_config(cls, config: SchedulerConfig, **overrides):
        """A scheduler of this kind with `config`'s process and `overrides` (e.g. clip_sample_range=3.0)."""
        return cls(config, **overrides)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.config})"

    def set_timesteps(self, num_inference_steps: int, device: str | torch.device | None = None) -> None:
        """Visit `num_inference_steps` timesteps: (0, r, 2r, ...) reversed, r = T // n. `timesteps` stays a CPU
        tensor whatever `device` says (the loop reads its values; the step moves what it computes)."""
        steps = self.config.num_train_timesteps
        if not 1 <= num_inference_steps <= steps:
            raise ValueError(f"num_inference_steps must be in 1..{steps} (the training steps), got "
                             f"{num_inference_steps}")
        self.num_inference_steps = int(num_inference_steps)
        ratio = steps // self.num_inference_steps
        visited = np.arange(0, self.num_inference_steps) * ratio
        self.timesteps = torch.from_numpy(visited[::-1].copy().astype(np.int64))

    def previous_timestep(self, timestep: int) -> int:
        """t', the timestep after `timestep` in the visited order (negative past the last one)."""
        if self.num_inference_steps is None:
            raise ValueError(f"{type(self).__name__}: run set_timesteps before step")
        return int(timestep) - self.config.num_train_timesteps // self.num_inference_steps

    def alphas_cumprod_like(self, sample: torch.Tensor) -> torch.Tensor:
        """alphas_cumprod (T,) on `sample`'s device in its dtype (cached; float32 CPU is the schedule itself)."""
        key = (sample.device, sample.dtype)
        if key not in self._on:
            self._on[key] = self.alphas_cumprod.to(device=sample.device, dtype=sample.dtype)
        return self._on[key]

    def _clip(self, pred_original_sample: torch.Tensor) -> torch.Tensor:
        if not self.config.clip_sample:
            return pred_original_sample
        return pred_original_sample.clamp(-self.config.clip_sample_range, self.config.clip_sample_range)

    def add_noise(self, original_samples: torch.Tensor, noise: torch.Tensor, timesteps: torch.Tensor) -> torch.Tensor:
        """The forward process q(x_t | x_0) = N(sqrt(abar_t) x_0, (1 - abar_t) I), per sample.

        Args:
            original_samples: x_0 (B, ...).
            noise: eps (B, ...), standard normal.
            timesteps: t (B,) integer.

        Returns:
            x_t (B, ...) = sqrt(abar_t) x_0 + sqrt(1 - abar_t) eps.
        """
        alphas_cumprod = self.alphas_cumprod_like(original_samples)
        timesteps = timesteps.to(original_samples.device)
        shape = (-1,) + (1,) * (original_samples.ndim - 1)
        sqrt_alpha_prod = (alphas_cumprod[timesteps] ** 0.5).reshape(shape)
        sqrt_one_minus_alpha_prod = ((1 - alphas_cumprod[timesteps]) ** 0.5).reshape(shape)
        return sqrt_alpha_prod * original_samples + sqrt_one_minus_alpha_prod * noise

    def step(self, model_output: torch.Tensor, timestep: int, sample: torch.Tensor,
             generator: Generators = None) -> SchedulerOutput:
        raise NotImplementedError


class DDPMScheduler(DiffusionScheduler):
    """Ancestral sampling (Ho et al. 2020, Algorithm 2) with the posterior variance beta~_t ("fixed_small")."""

    def step(self, model_output: torch.Tensor, timestep: int, sample: torch.Tensor,
             generator: Generators = None) -> SchedulerOutput:
        """x_t -> x_t' = mu_t(x_t, x_0) + sigma_t z, z ~ N(0, I) from `generator` (no noise at t = 0).

        Args:
            model_output: eps_theta(x_t, t) (B, ...).
            timestep: t, one of `timesteps`.
            sample: x_t (B, ...).
            generator: draws z (None: torch's global generator; one per sample: see draw_normal).
        """
        t = int(timestep)
        prev_t = self.previous_timestep(t)
        alphas_cumprod = self.alphas_cumprod_like(sample)
        one = alphas_cumprod.new_ones(())

        # 1. abar_t, abar_t', and the effective beta_t of a step from t to t'
        alpha_prod_t = alphas_cumprod[t]
        alpha_prod_t_prev = alphas_cumprod[prev_t] if prev_t >= 0 else one
        beta_prod_t = 1 - alpha_prod_t
        beta_prod_t_prev = 1 - alpha_prod_t_prev
        current_alpha_t = alpha_prod_t / alpha_prod_t_prev
        current_beta_t = 1 - current_alpha_t

        # 2. x_0 from the predicted noise (Eq. 15 of Ho et al.), 3. clipped
        pred_original_sample = (sample - beta_prod_t ** (0.5) * model_output) / alpha_prod_t ** (0.5)
        pred_original_sample = self._clip(pred_original_sample)

        # 4.-5. the posterior mean mu_t = c_0 x_0 + c_t x_t (Eq. 7)
        pred_original_sample_coeff = (alpha_prod_t_prev ** (0.5) * current_beta_t) / beta_prod_t
        current_sample_coeff = current_alpha_t ** (0.5) * beta_prod_t_prev / beta_prod_t
        pred_prev_sample = pred_original_sample_coeff * pred_original_sample + current_sample_coeff * sample

        # 6. + sigma_t z, sigma_t^2 = beta~_t = (1 - abar_t') / (1 - abar_t) beta_t (Eq. 7), floored as diffusers
        if t > 0:
            variance = torch.clamp((1 - alpha_prod_t_prev) / (1 - alpha_prod_t) * current_beta_t, min=1e-20)
            noise = draw_normal(model_output.shape, generator, model_output.device, model_output.dtype)
            pred_prev_sample = pred_prev_sample + (variance ** 0.5) * noise
        return SchedulerOutput(pred_prev_sample, pred_original_sample)


class DDIMScheduler(DiffusionScheduler):
    """Deterministic DDIM (Song et al. 2021, Eq. 12 with eta = 0); abar past the last step is 1
    (diffusers' set_alpha_to_one), so the last step returns the clipped x_0 itself."""

    def step(self, model_output: torch.Tensor, timestep: int, sample: torch.Tensor,
             generator: Generators = None) -> SchedulerOutput:
        """x_t -> x_t' = sqrt(abar_t') x_0 + sqrt(1 - abar_t') eps_theta. `generator` is unused (eta = 0).

        Args:
            model_output: eps_theta(x_t, t) (B, ...).
            timestep: t, one of `timesteps`.
            sample: x_t (B, ...).
        """
        t = int(timestep)
        prev_t = self.previous_timestep(t)
        alphas_cumprod = self.alphas_cumprod_like(sample)

        # 1.-2. abar_t and abar_t' (1 past the last step)
        alpha_prod_t = alphas_cumprod[t]
        alpha_prod_t_prev = alphas_cumprod[prev_t] if prev_t >= 0 else alphas_cumprod.new_ones(())
        beta_prod_t = 1 - alpha_prod_t

        # 3. x_0 from the predicted noise (Eq. 12's "predicted x_0"), 4. clipped
        pred_original_sample = (sample - beta_prod_t ** (0.5) * model_output) / alpha_prod_t ** (0.5)
        pred_original_sample = self._clip(pred_original_sample)

        # 6. the "direction pointing to x_t" (sigma_t = 0), 7. x_t' without random noise
        pred_sample_direction = (1 - alpha_prod_t_prev) ** (0.5) * model_output
        prev_sample = alpha_prod_t_prev ** (0.5) * pred_original_sample + pred_sample_direction
        return SchedulerOutput(prev_sample, pred_original_sample)


SCHEDULERS: dict[str, type[DiffusionScheduler]] = {"ddpm": DDPMScheduler, "ddim": DDIMScheduler}


def draw_normal(shape: tuple[int, ...] | torch.Size, generator: Generators, device: torch.device | str,
                dtype: torch.dtype) -> torch.Tensor:
    """Standard normal noise of `shape` (B, ...) on `device`, in `dtype`.

    Drawn where the generator lives (the CPU for None or a CPU generator), then moved, so one seed gives the
    same noise on any device. A sequence of B generators draws row i from generator i alone (each (1, ...)),
    so a sample of a batch gets the noise it would get sampled on its own with that generator.
    """
    shape = tuple(shape)
    if generator is None or isinstance(generator, torch.Generator):
        source = generator.device if generator is not None else torch.device("cpu")
        return torch.randn(shape, generator=generator, device=source, dtype=dtype).to(device)
    generators = list(generator)
    if len(generators) != shape[0]:
        raise ValueError(f"got {len(generators)} generators for a batch of {shape[0]}; give one per sample")
    return torch.cat([draw_normal((1, *shape[1:]), one, device, dtype) for one in generators], dim=0)
