"""sweep_to_dustpan: sweep dirt into a dustpan with a broom (RLBench `sweep_to_dustpan`, simplified).

Layout: a static dustpan (`objects.articulated.add_dustpan`: floor flush with the table, walls on
three sides, 12 x 17 cm) with its mouth at x in [0.38, 0.52], |y| in [0.10, 0.16], opening towards
the middle of the table; the sweep direction v (from the middle into the pan) is +-y turned by up
to 0.4 rad. Four dirt cubes (1.6 cm, 4 g) lie in a cluster 10 cm in front of the mouth, spread
7 cm across v. A push broom (`add_broom`: 12 cm head, 22 cm handle, 60 g) lies flat on the other
side of the table at any yaw. Instance variation: broom and dustpan scaled 0.8 / 1.2 and
recoloured, the broom never larger than the dustpan (its head must fit the mouth).

Expert: top-down grasp of the handle at the broom's centre of mass (fingers across the handle,
tips 2 mm above the table; of the two such grasps, the one with the head along the hand's +x), lift
6 cm, turn and carry the broom until its head is behind the dirt with the handle along v, lower
the head to 2 mm above the table, push along v until the head is 3.5 cm short of the dustpan's
back wall, lift the broom (still held).

Success: at least 3 of the 4 dirt cubes lie inside the dustpan (between its mouth and back wall,
between its side walls, on the floor).

Stages: reached_broom (TCP within 3 cm of the handle's axis), grasped (the broom held), lifted
(held, its head 3 cm above the table), swept (3 of the 4 cubes pushed 3 cm towards the dustpan
from where they lay), in_dustpan (success).

Differences from RLBench: a push broom moved in a straight line (RLBench's broom is swept with a
wrist motion), 4 cubes instead of 5 small dirt particles, and a lip-less dustpan floor.
"""

from __future__ import annotations

import numpy as np

from lano3dp.sim.experts import MotionPlan
from lano3dp.sim.objects import primitives
from lano3dp.sim.objects.articulated import BroomParts, DustpanParts, add_broom, add_dustpan
from lano3dp.sim.robot import HOME_POSITION, rot_z, top_down
from lano3dp.sim.tasks import register_task
from lano3dp.sim.tasks.base import (
    LIFT_HEIGHT,
    REACH_TOLERANCE,
    Layout,
    Placement,
    SimState,
    Task,
    segment_distance,
)
from lano3dp.sim.tasks.open_drawer import close_gently
from lano3dp.sim.variations import Variation

N_DIRT, MIN_SWEPT = 4, 3
DIRT_HALF, DIRT_MASS = 0.008, 0.004
DIRT_OFFSET = 0.10  # cluster centre in front of the mouth, m
GRASP_TCP_HEIGHT = 0.002 + 0.01  # fingertips 2 mm above the table (1 cm below the TCP)
HEAD_CLEARANCE = 0.002  # broom head above the table while sweeping
LIFT = 0.06
SWEPT = 0.03  # m a dirt cube moved along the sweep direction for the "swept" stage
BROOM_COLORS = ("red", "blue", "green", "purple")
DUSTPAN_COLORS = ("black", "yellow", "grey", "orange")


def pose(rotation: np.ndarray, position: np.ndarray) -> np.ndarray:
    transform = np.eye(4)
    transform[:3, :3], transform[:3, 3] = rotation, position
    return transform


@register_task
class SweepToDustpan(Task):
    name = "sweep_to_dustpan"
    skill = "sweep_to_dustpan"
    object_slots = ("broom", "dustpan")
    instruction = "sweep the dirt into the {dustpan} with the {broom}"
    max_steps = 150
    similar_slots = ("broom",)
    stages = ("reached_broom", "grasped", "lifted", "swept", "in_dustpan")
    description = "sweep the dirt into the dustpan with the broom"
    verbs = ("sweep", "brush", "sweep up", "brush up")
    synonyms = {"broom": ("brush", "hand brush", "push broom"), "dustpan": ("dust pan",)}
    carried = "broom"

    def sample_layout(self, rng: np.random.Generator, variation: Variation) -> Layout:
        instance = variation.has("instance")
        broom_scale, pan_scale = self.instance_scale(rng, variation), self.instance_scale(rng, variation)
        if pan_scale < broom_scale:  # a large broom's 14 cm head does not fit a small pan's 12 cm mouth
            broom_scale = pan_scale
        broom_color = str(rng.choice(BROOM_COLORS)) if instance else "yellow"
        pan_color = str(rng.choice(DUSTPAN_COLORS)) if instance else "blue"
        side = rng.choice([-1.0, 1.0])
        angle = side * np.pi / 2 + rng.uniform(-0.4, 0.4)
        v = np.array([np.cos(angle), np.sin(angle)])
        across = np.array([-v[1], v[0]])
        mouth = np.array([rng.uniform(0.38, 0.52), side * rng.uniform(0.10, 0.16)])
        pan = DustpanParts.of("dustpan", pan_scale)
        objects = {
            "dustpan": Placement("dustpan", np.array([*mouth, 0.0]), float(angle), pan_color, pan_scale,
                                 float(np.hypot(pan.depth, pan.width)) / 2 + 0.01),
        }
        centre = mouth - v * DIRT_OFFSET
        dirt: list[np.ndarray] = []
        while len(dirt) < N_DIRT:
            xy = centre + across * rng.uniform(-0.035, 0.035) + v * rng.uniform(-0.02, 0.02)
            if all(np.linalg.norm(xy - other) > 0.025 for other in dirt):
                dirt.append(xy)
        for i, xy in enumerate(dirt):
            objects[f"dirt{i}"] = Placement("item", np.array([*xy, DIRT_HALF]), float(rng.uniform(0, np.pi / 2)),
                                            "brown", 1.0, 0.0)
        broom = BroomParts.of("broom", broom_scale)
        radius = (broom.head_half[0] + broom.handle_length) / 2 + 0.03
        # Clear of the dirt and the dustpan (where the broom sweeps later it has already been picked up).
        keep_clear = [(centre, 0.06), (mouth + v * pan.depth / 2, objects["dustpan"].radius)]
        for _ in range(1000):
            xy = np.array([rng.uniform(0.30, 0.56), -side * rng.uniform(0.10, 0.30)])
            if all(np.linalg.norm(xy - c) > r + radius for c, r in keep_clear):
                break
        else:
            raise RuntimeError("no free spot for the broom")
        yaw = float(rng.uniform(-np.pi, np.pi))
        # `position` is the broom's centre; the body origin (the head) is half a length along +x.
        objects["broom"] = Placement("broom", np.array([*xy, 0.0]), yaw, broom_color, broom_scale, radius)
        layout = Layout(seed=0, objects=objects, params={"sweep_angle": float(angle)})
        layout.set_names(self.object_slots, variation)
        return layout

    @staticmethod
    def broom_origin(placement: Placement, parts: BroomParts) -> np.ndarray:
        """(2,) table position of the broom's body origin (its head) from the placement's centre."""
        half = (parts.head_half[0] + parts.handle_length) / 2 - parts.head_half[0]
        return placement.position[:2] + rot_z(placement.yaw)[:2, 0] * half

    def build(self, builder, layout: Layout) -> None:
        broom, pan = layout.objects["broom"], layout.objects["dustpan"]
        parts = BroomParts.of(layout.names["broom"], broom.scale)
        add_broom(builder, layout.names["broom"], self.broom_origin(broom, parts), broom.yaw, broom.color, broom.scale)
        add_dustpan(builder, layout.names["dustpan"], pan.position, pan.yaw, pan.color, pan.scale)
        for key, dirt in layout.objects.items():
            if dirt.kind == "item":
                info = primitives.add_cube(builder, key, dirt.position, dirt.yaw, dirt.color, role="item",
                                           half_size=DIRT_HALF, mass=DIRT_MASS)
                info.kind = "dirt"

    def plan_expert(self, sim: SimState | None, layout: Layout) -> MotionPlan:
        broom, pan = layout.objects["broom"], layout.objects["dustpan"]
        parts, pan_parts = BroomParts.of(layout.names["broom"], broom.scale), DustpanParts.of("dustpan", pan.scale)
        hz = parts.head_half[2]
        if sim is None:
            broom_pose = pose(rot_z(broom.yaw), np.array([*self.broom_origin(broom, parts), hz]))
        else:
            broom_pose = pose(sim.body_rotation(parts.body), sim.body_position(parts.body))
        angle = layout.params["sweep_angle"]
        v = np.array([np.cos(angle), np.sin(angle), 0.0])
        mouth = np.asarray(pan.position, float)

        # Grasp: on the handle at the centre of mass, fingers closing across the handle.
        grasp = broom_pose[:3, :3] @ np.array([parts.grasp_x, 0.0, 0.0]) + broom_pose[:3, 3]
        grasp[2] = GRASP_TCP_HEIGHT
        target_rotation = rot_z(angle)  # the broom's heading while sweeping: its +x along v
        # Of the two grasps across the handle, the one that holds the head on the hand's +x side: the carry
        # then turns the hand to the sweep direction whichever way the broom lay, so which end is the head
        # is read once, off the broom lying on the table. With the grasp nearest the hand's start yaw the
        # carry's turn hung on which side of the hand the head was, and policies swept reversed (README).
        ee = pose(top_down(float(np.arctan2(broom_pose[1, 0], broom_pose[0, 0]))), grasp)
        in_hand = np.linalg.inv(ee) @ broom_pose  # broom in the EE frame, fixed once grasped

        def ee_for_head(head: np.ndarray) -> np.ndarray:
            """EE pose (4, 4) that puts the broom's head centre at `head` (3,) with its +x along v."""
            return pose(target_rotation, head) @ np.linalg.inv(in_hand)

        start_head = mouth - v * (DIRT_OFFSET + 0.02 + DIRT_HALF * 1.5 + parts.head_half[0] + 0.02)
        end_head = mouth + v * (pan_parts.depth - pan_parts.wall - 0.035 - parts.head_half[0])
        start_head[2] = end_head[2] = hz + HEAD_CLEARANCE
        start, end = ee_for_head(start_head), ee_for_head(end_head)
        up = np.array([0.0, 0.0, LIFT])

        plan = MotionPlan(HOME_POSITION, top_down())
        plan.move_to(grasp + np.array([0, 0, 0.08]), ee[:3, :3])
        plan.move_to(grasp, speed=0.12)
        close_gently(plan, 0.0)
        plan.move_to(grasp + up, speed=0.12)
        plan.move_to(start[:3, 3] + up, start[:3, :3], speed=0.2)
        plan.move_to(start[:3, 3], speed=0.08)
        plan.move_to(end[:3, 3], speed=0.08)
        plan.hold(3)
        plan.move_to(end[:3, 3] + up, speed=0.1)
        return plan

    def obstacle_region(self, layout: Layout) -> np.ndarray:
        """The carry from above the broom to above the sweep's start."""
        return self.nominal_path(layout)[3:5]

    def is_success(self, sim: SimState, layout: Layout) -> bool:
        pan = layout.objects["dustpan"]
        parts = DustpanParts.of(layout.names["dustpan"], pan.scale)
        origin, rotation = sim.body_position(parts.body), sim.body_rotation(parts.body)
        swept = 0
        for key, dirt in layout.objects.items():
            if dirt.kind != "item":
                continue
            local = rotation.T @ (sim.body_position(key) - origin)
            swept += bool(0.0 < local[0] < parts.depth and abs(local[1]) < parts.inner_half_width
                          and local[2] < parts.wall_height)
        return swept >= MIN_SWEPT

    def stage_reached(self, sim: SimState, layout: Layout) -> dict[str, bool]:
        broom = layout.objects["broom"]
        parts = BroomParts.of(layout.names["broom"], broom.scale)
        origin, rotation = sim.body_position(parts.body), sim.body_rotation(parts.body)
        hx, _, hz = parts.head_half
        handle = [origin + rotation @ np.array([x, 0.0, 0.0]) for x in (-hx, -hx - parts.handle_length)]
        held = sim.holds(layout.names["broom"])
        angle = layout.params["sweep_angle"]
        v = np.array([np.cos(angle), np.sin(angle)])
        pushed = sum(float((sim.body_position(key)[:2] - dirt.position[:2]) @ v) >= SWEPT
                     for key, dirt in layout.objects.items() if dirt.kind == "item")
        return {"reached_broom": segment_distance(sim.ee_pose()[0], *handle) < REACH_TOLERANCE,
                "grasped": held,
                "lifted": held and origin[2] - hz >= LIFT_HEIGHT,
                "swept": pushed >= MIN_SWEPT,
                "in_dustpan": self.is_success(sim, layout)}
