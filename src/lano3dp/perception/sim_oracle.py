"""Ground-truth segmenter for simulated frames: phrases resolved against the scene's objects.

A phrase such as "bowl", "red bowl", "the small red bowl" or an exact object name
("bowl_2") is resolved by its kind noun plus attribute words (colour, size) against
`frame.instance_names` and `frame.instance_attributes`; the mask comes from
`frame.segmentation`. Resolution is by meaning, not by what is visible, so an occluded
object is reported as not found rather than silently replaced by a look-alike.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np

from lano3dp.geometry.frame import RGBDFrame
from lano3dp.perception.base import MaskResult
from lano3dp.perception.exceptions import AmbiguousObjectError

# The phrase vocabulary lives in lano3dp.vocabulary (language resolves phrases the same way); these names are
# re-exported because callers and tests import them from here.
from lano3dp.vocabulary import (  # noqa: F401
    COLOURS,
    SIZE_WORDS,
    SceneObject,
    canonical_attribute,
    resolve_phrase,
    singular,
    tokens,
)


class SimOracleSegmenter:
    """Segmenter reading the simulator's ground-truth instance map.

    Args:
        ambiguity: what to do when a phrase matches several objects.
            "error" (default) raises AmbiguousObjectError listing them, because silently
            conditioning a policy on the wrong object is worse than stopping.
            "largest" picks the candidate with the most visible pixels (ties: first by name),
            a deterministic choice for scripted data collection in cluttered scenes.
    """

    def __init__(self, ambiguity: Literal["error", "largest"] = "error"):
        if ambiguity not in ("error", "largest"):
            raise ValueError(f"ambiguity must be 'error' or 'largest', got {ambiguity!r}")
        self.ambiguity = ambiguity

    def per_frame(self, phrases: Sequence[str]) -> bool:
        """Whether `segment(frame, phrases)` depends on the frame alone: always (ground truth keeps no memory)."""
        return True

    @staticmethod
    def _scene(frame: RGBDFrame) -> tuple[list[SceneObject], dict[str, np.ndarray]]:
        return scene_objects(frame)

    def segment_instances(self, frame: RGBDFrame, phrase: str) -> list[MaskResult]:
        """Every visible object `phrase` can mean, by name (obstacles: "avoid the cups" means all of them)."""
        objects, masks = self._scene(frame)
        return [
            MaskResult(phrase, masks[name], 1.0, True, name)
            for name in sorted(resolve_phrase(phrase, objects))
            if masks[name].any()
        ]

    def segment(self, frame: RGBDFrame, phrases: Sequence[str],
                scene: tuple[list[SceneObject], dict[str, np.ndarray]] | None = None) -> list[MaskResult]:
        """One result per phrase; `scene` is `scene_objects(frame)` when the caller already has it."""
        objects, masks = scene if scene is not None else self._scene(frame)
        visible = tuple(name for name in sorted(masks) if masks[name].any())
        results = []
        for phrase in phrases:
            candidates = resolve_phrase(phrase, objects)
            if not candidates:
                results.append(MaskResult.missing(phrase, visible))
                continue
            if len(candidates) > 1:
                if self.ambiguity == "error":
                    raise AmbiguousObjectError(phrase, candidates)
                candidates = sorted(candidates, key=lambda n: (-int(masks[n].sum()), n))
            name = candidates[0]
            if not masks[name].any():
                results.append(MaskResult.missing(phrase, visible, matched_name=name))
            else:
                results.append(MaskResult(phrase, masks[name], 1.0, True, name))
        return results


def scene_objects(frame: RGBDFrame) -> tuple[list[SceneObject], dict[str, np.ndarray]]:
    """The frame's objects in words (sorted by name) and each one's (H, W) bool ground-truth mask."""
    if frame.segmentation is None:
        raise ValueError("SimOracleSegmenter needs frame.segmentation (simulator ground truth); got none")
    objects = [
        SceneObject.from_frame_entry(name, frame.instance_attributes.get(name))
        for name in sorted(frame.instance_names)
    ]
    masks = {
        name: np.isin(frame.segmentation, np.asarray(ids, dtype=np.int64))
        for name, ids in frame.instance_names.items()
    }
    return objects, masks
