"""Video object tracking with SAM2 (transformers `Sam2VideoModel`), standing in for the paper's Cutie.

`VideoTracker` is seeded with one mask per object on a first frame and then follows them frame by
frame in streaming mode. `TrackingSegmenter` wires it behind the `Segmenter` protocol: the first
frame (and any frame where an object is lost) goes through an initial segmenter such as
`OpenVocabSegmenter`; later frames are tracked. Preprocessing is done here (resize to the model's
square input, ImageNet normalisation), so torchvision is not needed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lano3dp.geometry.frame import RGBDFrame
from lano3dp.perception._hf import check_weights_dir, load_local
from lano3dp.perception.base import MaskResult, Segmenter

_IMAGENET_MEAN = (0.485, 0.456, 0.406)
_IMAGENET_STD = (0.229, 0.224, 0.225)


@dataclass(frozen=True)
class TrackedMask:
    """mask: (H, W) bool, or None when the model says the object left the view; score: presence in [0, 1]."""

    mask: np.ndarray | None
    score: float


class VideoTracker:
    """Streaming SAM2 video tracker.

    Args:
        model: a transformers `Sam2VideoModel`.
        keep_frames: frames of history kept in the session (older non-conditioning frames and their
            outputs are dropped so a long rollout does not grow memory without bound); None derives
            it from the model's memory size.
    """

    def __init__(self, model, keep_frames: int | None = None):
        self.model = model.eval()
        config = model.config
        self.image_size = int(config.image_size)
        self.keep_frames = keep_frames or max(config.num_maskmem, config.max_object_pointers_in_encoder) + 1
        self.names: list[str] = []
        self._session = None
        self._frame_shape: tuple[int, int] | None = None
        self._next_frame = 0

    @classmethod
    def from_pretrained(cls, path: str | Path, keep_frames: int | None = None) -> VideoTracker:
        path = check_weights_dir(path, "SAM2 video weights")
        from transformers import Sam2VideoModel

        return cls(load_local(Sam2VideoModel, path, "SAM2 video weights"), keep_frames)

    @property
    def started(self) -> bool:
        return self._session is not None

    def preprocess(self, rgb: np.ndarray):
        """(1, 3, S, S) float tensor: what Sam2ImageProcessor produces (resize, /255, ImageNet mean/std)."""
        import torch
        import torch.nn.functional as F

        x = torch.from_numpy(np.ascontiguousarray(rgb)).permute(2, 0, 1)[None].float() / 255.0
        x = F.interpolate(x, size=(self.image_size, self.image_size), mode="bilinear", align_corners=False)
        mean = torch.tensor(_IMAGENET_MEAN).view(1, 3, 1, 1)
        std = torch.tensor(_IMAGENET_STD).view(1, 3, 1, 1)
        return (x - mean) / std

    def start(self, rgb: np.ndarray, masks: Mapping[str, np.ndarray]) -> dict[str, TrackedMask]:
        """Begin a new session on `rgb` (H, W, 3) uint8 with one (H, W) bool mask per object name."""
        import torch
        import torch.nn.functional as F
        from transformers import Sam2VideoInferenceSession

        if not masks:
            raise ValueError("the tracker needs at least one object mask to start")
        height, width = rgb.shape[:2]
        self._frame_shape = (height, width)
        self.names = list(masks)
        # dtype must be a torch dtype: the session's string default breaks `.to()` (transformers 5.23).
        self._session = Sam2VideoInferenceSession(video_height=height, video_width=width, dtype=torch.float32)
        for obj_id, name in enumerate(self.names):
            mask = np.asarray(masks[name], dtype=bool)
            if mask.shape != (height, width) or not mask.any():
                raise ValueError(f"seed mask of '{name}' must be a non-empty ({height}, {width}) bool array")
            small = F.interpolate(
                torch.from_numpy(mask)[None, None].float(), size=(self.image_size, self.image_size), mode="bilinear"
            ).ge(0.5)
            self._session.add_mask_inputs(self._session.obj_id_to_idx(obj_id), 0, small.float())
        self._session.obj_with_new_inputs = list(range(len(self.names)))
        self._next_frame = 0
        return self._step(rgb)

    def track(self, rgb: np.ndarray) -> dict[str, TrackedMask]:
        """Masks of every object in the next frame."""
        if self._session is None:
            raise RuntimeError("call start(rgb, masks) before track(rgb)")
        if rgb.shape[:2] != self._frame_shape:
            raise ValueError(f"frame is {rgb.shape[:2]} but the session started at {self._frame_shape}")
        return self._step(rgb)

    def reset(self) -> None:
        self._session = None
        self.names = []

    def _step(self, rgb: np.ndarray) -> dict[str, TrackedMask]:
        import torch
        import torch.nn.functional as F

        # Explicit indices: after pruning, the session's own count (len of its frame dict) would repeat.
        frame_idx, self._next_frame = self._next_frame, self._next_frame + 1
        with torch.inference_mode():
            output = self.model(inference_session=self._session, frame_idx=frame_idx, frame=self.preprocess(rgb))
        logits = F.interpolate(output.pred_masks, size=self._frame_shape, mode="bilinear", align_corners=False)
        presence = torch.sigmoid(output.object_score_logits.reshape(-1)).numpy()
        result = {}
        for i, obj_id in enumerate(output.object_ids):
            mask = logits[i, 0].numpy() > 0
            present = presence[i] > 0.5 and mask.any()
            result[self.names[obj_id]] = TrackedMask(mask if present else None, float(presence[i]))
        self._prune(output.frame_idx)
        return result

    def _prune(self, current: int) -> None:
        """Drop frames (and their non-conditioning outputs) older than `keep_frames`."""
        session = self._session
        oldest = current - self.keep_frames
        for index in [i for i in session.processed_frames if 0 < i < oldest]:
            del session.processed_frames[index]
        for outputs in session.output_dict_per_obj.values():
            for index in [i for i in outputs["non_cond_frame_outputs"] if i < oldest]:
                del outputs["non_cond_frame_outputs"][index]
        for tracked in session.frames_tracked_per_obj.values():
            for index in [i for i in tracked if i < oldest]:
                del tracked[index]


class TrackingSegmenter:
    """Segmenter that detects once and tracks afterwards (the paper's GroundingDINO + SAM -> Cutie).

    One tracking session covers every phrase asked for so far, so a runtime that asks for its
    targets and then its obstacles on the same frame tracks that frame once (the result is cached
    for the frame object) instead of restarting. The first frame, a frame that brings new phrases,
    and a frame where any tracked object is lost go through `initial` (e.g. `OpenVocabSegmenter`)
    for all session phrases, and the tracker restarts from those masks. Each episode starts afresh
    (`start_episode`, which the runner calls).
    """

    def __init__(self, initial: Segmenter, tracker: VideoTracker):
        self.initial = initial
        self.tracker = tracker
        self._phrases: tuple[str, ...] = ()
        self._last_frame: RGBDFrame | None = None
        self._last: dict[str, MaskResult] = {}
        self.redetections = 0

    def start_episode(self, seed: int) -> None:
        """Forget the last episode's objects (the runner calls it at every episode's start)."""
        self.reset()

    def reset(self) -> None:
        self.tracker.reset()
        self._phrases = ()
        self._last_frame = None
        self._last = {}

    def segment(self, frame: RGBDFrame, phrases: Sequence[str]) -> list[MaskResult]:
        phrases = tuple(phrases)
        if frame is self._last_frame and all(p in self._last for p in phrases):
            return [self._last[p] for p in phrases]
        known = self.tracker.started and set(phrases) <= set(self._phrases)
        if known:
            tracked = self.tracker.track(frame.rgb)
            if all(t.mask is not None for t in tracked.values()):
                self._remember(frame, [MaskResult(p, t.mask, t.score, True, p) for p, t in tracked.items()])
                return [self._last[p] for p in phrases]
            self.redetections += 1
        wanted = tuple(dict.fromkeys((*self._phrases, *phrases)))
        results = self.initial.segment(frame, wanted)
        self._phrases = wanted
        if all(r.found for r in results):
            self.tracker.start(frame.rgb, {r.phrase: r.mask for r in results})
        else:
            self.tracker.reset()  # something is missing: detect again on the next frame
        self._remember(frame, results)
        return [self._last[p] for p in phrases]

    def _remember(self, frame: RGBDFrame, results: Sequence[MaskResult]) -> None:
        self._last_frame = frame
        self._last = {r.phrase: r for r in results}
