"""Training-free, cost-guided sampling (the paper's Algorithm 1) and obstacle costs."""

from lano3dp.guidance.sampler import GuidanceConfig, GuidanceMode, denoise

__all__ = ["GuidanceConfig", "GuidanceMode", "denoise"]
