"""Contract tests shared by the RLBench-style tasks: the scripted expert solves seeded episodes,
the task is not solved at reset, layouts are random per seed, and the instance variation
really changes object sizes. Task-specific success checks are in `test_tasks_<name>.py`.

Episodes run through `TabletopEnv` at 16x16 pixels: the physics is what is tested and the
tiny render keeps an episode well under a second.
"""

from __future__ import annotations

import numpy as np
import pytest

from lano3dp.sim import TabletopEnv, make_task
from lano3dp.sim.variations import Variation

TASKS = ("open_drawer", "bottle_in_drawer", "close_microwave", "put_item_in_drawer", "phone_on_base",
         "open_wine_bottle", "water_plants", "sweep_to_dustpan")
# The handle is within reach of the start: the cabinet's and the door's footprints leave no room for an
# obstacle between them and the gripper's start footprint.
NO_OBSTACLE_ROOM = ("open_drawer", "close_microwave")
# A short carry from the bottle to the drawer: with the hand's reach kept free at the grasp and the release,
# about a third of the layouts leave room (41 of 100 seeds); an evaluation picks seeds that have one.
SHORT_CARRY = ("bottle_in_drawer",)
# Size measure per slot: the axis of the object's own bounding box that scales with the instance
# (heights of cabinet, box, bottles, block, can and plant scale exactly; the thickness of the phone,
# the base, the broom and the dustpan's walls does not, their length does).
SIZE_AXIS = {"drawer": 2, "microwave": 2, "bottle": 2, "block": 2, "phone": 0, "base": 0, "watering can": 2,
             "plant": 2, "broom": 0, "dustpan": 0}


def make_env(task: str, variation: str | None = None) -> TabletopEnv:
    return TabletopEnv(task, variation=variation, image_size=16, render_rgb=False)


def run_expert(env: TabletopEnv, seed: int, extra_steps: int = 15) -> tuple[bool, bool, int]:
    """(solved at reset, solved by the expert, steps) for one seeded episode."""
    env.reset(seed=seed)
    at_reset = bool(env.task.is_success(env.sim, env.episode.layout))
    actions = env.expert_plan().actions()
    actions = np.concatenate([actions, np.repeat(actions[-1:], extra_steps, axis=0)])
    for step, action in enumerate(actions, start=1):
        _, _, terminated, truncated, _ = env.step(action)
        if terminated:
            return at_reset, True, step
        if truncated:
            break
    return at_reset, False, step


def object_extent(env: TabletopEnv, name: str) -> np.ndarray:
    """(3,) size (m) of the bounding box of all geoms of scene object `name`, in the frame of its first body."""
    model, data = env.model, env.data
    bodies = [model.body(b).id for b in env.objects[name].body_names]
    frame_position, frame_rotation = data.xpos[bodies[0]], data.xmat[bodies[0]].reshape(3, 3)
    corners = []
    for geom in np.flatnonzero(np.isin(model.geom_bodyid, bodies)):
        centre, half = model.geom_aabb[geom, :3], model.geom_aabb[geom, 3:]
        signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
        local = centre + signs * half
        corners.append(data.geom_xpos[geom] + local @ data.geom_xmat[geom].reshape(3, 3).T)
    corners = (np.concatenate(corners) - frame_position) @ frame_rotation
    return corners.max(0) - corners.min(0)


def size_measure(env: TabletopEnv, slot: str) -> float:
    return float(object_extent(env, env.episode.layout.names[slot])[SIZE_AXIS[slot]])


@pytest.mark.parametrize("task", TASKS)
def test_expert_solves_clean_episodes_that_start_unsolved(task):
    env = make_env(task)
    try:
        for seed in (0, 1, 2):
            at_reset, solved, steps = run_expert(env, seed)
            assert not at_reset, f"{task} seed {seed} is already solved at reset"
            assert solved, f"{task} expert failed on seed {seed} ({steps} steps)"
            assert steps <= env.max_steps
    finally:
        env.close()


@pytest.mark.parametrize("task", TASKS)
def test_expert_solves_instance_and_clutter_variants(task):
    env = make_env(task, "instance+clutter")
    try:
        for seed in (3, 4):
            at_reset, solved, _ = run_expert(env, seed)
            assert not at_reset and solved, f"{task} seed {seed}: at reset {at_reset}, solved {solved}"
    finally:
        env.close()


@pytest.mark.parametrize("task", TASKS)
def test_layouts_differ_across_seeds(task):
    t = make_task(task)
    layouts = [t.sample_layout(np.random.default_rng(seed), Variation()) for seed in range(6)]
    for slot in t.object_slots:
        poses = np.array([[*layout.objects[slot].position[:2], layout.objects[slot].yaw] for layout in layouts])
        distances = np.linalg.norm(poses[:, None, :2] - poses[None, :, :2], axis=-1)[np.triu_indices(6, 1)]
        assert distances.min() > 0.002, f"{task}: two seeds put the {slot} at the same place"
        assert np.ptp(poses[:, 0]) > 0.03 and np.ptp(poses[:, 1]) > 0.03
    # The same seed gives the same layout.
    again = t.sample_layout(np.random.default_rng(0), Variation())
    for slot in t.object_slots:
        np.testing.assert_allclose(again.objects[slot].position, layouts[0].objects[slot].position)


@pytest.mark.parametrize("task", TASKS)
def test_instance_variation_scales_the_task_objects(task):
    """Clean scenes use scale 1; "instance" scenes 0.8 or 1.2, and the built geometry follows."""
    clean, varied = make_env(task), make_env(task, "instance")
    try:
        clean.reset(seed=0)
        reference = {slot: size_measure(clean, slot) for slot in clean.task.object_slots}
        seen = set()
        for seed in range(6):
            varied.reset(seed=seed)
            for slot in varied.task.object_slots:
                scale = varied.episode.layout.objects[slot].scale
                seen.add(scale)
                ratio = size_measure(varied, slot) / reference[slot]
                assert scale in (0.8, 1.2)
                # Walls, handles and rims keep their size, so the ratio follows the scale only roughly.
                assert abs(ratio - scale) < 0.08, f"{task} {slot}: scale {scale} but size ratio {ratio:.3f}"
        assert seen == {0.8, 1.2}
    finally:
        clean.close()
        varied.close()


@pytest.mark.parametrize("task", TASKS)
def test_slot_objects_carry_kind_colour_and_size_words(task):
    env = make_env(task, "instance")
    try:
        env.reset(seed=1)
        layout = env.episode.layout
        for slot in env.task.object_slots:
            attributes = env.instance_attributes[layout.names[slot]]
            assert attributes["kind"] == layout.objects[slot].kind
            assert attributes["color"] == layout.objects[slot].color
            assert attributes["size"] in ("small", "large")
            assert attributes["role"] == "target"
    finally:
        env.close()


def teleport(env: TabletopEnv, body: str, position, quat=(1.0, 0.0, 0.0, 0.0), settle_steps: int = 100) -> None:
    """Put a free body at `position` (3,) with orientation `quat` (wxyz), at rest, then let physics run."""
    import mujoco

    joint = env.model.body(body).jntadr[0]
    address, dof = env.model.jnt_qposadr[joint], env.model.jnt_dofadr[joint]
    env.data.qpos[address:address + 7] = [*position, *quat]
    env.data.qvel[dof:dof + 6] = 0.0
    mujoco.mj_forward(env.model, env.data)
    mujoco.mj_step(env.model, env.data, nstep=settle_steps)


def set_joint(env: TabletopEnv, joint: str, value: float) -> None:
    import mujoco

    env.data.qpos[env.model.joint(joint).qposadr[0]] = value
    env.data.qvel[env.model.joint(joint).dofadr[0]] = 0.0
    mujoco.mj_forward(env.model, env.data)


@pytest.mark.parametrize("task", TASKS)
def test_obstacle_variation_finds_room_on_the_expert_path_in_most_layouts(task):
    """Obstacles must stand on the expert's path yet clear of every object and of the gripper's start; a
    layout that leaves no such spot drops the obstacle (evaluations count the episodes that got one)."""
    from lano3dp.sim.robot import GRIPPER_FOOTPRINT_RADIUS, HOME_POSITION
    from lano3dp.sim.variations import START_CLEARANCE, sample_extras

    t, variation = make_task(task), Variation.parse("obstacle")
    placed = 0
    for seed in range(20):
        rng = np.random.default_rng(seed)
        layout = t.sample_layout(rng, variation)
        extras = sample_extras(t, layout, rng, variation)
        for extra in extras.objects:
            if extra.role == "obstacle":
                placed += 1
                gap = np.linalg.norm(extra.position[:2] - HOME_POSITION[:2]) - extra.radius - GRIPPER_FOOTPRINT_RADIUS
                assert gap >= START_CLEARANCE - 1e-9
    if task in NO_OBSTACLE_ROOM:
        assert placed <= 3, f"{task}: {placed}/20 layouts now have room; move it out of NO_OBSTACLE_ROOM"
    else:
        assert placed >= (6 if task in SHORT_CARRY else 9), \
            f"{task}: an obstacle found room in only {placed}/20 layouts"


@pytest.mark.parametrize("task", TASKS)
@pytest.mark.parametrize("variation", ["clean", "camera+instance"])
def test_slot_objects_are_visible_to_the_camera(task, variation):
    """Each slot object covers enough pixels at 96x96 for a per-object cloud, from the training and
    the shifted camera (the policy sees nothing else). The smallest is the 3.2 cm block seen from the
    shifted camera, about 23 pixels."""
    env = TabletopEnv(task, variation=variation, image_size=96, render_rgb=False)
    try:
        for seed in (0, 1, 2):
            obs, _ = env.reset(seed=seed)
            for slot in env.task.object_slots:
                name = env.episode.layout.names[slot]
                pixels = int(np.isin(obs["segmentation"], env.instance_names[name]).sum())
                assert pixels >= 15, f"{task} seed {seed}: the {slot} covers only {pixels} pixels"
    finally:
        env.close()


@pytest.mark.parametrize("task", TASKS)
def test_every_variation_axis_builds(task):
    """All axes at once build a scene with the slot objects and the extras the axes add."""
    env = make_env(task, "clutter+similar+instance+camera+background+obstacle")
    try:
        roles = set()
        for seed in range(4):
            env.reset(seed=seed)
            for slot in env.task.object_slots:
                assert env.episode.layout.names[slot] in env.objects
            roles |= {info.role for info in env.objects.values()}
        assert {"target", "distractor"} | ({"obstacle"} if task not in NO_OBSTACLE_ROOM else set()) <= roles
    finally:
        env.close()


@pytest.mark.parametrize("task", TASKS)
def test_layouts_sample_for_many_seeds_under_every_variation(task):
    """Layout sampling never gives up: large instances and all the extras still fit on the table."""
    from lano3dp.sim.variations import sample_extras

    t = make_task(task)
    for name in ("clean", "instance+clutter", "instance+similar+clutter+obstacle"):
        variation = Variation.parse(name)
        for seed in [*range(50), 175, 279]:  # 175, 279: a large drawer once left no room for the bottle
            rng = np.random.default_rng(seed)
            layout = t.sample_layout(rng, variation)
            sample_extras(t, layout, rng, variation)
            assert set(t.object_slots) <= set(layout.objects)
