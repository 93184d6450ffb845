"""Open-vocabulary segmentation: text -> boxes (GroundingDINO or OWLv2) -> masks (SAM).

This is the paper's perception at the start of a recording or a rollout (GroundingDINO boxes as
SAM prompts); `tracker.TrackingSegmenter` then follows the masks from frame to frame. Models load
only from local folders given by the user (`from_pretrained(dir)`); nothing is fetched from the
hub. transformers is imported lazily, so importing this module is cheap.

Preparing the folders on a machine with internet access (then copy them over):

    from transformers import (GroundingDinoForObjectDetection, GroundingDinoProcessor,
                              SamModel, SamProcessor, Sam2VideoModel)
    for cls in (GroundingDinoForObjectDetection, GroundingDinoProcessor):
        cls.from_pretrained("IDEA-Research/grounding-dino-tiny").save_pretrained("weights/grounding-dino-tiny")
    for cls in (SamModel, SamProcessor):
        cls.from_pretrained("facebook/sam-vit-base").save_pretrained("weights/sam-vit-base")
    Sam2VideoModel.from_pretrained("facebook/sam2.1-hiera-tiny").save_pretrained("weights/sam2.1-hiera-tiny")

Without torchvision the processors fall back to their PIL versions (same outputs, a warning).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from lano3dp.geometry.frame import RGBDFrame
from lano3dp.perception._hf import check_weights_dir, clip_box, load_local, to_pil
from lano3dp.perception.base import MaskResult


@dataclass(frozen=True, eq=False)  # eq on numpy fields would be ambiguous; compare .box explicitly
class Detection:
    """The best box for one phrase.

    Attributes:
        phrase: the text query.
        box: (4,) float32 x0, y0, x1, y1 in pixels of the original image.
        score: detector confidence in [0, 1].
    """

    phrase: str
    box: np.ndarray
    score: float


class Detector(Protocol):
    def detect(self, rgb: np.ndarray, phrases: Sequence[str]) -> list[Detection | None]:
        """Best detection per phrase (None when nothing scores above the threshold)."""
        ...


def non_max_suppression(detections: list[Detection], iou_threshold: float = 0.5) -> list[Detection]:
    """Greedy NMS, best score first. Hand-written (a few lines) so torchvision stays optional."""
    kept: list[Detection] = []
    for det in sorted(detections, key=lambda d: -d.score):
        if all(box_iou(det.box, k.box) < iou_threshold for k in kept):
            kept.append(det)
    return kept


def box_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two xyxy boxes."""
    w = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    h = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = w * h
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return float(inter / union) if union > 0 else 0.0


class _BestOfAll:
    """`detect` from `detect_all`: the top detection of each phrase."""

    def detect(self, rgb: np.ndarray, phrases: Sequence[str]) -> list[Detection | None]:
        return [found[0] if found else None for found in self.detect_all(rgb, phrases)]


class BoxSegmenter(Protocol):
    def masks_from_boxes(self, rgb: np.ndarray, boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(M, H, W) bool masks and (M,) quality scores for (M, 4) xyxy pixel boxes."""
        ...


def _torch():
    import torch

    return torch


class GroundingDinoDetector(_BestOfAll):
    """GroundingDINO (transformers) with one forward pass for all phrases.

    Phrases are joined as "red bowl. pan." (GroundingDINO's prompt format); each phrase is scored
    on its own tokens (max over them, as the library's post-processing does per box), so a box is
    attributed to the phrase it matches, not to whichever label string the token spans decode to.

    Args:
        model, processor: a GroundingDinoForObjectDetection and its GroundingDinoProcessor.
        box_threshold: minimum phrase score for a detection.
    """

    def __init__(self, model, processor, box_threshold: float = 0.35, nms_iou: float = 0.5):
        self.model = model.eval()
        self.processor = processor
        self.box_threshold = box_threshold
        self.nms_iou = nms_iou

    @classmethod
    def from_pretrained(
        cls, path: str | Path, box_threshold: float = 0.35, nms_iou: float = 0.5
    ) -> GroundingDinoDetector:
        path = check_weights_dir(path, "GroundingDINO weights")
        from transformers import GroundingDinoForObjectDetection, GroundingDinoProcessor

        return cls(
            load_local(GroundingDinoForObjectDetection, path, "GroundingDINO weights"),
            load_local(GroundingDinoProcessor, path, "GroundingDINO processor"),
            box_threshold,
            nms_iou,
        )

    def phrase_scores(self, rgb: np.ndarray, phrases: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
        """(K, Q) per-phrase query scores and (Q, 4) xyxy boxes in original-image pixels."""
        torch = _torch()
        phrases = [p.strip().lower() for p in phrases]
        text = ". ".join(phrases) + "."
        inputs = self.processor(images=to_pil(rgb), text=text, return_tensors="pt")
        offsets = self.processor.tokenizer(text, return_offsets_mapping=True)["offset_mapping"]
        with torch.inference_mode():
            outputs = self.model(**inputs)
        probs = outputs.logits[0].sigmoid().numpy()  # (Q, max_text_len)
        scores = np.zeros((len(phrases), probs.shape[0]), dtype=np.float32)
        start = 0
        for k, phrase in enumerate(phrases):
            end = start + len(phrase)
            tokens = [i for i, (a, b) in enumerate(offsets) if b > a and a >= start and b <= end and i < probs.shape[1]]
            if tokens:
                scores[k] = probs[:, tokens].max(axis=1)
            start = end + 2  # ". "
        height, width = rgb.shape[:2]
        cx, cy, w, h = outputs.pred_boxes[0].numpy().T  # normalised to the (unpadded) image
        boxes = np.stack([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2], axis=1) * [width, height, width, height]
        return scores, boxes.astype(np.float32)

    def detect_all(self, rgb: np.ndarray, phrases: Sequence[str]) -> list[list[Detection]]:
        """Per phrase, every box above the threshold after NMS, best first."""
        scores, boxes = self.phrase_scores(rgb, phrases)
        height, width = rgb.shape[:2]
        return [
            non_max_suppression(
                [
                    Detection(phrase, clip_box(boxes[q], height, width), float(scores[k, q]))
                    for q in np.flatnonzero(scores[k] >= self.box_threshold)
                ],
                self.nms_iou,
            )
            for k, phrase in enumerate(phrases)
        ]


class Owlv2Detector(_BestOfAll):
    """OWLv2 (transformers): one text query per phrase; boxes come back per query natively.

    OWLv2 pads the image to a square before resizing; the processor's post-processing scales
    boxes by the longer side accordingly, and boxes are then clipped to the real image.
    """

    def __init__(self, model, processor, box_threshold: float = 0.1, nms_iou: float = 0.5):
        self.model = model.eval()
        self.processor = processor
        self.box_threshold = box_threshold
        self.nms_iou = nms_iou

    @classmethod
    def from_pretrained(cls, path: str | Path, box_threshold: float = 0.1, nms_iou: float = 0.5) -> Owlv2Detector:
        path = check_weights_dir(path, "OWLv2 weights")
        from transformers import Owlv2ForObjectDetection, Owlv2Processor

        return cls(
            load_local(Owlv2ForObjectDetection, path, "OWLv2 weights"),
            load_local(Owlv2Processor, path, "OWLv2 processor"),
            box_threshold,
            nms_iou,
        )

    def detect_all(self, rgb: np.ndarray, phrases: Sequence[str]) -> list[list[Detection]]:
        """Per phrase, every box above the threshold after NMS, best first."""
        torch = _torch()
        phrases = list(phrases)
        height, width = rgb.shape[:2]
        max_length = self.model.config.text_config.max_position_embeddings
        inputs = self.processor(
            text=[phrases], images=to_pil(rgb), return_tensors="pt", padding="max_length", max_length=max_length
        )
        with torch.inference_mode():
            outputs = self.model(**inputs)
        (result,) = self.processor.post_process_grounded_object_detection(
            outputs, threshold=self.box_threshold, target_sizes=[(height, width)]
        )
        per_phrase: list[list[Detection]] = [[] for _ in phrases]
        for score, label, box in zip(result["scores"], result["labels"], result["boxes"], strict=True):
            k = int(label)
            per_phrase[k].append(Detection(phrases[k], clip_box(box.numpy(), height, width), float(score)))
        return [non_max_suppression(found, self.nms_iou) for found in per_phrase]


class SamBoxSegmenter:
    """SAM (transformers) prompted with boxes: the image is embedded once for all boxes.

    Args:
        model, processor: a SamModel and its SamProcessor.
        clip_margin: SAM masks can spill far outside their prompt box (background of similar colour);
            pixels further than this fraction of the box size (plus 2 px) outside it are dropped.
            None keeps SAM's mask as is.
    """

    def __init__(self, model, processor, clip_margin: float | None = 0.1):
        self.model = model.eval()
        self.processor = processor
        self.clip_margin = clip_margin

    @classmethod
    def from_pretrained(cls, path: str | Path, clip_margin: float | None = 0.1) -> SamBoxSegmenter:
        path = check_weights_dir(path, "SAM weights")
        from transformers import SamModel, SamProcessor

        return cls(
            load_local(SamModel, path, "SAM weights"), load_local(SamProcessor, path, "SAM processor"), clip_margin
        )

    def masks_from_boxes(self, rgb: np.ndarray, boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        torch = _torch()
        boxes = np.asarray(boxes, dtype=np.float32).reshape(-1, 4)
        height, width = rgb.shape[:2]
        if len(boxes) == 0:
            return np.zeros((0, height, width), dtype=bool), np.zeros(0, dtype=np.float32)
        inputs = self.processor(images=to_pil(rgb), input_boxes=[boxes.tolist()], return_tensors="pt")
        with torch.inference_mode():
            embeddings = self.model.get_image_embeddings(inputs["pixel_values"])
            outputs = self.model(image_embeddings=embeddings, input_boxes=inputs["input_boxes"], multimask_output=False)
        masks = (
            self.processor.post_process_masks(
                outputs.pred_masks, inputs["original_sizes"], inputs["reshaped_input_sizes"]
            )[0][:, 0]
            .numpy()
            .astype(bool)
        )  # (M, H, W)
        scores = outputs.iou_scores[0, :, 0].numpy().astype(np.float32)
        if self.clip_margin is not None:
            rows, cols = np.arange(height)[:, None], np.arange(width)[None, :]
            for m, (x0, y0, x1, y1) in enumerate(boxes):
                pad_x = self.clip_margin * (x1 - x0) + 2
                pad_y = self.clip_margin * (y1 - y0) + 2
                inside = (cols + 0.5 >= x0 - pad_x) & (cols + 0.5 <= x1 + pad_x)
                inside = inside & (rows + 0.5 >= y0 - pad_y) & (rows + 0.5 <= y1 + pad_y)
                masks[m] &= inside
        return masks, scores


class OpenVocabSegmenter:
    """Segmenter: detector boxes -> SAM masks, one `MaskResult` per phrase.

    A phrase without a box above the detector's threshold, or whose mask comes out empty, is an
    explicit miss listing the phrases that were found.
    """

    def __init__(self, detector: Detector, box_segmenter: BoxSegmenter):
        self.detector = detector
        self.box_segmenter = box_segmenter
        self.last_detections: list[Detection | None] = []

    @classmethod
    def from_pretrained(
        cls,
        detector_dir: str | Path,
        sam_dir: str | Path,
        detector: str = "grounding_dino",
        box_threshold: float | None = None,
    ) -> OpenVocabSegmenter:
        """Load from local folders; `detector` is "grounding_dino" or "owlv2"."""
        kinds = {"grounding_dino": GroundingDinoDetector, "owlv2": Owlv2Detector}
        if detector not in kinds:
            raise ValueError(f"detector must be one of {sorted(kinds)}, got {detector!r}")
        extra = {} if box_threshold is None else {"box_threshold": box_threshold}
        return cls(kinds[detector].from_pretrained(detector_dir, **extra), SamBoxSegmenter.from_pretrained(sam_dir))

    def segment_instances(self, frame: RGBDFrame, phrase: str) -> list[MaskResult]:
        """Every detected instance of `phrase` (after NMS) with its SAM mask; named "phrase#i"."""
        if not hasattr(self.detector, "detect_all"):
            return [r for r in self.segment(frame, [phrase]) if r.found]
        (detections,) = self.detector.detect_all(frame.rgb, [phrase])
        boxes = np.stack([d.box for d in detections]) if detections else np.zeros((0, 4))
        masks, _ = self.box_segmenter.masks_from_boxes(frame.rgb, boxes)
        return [
            MaskResult(phrase, mask, det.score, True, f"{phrase}#{i}")
            for i, (det, mask) in enumerate(zip(detections, masks, strict=True))
            if mask.any()
        ]

    def segment(self, frame: RGBDFrame, phrases: Sequence[str]) -> list[MaskResult]:
        phrases = list(phrases)
        detections = self.detector.detect(frame.rgb, phrases)
        self.last_detections = detections
        found = [k for k, d in enumerate(detections) if d is not None]
        masks, _ = self.box_segmenter.masks_from_boxes(
            frame.rgb, np.stack([detections[k].box for k in found]) if found else np.zeros((0, 4))
        )
        mask_of = {k: masks[i] for i, k in enumerate(found)}
        seen = tuple(phrases[k] for k in found if mask_of[k].any())
        results = []
        for k, phrase in enumerate(phrases):
            if k in mask_of and mask_of[k].any():
                results.append(MaskResult(phrase, mask_of[k], detections[k].score, True, phrase))
            else:
                results.append(MaskResult.missing(phrase, seen))
        return results
