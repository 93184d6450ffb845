"""Object-centric diffusion policy: configuration, normaliser, encoders, FiLM ConditionalUnet1D, checkpoints."""

from lano3dp.policy.config import DOWN_DIMS_PRESETS, PolicyConfig, down_dims_for
from lano3dp.policy.modeling import ActionChunk, DiffusionPolicy, make_scheduler
from lano3dp.policy.normalizer import LinearNormalizer, NormalizerNotFittedError

__all__ = [
    "DOWN_DIMS_PRESETS",
    "ActionChunk",
    "DiffusionPolicy",
    "LinearNormalizer",
    "NormalizerNotFittedError",
    "PolicyConfig",
    "down_dims_for",
    "make_scheduler",
]
