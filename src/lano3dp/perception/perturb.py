"""Controlled segmentation errors, to measure how a policy degrades with imperfect masks.

The paper assumes the detector finds the objects (its stated limitation); wrapping the
oracle in `PerturbedSegmenter` lets training and evaluation put a number on that
assumption: shrunk or swollen masks, speckle, and whole-object misses.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from lano3dp.geometry.frame import RGBDFrame
from lano3dp.perception.base import InstanceSegmenter, MaskResult, Segmenter

# 4-connected structuring element: each iteration moves the boundary by one pixel.
_CROSS = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], dtype=bool)


@dataclass(frozen=True)
class MaskPerturbation:
    """Errors applied to every found mask, in this order: miss, erode, dilate, drop.

    Attributes:
        erode_px: boundary pixels removed (under-segmentation).
        dilate_px: boundary pixels added (over-segmentation; background depth leaks into the cloud).
        drop_fraction: fraction of the remaining mask pixels removed at random (speckle).
        miss_probability: chance the object is reported not found in a frame.
        seed: seeds the random stream of a `PerturbedSegmenter`.
    """

    erode_px: int = 0
    dilate_px: int = 0
    drop_fraction: float = 0.0
    miss_probability: float = 0.0
    seed: int = 0

    def __post_init__(self):
        if self.erode_px < 0 or self.dilate_px < 0:
            raise ValueError(f"erode_px and dilate_px must be >= 0, got {self.erode_px}, {self.dilate_px}")
        if not 0.0 <= self.drop_fraction < 1.0:
            raise ValueError(f"drop_fraction must be in [0, 1), got {self.drop_fraction}")
        if not 0.0 <= self.miss_probability <= 1.0:
            raise ValueError(f"miss_probability must be in [0, 1], got {self.miss_probability}")

    @property
    def is_identity(self) -> bool:
        return not (self.erode_px or self.dilate_px or self.drop_fraction or self.miss_probability)

    def apply(self, mask: np.ndarray, rng: np.random.Generator) -> np.ndarray | None:
        """Perturbed copy of an (H, W) bool mask, or None when the object is missed or erased."""
        if self.miss_probability and rng.random() < self.miss_probability:
            return None
        from scipy import ndimage  # the "perception" extra; imported here so the package imports without it

        out = np.asarray(mask, dtype=bool)
        if self.erode_px:
            out = ndimage.binary_erosion(out, _CROSS, iterations=self.erode_px)
        if self.dilate_px:
            out = ndimage.binary_dilation(out, _CROSS, iterations=self.dilate_px)
        if self.drop_fraction:
            out = out & (rng.random(out.shape) >= self.drop_fraction)
        return out if out.any() else None


class PerturbedSegmenter:
    """Wraps any segmenter and perturbs its found masks.

    The random stream advances call by call, so a rollout sees fresh (but reproducible
    from `perturbation.seed`) errors every frame; `reset()` restarts it.
    """

    def __init__(self, inner: Segmenter, perturbation: MaskPerturbation):
        self.inner = inner
        self.perturbation = perturbation
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        self._rng = np.random.default_rng(self.perturbation.seed if seed is None else seed)

    def segment_instances(self, frame: RGBDFrame, phrase: str) -> list[MaskResult]:
        """Perturbed instances of `phrase` (a missed instance is dropped); needs an inner InstanceSegmenter."""
        if not isinstance(self.inner, InstanceSegmenter):
            return [r for r in self.segment(frame, [phrase]) if r.found]
        out = []
        for result in self.inner.segment_instances(frame, phrase):
            mask = self.perturbation.apply(result.mask, self._rng)
            if mask is not None:
                out.append(MaskResult(result.phrase, mask, result.score, True, result.matched_name))
        return out

    def segment(self, frame: RGBDFrame, phrases: Sequence[str]) -> list[MaskResult]:
        results = self.inner.segment(frame, phrases)
        if self.perturbation.is_identity:
            return results
        masks = [self.perturbation.apply(r.mask, self._rng) if r.found else None for r in results]
        still_seen = tuple(r.matched_name or r.phrase for r, m in zip(results, masks, strict=True) if m is not None)
        out = []
        for result, mask in zip(results, masks, strict=True):
            if not result.found:
                out.append(result)
            elif mask is None:
                out.append(MaskResult.missing(result.phrase, still_seen, result.matched_name))
            else:
                out.append(MaskResult(result.phrase, mask, result.score, True, result.matched_name))
        return out
