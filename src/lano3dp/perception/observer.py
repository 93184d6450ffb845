"""Frame + object phrases -> fixed-size per-object world clouds (the Lan-o3dp observation).

Also `scene_cloud`, the whole cropped scene without the table, for the DP3 baseline.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from lano3dp.errors import EmptyCloudError
from lano3dp.geometry.frame import RGBDFrame
from lano3dp.geometry.pointcloud import crop_to_box, depth_to_points, farthest_point_sample
from lano3dp.perception.base import InstanceSegmenter, MaskResult, Segmenter
from lano3dp.perception.exceptions import ObjectNotFoundError, TooFewPointsError


@dataclass(frozen=True)
class ObjectClouds:
    """Per-object clouds of one frame, in the order the phrases were asked.

    Attributes:
        points: (K, N, 3) float32, world frame, metres, farthest-point sampled.
        names: the K phrases (slot words) as asked.
        matched_names: what each phrase resolved to (scene object or detector label).
        pixel_counts: (K,) int64 mask pixels per object.
        point_counts: (K,) int64 valid depth points per object before sampling (after the crop).
        scores: (K,) float32 segmenter confidence.
        masks: the K (H, W) bool masks, kept for visualisation.
    """

    points: np.ndarray
    names: tuple[str, ...]
    matched_names: tuple[str | None, ...]
    pixel_counts: np.ndarray
    point_counts: np.ndarray
    scores: np.ndarray
    masks: tuple[np.ndarray, ...] = ()

    def __getitem__(self, name: str) -> np.ndarray:
        """(N, 3) cloud of the object asked for as `name`."""
        try:
            return self.points[self.names.index(name)]
        except ValueError:
            raise KeyError(f"no cloud named '{name}'; have {', '.join(self.names)}") from None

    def centroids(self) -> np.ndarray:
        """(K, 3) mean point per object, metres."""
        return self.points.mean(axis=1)


class ObjectObserver:
    """Segments named objects and turns each mask into a fixed-size world-frame cloud.

    Args:
        segmenter: any `Segmenter` (oracle, open-vocabulary, tracker, perturbed).
        n_points: N, points per object after farthest-point sampling.
        crop_low, crop_high: optional (3,) workspace box in the world frame, metres; points outside
            are dropped before the point-count check (drops far background bleeding into a mask).
        min_points: fewer valid points than this raises TooFewPointsError naming the object.
        seed: FPS start point (and repeats when a cloud is smaller than N).
    """

    def __init__(
        self,
        segmenter: Segmenter,
        n_points: int = 256,
        crop_low: Sequence[float] | None = None,
        crop_high: Sequence[float] | None = None,
        min_points: int = 10,
        seed: int = 0,
    ):
        if n_points <= 0 or min_points < 1:
            raise ValueError(f"n_points and min_points must be positive, got {n_points}, {min_points}")
        if (crop_low is None) != (crop_high is None):
            raise ValueError("give both crop_low and crop_high, or neither")
        self.segmenter = segmenter
        self.n_points = n_points
        self.crop_low = None if crop_low is None else np.asarray(crop_low, dtype=np.float32)
        self.crop_high = None if crop_high is None else np.asarray(crop_high, dtype=np.float32)
        self.min_points = min_points
        self.seed = seed

    def observe(self, frame: RGBDFrame, phrases: Sequence[str], *, min_points: int | None = None) -> ObjectClouds:
        """Clouds of `phrases` in `frame` (`min_points` overrides the observer's own threshold).

        Raises:
            ObjectNotFoundError: a phrase matched nothing visible (names the phrase and what was seen).
            AmbiguousObjectError: from the segmenter, when a phrase matches several objects.
            TooFewPointsError: an object has fewer than `min_points` valid depth points.
        """
        phrases = list(phrases)
        if not phrases:
            raise ValueError("observe needs at least one object phrase")
        results = self.segmenter.segment(frame, phrases)
        if len(results) != len(phrases):
            raise RuntimeError(f"segmenter returned {len(results)} results for {len(phrases)} phrases")
        clouds, counts = [], []
        for result in results:
            cloud, count = self.cloud_from_mask(frame, result, min_points=min_points)
            clouds.append(cloud)
            counts.append(count)
        return ObjectClouds(
            points=np.stack(clouds).astype(np.float32),
            names=tuple(phrases),
            matched_names=tuple(r.matched_name for r in results),
            pixel_counts=np.array([r.pixel_count for r in results], dtype=np.int64),
            point_counts=np.array(counts, dtype=np.int64),
            scores=np.array([r.score for r in results], dtype=np.float32),
            masks=tuple(r.mask for r in results),
        )

    def observe_instances(self, frame: RGBDFrame, phrases: Sequence[str]) -> ObjectClouds:
        """Clouds of every instance each phrase matches, for obstacles ("avoid the cups": each cup is one
        obstacle, and two mugs are never merged into one cloud). `names` repeats the phrase per instance;
        `matched_names` tells them apart. A segmenter without `segment_instances` gives one per phrase.

        Raises:
            ObjectNotFoundError: a phrase matches nothing visible.
            TooFewPointsError: an instance has fewer than `min_points` valid depth points.
        """
        if not isinstance(self.segmenter, InstanceSegmenter):
            return self.observe(frame, phrases)
        results: list[MaskResult] = []
        for phrase in phrases:
            instances = self.segmenter.segment_instances(frame, phrase)
            if not instances:
                (missing,) = self.segmenter.segment(frame, [phrase])
                raise ObjectNotFoundError(phrase, missing.visible)
            results.extend(instances)
        if not results:
            raise ValueError("observe_instances needs at least one object phrase")
        clouds, counts = zip(*(self.cloud_from_mask(frame, r) for r in results), strict=True)
        return ObjectClouds(
            points=np.stack(clouds).astype(np.float32),
            names=tuple(r.phrase for r in results),
            matched_names=tuple(r.matched_name for r in results),
            pixel_counts=np.array([r.pixel_count for r in results], dtype=np.int64),
            point_counts=np.array(counts, dtype=np.int64),
            scores=np.array([r.score for r in results], dtype=np.float32),
            masks=tuple(r.mask for r in results),
        )

    def cloud_from_mask(self, frame: RGBDFrame, result: MaskResult, *,
                        min_points: int | None = None) -> tuple[np.ndarray, int]:
        """(N, 3) float32 FPS cloud of one segmented object and its valid point count before sampling."""
        if not result.found:
            raise ObjectNotFoundError(result.phrase, result.visible)
        points = depth_to_points(frame.depth, frame.camera, result.mask)
        if self.crop_low is not None:
            points = crop_to_box(points, self.crop_low, self.crop_high)
        needed = self.min_points if min_points is None else max(1, int(min_points))
        if len(points) < needed:
            same = result.matched_name in (None, result.phrase)
            label = result.phrase if same else f"{result.phrase} [{result.matched_name}]"
            raise TooFewPointsError(label, len(points), needed)
        return farthest_point_sample(points, self.n_points, seed=self.seed, name=result.phrase), len(points)


def scene_cloud(
    frame: RGBDFrame,
    n_points: int = 512,
    crop_low: Sequence[float] | None = None,
    crop_high: Sequence[float] | None = None,
    table_height: float = 0.0,
    table_margin: float = 0.005,
    seed: int = 0,
) -> np.ndarray:
    """Whole-scene cloud for the DP3 baseline: back-project, crop, drop the table, FPS.

    Args:
        frame: the RGB-D frame; depth holes (0 / NaN) are skipped.
        n_points: size of the result.
        crop_low, crop_high: optional (3,) world-frame workspace box, metres.
        table_height: z of the table top, metres; points with z <= table_height + table_margin
            are the table (a horizontal plane in the world frame, see docs/architecture.md).
        table_margin: metres of tolerance above the plane for depth noise.
        seed: FPS seed.

    Returns:
        (n_points, 3) float32, world frame.

    Raises:
        EmptyCloudError: nothing is left above the table inside the crop box.
    """
    if (crop_low is None) != (crop_high is None):
        raise ValueError("give both crop_low and crop_high, or neither")
    points = depth_to_points(frame.depth, frame.camera)
    if crop_low is not None:
        points = crop_to_box(points, crop_low, crop_high)
    points = points[points[:, 2] > table_height + table_margin]
    if len(points) == 0:
        raise EmptyCloudError(
            f"scene cloud is empty: no valid depth point above the table (z > {table_height + table_margin:.3f} m) "
            "inside the crop box"
        )
    return farthest_point_sample(points, n_points, seed=seed, name="scene cloud")
