"""An exact noise predictor for a Gaussian trajectory prior, to exercise guidance without training.

If the data are A_0 ~ N(mean, std^2 I), the ideal epsilon-prediction network is known in closed form:

    A_0|k = E[A_0 | A_k] = mean + c_k (A_k - sqrt(abar_k) mean),  c_k = sqrt(abar_k) std^2 / (abar_k std^2 + 1 - abar_k)
    eps   = (A_k - sqrt(abar_k) A_0|k) / sqrt(1 - abar_k)

so unguided sampling returns `mean` plus noise of size `std`, and d A_0|k / d A_k = c_k is non-zero:
guidance on A_0|k can bend the samples, exactly as with a trained network but in microseconds.
Used by the tests and by the diagnostics' self-check.
"""

from __future__ import annotations

import torch


class GaussianPathPrior:
    """eps_theta for A_0 ~ N(mean, std^2 I).

    Args:
        mean: (H, D) or (B, H, D) the reference trajectory, normalised units.
        std: spread of the prior around it.
        alphas_cumprod: (T,) the scheduler's abar.
    """

    def __init__(self, mean: torch.Tensor, std: float, alphas_cumprod: torch.Tensor):
        self.mean = mean
        self.std = float(std)
        self.alphas_cumprod = alphas_cumprod

    def clean_estimate(self, sample: torch.Tensor, timestep: torch.Tensor) -> torch.Tensor:
        alpha_bar = self.alphas_cumprod.to(sample)[timestep].view(-1, *([1] * (sample.ndim - 1)))
        gain = alpha_bar.sqrt() * self.std**2 / (alpha_bar * self.std**2 + 1 - alpha_bar)
        mean = self.mean.to(sample)
        return mean + gain * (sample - alpha_bar.sqrt() * mean)

    def __call__(self, sample: torch.Tensor, timestep: torch.Tensor) -> torch.Tensor:
        alpha_bar = self.alphas_cumprod.to(sample)[timestep].view(-1, *([1] * (sample.ndim - 1)))
        return (sample - alpha_bar.sqrt() * self.clean_estimate(sample, timestep)) / (1 - alpha_bar).sqrt()


def straight_line(start, goal, horizon: int) -> torch.Tensor:
    """(horizon, len(start)) waypoints evenly spaced from start to goal."""
    start, goal = torch.as_tensor(start, dtype=torch.float32), torch.as_tensor(goal, dtype=torch.float32)
    fractions = torch.linspace(0, 1, horizon)[:, None]
    return start + fractions * (goal - start)
