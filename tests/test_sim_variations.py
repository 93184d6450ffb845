"""Each variation axis changes what it claims, and only that; axes combine."""

import mujoco
import numpy as np
import pytest

from lano3dp.perception import ObjectObserver, SimOracleSegmenter
from lano3dp.sim import TabletopEnv
from lano3dp.sim.robot import GRIPPER_FOOTPRINT_RADIUS
from lano3dp.sim.variations import Variation, VariationError, distance_to_polyline

SEED = 4


@pytest.fixture(scope="module")
def env():
    environment = TabletopEnv("bowl_pour", image_size=96)
    yield environment
    environment.close()


def reset(env, variation):
    obs, info = env.reset(seed=SEED, options={"variation": variation})
    return obs, info, env.frame()


def roles(env):
    return {name: info.role for name, info in env.objects.items()}


def test_parse_accepts_plus_and_comma_and_rejects_unknown_axes():
    assert Variation.parse("clutter+camera") == Variation.parse("camera,clutter")
    assert Variation.parse("clean").name == "clean"
    with pytest.raises(VariationError, match="lighting"):
        Variation.parse("lighting")


def test_clutter_adds_visible_distractors_of_other_kinds(env):
    _, _, clean = reset(env, "clean")
    _, _, frame = reset(env, "clutter")
    distractors = [n for n, r in roles(env).items() if r == "distractor"]
    assert len(distractors) >= 2
    kinds = {env.objects[n].kind for n in distractors}
    assert not kinds & {"bowl", "pan"}
    visible = [n for n in distractors if np.isin(frame.segmentation, frame.instance_names[n]).sum() > 0]
    assert len(visible) >= 1
    # The task objects are where they were in the clean scene.
    for name in ("bowl", "pan"):
        assert np.array_equal(np.isin(clean.segmentation, clean.instance_names[name]).nonzero()[0].size > 0, True)


def test_similar_adds_look_alikes_and_names_the_target_by_colour(env):
    _, info, frame = reset(env, "similar")
    bowls = [n for n, a in frame.instance_attributes.items() if a["kind"] == "bowl"]
    assert len(bowls) >= 2
    assert len({frame.instance_attributes[n]["color"] for n in bowls}) == len(bowls)
    target = info["slot_objects"]["bowl"]
    assert target == "blue_bowl" and info["target_phrases"]["bowl"] == "blue bowl"
    assert "blue bowl" in info["instruction"]
    clouds = ObjectObserver(SimOracleSegmenter(), n_points=64).observe(frame, [info["target_phrases"]["bowl"]])
    assert clouds.matched_names == (target,)
    bowl_xy = env.sim.body_position(target)[:2]
    assert np.linalg.norm(clouds.points[0].mean(0)[:2] - bowl_xy) < 0.05


def test_instance_changes_size_and_colour_of_task_objects(env):
    sizes, colours = set(), set()
    for seed in range(6):
        env.reset(seed=seed, options={"variation": "instance"})
        sizes.add(env.objects["bowl"].size)
        colours.add(env.objects["bowl"].color)
    assert sizes <= {"small", "large"} and len(sizes) == 2
    assert "blue" not in colours  # the training colour


def test_camera_moves_only_the_camera(env):
    obs_clean, _, clean = reset(env, "clean")
    obs_shift, _, shifted = reset(env, "camera")
    moved = np.linalg.norm(clean.camera.position - shifted.camera.position)
    assert moved > 0.3
    assert np.mean(np.abs(obs_clean["rgb"].astype(int) - obs_shift["rgb"].astype(int))) > 10
    assert set(clean.instance_names) == set(shifted.instance_names)
    # Both views back-project the bowl to the same place (extrinsics are right).
    observer = ObjectObserver(SimOracleSegmenter(), n_points=128)
    a = observer.observe(clean, ["bowl"]).points[0].mean(0)
    b = observer.observe(shifted, ["bowl"]).points[0].mean(0)
    assert np.linalg.norm(a - b) < 0.03


def test_other_views_see_what_the_obstacle_hides_from_the_camera():
    """bottle_in_drawer's table scene 1000057: the obstacle hides the whole bottle from the front camera. The
    env's other cameras see it, back-project it where it stands, and leave out the observation camera."""
    environment = TabletopEnv("bottle_in_drawer", "obstacle", image_size=96)
    try:
        environment.reset(seed=1000057)
        frame = environment.frame()
        bottle = environment.instance_names["bottle"]
        assert not np.isin(frame.segmentation, bottle).any()
        views = environment.other_views()
        assert len(views) == 2  # shifted and shifted_left: the front camera is the observation camera
        assert all(np.linalg.norm(view.camera.position - frame.camera.position) > 0.3 for view in views)
        observer = ObjectObserver(SimOracleSegmenter(), n_points=128)
        seen = [observer.observe(view, ["bottle"]).points[0] for view in views
                if np.isin(view.segmentation, bottle).sum() >= observer.min_points]
        assert seen
        true_xy = environment.data.xpos[bottle[0], :2]
        assert all(np.linalg.norm(cloud.mean(0)[:2] - true_xy) < 0.04 for cloud in seen)
        environment.reset(seed=1000057, options={"variation": "obstacle+camera"})
        # the shifted camera observes: the front one becomes another view
        positions = [view.camera.position for view in environment.other_views()]
        assert len(positions) == 2 and min(np.linalg.norm(p - frame.camera.position) for p in positions) < 1e-6
    finally:
        environment.close()


def test_background_recolours_the_table_but_not_the_objects(env):
    table_colours = []
    for variation in ("clean", "background"):
        obs, _, frame = reset(env, variation)
        table = frame.segmentation == env.model.body("table").id
        table_colours.append(obs["rgb"][table].mean(0))
        bowl = np.isin(frame.segmentation, frame.instance_names["bowl"])
        assert bowl.sum() > 20
    assert np.abs(table_colours[0] - table_colours[1]).max() > 25


def test_obstacle_stands_on_the_expert_path_and_never_in_clean_scenes(env):
    reset(env, "clean")
    assert "obstacle" not in roles(env).values()
    for seed in range(3):
        env.reset(seed=seed, options={"variation": "obstacle"})
        obstacles = [n for n, r in roles(env).items() if r == "obstacle"]
        assert len(obstacles) == 1
        info = env.objects[obstacles[0]]
        assert info.kind == "cylinder"
        region = env.task.obstacle_region(env.episode.layout)
        assert distance_to_polyline(info.position[:2], region[:, 2 - 2:2]) <= 0.021
        # Clear of the task objects, so the task stays feasible for a policy that goes around.
        for name in ("bowl", "pan"):
            gap = np.linalg.norm(info.position[:2] - env.sim.body_position(name)[:2])
            assert gap > env.objects[name].footprint_radius
        # and out of the open hand's reach where the carry starts and ends (grasp, release)
        for end in (region[0, :2], region[-1, :2]):
            assert np.linalg.norm(info.position[:2] - end) >= GRIPPER_FOOTPRINT_RADIUS + info.footprint_radius


def test_obstacles_leave_the_grasp_of_a_pick_and_place_reachable():
    """An obstacle beside the block blocks the palm as it closes on the block: no detour can avoid it."""
    environment = TabletopEnv("put_item_in_drawer", image_size=64)
    try:
        placed = 0
        for seed in range(12):
            environment.reset(seed=seed, options={"variation": "obstacle"})
            region = environment.task.obstacle_region(environment.episode.layout)
            for info in (i for i in environment.objects.values() if i.role == "obstacle"):
                placed += 1
                for end in (region[0, :2], region[-1, :2]):
                    assert np.linalg.norm(info.position[:2] - end) >= GRIPPER_FOOTPRINT_RADIUS + info.footprint_radius
        assert placed >= 6  # most layouts still have room on the carry
    finally:
        environment.close()


def test_the_expert_hits_an_obstacle_and_the_env_reports_it(env):
    env.reset(seed=0, options={"variation": "obstacle"})
    actions = env.expert_plan().actions()
    contacts, clearances = 0, []
    for t in range(env.max_steps):
        _, _, terminated, truncated, info = env.step(actions[min(t, len(actions) - 1)])
        contacts = info["n_obstacle_contacts"]
        clearances.append(info["min_obstacle_clearance"])
        if terminated or truncated:
            break
    assert contacts > 0
    assert min(clearances) <= 0.0 < max(clearances) < np.inf


def test_axes_combine(env):
    env.reset(seed=SEED, options={"variation": "clutter+similar+camera+background+obstacle"})
    present = set(roles(env).values())
    assert {"distractor", "similar", "obstacle", "target"} <= present
    assert env.episode.extras.camera.position != (1.18, 0.0, 0.70)


def test_obstacle_modifiers_make_boxes_clusters_several_and_moving_obstacles(env):
    assert Variation.parse("obstacle").name == "obstacle"  # the paper's single cylinder stays the default
    assert Variation.parse("clutter+obstacle:box:moving").name == "clutter+obstacle:box:moving"
    with pytest.raises(VariationError, match="modifier"):
        Variation.parse("obstacle:cone")

    def obstacles():
        return [(name, info) for name, info in env.objects.items() if info.role == "obstacle"]

    env.reset(seed=1, options={"variation": "obstacle:box"})
    ((name, info),) = obstacles()
    assert info.kind == "box" and env.model.geom(f"{name}/box").type == mujoco.mjtGeom.mjGEOM_BOX

    mates = []
    for seed in range(6):
        env.reset(seed=seed, options={"variation": "obstacle:cluster"})
        if len(pair := obstacles()) == 2:
            (_, a), (_, b) = pair
            mates.append(np.linalg.norm(a.position[:2] - b.position[:2]) - a.footprint_radius - b.footprint_radius)
    assert mates and max(mates) <= 0.015 + 1e-9  # closer than the 4 cm thick hand: no way between them

    env.reset(seed=0, options={"variation": "obstacle:2"})
    assert len(obstacles()) == 2

    obs, _ = env.reset(seed=3, options={"variation": "obstacle:moving"})
    ((name, _),) = obstacles()
    track = []
    for _ in range(40):
        obs, *_ = env.step(np.concatenate([obs["state"][:9], [1.0]]))
        track.append(env.data.xpos[env.model.body(name).id][:2].copy())
    speeds = np.linalg.norm(np.diff(track, axis=0), axis=1) * env.control_hz
    assert 0.02 < speeds.max() <= 0.05  # it moves, and no faster than 5 cm/s
