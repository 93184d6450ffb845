"""Perception that can fail: the simulator's ground truth seen through a stated model of open-vocabulary
detection + SAM + video tracking errors (docs/perception-error-model.md gives each rate's source).

The paper's perception finds each named object once (GroundingDINO boxes prompting SAM) and then tracks it
(Cutie; SAM 2 here). Its errors are of two kinds, and the model keeps them apart:

    per episode, at first sight (then tracked, so they persist):
        first_miss      the object is not found at all (the episode cannot start)
        lookalike       the phrase is grounded on another object of the same kind ("blue block" -> the red one)
        other_kind      ... on an object of another kind (a distractor, the other task object)
    per frame, after first sight:
        frame_miss      the tracker loses the object this frame
        boundary        the mask's boundary is off by `boundary_px` pixels (eroded or dilated, even odds)
        gross           a grossly wrong mask (IoU < 0.75): half the time a partial mask (a part cut off, as an
                        occluder would), half the time a spill `spill_px` pixels onto the neighbouring surfaces
                        (the table, a depth edge's far side), whose depth then enters the object's cloud

Every draw comes from a generator seeded by the episode seed (`start_episode`), the phrase and, per frame, the
frame's time and camera: the same episode gives the same errors whatever else runs, and nothing here touches
the policy's sampling noise. With every rate 0 the segmenter returns the oracle's results unchanged.
"""

from __future__ import annotations

import zlib
from collections import Counter
from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields

import numpy as np

from lano3dp.geometry.frame import RGBDFrame
from lano3dp.perception.base import MaskResult
from lano3dp.perception.sim_oracle import SimOracleSegmenter, scene_objects
from lano3dp.vocabulary import SceneObject, canonical_attribute, tokens

_MISSED = "<missed>"  # an episode decision: never found


@dataclass(frozen=True)
class PerceptionErrorModel:
    """Error rates of a detector + SAM + tracker pipeline (defaults: docs/perception-error-model.md).

    Attributes:
        first_miss: per object and episode, never found (RefCOCO val top-10 recall of GroundingDINO-T, 94.9%).
        lookalike: per phrase and episode with a same-kind object in view, grounded on it instead (RefCOCO+ testB
            top-1 accuracy of GroundingDINO-T, zero-shot, 46.4%).
        other_kind: per phrase and episode with an object of another kind in view, grounded on it instead (the
            no-target accuracy of GroundingDINO-T on gRefCOCO val, 91.8%).
        frame_miss: per object and frame after first sight, lost by the tracker (half of SAM 2.1-tiny's J&F
            shortfall on SA-V test, 76.5).
        boundary: per object and frame, boundary off by `boundary_px` (the other half, less `gross`).
        gross: per object and frame, a partial mask or a spill (SAM: 3% of masks under 0.75 IoU).
        boundary_px, spill_px: pixels a boundary error and a spill move the boundary.
        partial_keep: (low, high) fraction of the mask a partial mask keeps.
    """

    first_miss: float = 0.051
    lookalike: float = 0.536
    other_kind: float = 0.082
    frame_miss: float = 0.1175
    boundary: float = 0.0875
    gross: float = 0.03
    boundary_px: int = 1
    spill_px: int = 3
    partial_keep: tuple[float, float] = (0.5, 0.75)

    RATES = ("first_miss", "lookalike", "other_kind", "frame_miss", "boundary", "gross")

    def __post_init__(self):
        for name in self.RATES:
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"PerceptionErrorModel.{name} must be a probability in [0, 1], got {value}")
        if self.boundary + self.gross > 1.0:
            raise ValueError(f"boundary + gross must be at most 1 (one draw picks either), got "
                             f"{self.boundary} + {self.gross}")
        if self.boundary_px < 1 or self.spill_px < 1:
            raise ValueError(f"boundary_px and spill_px must be >= 1 pixel, got {self.boundary_px}, {self.spill_px}")
        low, high = self.partial_keep
        if not 0.0 < low <= high < 1.0:
            raise ValueError(f"partial_keep must be 0 < low <= high < 1, got {self.partial_keep}")
        object.__setattr__(self, "partial_keep", (float(low), float(high)))

    @classmethod
    def none(cls) -> PerceptionErrorModel:
        """Every rate 0: the oracle itself."""
        return cls(**dict.fromkeys(cls.RATES, 0.0))

    def scaled(self, factor: float) -> PerceptionErrorModel:
        """Every rate times `factor` (clipped to 1), for sensitivity runs: 0 is the oracle, 1 this model."""
        if factor < 0:
            raise ValueError(f"scale factor must be >= 0, got {factor}")
        rates = {name: min(1.0, getattr(self, name) * factor) for name in self.RATES}
        if rates["boundary"] + rates["gross"] > 1.0:
            rates["boundary"] = 1.0 - rates["gross"]
        return PerceptionErrorModel(**{**asdict(self), **rates})

    @property
    def is_zero(self) -> bool:
        return not any(getattr(self, name) for name in self.RATES)

    def to_dict(self) -> dict:
        data = asdict(self)
        data["partial_keep"] = list(self.partial_keep)
        return data

    @classmethod
    def from_dict(cls, data) -> PerceptionErrorModel:
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"unknown perception error model fields {unknown}; known: {sorted(known)}")
        return cls(**{k: tuple(v) if k == "partial_keep" else v for k, v in data.items()})


def _key(*parts) -> int:
    """A stable 32-bit number for strings and numbers (Python's hash() is salted per process)."""
    return zlib.crc32(repr(parts).encode())


def _frame_key(frame: RGBDFrame) -> int:
    """The frame's moment and camera: equal for the same frame asked twice, different for another view."""
    position = np.round(frame.camera.cam_to_world[:3, 3], 4).tolist()
    return _key(round(float(frame.timestamp) * 1000), position)


@dataclass
class _Grounding:
    """What a phrase was grounded on at first sight this episode, in which frame, and what it means."""

    name: str  # scene object name, or _MISSED
    first_frame: int
    truth: str | None = None


class ErrorModelSegmenter:
    """The simulator's ground-truth segmenter with `PerceptionErrorModel`'s errors on top.

    Call `start_episode(seed)` at each episode's start (the runtime does, `PolicyRunner.reset`); without it every
    episode uses `seed` and keeps the first episode's groundings. One instance per concurrently running episode.

    Args:
        model: the error rates (default: the published-numbers model).
        ambiguity: the oracle's rule for a phrase that matches several objects ("error" or "largest").
        seed: the episode seed used until `start_episode` is called.

    Attributes:
        counts: errors applied this episode by kind ("first_miss", "lookalike", "other_kind", "frame_miss",
            "boundary", "partial", "spill") and `segment` calls ("calls"); for logs and tests.
        groundings: phrase -> the scene object it was grounded on this episode (None: never found).
        misgroundings: phrase -> (the object it means, the object it was grounded on, None: never found) for the
            phrases this episode got wrong.
    """

    def __init__(self, model: PerceptionErrorModel | None = None, ambiguity: str = "error", seed: int = 0):
        self.model = model if model is not None else PerceptionErrorModel()
        self.oracle = SimOracleSegmenter(ambiguity=ambiguity)
        self.start_episode(seed)

    def start_episode(self, seed: int) -> None:
        """Forget this episode's groundings and draw the next episode's errors from `seed`."""
        self.seed = int(seed)
        self._groundings: dict[str, _Grounding] = {}
        self.counts: Counter[str] = Counter()

    reset = start_episode

    @property
    def groundings(self) -> dict[str, str | None]:
        return {p: (None if g.name == _MISSED else g.name) for p, g in self._groundings.items()}

    @property
    def misgroundings(self) -> dict[str, tuple[str | None, str | None]]:
        return {p: (g.truth, None if g.name == _MISSED else g.name) for p, g in self._groundings.items()
                if g.name != g.truth}

    def _rng(self, *parts) -> np.random.Generator:
        return np.random.default_rng([self.seed & 0xFFFFFFFF, *(_key(p) for p in parts)])

    # ---- per episode: grounding at first sight ------------------------------------------------------
    def _ground(self, phrase: str, truth: str, objects: Sequence[SceneObject], masks: dict[str, np.ndarray],
                frame_key: int, robot: frozenset[str] = frozenset()) -> _Grounding:
        """The episode's grounding of `phrase` (whose true object is `truth`), drawn at its first sight. The robot's
        own parts (`robot`) are never taken for a scene object: the confusion rates are for objects in a scene."""
        model = self.model
        u_miss, u_lookalike, u_other, u_pick = self._rng("ground", phrase).random(4)  # fixed order: stable streams
        by_name = {o.name: o for o in objects}
        true = by_name[truth]
        visible = [o for o in objects if o.name != truth and o.name not in robot and masks[o.name].any()]
        lookalikes = [o for o in visible if o.kind == true.kind]
        others = [o for o in visible if o.kind != true.kind]
        if u_miss < model.first_miss:
            self.counts["first_miss"] += 1
            return _Grounding(_MISSED, frame_key, truth)
        if lookalikes and u_lookalike < model.lookalike:
            self.counts["lookalike"] += 1
            return _Grounding(_pick(most_similar(phrase, lookalikes), u_pick).name, frame_key, truth)
        if others and u_other < model.other_kind:
            self.counts["other_kind"] += 1
            return _Grounding(_pick(sorted(others, key=lambda o: o.name), u_pick).name, frame_key, truth)
        return _Grounding(truth, frame_key, truth)

    # ---- per frame: tracking losses and mask errors --------------------------------------------------
    def _frame_mask(self, phrase: str, mask: np.ndarray, frame_key: int, first: bool) -> np.ndarray | None:
        model = self.model
        rng = self._rng("frame", phrase, frame_key)
        u_miss, u_mask, u_side = rng.random(3)
        if not first and u_miss < model.frame_miss:
            self.counts["frame_miss"] += 1
            return None
        if u_mask < model.gross:
            if u_side < 0.5:
                self.counts["partial"] += 1
                mask = partial_mask(mask, rng, model.partial_keep)
            else:
                self.counts["spill"] += 1
                mask = _morph(mask, dilate=True, pixels=model.spill_px)
        elif u_mask < model.gross + model.boundary:
            self.counts["boundary"] += 1
            mask = _morph(mask, dilate=u_side < 0.5, pixels=model.boundary_px)
        return mask if mask.any() else None

    def per_frame(self, phrases: Sequence[str]) -> bool:
        """Whether `segment(frame, phrases)` depends on the frame alone: once every phrase is grounded (its first
        sight drew the episode's confusion), a frame's errors come from that frame's own draws."""
        return self.model.is_zero or all(phrase in self._groundings for phrase in phrases)

    # ---- the Segmenter protocol -----------------------------------------------------------------------
    def segment(self, frame: RGBDFrame, phrases: Sequence[str]) -> list[MaskResult]:
        if self.model.is_zero:
            return self.oracle.segment(frame, phrases)
        objects, masks = scene = scene_objects(frame)
        truths = self.oracle.segment(frame, phrases, scene)  # raises AmbiguousObjectError as the oracle does
        frame_key = _frame_key(frame)
        self.counts["calls"] += 1
        visible = tuple(name for name in sorted(masks) if masks[name].any())
        results = []
        for phrase, truth in zip(phrases, truths, strict=True):
            grounding = self._groundings.get(phrase)
            if grounding is None:
                if not truth.found:  # not in view yet: first sight is later
                    results.append(truth)
                    continue
                robot = frozenset(name for name, words in frame.instance_attributes.items()
                                  if (words or {}).get("role") == "robot")
                grounding = self._groundings[phrase] = self._ground(phrase, truth.matched_name, objects, masks,
                                                                    frame_key, robot)
            if grounding.name == _MISSED or not masks[grounding.name].any():
                results.append(MaskResult.missing(phrase, visible, None if grounding.name == _MISSED
                                                  else grounding.name))
                continue
            mask = self._frame_mask(phrase, masks[grounding.name], frame_key, first=frame_key == grounding.first_frame)
            results.append(MaskResult(phrase, mask, 1.0, True, grounding.name) if mask is not None
                           else MaskResult.missing(phrase, visible, grounding.name))
        return results

    def segment_instances(self, frame: RGBDFrame, phrase: str) -> list[MaskResult]:
        """Every visible instance `phrase` means (obstacles), each with its own first-sight miss and per-frame
        mask errors (no confusion: every instance is wanted)."""
        instances = self.oracle.segment_instances(frame, phrase)
        if self.model.is_zero:
            return instances
        frame_key = _frame_key(frame)
        out = []
        for result in instances:
            key = f"{phrase}\x00{result.matched_name}"
            grounding = self._groundings.get(key)
            if grounding is None:
                missed = self._rng("ground", key).random() < self.model.first_miss
                self.counts["first_miss"] += missed
                grounding = self._groundings[key] = _Grounding(_MISSED if missed else result.matched_name, frame_key,
                                                               result.matched_name)
            if grounding.name == _MISSED:
                continue
            mask = self._frame_mask(key, result.mask, frame_key, first=frame_key == grounding.first_frame)
            if mask is not None:
                out.append(MaskResult(phrase, mask, 1.0, True, result.matched_name))
        return out


def most_similar(phrase: str, candidates: Sequence[SceneObject]) -> list[SceneObject]:
    """The candidates sharing the most of the phrase's words as attributes (a "large blue bowl" is confused with
    a blue bowl before a red one), by name."""
    words = {canonical_attribute(t) for t in tokens(phrase)}
    shared = {o.name: len(words & o.attributes) for o in candidates}
    best = max(shared.values())
    return sorted((o for o in candidates if shared[o.name] == best), key=lambda o: o.name)


def _pick(candidates: Sequence[SceneObject], u: float) -> SceneObject:
    return candidates[min(int(u * len(candidates)), len(candidates) - 1)]


def _morph(mask: np.ndarray, *, dilate: bool, pixels: int) -> np.ndarray:
    """`pixels` steps of 4-connected binary dilation (or erosion), as scipy.ndimage's with a cross; written with
    numpy shifts so that evaluating with this segmenter needs no optional extra."""
    out = np.asarray(mask, dtype=bool)
    for _ in range(pixels):
        padded = np.pad(out, 1)  # outside the image is unset, as scipy's border_value=0
        centre = padded[1:-1, 1:-1]
        neighbours = (padded[:-2, 1:-1], padded[2:, 1:-1], padded[1:-1, :-2], padded[1:-1, 2:])
        out = centre.copy()
        for shifted in neighbours:
            out = out | shifted if dilate else out & shifted
    return out


def partial_mask(mask: np.ndarray, rng: np.random.Generator, keep: tuple[float, float]) -> np.ndarray:
    """The part of `mask` on one side of a random straight cut, keeping a fraction in `keep` of its pixels (what an
    occluder or a half-found object leaves)."""
    rows, cols = np.nonzero(mask)
    angle = rng.uniform(0.0, 2.0 * np.pi)
    along = rows * np.sin(angle) + cols * np.cos(angle)
    threshold = np.quantile(along, rng.uniform(*keep))
    out = np.zeros_like(mask)
    kept = along <= threshold
    out[rows[kept], cols[kept]] = True
    return out
