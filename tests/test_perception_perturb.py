"""MaskPerturbation / PerturbedSegmenter: controlled segmentation errors."""

import numpy as np
import pytest

from lano3dp.perception import (
    MaskPerturbation,
    ObjectNotFoundError,
    ObjectObserver,
    PerturbedSegmenter,
    Segmenter,
    SimOracleSegmenter,
)
from lano3dp.perception.synthetic import Box, render_boxes, top_down_camera

# Straight top-down camera: each box projects to a solid rectangle of pixels (top and a sliver of side).
FRAME = render_boxes(
    top_down_camera(96),
    [
        Box("bowl", (0.10, 0.05), (0.12, 0.12, 0.06), {"kind": "bowl"}),
        Box("pan", (-0.15, -0.10), (0.20, 0.15, 0.04), {"kind": "pan"}),
    ],
)
BOWL_MASK = np.isin(FRAME.segmentation, FRAME.instance_names["bowl"])


def bbox_size(mask):
    rows, cols = np.nonzero(mask)
    return rows.max() - rows.min() + 1, cols.max() - cols.min() + 1


def perturbed(**kwargs):
    return PerturbedSegmenter(SimOracleSegmenter(), MaskPerturbation(**kwargs))


def test_erosion_and_dilation_move_the_boundary_by_whole_pixels():
    h, w = bbox_size(BOWL_MASK)
    assert BOWL_MASK.sum() == h * w  # the top face is a solid rectangle
    (eroded,) = perturbed(erode_px=2).segment(FRAME, ["bowl"])
    assert eroded.mask.sum() == (h - 4) * (w - 4) and not (eroded.mask & ~BOWL_MASK).any()
    (dilated,) = perturbed(dilate_px=1).segment(FRAME, ["bowl"])
    # A 4-connected dilation adds one pixel on each side but not at the corners.
    assert dilated.mask.sum() == h * w + 2 * (h + w) and (dilated.mask & BOWL_MASK).sum() == h * w
    assert isinstance(perturbed(), Segmenter)


def test_drop_fraction_removes_that_share_of_pixels():
    (result,) = perturbed(drop_fraction=0.5, seed=1).segment(FRAME, ["bowl"])
    assert result.found and not (result.mask & ~BOWL_MASK).any()
    assert result.mask.sum() / BOWL_MASK.sum() == pytest.approx(0.5, abs=0.08)


def test_misses_happen_at_the_given_rate_and_are_reproducible():
    segmenter = perturbed(miss_probability=0.3, seed=7)
    found = [segmenter.segment(FRAME, ["bowl"])[0].found for _ in range(400)]
    assert 1 - np.mean(found) == pytest.approx(0.3, abs=0.06)
    segmenter.reset()
    again = [segmenter.segment(FRAME, ["bowl"])[0].found for _ in range(400)]
    assert found == again
    (missed,) = perturbed(miss_probability=1.0).segment(FRAME, ["bowl"])
    assert not missed.found and missed.mask is None and missed.matched_name == "bowl"


def test_a_miss_reaches_the_observer_as_object_not_found():
    observer = ObjectObserver(perturbed(miss_probability=1.0))
    with pytest.raises(ObjectNotFoundError, match="'pan' was not found"):
        observer.observe(FRAME, ["pan"])


def test_eroding_away_a_small_mask_is_a_miss_not_an_empty_mask():
    (result,) = perturbed(erode_px=40).segment(FRAME, ["bowl"])
    assert not result.found and result.mask is None


def test_dilation_leaks_table_points_into_the_object_cloud():
    clean = ObjectObserver(SimOracleSegmenter()).observe(FRAME, ["bowl"])
    swollen = ObjectObserver(perturbed(dilate_px=3)).observe(FRAME, ["bowl"])
    assert clean.points[0, :, 2].min() > 0.03  # perspective shows the upper part of one side
    assert swollen.points[0, :, 2].min() == pytest.approx(0.0, abs=1e-4)
    assert swollen.centroids()[0, 2] < clean.centroids()[0, 2] - 0.005


def test_invalid_settings_are_rejected():
    with pytest.raises(ValueError, match="erode_px"):
        MaskPerturbation(erode_px=-1)
    with pytest.raises(ValueError, match="drop_fraction"):
        MaskPerturbation(drop_fraction=1.0)
    with pytest.raises(ValueError, match="miss_probability"):
        MaskPerturbation(miss_probability=1.5)


def test_instances_are_perturbed_one_by_one():
    (eroded,) = perturbed(erode_px=2).segment_instances(FRAME, "bowl")
    h, w = bbox_size(BOWL_MASK)
    assert eroded.matched_name == "bowl" and eroded.mask.sum() == (h - 4) * (w - 4)
    assert perturbed(miss_probability=1.0).segment_instances(FRAME, "bowl") == []


def test_factory_builds_the_oracle_with_optional_perturbation():
    from lano3dp.perception import SegmenterConfig, build_segmenter

    plain = build_segmenter(SegmenterConfig(ambiguity="largest"))
    assert isinstance(plain, SimOracleSegmenter) and plain.ambiguity == "largest"
    noisy = build_segmenter(SegmenterConfig(perturbation=MaskPerturbation(dilate_px=2, seed=3)))
    assert isinstance(noisy, PerturbedSegmenter) and noisy.perturbation.dilate_px == 2
    assert isinstance(build_segmenter(SegmenterConfig(perturbation=MaskPerturbation())), SimOracleSegmenter)
    with pytest.raises(ValueError, match="needs local weight folders for: detector_dir, sam_dir, tracker_dir"):
        build_segmenter(SegmenterConfig(kind="tracking"))
    with pytest.raises(ValueError, match="kind must be"):
        build_segmenter(SegmenterConfig(kind="magic"))
