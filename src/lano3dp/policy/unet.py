"""ConditionalUnet1D: Chi et al.'s temporal U-Net with FiLM conditioning (Diffusion Policy, CNN variant).

Written here because diffusers has no 1-D U-Net with per-block FiLM (scale + bias) on a global
condition. Follows diffusion_policy/model/diffusion/conditional_unet1d.py with `cond_predict_scale=True`
and `obs_as_global_cond=True`: the condition is [diffusion-step embedding ; flattened observation
features], and every residual block modulates its first convolution's output as scale * x + bias.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import nn


class SinusoidalPosEmb(nn.Module):
    """timesteps (B,) -> (B, dim) sinusoidal embedding (Vaswani et al.)."""

    def __init__(self, dim: int):
        super().__init__()
        self.dim = dim

    def forward(self, timesteps: torch.Tensor) -> torch.Tensor:
        half = self.dim // 2
        steps = timesteps if timesteps.is_floating_point() else timesteps.float()
        frequencies = torch.exp(-math.log(10000) / max(half - 1, 1) * torch.arange(half, device=steps.device,
                                                                                   dtype=steps.dtype))
        angles = steps[:, None] * frequencies[None, :]
        return torch.cat([angles.sin(), angles.cos()], dim=-1)


def _run(module: nn.Module, x: torch.Tensor) -> torch.Tensor:
    """module(x) through `forward`, skipping nn.Module.__call__'s hook dispatch: the UNet makes ~180 module calls a
    pass, and at batch 1 that dispatch was 40% of a pass on one core (2.4 vs 1.5 ms; the same ops, the same bits).
    torch.jit.trace saves the same but is deprecated in torch 2.13, and a torch.export module runs slower than eager.
    No hooks are registered on the UNet's parts; one registered there would not run."""
    if isinstance(module, nn.Sequential):
        for child in module:
            x = _run(child, x)
        return x
    return module.forward(x)


class Conv1dBlock(nn.Sequential):
    """Conv1d (same length) + GroupNorm + Mish."""

    def __init__(self, in_channels: int, out_channels: int, kernel_size: int, n_groups: int):
        super().__init__(nn.Conv1d(in_channels, out_channels, kernel_size, padding=kernel_size // 2),
                         nn.GroupNorm(n_groups, out_channels), nn.Mish())


class ConditionalResidualBlock1D(nn.Module):
    """x (B, C_in, T), cond (B, cond_dim) -> (B, C_out, T), FiLM between the two convolutions."""

    def __init__(self, in_channels: int, out_channels: int, cond_dim: int, kernel_size: int, n_groups: int):
        super().__init__()
        self.blocks = nn.ModuleList([Conv1dBlock(in_channels, out_channels, kernel_size, n_groups),
                                     Conv1dBlock(out_channels, out_channels, kernel_size, n_groups)])
        self.out_channels = out_channels
        self.cond_encoder = nn.Sequential(nn.Mish(), nn.Linear(cond_dim, 2 * out_channels))
        self.residual_conv = (nn.Conv1d(in_channels, out_channels, 1) if in_channels != out_channels
                              else nn.Identity())

    def forward(self, x: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        out = _run(self.blocks[0], x)
        scale, bias = _run(self.cond_encoder, cond).unsqueeze(-1).chunk(2, dim=1)
        out = _run(self.blocks[1], scale * out + bias)
        return out + _run(self.residual_conv, x)


class ConditionalUnet1D(nn.Module):
    """Noise predictor eps_theta(A_k, k, O) over action sequences.

    Args:
        input_dim: action dimension D.
        global_cond_dim: size of the flattened observation feature.
        diffusion_step_embed_dim: size of the step embedding.
        down_dims: channel widths per level; every level but the last halves the time axis, so the
            horizon must be divisible by 2^(len(down_dims) - 1).
        kernel_size, n_groups: Conv1d kernel and GroupNorm groups.
    """

    def __init__(self, input_dim: int, global_cond_dim: int, diffusion_step_embed_dim: int = 128,
                 down_dims: Sequence[int] = (64, 128, 256), kernel_size: int = 5, n_groups: int = 8):
        super().__init__()
        dims = [input_dim, *down_dims]
        embed = diffusion_step_embed_dim
        self.diffusion_step_encoder = nn.Sequential(SinusoidalPosEmb(embed), nn.Linear(embed, 4 * embed), nn.Mish(),
                                                    nn.Linear(4 * embed, embed))
        cond_dim = embed + global_cond_dim
        self.levels = len(down_dims)

        def block(a: int, b: int) -> ConditionalResidualBlock1D:
            return ConditionalResidualBlock1D(a, b, cond_dim, kernel_size, n_groups)

        mid = down_dims[-1]
        self.mid_modules = nn.ModuleList([block(mid, mid), block(mid, mid)])
        self.down_modules = nn.ModuleList()
        for index, (a, b) in enumerate(zip(dims[:-1], dims[1:], strict=True)):
            last = index == len(down_dims) - 1
            self.down_modules.append(nn.ModuleList([
                block(a, b), block(b, b), nn.Conv1d(b, b, 3, 2, 1) if not last else nn.Identity()]))
        self.up_modules = nn.ModuleList()
        reversed_pairs = list(zip(dims[1:][::-1][:-1], dims[1:][::-1][1:], strict=True))
        for a, b in reversed_pairs:  # (deeper width, shallower width)
            self.up_modules.append(nn.ModuleList([
                block(2 * a, b), block(b, b), nn.ConvTranspose1d(b, b, 4, 2, 1)]))
        self.final_conv = nn.Sequential(Conv1dBlock(down_dims[0], down_dims[0], kernel_size, n_groups),
                                        nn.Conv1d(down_dims[0], input_dim, 1))

    def forward(self, sample: torch.Tensor, timestep: torch.Tensor | int, global_cond: torch.Tensor) -> torch.Tensor:
        """sample (B, H, D), timestep (B,) or scalar, global_cond (B, global_cond_dim) -> (B, H, D)."""
        horizon = sample.shape[1]
        factor = 2 ** (self.levels - 1)
        if horizon % factor:
            raise ValueError(f"horizon {horizon} must be divisible by 2^(levels-1) = {factor} "
                             f"for a UNet with {self.levels} levels")
        if not torch.is_tensor(timestep):
            timestep = torch.tensor([timestep], device=sample.device)
        timestep = timestep.reshape(-1).expand(sample.shape[0]).to(sample.dtype)  # the embedding in the sample's dtype
        cond = torch.cat([_run(self.diffusion_step_encoder, timestep), global_cond], dim=-1)
        x = sample.transpose(1, 2)
        skips = []
        for first, second, downsample in self.down_modules:
            x = second.forward(first.forward(x, cond), cond)
            skips.append(x)
            x = _run(downsample, x)
        for module in self.mid_modules:
            x = module.forward(x, cond)
        for first, second, upsample in self.up_modules:
            x = torch.cat([x, skips.pop()], dim=1)
            x = _run(upsample, second.forward(first.forward(x, cond), cond))
        return _run(self.final_conv, x).transpose(1, 2)
