"""put_item_in_drawer: pick a block and put it into an open drawer (RLBench `put_item_in_drawer`).

Layout: the drawer cabinet as in `open_drawer` (on one side of the table, its front towards the
middle and turned towards the camera) open by 85-100% of its travel; a 4 cm block
(`objects.articulated.add_block`, 60 g, kind "block") at a random yaw on the other side
of the table (x in [0.28, 0.58], opposite sign of y, |y| in [0.08, 0.26]), 5 cm clear of the
drawer's footprint and of the pulled-out drawer. Instance variation:
block and drawer scaled 0.8 / 1.2 independently and recoloured.

Expert: top-down grasp of the block low on two opposite faces (of the two face pairs, the
one whose grasp axis is nearest the drawer's width, so the open fingers fit between the
drawer's side walls), lift until the block clears the cabinet by 4 cm, carry over the middle of
the pulled-out part of the drawer (turning the hand to close across the drawer), lower until
the block is 1 cm above the floor, release, retreat.

Success: the block is released, its centre over the drawer's inner floor, its bottom within
2 cm of the floor, nearly at rest (< 5 cm/s).

Stages: reached_block (TCP within 3 cm of the block's centre), grasped (the block held), lifted
(held, its bottom 3 cm above the table), carried_to_drawer (its centre over the drawer's inner
floor, at any height), placed (success).

Differences from RLBench: RLBench's cabinet has three closed drawers and the robot first
opens the named one; here the single drawer starts open (the language registry's "open
drawer"), so the task is the pick-and-place part; `open_drawer` covers the opening.
"""

from __future__ import annotations

import numpy as np

from lano3dp.sim.experts import MotionPlan
from lano3dp.sim.objects.articulated import BLOCK_HALF, add_block
from lano3dp.sim.robot import HOME_POSITION, rot_z, top_down
from lano3dp.sim.tasks import register_task
from lano3dp.sim.tasks.base import LIFT_HEIGHT, REACH_TOLERANCE, Layout, Placement, SimState, Task
from lano3dp.sim.tasks.bottle_in_drawer import CARRY_CLEARANCE, INTO_DRAWER_VERBS, drawer_slot_centre, in_drawer
from lano3dp.sim.tasks.close_microwave import yaw_along
from lano3dp.sim.tasks.open_drawer import build_drawer, close_gently, drawer_frame, sample_beside, sample_drawer
from lano3dp.sim.variations import Variation

BLOCK_COLORS = ("red", "yellow", "purple", "orange")
GRASP_TCP_HEIGHT = 0.012  # TCP above the block's bottom at the grasp


@register_task
class PutItemInDrawer(Task):
    name = "put_item_in_drawer"
    skill = "put_item_in_drawer"
    object_slots = ("block", "drawer")
    instruction = "put the {block} into the {drawer}"
    max_steps = 130
    similar_slots = ("block",)
    stages = ("reached_block", "grasped", "lifted", "carried_to_drawer", "placed")
    description = "put a small item (a block by default) into the open drawer"
    verbs = INTO_DRAWER_VERBS
    synonyms = {"block": ("item", "object", "toy")}
    carried = "block"
    accepts_any = ("block",)

    def sample_layout(self, rng: np.random.Generator, variation: Variation) -> Layout:
        scale = self.instance_scale(rng, variation)
        color = str(rng.choice(BLOCK_COLORS)) if variation.has("instance") else "blue"
        radius = 1.5 * BLOCK_HALF * scale
        xy = None
        while xy is None:  # a large drawer pulled out across the table can leave no room: redraw it
            objects = sample_drawer(rng, variation, opening=(0.85, 1.0))
            xy = sample_beside(rng, objects, radius, (0.28, 0.58), (0.08, 0.26))
        objects["block"] = Placement("block", np.array([*xy, 0.0]), float(rng.uniform(-np.pi, np.pi)), color, scale,
                                     radius)
        layout = Layout(seed=0, objects=objects)
        layout.set_names(self.object_slots, variation)
        return layout

    def build(self, builder, layout: Layout) -> None:
        build_drawer(builder, layout)
        block = layout.objects["block"]
        add_block(builder, layout.names["block"], block.position, block.yaw, block.color, block.scale)

    def plan_expert(self, sim: SimState | None, layout: Layout) -> MotionPlan:
        parts, origin, rotation = drawer_frame(layout)
        block = layout.objects["block"]
        half = BLOCK_HALF * block.scale
        if sim is None:
            centre, block_rotation = np.array([*block.position[:2], half]), rot_z(block.yaw)
            opening = layout.objects["drawer"].params["opening"]
        else:
            centre, block_rotation = sim.body_position(layout.names["block"]), sim.body_rotation(layout.names["block"])
            opening = sim.joint_qpos(parts.joint)
        across = rotation[:, 1]  # the drawer's width direction
        # Face normals of the block in the plane; grasp along the one nearest the drawer's width.
        normals = [block_rotation[:, 0], block_rotation[:, 1]]
        normal = max(normals, key=lambda n: abs(float(np.dot(n[:2], across[:2]))))
        grasp_yaw = yaw_along(normal)
        place_yaw = yaw_along(across, grasp_yaw)

        # Fingertips (1 cm below the TCP) 2 mm above the table: the pads then cover the block's whole
        # side; pinching only its upper part let the small block pivot out of the grasp.
        grasp = np.array([centre[0], centre[1], centre[2] - half + GRASP_TCP_HEIGHT])
        carry_z = parts.height + CARRY_CLEARANCE + GRASP_TCP_HEIGHT
        place = drawer_slot_centre(parts, origin, rotation, opening) + np.array([0.0, 0.0, 0.01 + GRASP_TCP_HEIGHT])
        plan = MotionPlan(HOME_POSITION, top_down())
        plan.move_to(grasp + np.array([0, 0, 0.08]), top_down(grasp_yaw))
        plan.move_to(grasp, speed=0.12)
        close_gently(plan, 0.0)
        plan.move_to(np.array([*grasp[:2], carry_z]), speed=0.15)
        plan.move_to(np.array([*place[:2], carry_z]), top_down(place_yaw), speed=0.2)
        plan.move_to(place, speed=0.12)
        plan.release()
        plan.retreat(0.10)
        return plan

    def obstacle_region(self, layout: Layout) -> np.ndarray:
        """The carry from above the block to above the drawer."""
        return self.nominal_path(layout)[3:5]

    def is_success(self, sim: SimState, layout: Layout) -> bool:
        name = layout.names["block"]
        if sim.held_object() == name or np.linalg.norm(sim.body_velocity(name)[3:]) > 0.05:
            return False
        half = BLOCK_HALF * layout.objects["block"].scale
        return in_drawer(sim, layout, sim.body_position(name), bottom_offset=half)

    def stage_reached(self, sim: SimState, layout: Layout) -> dict[str, bool]:
        name = layout.names["block"]
        centre, half = sim.body_position(name), BLOCK_HALF * layout.objects["block"].scale
        held = sim.holds(name)
        return {"reached_block": sim.tcp_distance(centre) < REACH_TOLERANCE,
                "grasped": held,
                "lifted": held and centre[2] - half >= LIFT_HEIGHT,
                "carried_to_drawer": in_drawer(sim, layout, centre, bottom_offset=half, floor_tolerance=np.inf),
                "placed": self.is_success(sim, layout)}
