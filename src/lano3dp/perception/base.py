"""The `Segmenter` protocol: phrases in, one explicit `MaskResult` per phrase out.

Every backend (simulator oracle, open-vocabulary detector + SAM, video tracker, a
perturbation wrapper) meets this contract, so `ObjectObserver` and the runtime never
know which one they drive.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from lano3dp.geometry.frame import RGBDFrame


@dataclass(frozen=True)
class MaskResult:
    """The answer for one phrase.

    Attributes:
        phrase: the words asked for, as given.
        mask: (H, W) bool when found, else None (a miss is never an all-False mask).
        score: confidence in [0, 1] (1 for ground truth, detector score otherwise).
        found: whether the object is visible in this frame.
        matched_name: the scene object (oracle) or detector label the phrase resolved to.
        visible: when not found, what the segmenter did see (object names or labels), for error messages.
    """

    phrase: str
    mask: np.ndarray | None
    score: float
    found: bool
    matched_name: str | None = None
    visible: tuple[str, ...] = ()

    def __post_init__(self):
        if self.found:
            if self.mask is None or self.mask.ndim != 2 or self.mask.dtype != np.bool_:
                raise ValueError(f"a found result for '{self.phrase}' needs an (H, W) bool mask")
            if not self.mask.any():
                raise ValueError(f"a found result for '{self.phrase}' has an empty mask; report found=False")
        elif self.mask is not None:
            raise ValueError(f"a not-found result for '{self.phrase}' must have mask=None")

    @property
    def pixel_count(self) -> int:
        return 0 if self.mask is None else int(self.mask.sum())

    @classmethod
    def missing(cls, phrase: str, visible: Sequence[str] = (), matched_name: str | None = None) -> MaskResult:
        return cls(phrase, None, 0.0, False, matched_name, tuple(visible))


@runtime_checkable
class Segmenter(Protocol):
    """Anything that turns an RGB-D frame and object phrases into masks."""

    def segment(self, frame: RGBDFrame, phrases: Sequence[str]) -> list[MaskResult]:
        """One `MaskResult` per phrase, in the order given."""
        ...


@runtime_checkable
class InstanceSegmenter(Protocol):
    """A segmenter that can also return every instance a phrase matches ("avoid the cups")."""

    def segment_instances(self, frame: RGBDFrame, phrase: str) -> list[MaskResult]:
        """One found `MaskResult` per visible instance of `phrase` (empty list if none)."""
        ...
