"""Object-centric diffusion policy: configuration, normaliser, encoders, FiLM ConditionalUnet1D, checkpoints, and the
registry of observation types (`policy.observations`)."""

from lano3dp.policy.config import DOWN_DIMS_PRESETS, PolicyConfig, down_dims_for
from lano3dp.policy.modeling import ActionChunk, ChunkedControl, ControlPolicy, DiffusionPolicy, make_scheduler
from lano3dp.policy.normalizer import LinearNormalizer, NormalizerNotFittedError
from lano3dp.policy.observations import (
    ObservationType,
    UnknownObservationTypeError,
    get_observation_type,
    observation_type_names,
    register_observation_type,
    unregister_observation_type,
)

__all__ = [
    "DOWN_DIMS_PRESETS",
    "ActionChunk",
    "ChunkedControl",
    "ControlPolicy",
    "DiffusionPolicy",
    "LinearNormalizer",
    "NormalizerNotFittedError",
    "ObservationType",
    "PolicyConfig",
    "UnknownObservationTypeError",
    "down_dims_for",
    "get_observation_type",
    "make_scheduler",
    "observation_type_names",
    "register_observation_type",
    "unregister_observation_type",
]
