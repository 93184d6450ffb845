"""Perception: named objects -> masks -> per-object world clouds.

Light imports only; the transformers backends (`open_vocab`, `tracker`) and the RealSense
source are imported from their modules on demand.
"""

from lano3dp.perception.base import InstanceSegmenter, MaskResult, Segmenter
from lano3dp.perception.error_model import ErrorModelSegmenter, PerceptionErrorModel
from lano3dp.perception.exceptions import (
    AmbiguousObjectError,
    MissingWeightsError,
    ObjectNotFoundError,
    PerceptionError,
    TooFewPointsError,
)
from lano3dp.perception.factory import SegmenterConfig, build_segmenter
from lano3dp.perception.observer import ObjectClouds, ObjectObserver, scene_cloud
from lano3dp.perception.perturb import MaskPerturbation, PerturbedSegmenter
from lano3dp.perception.sim_oracle import SimOracleSegmenter
from lano3dp.vocabulary import resolve_phrase

__all__ = [
    "AmbiguousObjectError",
    "ErrorModelSegmenter",
    "InstanceSegmenter",
    "MaskPerturbation",
    "MaskResult",
    "MissingWeightsError",
    "ObjectClouds",
    "ObjectNotFoundError",
    "ObjectObserver",
    "PerceptionError",
    "PerceptionErrorModel",
    "PerturbedSegmenter",
    "Segmenter",
    "SegmenterConfig",
    "SimOracleSegmenter",
    "TooFewPointsError",
    "build_segmenter",
    "resolve_phrase",
    "scene_cloud",
]
