"""close_microwave: push an open microwave door shut (RLBench `close_microwave`).

Layout: a microwave-like box (`objects.articulated.add_microwave`: a static box, its door on a
vertical hinge at the front-left edge, 16 x 22 x 14 cm) with its centre at x in [0.44, 0.54],
y in [0.14, 0.22] (the table's left), its front towards the middle turned 0.3-0.7 rad
towards the camera, so the hinge is on the robot's side; the door starts open by 0.8-1.4 rad.
Instance variation: scale 0.8 / 1.2 and another colour.

Expert: with the fingers closed and their closing axis along the door, come down beside the
door's outer face near its top edge (fingertips 4 cm below the door's top, so the palm passes
above it), 60% of the way from the hinge to the free edge, then sweep along the circle the
contact point travels (steps of ~0.15 rad, the hand turning with the door) to just past
closed, and lift away.

Success: the door angle is below 0.1 rad (~6 degrees).

Stages: reached_door (TCP on the door's outer side within 4 cm of its face, between hinge and free
edge, below its top), pushed (the door 0.2 rad more closed than at the start), half_closed (at
most half its starting angle), closed (success).

Differences from RLBench: a box primitive instead of the microwave mesh, and a free-floating
gripper instead of an arm.
"""

from __future__ import annotations

import numpy as np

from lano3dp.sim.experts import CLOSED, MotionPlan
from lano3dp.sim.objects.articulated import MicrowaveParts, add_microwave
from lano3dp.sim.robot import HOME_POSITION, GripperSpec, rot_z, top_down
from lano3dp.sim.tasks import register_task
from lano3dp.sim.tasks.base import Layout, Placement, SimState, Task
from lano3dp.sim.tasks.open_drawer import approach_clear_of
from lano3dp.sim.variations import Variation

CLOSED_ANGLE = 0.1  # rad, success threshold
MICROWAVE_COLORS = ("grey", "red", "blue", "yellow")
CONTACT_FRACTION = 0.6  # contact point along the door, from the hinge
PUSH_DEPTH_BELOW_TOP = 0.03  # TCP below the door's top edge (fingertips 1 cm lower still)
SWEEP_STEP = 0.15  # rad between sweep waypoints
FINGER_HALF_WIDTH = GripperSpec().finger_half[0]  # pad half extent across the door when pushing
# 4 cm: the hand's half width (1.2 cm) plus the reach tolerance, so a hand touching the door counts,
# and the expert's stand-off before it comes down beside the door (4.2 cm) does not.
DOOR_REACH = 0.04  # m, TCP off the door's outer face
PUSHED = 0.2  # rad closed beyond the starting angle
CLEARANCE_KEY = "microwave_clearance"
# On the table's left (+y), front towards the middle: the open door swings over the middle of the
# table, in the camera's view, and the approach from home passes beside the box, leaving room for
# "obstacle" cylinders in about half of the layouts (the open door's sector fills the rest; with
# the box in the middle, under the home pose, no layout had room).
XY_LOW, XY_HIGH = np.array([0.44, 0.14]), np.array([0.54, 0.22])


def door_point(parts: MicrowaveParts, origin: np.ndarray, rotation: np.ndarray, angle: float, along: float,
               out: float) -> tuple[np.ndarray, np.ndarray]:
    """World point at `along` m from the hinge along the door and `out` m off its outer face, at
    z = 0, and the door's unit direction from the hinge (both (3,)), for door angle `angle`."""
    hinge = origin + rotation @ parts.hinge_local
    edge = rotation @ np.array([np.sin(angle), np.cos(angle), 0.0])
    normal = rotation @ np.array([np.cos(angle), -np.sin(angle), 0.0])
    return hinge + along * edge + out * normal, edge


def yaw_along(direction: np.ndarray, previous: float | None = None) -> float:
    """Yaw psi of `top_down(psi)` whose finger axis (sin psi, -cos psi) is parallel to `direction`;
    of the two (the fingers are symmetric) the one nearest `previous`."""
    psi = float(np.arctan2(direction[0], -direction[1]))
    reference = 0.0 if previous is None else previous
    return psi + np.pi * np.round((reference - psi) / np.pi)


@register_task
class CloseMicrowave(Task):
    name = "close_microwave"
    skill = "close_microwave"
    object_slots = ("microwave",)
    instruction = "close the {microwave}"
    max_steps = 120
    stages = ("reached_door", "pushed", "half_closed", "closed")
    description = "push the microwave door closed"
    verbs = ("close", "shut", "slam", "push shut", "push closed", "swing shut", "swing closed", "push to")
    synonyms = {"microwave": ("microwave oven", "oven")}

    def sample_layout(self, rng: np.random.Generator, variation: Variation) -> Layout:
        scale = self.instance_scale(rng, variation)
        color = str(rng.choice(MICROWAVE_COLORS)) if variation.has("instance") else "white"
        xy = rng.uniform(XY_LOW, XY_HIGH)
        yaw = float(-(np.pi / 2 - rng.uniform(0.3, 0.7)))  # front towards -y, turned towards the camera
        angle = float(rng.uniform(0.8, 1.4))
        parts = MicrowaveParts.of("microwave", scale)
        box = Placement("microwave", np.array([*xy, 0.0]), yaw, color, scale,
                        float(np.hypot(parts.depth, parts.width)) / 2 + 0.01, {"door_angle": angle})
        # The sector the door sweeps while closing (radius = door width, angles 0..angle about the
        # hinge) and the hand pushing it: a disc around the sector's middle.
        hinge = np.array([*xy, 0.0]) + rot_z(yaw) @ parts.hinge_local
        middle = rot_z(yaw) @ np.array([np.sin(angle / 2), np.cos(angle / 2), 0.0])
        reach = parts.door_width * np.sqrt(1.25 - np.cos(angle / 2))  # farthest sector point from the centre
        sweep = Placement("clearance", hinge + 0.5 * parts.door_width * middle, yaw, color, scale, reach + 0.05)
        layout = Layout(seed=0, objects={"microwave": box, CLEARANCE_KEY: sweep})
        layout.set_names(self.object_slots, variation)
        return layout

    def build(self, builder, layout: Layout) -> None:
        box = layout.objects["microwave"]
        add_microwave(builder, layout.names["microwave"], box.position, box.yaw, box.color, box.scale,
                      door_angle=box.params["door_angle"])

    def plan_expert(self, sim: SimState | None, layout: Layout) -> MotionPlan:
        box = layout.objects["microwave"]
        parts = MicrowaveParts.of(layout.names["microwave"], box.scale)
        origin, rotation = np.asarray(box.position, float), rot_z(box.yaw)
        angle = box.params["door_angle"] if sim is None else sim.joint_qpos(parts.joint)
        along = CONTACT_FRACTION * parts.door_width
        z = parts.height - PUSH_DEPTH_BELOW_TOP
        touch = parts.door_thickness / 2 + FINGER_HALF_WIDTH  # pad face on the door's outer face

        start, edge = door_point(parts, origin, rotation, angle, along, touch + 0.03)
        psi = yaw_along(edge)
        plan = MotionPlan(HOME_POSITION, top_down(), gripper=CLOSED)
        plan.move_to(start + np.array([0, 0, z + 0.12]), top_down(psi))
        plan.move_to(start + np.array([0, 0, z]), speed=0.15)
        for target in np.linspace(angle, -0.02, max(2, int(np.ceil((angle + 0.02) / SWEEP_STEP))) + 1)[1:]:
            point, edge = door_point(parts, origin, rotation, target, along, touch + 0.004)
            psi = yaw_along(edge, psi)
            plan.move_to(point + np.array([0, 0, z]), top_down(psi), speed=0.12)
        plan.retreat(0.10)
        return plan

    def obstacle_region(self, layout: Layout) -> np.ndarray:
        """The approach from home to above the door, where it is not over the microwave."""
        path = self.nominal_path(layout)
        return approach_clear_of(path[0], path[1], layout)

    def is_success(self, sim: SimState, layout: Layout) -> bool:
        parts = MicrowaveParts.of(layout.names["microwave"], layout.objects["microwave"].scale)
        return sim.joint_qpos(parts.joint) < CLOSED_ANGLE

    def stage_reached(self, sim: SimState, layout: Layout) -> dict[str, bool]:
        box = layout.objects["microwave"]
        parts = MicrowaveParts.of(layout.names["microwave"], box.scale)
        angle, start = sim.joint_qpos(parts.joint), box.params["door_angle"]
        origin, rotation = np.asarray(box.position, float), rot_z(box.yaw)
        hinge, edge = door_point(parts, origin, rotation, angle, 0.0, 0.0)
        normal = door_point(parts, origin, rotation, angle, 0.0, 1.0)[0] - hinge  # out of the outer face
        offset = sim.ee_pose()[0] - hinge
        along, out = float(offset @ edge), float(offset @ normal) - parts.door_thickness / 2
        at_door = 0.0 <= along <= parts.door_width and 0.0 <= out <= DOOR_REACH and offset[2] <= parts.height
        return {"reached_door": at_door,
                "pushed": angle <= start - PUSHED,
                "half_closed": angle <= start / 2,
                "closed": self.is_success(sim, layout)}
