"""ObjectObserver and scene_cloud: masks -> fixed-size world-frame clouds."""

import numpy as np
import pytest

from lano3dp.errors import EmptyCloudError
from lano3dp.perception import (
    AmbiguousObjectError,
    ObjectNotFoundError,
    ObjectObserver,
    SimOracleSegmenter,
    TooFewPointsError,
    scene_cloud,
)
from lano3dp.perception.synthetic import Box, render_boxes, top_down_camera

BOWL = Box("red_bowl", (0.12, 0.05), (0.10, 0.10, 0.06), {"kind": "bowl", "color": "red"})
PAN = Box("pan", (-0.15, -0.10), (0.20, 0.15, 0.04), {"kind": "pan"})


def scene(tilt_deg=25.0, size=96):
    return render_boxes(top_down_camera(size, tilt_deg=tilt_deg), [BOWL, PAN])


def inside(points, box, tol=1e-4):
    return np.all((points >= box.low - tol) & (points <= box.high + tol), axis=-1)


def test_clouds_are_world_frame_points_on_each_object_in_phrase_order():
    clouds = ObjectObserver(SimOracleSegmenter(), n_points=128).observe(scene(), ["pan", "red bowl"])
    assert clouds.points.shape == (2, 128, 3) and clouds.points.dtype == np.float32
    assert clouds.names == ("pan", "red bowl") and clouds.matched_names == ("pan", "red_bowl")
    assert inside(clouds["pan"], PAN).all() and inside(clouds["red bowl"], BOWL).all()
    # The tilted camera sees the top and one side, so the clouds span the object heights.
    assert clouds["red bowl"][:, 2].max() == pytest.approx(0.06, abs=1e-4)
    assert clouds["pan"][:, 2].max() == pytest.approx(0.04, abs=1e-4)
    assert np.all(clouds.pixel_counts > 50) and np.array_equal(clouds.pixel_counts, clouds.point_counts)
    np.testing.assert_array_equal(clouds.scores, [1.0, 1.0])
    # FPS spreads the points: few exact duplicates when the mask has more pixels than N.
    assert len(np.unique(clouds["pan"], axis=0)) == 128


def test_same_seed_gives_the_same_cloud():
    a = ObjectObserver(SimOracleSegmenter(), seed=3).observe(scene(), ["pan"]).points
    b = ObjectObserver(SimOracleSegmenter(), seed=3).observe(scene(), ["pan"]).points
    np.testing.assert_array_equal(a, b)


def test_depth_holes_and_nan_are_skipped():
    frame = scene()
    rng = np.random.default_rng(0)
    holes = rng.random(frame.depth.shape) < 0.3
    frame.depth[holes & (rng.random(frame.depth.shape) < 0.5)] = np.nan
    frame.depth[holes] = np.where(np.isnan(frame.depth[holes]), np.nan, 0.0)
    clouds = ObjectObserver(SimOracleSegmenter()).observe(frame, ["red bowl", "pan"])
    assert np.all(np.isfinite(clouds.points))
    assert np.all(clouds.point_counts < clouds.pixel_counts)
    assert inside(clouds["red bowl"], BOWL).all()


def test_object_with_too_few_valid_points_is_named():
    frame = scene()
    bowl_pixels = np.isin(frame.segmentation, frame.instance_names["red_bowl"])
    keep = np.flatnonzero(bowl_pixels)[:5]
    frame.depth[bowl_pixels] = 0.0
    frame.depth.flat[keep] = 0.9
    with pytest.raises(TooFewPointsError, match=r"'red bowl \[red_bowl\]' has 5 valid depth points") as info:
        ObjectObserver(SimOracleSegmenter(), min_points=10).observe(frame, ["pan", "red bowl"])
    assert info.value.name == "red bowl [red_bowl]" and isinstance(info.value, EmptyCloudError)


def test_crop_box_removes_objects_outside_the_workspace():
    observer = ObjectObserver(SimOracleSegmenter(), crop_low=[0.0, -0.5, -0.01], crop_high=[0.5, 0.5, 0.5])
    assert observer.observe(scene(), ["bowl"]).points.shape == (1, 256, 3)
    with pytest.raises(TooFewPointsError, match="pan"):
        observer.observe(scene(), ["pan"])
    with pytest.raises(ValueError, match="both"):
        ObjectObserver(SimOracleSegmenter(), crop_low=[0, 0, 0])


def test_missing_object_raises_naming_phrase_and_visible_objects():
    with pytest.raises(ObjectNotFoundError) as info:
        ObjectObserver(SimOracleSegmenter()).observe(scene(), ["bowl", "dustpan"])
    assert info.value.phrase == "dustpan" and info.value.visible == ("pan", "red_bowl")
    assert str(info.value) == "object 'dustpan' was not found in the frame; visible: pan, red_bowl"


def test_small_masks_are_padded_to_n_points():
    clouds = ObjectObserver(SimOracleSegmenter(), n_points=256).observe(scene(size=48), ["bowl"])
    assert clouds.point_counts[0] < 256 and clouds.points.shape == (1, 256, 3)
    assert len(np.unique(clouds.points[0], axis=0)) == clouds.point_counts[0]


def test_scene_cloud_drops_the_table_and_keeps_both_objects():
    frame = scene()
    cloud = scene_cloud(frame, n_points=512, crop_low=[-0.5, -0.5, -0.1], crop_high=[0.5, 0.5, 0.5])
    assert cloud.shape == (512, 3) and cloud.dtype == np.float32
    assert cloud[:, 2].min() > 0.005
    assert inside(cloud, BOWL).sum() > 50 and inside(cloud, PAN).sum() > 50
    assert np.all(inside(cloud, BOWL) | inside(cloud, PAN))


def test_scene_cloud_of_an_empty_table_is_an_error():
    frame = render_boxes(top_down_camera(32), [])
    with pytest.raises(EmptyCloudError, match="above the table"):
        scene_cloud(frame)


def test_observe_instances_gives_every_matching_object_its_own_cloud():
    mugs = [
        Box("mug_1", (0.15, -0.15), (0.05, 0.05, 0.08), {"kind": "mug", "color": "blue"}),
        Box("mug_2", (-0.15, 0.15), (0.05, 0.05, 0.08), {"kind": "mug", "color": "white"}),
    ]
    frame = render_boxes(top_down_camera(96, tilt_deg=25.0), [BOWL, *mugs])
    observer = ObjectObserver(SimOracleSegmenter(), n_points=32)
    with pytest.raises(AmbiguousObjectError):
        observer.observe(frame, ["mugs"])
    clouds = observer.observe_instances(frame, ["mugs", "bowl"])
    assert clouds.names == ("mugs", "mugs", "bowl") and clouds.matched_names == ("mug_1", "mug_2", "red_bowl")
    assert clouds.points.shape == (3, 32, 3)
    assert inside(clouds.points[0], mugs[0]).all() and inside(clouds.points[1], mugs[1]).all()
    assert observer.observe_instances(frame, ["white mug"]).matched_names == ("mug_2",)
    with pytest.raises(ObjectNotFoundError, match="'vase' was not found.*visible: mug_1, mug_2, red_bowl"):
        observer.observe_instances(frame, ["vase"])


def test_observe_instances_falls_back_to_one_object_per_phrase():
    class Plain:  # a segmenter with no segment_instances
        def segment(self, frame, phrases):
            return SimOracleSegmenter().segment(frame, phrases)

    plain = Plain()
    clouds = ObjectObserver(plain, n_points=16).observe_instances(scene(), ["bowl", "pan"])
    assert clouds.matched_names == ("red_bowl", "pan")
