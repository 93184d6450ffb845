"""One place that builds a segmenter from settings, for the CLI, evaluation and the runtime."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from lano3dp.perception.base import Segmenter
from lano3dp.perception.error_model import ErrorModelSegmenter, PerceptionErrorModel
from lano3dp.perception.perturb import MaskPerturbation, PerturbedSegmenter
from lano3dp.perception.sim_oracle import SimOracleSegmenter


@dataclass(frozen=True)
class SegmenterConfig:
    """Which segmenter to build.

    Attributes:
        kind: "oracle" (simulator ground truth), "error_model" (the ground truth with a published-numbers model
            of detection, SAM and tracking errors, `perception.error_model`), "open_vocab" (detector + SAM on
            every frame) or "tracking" (detector + SAM once, then the SAM2 video tracker).
        detector: "grounding_dino" or "owlv2" (open_vocab / tracking).
        detector_dir, sam_dir, tracker_dir: local weight folders (never downloaded).
        box_threshold: detector score threshold (None: the detector's default).
        ambiguity: oracle policy for phrases matching several objects ("error" or "largest").
        perturbation: optional mask errors applied on top (sensitivity experiments).
        error_model: (error_model) the rates; None: `PerceptionErrorModel()`, the published-numbers model.
    """

    kind: Literal["oracle", "error_model", "open_vocab", "tracking"] = "oracle"
    detector: Literal["grounding_dino", "owlv2"] = "grounding_dino"
    detector_dir: Path | None = None
    sam_dir: Path | None = None
    tracker_dir: Path | None = None
    box_threshold: float | None = None
    ambiguity: Literal["error", "largest"] = "error"
    perturbation: MaskPerturbation | None = None
    error_model: PerceptionErrorModel | None = None


def build_segmenter(config: SegmenterConfig) -> Segmenter:
    """The segmenter `config` describes.

    Raises:
        ValueError: an unknown kind, or a weights folder the kind needs is not given.
        MissingWeightsError: a given weights folder does not exist or is incomplete.
    """
    if config.kind == "oracle":
        segmenter: Segmenter = SimOracleSegmenter(ambiguity=config.ambiguity)
    elif config.kind == "error_model":
        segmenter = ErrorModelSegmenter(config.error_model, ambiguity=config.ambiguity)
    elif config.kind in ("open_vocab", "tracking"):
        missing = [n for n in ("detector_dir", "sam_dir") if getattr(config, n) is None]
        if config.kind == "tracking" and config.tracker_dir is None:
            missing.append("tracker_dir")
        if missing:
            raise ValueError(f"a '{config.kind}' segmenter needs local weight folders for: {', '.join(missing)}")
        from lano3dp.perception.open_vocab import OpenVocabSegmenter

        segmenter = OpenVocabSegmenter.from_pretrained(
            config.detector_dir, config.sam_dir, config.detector, config.box_threshold
        )
        if config.kind == "tracking":
            from lano3dp.perception.tracker import TrackingSegmenter, VideoTracker

            segmenter = TrackingSegmenter(segmenter, VideoTracker.from_pretrained(config.tracker_dir))
    else:
        raise ValueError(f"segmenter kind must be 'oracle', 'error_model', 'open_vocab' or 'tracking', "
                         f"got {config.kind!r}")
    if config.perturbation is not None and not config.perturbation.is_identity:
        segmenter = PerturbedSegmenter(segmenter, config.perturbation)
    return segmenter
