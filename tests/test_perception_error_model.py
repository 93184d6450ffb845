"""ErrorModelSegmenter: the ground truth through a stated model of detection, SAM and tracking errors.

The measured rates over many synthetic frames and episodes must match the model's parameters (inside a 99.9%
Wilson interval, so a correct model fails about once in a thousand runs per check), look-alikes from a `similar`
scene must be able to take a target's place and keep it for the episode, and with every rate 0 it must be the
oracle exactly.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from lano3dp.perception import (
    ErrorModelSegmenter,
    ObjectObserver,
    PerceptionErrorModel,
    SegmenterConfig,
    SimOracleSegmenter,
    build_segmenter,
)
from lano3dp.perception.error_model import partial_mask
from lano3dp.perception.synthetic import Box, render_boxes, top_down_camera
from lano3dp.report import wilson_interval

BLUE = Box("blue_block", (0.10, 0.05), (0.10, 0.10, 0.05), {"kind": "block", "color": "blue", "role": "target"})
DRAWER = Box("drawer", (-0.20, -0.10), (0.20, 0.15, 0.10), {"kind": "drawer", "color": "brown", "role": "target"})
RED = Box("red_block", (-0.15, 0.20), (0.10, 0.10, 0.05), {"kind": "block", "color": "red", "role": "similar"})
YELLOW = Box("yellow_block", (0.25, -0.22), (0.10, 0.10, 0.05), {"kind": "block", "color": "yellow",
                                                                   "role": "similar"})
CAMERA = top_down_camera(64)
CLEAN = render_boxes(CAMERA, [BLUE, DRAWER])  # put_item_in_drawer's two targets
SIMILAR = render_boxes(CAMERA, [BLUE, DRAWER, RED, YELLOW])  # ... with two look-alikes of the block
ALONE = render_boxes(CAMERA, [DRAWER])  # open_drawer: nothing to confuse the drawer with


def only(**rates) -> PerceptionErrorModel:
    """A model with the given rates and every other rate 0."""
    return replace(PerceptionErrorModel.none(), **rates)


def at(frame, step: int):
    """The same scene at control step `step` (10 Hz), as the simulator stamps its frames."""
    return replace(frame, timestamp=step / 10)


def assert_rate(count: int, trials: int, rate: float) -> None:
    low, high = wilson_interval(count, trials, z=3.29)  # 99.9%
    assert low <= rate <= high, f"measured {count}/{trials} = {count / trials:.4f}, model {rate} outside " \
                                f"[{low:.4f}, {high:.4f}]"


def mask_of(frame, name):
    return np.isin(frame.segmentation, frame.instance_names[name])


# ---- the oracle, exactly, with every rate 0 -------------------------------------------------------------
@pytest.mark.parametrize("frame", [CLEAN, SIMILAR], ids=["clean", "similar"])
def test_with_every_rate_zero_it_is_the_oracle(frame):
    oracle, model = SimOracleSegmenter(), ErrorModelSegmenter(PerceptionErrorModel.none())
    for seed in range(20):
        model.start_episode(seed)
        for step in range(5):
            for phrases in (["blue block", "drawer"], ["drawer"], ["red block"], ["cup"]):
                expected, got = oracle.segment(at(frame, step), phrases), model.segment(at(frame, step), phrases)
                assert [(r.phrase, r.found, r.matched_name, r.visible) for r in got] == \
                       [(r.phrase, r.found, r.matched_name, r.visible) for r in expected]
                assert all(np.array_equal(g.mask, e.mask) for g, e in zip(got, expected, strict=True) if e.found)
        assert [(r.matched_name, r.mask.sum()) for r in model.segment_instances(frame, "block")] == \
               [(r.matched_name, r.mask.sum()) for r in oracle.segment_instances(frame, "block")]


def test_the_factory_builds_it_and_the_published_model_by_default():
    segmenter = build_segmenter(SegmenterConfig(kind="error_model"))
    assert isinstance(segmenter, ErrorModelSegmenter) and segmenter.model == PerceptionErrorModel()
    rates = PerceptionErrorModel()
    assert (rates.first_miss, rates.lookalike, rates.other_kind) == (0.051, 0.536, 0.082)
    assert rates.frame_miss == pytest.approx((1 - 0.765) / 2) and rates.boundary + rates.gross == \
           pytest.approx((1 - 0.765) / 2)
    custom = only(lookalike=0.25)
    assert build_segmenter(SegmenterConfig(kind="error_model", error_model=custom)).model is custom


# ---- measured rates against the parameters --------------------------------------------------------------
def test_first_sight_misses_happen_at_the_models_rate_and_last_the_episode():
    model = ErrorModelSegmenter(only(first_miss=0.2))
    missed = 0
    for seed in range(800):
        model.start_episode(seed)
        first = model.segment(at(ALONE, 0), ["drawer"])[0]
        later = model.segment(at(ALONE, 7), ["drawer"])[0]
        assert later.found == first.found  # a detector that missed the object in this scene keeps missing it
        missed += not first.found
    assert_rate(missed, 800, 0.2)


def test_lookalikes_take_the_targets_place_at_the_models_rate_and_keep_it():
    model = ErrorModelSegmenter(only(lookalike=0.536))
    wrong = {"red_block": 0, "yellow_block": 0}
    for seed in range(800):
        model.start_episode(seed)
        picked = {model.segment(at(SIMILAR, step), ["blue block"])[0].matched_name for step in (0, 5)}
        assert len(picked) == 1  # tracked: one grounding for the whole episode
        (name,) = picked
        assert name in ("blue_block", "red_block", "yellow_block")
        assert model.misgroundings == ({} if name == "blue_block" else {"blue block": ("blue_block", name)})
        if name != "blue_block":
            wrong[name] += 1
            assert np.array_equal(model.segment(at(SIMILAR, 9), ["blue block"])[0].mask, mask_of(SIMILAR, name))
    assert_rate(sum(wrong.values()), 800, 0.536)
    assert min(wrong.values()) > 0.4 * max(wrong.values())  # either look-alike, not always the same one


def test_the_similar_scene_confuses_the_published_model_and_the_clean_one_cannot_by_lookalikes():
    similar, clean = ErrorModelSegmenter(), ErrorModelSegmenter()
    confused = {"similar": 0, "clean": 0}
    for seed in range(200):
        similar.start_episode(seed)
        clean.start_episode(seed)
        confused["similar"] += similar.segment(at(SIMILAR, 0), ["blue block"])[0].matched_name in ("red_block",
                                                                                                   "yellow_block")
        clean.segment(at(CLEAN, 0), ["blue block"])
        confused["clean"] += clean.counts["lookalike"]
    assert confused["clean"] == 0  # no block to confuse it with
    assert confused["similar"] > 70  # about half the episodes: 0.536 of those without a first-sight miss


def test_other_kinds_take_the_targets_place_at_the_models_rate():
    model = ErrorModelSegmenter(only(other_kind=0.3))
    grounded_elsewhere = 0
    for seed in range(800):
        model.start_episode(seed)
        grounded_elsewhere += model.segment(at(CLEAN, 0), ["blue block"])[0].matched_name == "drawer"
    assert_rate(grounded_elsewhere, 800, 0.3)
    model.start_episode(0)  # nothing of another kind in view: nothing to be grounded on
    assert all(model.segment(at(ALONE, 0), ["drawer"])[0].matched_name == "drawer" for _ in range(3))


def test_the_robots_own_parts_are_never_taken_for_a_target():
    hand = Box("gripper", (0.0, -0.25), (0.08, 0.04, 0.2), {"kind": "gripper", "color": "grey", "role": "robot"})
    model = ErrorModelSegmenter(only(other_kind=1.0))
    for seed in range(30):
        model.start_episode(seed)
        assert model.segment(at(render_boxes(CAMERA, [DRAWER, hand]), 0), ["drawer"])[0].matched_name == "drawer"


def test_tracking_losses_and_mask_errors_happen_at_the_models_per_frame_rates():
    model = ErrorModelSegmenter(only(frame_miss=0.15, boundary=0.2, gross=0.1), seed=3)
    truth = mask_of(CLEAN, "drawer")
    grown, shrunk = truth | dilation_ring(truth), truth & ~erosion_ring(truth)
    kinds = {"lost": 0, "exact": 0, "grown": 0, "shrunk": 0, "gross": 0}
    model.segment(at(CLEAN, 0), ["drawer"])  # first sight: frame losses only happen after it
    frames = 2000
    for step in range(1, frames + 1):
        (result,) = model.segment(at(CLEAN, step), ["drawer"])
        if not result.found:
            kinds["lost"] += 1
            continue
        kind = next((k for k, m in (("exact", truth), ("grown", grown), ("shrunk", shrunk))
                     if np.array_equal(result.mask, m)), "gross")
        kinds[kind] += 1
    seen = frames - kinds["lost"]
    assert_rate(kinds["lost"], frames, 0.15)
    assert_rate(kinds["grown"] + kinds["shrunk"], seen, 0.2)
    assert_rate(kinds["gross"], seen, 0.1)
    assert abs(kinds["grown"] - kinds["shrunk"]) < 0.25 * (kinds["grown"] + kinds["shrunk"])  # even odds
    assert model.counts["frame_miss"] == kinds["lost"]


def dilation_ring(mask):
    """The pixels a 1-pixel 4-connected dilation adds."""
    from scipy import ndimage

    return ndimage.binary_dilation(mask, ndimage.generate_binary_structure(2, 1)) & ~mask


def erosion_ring(mask):
    """The pixels a 1-pixel 4-connected erosion removes."""
    from scipy import ndimage

    return mask & ~ndimage.binary_erosion(mask, ndimage.generate_binary_structure(2, 1))


def test_first_sight_is_never_a_tracking_loss():
    model = ErrorModelSegmenter(only(frame_miss=1.0))
    for seed in range(50):
        model.start_episode(seed)
        assert model.segment(at(CLEAN, 0), ["drawer"])[0].found
        assert not model.segment(at(CLEAN, 1), ["drawer"])[0].found


def test_a_partial_mask_keeps_part_of_the_object_and_a_spill_reaches_the_surfaces_around_it():
    truth = mask_of(CLEAN, "drawer")
    rng = np.random.default_rng(0)
    for _ in range(50):
        part = partial_mask(truth, rng, (0.5, 0.75))
        assert not (part & ~truth).any() and 0.45 <= part.sum() / truth.sum() <= 0.8
    model = ErrorModelSegmenter(only(gross=1.0, spill_px=3), seed=1)
    spills = [r.mask for step in range(60) for r in model.segment(at(CLEAN, step), ["drawer"])
              if (r.mask & ~truth).any()]
    assert spills and all((m & truth).sum() == truth.sum() for m in spills)
    observer = ObjectObserver(ErrorModelSegmenter(only(gross=1.0)), n_points=32)
    clouds = [observer.observe(at(CLEAN, step), ["drawer"]) for step in range(12)]
    assert any(c.point_counts[0] > truth.sum() for c in clouds)  # spilled pixels bring their depth along


# ---- seeding --------------------------------------------------------------------------------------------
def run_episode(segmenter, seed):
    segmenter.start_episode(seed)
    out = []
    for step in range(20):
        for result in segmenter.segment(at(SIMILAR, step), ["blue block", "drawer"]):
            out.append((result.matched_name, None if result.mask is None else result.mask.tobytes()))
    return out


def test_the_same_episode_seed_gives_the_same_errors_whatever_ran_before():
    a, b = ErrorModelSegmenter(), ErrorModelSegmenter()
    first = run_episode(a, 1234)
    run_episode(b, 99)  # another episode first, and other phrases asked in another order
    b.segment(at(SIMILAR, 0), ["drawer", "red block"])
    assert run_episode(b, 1234) == first
    assert run_episode(a, 1235) != first


def test_a_phrases_grounding_does_not_depend_on_what_else_was_asked():
    alone, together = ErrorModelSegmenter(), ErrorModelSegmenter()
    for seed in range(40):
        alone.start_episode(seed)
        together.start_episode(seed)
        together.segment(at(SIMILAR, 0), ["drawer", "yellow block"])
        assert alone.segment(at(SIMILAR, 0), ["blue block"])[0].matched_name == \
               together.segment(at(SIMILAR, 0), ["blue block"])[0].matched_name


def test_bad_rates_are_refused_with_their_name():
    with pytest.raises(ValueError, match="lookalike"):
        PerceptionErrorModel(lookalike=1.5)
    with pytest.raises(ValueError, match="boundary \\+ gross"):
        PerceptionErrorModel(boundary=0.8, gross=0.3)
    with pytest.raises(ValueError, match="unknown perception error model fields"):
        PerceptionErrorModel.from_dict({"miss": 0.1})
    assert PerceptionErrorModel.from_dict(PerceptionErrorModel().to_dict()) == PerceptionErrorModel()
    assert PerceptionErrorModel().scaled(0).is_zero and PerceptionErrorModel().scaled(1) == PerceptionErrorModel()
