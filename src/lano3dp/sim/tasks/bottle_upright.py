"""bottle_upright: stand a bottle that lies on its side upright.

Layout: the bottle lies with its axis along world +y (neck towards +y) turned by a yaw in
[-0.3, 0.3] rad (the paper keeps the orientation fixed; a little yaw keeps the expert honest),
centre x in [0.38, 0.56], y in [-0.12, 0.12]. Instance variation: scale 0.8 / 1.2, a slim (0.8x)
or stout (1.15x) body, and colour.

Expert: top-down grasp at the centre of mass with the fingers across the bottle, lift,
rotate 90 degrees about the finger axis so the neck points up, lower until the bottom is
5 mm above the table, open, back away along the (now horizontal) approach axis, rise.

Success: the bottle axis is within 15 degrees of vertical with the neck up, it stands on the
table (centre at its half height +- 1.5 cm), is not held, and moves slower than 5 cm/s.

Stages: reached_bottle (TCP within 3 cm of the bottle's axis, bottom to cap), grasped (the bottle
held), lifted (held, its centre 3 cm above where it lay), upright (its axis within 15 degrees of
vertical, neck up, held or not), standing (success).
"""

from __future__ import annotations

import numpy as np

from lano3dp.sim.experts import CLOSED, OPEN, MotionPlan
from lano3dp.sim.objects import primitives
from lano3dp.sim.objects.primitives import BOTTLE_BODY_HALF, BOTTLE_RADIUS
from lano3dp.sim.robot import HOME_POSITION, rot_axis, rot_z, top_down
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
from lano3dp.sim.tasks.bottle_in_drawer import BOTTLE_TOP_ABOVE_CENTRE
from lano3dp.sim.variations import Variation

COM_OFFSET = 0.012  # centre of mass above the body centre along the bottle axis, metres at scale 1
UPRIGHT_COS = np.cos(np.deg2rad(15.0))


def lying_quat(yaw: float) -> np.ndarray:
    """(w, x, y, z) turning the bottle axis (local z) to the horizontal direction Rz(yaw) (0, 1, 0)."""
    import mujoco

    rotation = rot_z(yaw) @ rot_axis([1.0, 0.0, 0.0], -np.pi / 2)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, rotation.reshape(-1))
    return quat


@register_task
class BottleUpright(Task):
    name = "bottle_upright"
    skill = "bottle_upright"  # the language skill registry names skills after their task
    object_slots = ("bottle",)
    instruction = "stand the {bottle} upright"
    max_steps = 150
    similar_slots = ("bottle",)
    stages = ("reached_bottle", "grasped", "lifted", "upright", "standing")
    description = "stand a bottle that lies on its side upright"
    verbs = (
        "stand", "upright", "right", "erect", "raise", "straighten", "stand up", "set upright", "put upright",
        "turn upright", "flip upright", "prop up", "tip up",
    )
    synonyms = {"bottle": ("flask",)}
    carried = "bottle"

    def sample_layout(self, rng: np.random.Generator, variation: Variation) -> Layout:
        scale = self.instance_scale(rng, variation)
        color = str(rng.choice(["red", "blue", "orange", "purple"])) if variation.has("instance") else "green"
        radius_scale = float(rng.choice([0.8, 1.15])) if variation.has("instance") else 1.0  # slim / stout
        xy = rng.uniform([0.38, -0.12], [0.56, 0.12])
        yaw = float(rng.uniform(-0.3, 0.3))
        # The lying bottle's footprint: a disc at its centre plus one over each end (a disc around the
        # whole 19 cm bottle would wall off most of the table).
        radius = BOTTLE_RADIUS * scale * radius_scale
        placement = Placement("bottle", np.array([*xy, radius]), yaw, color, scale, 0.06 * scale,
                              {"radius_scale": radius_scale})
        axis = rot_z(yaw) @ np.array([0.0, 1.0, 0.0])
        keepout = [(xy + axis[:2] * 0.085 * scale, 0.05 * scale), (xy - axis[:2] * 0.06 * scale, 0.05 * scale)]
        layout = Layout(seed=0, objects={"bottle": placement}, keepout=keepout)
        layout.set_names(self.object_slots, variation)
        return layout

    def build(self, builder, layout: Layout) -> None:
        bottle = layout.objects["bottle"]
        primitives.add_bottle(builder, layout.names["bottle"], bottle.position, color=bottle.color,
                              scale=bottle.scale, quat=lying_quat(bottle.yaw),
                              radius_scale=bottle.params.get("radius_scale", 1.0))

    def plan_expert(self, sim: SimState | None, layout: Layout) -> MotionPlan:
        bottle = layout.objects["bottle"]
        scale = bottle.scale
        if sim is None:
            centre = bottle.position
            axis = rot_z(bottle.yaw) @ np.array([0.0, 1.0, 0.0])
        else:
            centre = sim.body_position(layout.names["bottle"])
            axis = sim.body_rotation(layout.names["bottle"])[:, 2]
            axis = np.array([axis[0], axis[1], 0.0]) / max(np.linalg.norm(axis[:2]), 1e-9)
        finger_axis = np.cross([0.0, 0.0, 1.0], axis)
        grasp_rotation = top_down(np.arctan2(finger_axis[0], -finger_axis[1]))
        grasp = centre + COM_OFFSET * scale * axis
        radius = BOTTLE_RADIUS * scale * bottle.params.get("radius_scale", 1.0)
        grasp[2] = radius
        upright_rotation = rot_axis(finger_axis, -np.pi / 2) @ grasp_rotation
        bottom_below_tcp = (BOTTLE_BODY_HALF + COM_OFFSET) * scale
        lift = np.array([*grasp[:2], bottom_below_tcp + radius + 0.06])
        place = np.array([*grasp[:2], bottom_below_tcp + 0.005])

        plan = MotionPlan(HOME_POSITION, top_down())
        plan.grasp(grasp, grasp_rotation, approach=0.10, lift=lift[2] - grasp[2])
        plan.move_to(lift, upright_rotation)
        plan.move_to(place, speed=0.1)
        plan.hold(5, gripper=OPEN)
        approach = upright_rotation[:, 2]
        plan.move_to(place - 0.10 * approach, speed=0.15)
        plan.move_to(place - 0.10 * approach + np.array([0, 0, 0.1]))
        plan.hold(5)
        assert plan.last.gripper == OPEN and CLOSED == 1.0
        return plan

    def is_success(self, sim: SimState, layout: Layout) -> bool:
        name = layout.names["bottle"]
        scale = layout.objects["bottle"].scale
        axis = sim.body_rotation(name)[:, 2]
        centre = sim.body_position(name)
        return bool(
            axis[2] > UPRIGHT_COS
            and abs(centre[2] - BOTTLE_BODY_HALF * scale) < 0.015
            and sim.held_object() != name
            and np.linalg.norm(sim.body_velocity(name)[3:]) < 0.05
        )

    def stage_reached(self, sim: SimState, layout: Layout) -> dict[str, bool]:
        bottle = layout.objects["bottle"]
        name, scale = layout.names["bottle"], bottle.scale
        centre, axis = sim.body_position(name), sim.body_rotation(name)[:, 2]
        bottom, top = centre - BOTTLE_BODY_HALF * scale * axis, centre + BOTTLE_TOP_ABOVE_CENTRE * scale * axis
        held = sim.holds(name)
        lying_z = BOTTLE_RADIUS * scale * bottle.params.get("radius_scale", 1.0)  # its centre's height as laid
        return {"reached_bottle": segment_distance(sim.ee_pose()[0], bottom, top) < REACH_TOLERANCE,
                "grasped": held,
                "lifted": held and centre[2] - lying_z >= LIFT_HEIGHT,
                "upright": bool(axis[2] > UPRIGHT_COS),
                "standing": self.is_success(sim, layout)}
