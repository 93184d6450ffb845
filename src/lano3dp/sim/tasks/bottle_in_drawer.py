"""bottle_in_drawer: put a bottle, standing upright, into an open drawer (the paper's real task).

Layout: the drawer cabinet as in `open_drawer` (on one side of the table, its front towards the
middle and turned towards the camera) but open by 85-100% of its travel; an upright bottle
(`primitives.add_bottle`, 19 cm tall at scale 1) on the other side of the table
(x in [0.28, 0.58], y of the opposite sign, |y| in [0.08, 0.26]), 5 cm clear of the
drawer's footprint and of the pulled-out drawer. As in
the paper the bottle's orientation does not change: it stays upright. Instance variation: bottle
and drawer scaled 0.8 / 1.2 independently and recoloured.

Expert: top-down grasp of the bottle's neck (the palm then clears the cap), fingers closing
across the drawer's width so they fit between its side walls; lift until the bottle's bottom
is 4 cm above the cabinet, carry over the middle of the pulled-out part of the drawer, lower
until the bottom is 5 mm above the drawer floor, release, retreat upwards.

Success: the bottle is released, upright (tilt under ~25 degrees), its centre inside the drawer's
inner floor rectangle, its bottom within 2 cm of the floor and nearly at rest (< 5 cm/s).

Stages: reached_bottle (TCP within 3 cm of the bottle's axis, bottom to cap), grasped (the bottle
held), lifted (held, its bottom 3 cm above the table), carried_to_drawer (its centre over the
drawer's inner floor, at any height), placed (success).
"""

from __future__ import annotations

import numpy as np

from lano3dp.sim.experts import MotionPlan
from lano3dp.sim.objects import primitives
from lano3dp.sim.objects.primitives import BOTTLE_BODY_HALF
from lano3dp.sim.robot import HOME_POSITION, top_down
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
from lano3dp.sim.tasks.open_drawer import build_drawer, close_gently, drawer_frame, sample_beside, sample_drawer
from lano3dp.sim.variations import Variation

BOTTLE_COLORS = ("red", "blue", "orange", "purple")
# Bottle geometry at scale 1 from `primitives.add_bottle`: origin at the body's centre; the cap
# ends 0.134 m above it (body half 0.06 + shoulder 0.016 + neck 0.044 + cap 0.014).
BOTTLE_TOP_ABOVE_CENTRE = 0.134
PALM_ABOVE_TCP = 0.05  # lowest palm point above the TCP for a top-down grasp (robot.GripperSpec)
CARRY_CLEARANCE = 0.04  # bottle bottom above the cabinet top while carrying
# Fingers pre-closed to a 4.4 cm gap around the 2.2 cm neck: closing from fully open, they hit the
# thin neck fast enough to pass through it at a 4 ms physics step.
PREGRASP_GRIP = 0.5
# Verbs that ask to put something into a drawer (put_item_in_drawer's too).
INTO_DRAWER_VERBS = (
    "put", "place", "store", "stow", "insert", "drop", "move", "tuck", "set", "stash", "pack", "slip", "slide",
    "put away", "put in", "drop in", "tuck away", "stow away",
)


def drawer_slot_centre(parts, origin: np.ndarray, rotation: np.ndarray, opening: float) -> np.ndarray:
    """(3,) world point on the drawer floor, midway between the cabinet front and the drawer front:
    the part of the drawer that is outside the cabinet."""
    local = np.array([parts.depth / 2 + opening / 2, 0.0, parts.floor_top])
    return origin + rotation @ local


def in_drawer(sim: SimState, layout: Layout, position: np.ndarray, bottom_offset: float, margin: float = 0.0,
              floor_tolerance: float = 0.02) -> bool:
    """Whether a point (an object's centre, (3,)) lies over the drawer's inner floor, shrunk by
    `margin`, with the object's bottom (`bottom_offset` below the point) within `floor_tolerance`
    of the floor."""
    parts, _, _ = drawer_frame(layout)
    origin, rotation = sim.body_position(parts.drawer), sim.body_rotation(parts.drawer)
    local = rotation.T @ (position - origin)
    back, front = parts.inner_x
    inside_x = back + margin < local[0] < front - margin
    inside_y = abs(local[1]) < parts.inner_half_width - margin
    resting = local[2] - bottom_offset < parts.floor_top + floor_tolerance
    return bool(inside_x and inside_y and resting)


@register_task
class BottleInDrawer(Task):
    name = "bottle_in_drawer"
    skill = "bottle_in_drawer"
    object_slots = ("bottle", "drawer")
    instruction = "put the {bottle} into the {drawer}"
    max_steps = 150
    similar_slots = ("bottle",)
    stages = ("reached_bottle", "grasped", "lifted", "carried_to_drawer", "placed")
    description = "put the bottle into the open drawer"
    verbs = INTO_DRAWER_VERBS
    synonyms = {"bottle": ("flask",)}
    carried = "bottle"

    def sample_layout(self, rng: np.random.Generator, variation: Variation) -> Layout:
        scale = self.instance_scale(rng, variation)
        color = str(rng.choice(BOTTLE_COLORS)) if variation.has("instance") else "green"
        radius = primitives.FOOTPRINTS["bottle"] * scale
        xy = None
        while xy is None:  # a large drawer pulled out across the table can leave no room: redraw it
            objects = sample_drawer(rng, variation, opening=(0.85, 1.0))
            xy = sample_beside(rng, objects, radius, (0.28, 0.58), (0.08, 0.26))
        objects["bottle"] = Placement("bottle", np.array([*xy, 0.0]), 0.0, color, scale, radius)
        layout = Layout(seed=0, objects=objects)
        layout.set_names(self.object_slots, variation)
        return layout

    def build(self, builder, layout: Layout) -> None:
        build_drawer(builder, layout)
        bottle = layout.objects["bottle"]
        primitives.add_bottle(builder, layout.names["bottle"], bottle.position, bottle.yaw, bottle.color, bottle.scale)

    def plan_expert(self, sim: SimState | None, layout: Layout) -> MotionPlan:
        parts, origin, rotation = drawer_frame(layout)
        bottle = layout.objects["bottle"]
        half = BOTTLE_BODY_HALF * bottle.scale
        top = BOTTLE_TOP_ABOVE_CENTRE * bottle.scale  # cap end above the bottle's centre
        if sim is None:
            centre = np.array([*bottle.position[:2], half])
            opening = layout.objects["drawer"].params["opening"]
        else:
            centre = sim.body_position(layout.names["bottle"])
            opening = sim.joint_qpos(parts.joint)
        grasp_above_centre = top - PALM_ABOVE_TCP - 0.006  # TCP below the cap end: the palm just clears it
        grasp = centre + np.array([0.0, 0.0, grasp_above_centre])
        # Fingers close across the drawer (along the cabinet's y axis): EE y = (sin psi, -cos psi).
        across = rotation[:, 1]
        ee_rotation = top_down(float(np.arctan2(across[0], -across[1])))
        carry_z = parts.height + CARRY_CLEARANCE + half + grasp_above_centre
        slot = drawer_slot_centre(parts, origin, rotation, opening)
        place = slot + np.array([0.0, 0.0, 0.005 + half + grasp_above_centre])

        plan = MotionPlan(HOME_POSITION, top_down())
        plan.move_to(grasp + np.array([0, 0, 0.08]), ee_rotation, gripper=PREGRASP_GRIP)
        plan.move_to(grasp, speed=0.12)
        close_gently(plan, PREGRASP_GRIP)
        plan.move_to(np.array([*grasp[:2], carry_z]), speed=0.15)
        plan.move_to(np.array([*place[:2], carry_z]), speed=0.2)
        plan.move_to(place, speed=0.12)
        plan.hold(2)
        plan.release()
        plan.retreat(0.10)
        return plan

    def obstacle_region(self, layout: Layout) -> np.ndarray:
        """The carry from above the bottle to above the drawer."""
        return self.nominal_path(layout)[3:5]

    def is_success(self, sim: SimState, layout: Layout) -> bool:
        name = layout.names["bottle"]
        if sim.held_object() == name:
            return False
        if sim.body_rotation(name)[2, 2] < 0.9:  # the bottle's axis is its local z
            return False
        if np.linalg.norm(sim.body_velocity(name)[3:]) > 0.05:
            return False
        half = BOTTLE_BODY_HALF * layout.objects["bottle"].scale
        return in_drawer(sim, layout, sim.body_position(name), bottom_offset=half)

    def stage_reached(self, sim: SimState, layout: Layout) -> dict[str, bool]:
        name, scale = layout.names["bottle"], layout.objects["bottle"].scale
        centre, axis = sim.body_position(name), sim.body_rotation(name)[:, 2]
        half = BOTTLE_BODY_HALF * scale
        held = sim.holds(name)
        tcp = sim.ee_pose()[0]
        near = segment_distance(tcp, centre - half * axis, centre + BOTTLE_TOP_ABOVE_CENTRE * scale * axis)
        return {"reached_bottle": near < REACH_TOLERANCE,
                "grasped": held,
                "lifted": held and centre[2] - half >= LIFT_HEIGHT,
                "carried_to_drawer": in_drawer(sim, layout, centre, bottom_offset=half, floor_tolerance=np.inf),
                "placed": self.is_success(sim, layout)}
