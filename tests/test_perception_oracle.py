"""SimOracleSegmenter: phrases resolve by kind noun + colour/size words against ground truth."""

import numpy as np
import pytest

from lano3dp.perception import (
    AmbiguousObjectError,
    MaskResult,
    ObjectNotFoundError,
    Segmenter,
    SimOracleSegmenter,
    resolve_phrase,
)
from lano3dp.perception.sim_oracle import SceneObject
from lano3dp.perception.synthetic import Box, render_boxes, top_down_camera

CAMERA = top_down_camera(96)


def bowls_scene():
    return render_boxes(
        CAMERA,
        [
            Box("bowl_1", (0.15, 0.10), (0.12, 0.12, 0.06), {"kind": "bowl", "color": "red", "size": "large"}),
            Box("bowl_2", (-0.15, 0.10), (0.06, 0.06, 0.04), {"kind": "bowl", "color": "red", "size": "small"}),
            Box("bowl_3", (0.00, -0.15), (0.06, 0.06, 0.04), {"kind": "bowl", "color": "blue", "size": "small"}),
            Box("pan", (-0.15, -0.15), (0.15, 0.10, 0.03), {"kind": "pan", "color": "black"}),
        ],
    )


def test_oracle_meets_the_segmenter_protocol():
    assert isinstance(SimOracleSegmenter(), Segmenter)


@pytest.mark.parametrize(
    "phrase, expected",
    [
        ("pan", "pan"),
        ("the pan", "pan"),
        ("the small red bowl", "bowl_2"),
        ("red small bowl", "bowl_2"),
        ("little red bowl", "bowl_2"),
        ("big bowl", "bowl_1"),
        ("large red bowl", "bowl_1"),
        ("blue bowl", "bowl_3"),
        ("the blue ceramic bowl", "bowl_3"),  # unknown descriptive words are ignored
        ("bowl_3", "bowl_3"),  # exact names are accepted
        ("bowl 1", "bowl_1"),
    ],
)
def test_phrase_resolves_to_the_one_matching_object(phrase, expected):
    frame = bowls_scene()
    (result,) = SimOracleSegmenter().segment(frame, [phrase])
    assert result.found and result.matched_name == expected and result.score == 1.0
    expected_mask = np.isin(frame.segmentation, frame.instance_names[expected])
    np.testing.assert_array_equal(result.mask, expected_mask)
    assert result.mask.dtype == np.bool_ and result.mask.shape == (96, 96)


def test_results_follow_phrase_order():
    results = SimOracleSegmenter().segment(bowls_scene(), ["pan", "blue bowl", "pan"])
    assert [r.matched_name for r in results] == ["pan", "bowl_3", "pan"]


def test_ambiguous_phrase_raises_with_the_candidates():
    with pytest.raises(AmbiguousObjectError) as info:
        SimOracleSegmenter().segment(bowls_scene(), ["red bowl"])
    assert info.value.candidates == ("bowl_1", "bowl_2")
    assert "red bowl" in str(info.value) and "bowl_1" in str(info.value)
    with pytest.raises(AmbiguousObjectError, match="bowl_3"):
        SimOracleSegmenter().segment(bowls_scene(), ["bowl"])


def test_largest_policy_picks_the_most_visible_candidate():
    frame = bowls_scene()
    (result,) = SimOracleSegmenter(ambiguity="largest").segment(frame, ["bowl"])
    counts = {n: int(np.isin(frame.segmentation, ids).sum()) for n, ids in frame.instance_names.items()}
    assert result.matched_name == "bowl_1" and counts["bowl_1"] > counts["bowl_2"]
    with pytest.raises(ValueError, match="ambiguity"):
        SimOracleSegmenter(ambiguity="random")


def test_unknown_phrase_is_an_explicit_miss_listing_what_is_visible():
    (result,) = SimOracleSegmenter().segment(bowls_scene(), ["green bowl"])
    assert not result.found and result.mask is None and result.score == 0.0
    assert result.visible == ("bowl_1", "bowl_2", "bowl_3", "pan")
    (result,) = SimOracleSegmenter().segment(bowls_scene(), ["microwave"])
    assert not result.found and result.matched_name is None
    assert "microwave" in str(ObjectNotFoundError(result.phrase, result.visible))


def test_occluded_object_is_not_found_rather_than_replaced():
    frame = bowls_scene()
    frame.instance_names["cup"] = [99]  # known to the simulator, zero pixels in view
    frame.instance_attributes["cup"] = {"kind": "cup", "color": "white"}
    (result,) = SimOracleSegmenter().segment(frame, ["white cup"])
    assert not result.found and result.matched_name == "cup" and "cup" not in result.visible


def test_names_carry_attributes_when_the_simulator_gives_none():
    objects = [SceneObject.from_frame_entry("red_bowl", None), SceneObject.from_frame_entry("blue_bowl", None)]
    assert objects[0].kind == ("bowl",) and objects[0].attributes == {"red"}
    assert resolve_phrase("the red bowl", objects) == ["red_bowl"]
    assert sorted(resolve_phrase("bowls", objects)) == ["blue_bowl", "red_bowl"]
    assert resolve_phrase("grey bowl", objects) == []


def test_role_is_not_a_descriptive_word():
    bowl = SceneObject.from_frame_entry("bowl", {"kind": "bowl", "color": "red", "size": "medium", "role": "target"})
    assert bowl.attributes == {"red", "medium"}


def test_longest_kind_wins_for_multiword_nouns():
    objects = [
        SceneObject.from_frame_entry("watering_can", {"kind": "watering can"}),
        SceneObject.from_frame_entry("soda", {"kind": "can", "color": "red"}),
    ]
    assert resolve_phrase("the watering can", objects) == ["watering_can"]
    assert resolve_phrase("red can", objects) == ["soda"]
    assert resolve_phrase("can", objects) == ["soda"]


def test_frame_without_ground_truth_is_rejected():
    frame = bowls_scene()
    frame.segmentation = None
    with pytest.raises(ValueError, match="segmentation"):
        SimOracleSegmenter().segment(frame, ["pan"])


def test_mask_result_rejects_silent_empty_masks():
    with pytest.raises(ValueError, match="found=False"):
        MaskResult("bowl", np.zeros((4, 4), bool), 1.0, True)
    with pytest.raises(ValueError, match="mask=None"):
        MaskResult("bowl", np.ones((4, 4), bool), 0.0, False)
    assert MaskResult.missing("bowl", ["pan"]).visible == ("pan",)
