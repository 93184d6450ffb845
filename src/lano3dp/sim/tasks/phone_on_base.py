"""phone_on_base: pick up a phone and put it on its base (RLBench `phone_on_base`).

Layout: a static base (`objects.articulated.add_phone_base`: a plate with a 12 mm rim around a
recess 2.5 cm larger than the phone on every side) at x in [0.34, 0.56], |y| in [0.10, 0.25],
any yaw; a 13 x 6 x 2 cm phone slab (90 g) lying flat on the other side of the table
(x in [0.28, 0.58], |y| in [0.10, 0.28], opposite sign), any yaw. Instance variation: phone and
base scaled 0.8 / 1.2 together (the recess must still fit the phone) and recoloured.

Expert: top-down grasp across the phone's width, lift to 12 cm, carry over the base while
turning the phone's long axis onto the recess's, lower until the phone is 5 mm above the rim
(the opening fingers would touch the rim lower down), release so it drops into the recess,
retreat.

Success: the phone is released, lies flat (tilt under ~18 degrees) on the recess floor (its
bottom within 6 mm of the floor, which it can only reach inside the rim) with its centre in
the recess, nearly at rest (< 5 cm/s).

Stages: reached_phone (TCP within 3 cm of the phone's centre), grasped (the phone held), lifted
(held, its bottom 3 cm above the table), carried_to_base (its centre over the recess, at any
height), placed (success).

Differences from RLBench: RLBench's base holds the phone upright in a slot; here the phone
lies flat in a rimmed recess, which keeps the pick, the carry and the aligned placement
without an in-hand reorientation.
"""

from __future__ import annotations

import numpy as np

from lano3dp.sim.experts import MotionPlan
from lano3dp.sim.objects.articulated import PhoneBaseParts, PhoneParts, add_phone, add_phone_base
from lano3dp.sim.robot import HOME_POSITION, rot_z, top_down
from lano3dp.sim.tasks import register_task
from lano3dp.sim.tasks.base import LIFT_HEIGHT, REACH_TOLERANCE, Layout, Placement, SimState, Task
from lano3dp.sim.tasks.close_microwave import yaw_along
from lano3dp.sim.tasks.open_drawer import close_gently
from lano3dp.sim.variations import Variation

PHONE_COLORS = ("white", "red", "blue", "pink")
BASE_COLORS = ("white", "green", "brown", "black")
CARRY_HEIGHT = 0.12
# TCP above the phone's centre: the fingertips (1 cm below the TCP) end 2 mm above the table, so the
# pads squeeze the slab's sides symmetrically about its centre of mass. Pinching only its upper
# half (tips 4 mm up on a 1.6 cm slab) rolled the phone over in the fingers on 29 of 30 seeds.
GRASP_ABOVE_CENTRE = 0.002


@register_task
class PhoneOnBase(Task):
    name = "phone_on_base"
    skill = "phone_on_base"
    object_slots = ("phone", "base")
    instruction = "put the {phone} on the {base}"
    max_steps = 130
    similar_slots = ("phone",)
    stages = ("reached_phone", "grasped", "lifted", "carried_to_base", "placed")
    description = "put the phone onto its charging base"
    verbs = (
        "put", "place", "dock", "return", "charge", "set", "rest", "hang", "replace", "hang up", "put back", "set back",
        "plug in",
    )
    synonyms = {
        "phone": ("cellphone", "cell phone", "smartphone", "mobile", "mobile phone", "handset", "telephone"),
        "base": ("dock", "cradle", "charger", "charging base", "charging dock", "station",
                 "charging pad", "charging station", "charging stand", "wireless charger"),
    }
    carried = "phone"

    def sample_layout(self, rng: np.random.Generator, variation: Variation) -> Layout:
        scale = self.instance_scale(rng, variation)
        instance = variation.has("instance")
        phone_color = str(rng.choice(PHONE_COLORS)) if instance else "black"
        base_color = str(rng.choice(BASE_COLORS)) if instance else "grey"
        phone, base = PhoneParts.of("phone", scale), PhoneBaseParts.of("base", scale)
        phone_radius = float(np.hypot(phone.length, phone.width)) / 2 + 0.02
        base_radius = float(np.hypot(base.inner_length, base.inner_width)) / 2 + base.rim + 0.01
        side = rng.choice([-1.0, 1.0])
        while True:  # 5 cm between the footprints leaves room for the fingers
            base_xy = np.array([rng.uniform(0.34, 0.56), side * rng.uniform(0.10, 0.25)])
            phone_xy = np.array([rng.uniform(0.28, 0.58), -side * rng.uniform(0.10, 0.28)])
            if np.linalg.norm(base_xy - phone_xy) >= phone_radius + base_radius + 0.05:
                break
        objects = {
            "phone": Placement("phone", np.array([*phone_xy, 0.0]), float(rng.uniform(-np.pi, np.pi)), phone_color,
                               scale, phone_radius),
            "base": Placement("base", np.array([*base_xy, 0.0]), float(rng.uniform(-np.pi, np.pi)), base_color,
                              scale, base_radius),
        }
        layout = Layout(seed=0, objects=objects)
        layout.set_names(self.object_slots, variation)
        return layout

    def build(self, builder, layout: Layout) -> None:
        phone, base = layout.objects["phone"], layout.objects["base"]
        add_phone_base(builder, layout.names["base"], base.position, base.yaw, base.color, base.scale)
        add_phone(builder, layout.names["phone"], phone.position, phone.yaw, phone.color, phone.scale)

    def plan_expert(self, sim: SimState | None, layout: Layout) -> MotionPlan:
        phone, base = layout.objects["phone"], layout.objects["base"]
        parts = PhoneParts.of(layout.names["phone"], phone.scale)
        base_parts = PhoneBaseParts.of(layout.names["base"], base.scale)
        if sim is None:
            centre, phone_rotation = np.array([*phone.position[:2], parts.thickness / 2]), rot_z(phone.yaw)
        else:
            centre, phone_rotation = sim.body_position(parts.body), sim.body_rotation(parts.body)
        base_rotation = rot_z(base.yaw)
        grasp_yaw = yaw_along(phone_rotation[:, 1])  # close across the phone's width
        # Turn the phone's long axis onto the recess's: the same relative yaw, mod pi (both are symmetric).
        place_yaw = yaw_along(base_rotation[:, 1], grasp_yaw)
        grasp = centre + np.array([0.0, 0.0, GRASP_ABOVE_CENTRE])
        rim_top = base_parts.plate + base_parts.rim_height
        place = np.array([*base.position[:2], rim_top + 0.005 + parts.thickness / 2 + GRASP_ABOVE_CENTRE])

        plan = MotionPlan(HOME_POSITION, top_down())
        plan.move_to(grasp + np.array([0, 0, 0.08]), top_down(grasp_yaw))
        plan.move_to(grasp, speed=0.12)
        close_gently(plan, 0.0)
        plan.move_to(np.array([*grasp[:2], CARRY_HEIGHT]), speed=0.15)
        plan.move_to(np.array([*place[:2], CARRY_HEIGHT]), top_down(place_yaw), speed=0.2)
        plan.move_to(place, speed=0.1)
        plan.hold(2)
        plan.release()
        plan.retreat(0.10)
        return plan

    def obstacle_region(self, layout: Layout) -> np.ndarray:
        """The carry from above the phone to above the base."""
        return self.nominal_path(layout)[3:5]

    def is_success(self, sim: SimState, layout: Layout) -> bool:
        phone, base = layout.objects["phone"], layout.objects["base"]
        parts = PhoneParts.of(layout.names["phone"], phone.scale)
        base_parts = PhoneBaseParts.of(layout.names["base"], base.scale)
        if sim.held_object() == layout.names["phone"]:
            return False
        rotation = sim.body_rotation(parts.body)
        if abs(rotation[2, 2]) < 0.95 or np.linalg.norm(sim.body_velocity(parts.body)[3:]) > 0.05:
            return False
        inside, local = self.over_recess(sim, layout)
        on_floor = local[2] - parts.thickness / 2 < base_parts.plate + 0.006
        return bool(inside and on_floor)

    def over_recess(self, sim: SimState, layout: Layout) -> tuple[bool, np.ndarray]:
        """Whether the phone's centre is over the base's recess (at any height), and that centre (3,) in
        the base's frame."""
        phone, base = layout.objects["phone"], layout.objects["base"]
        parts = PhoneParts.of(layout.names["phone"], phone.scale)
        base_parts = PhoneBaseParts.of(layout.names["base"], base.scale)
        base_name = base_parts.body
        local = sim.body_rotation(base_name).T @ (sim.body_position(parts.body) - sim.body_position(base_name))
        inside = abs(local[0]) < base_parts.inner_length / 2 and abs(local[1]) < base_parts.inner_width / 2
        return bool(inside), local

    def stage_reached(self, sim: SimState, layout: Layout) -> dict[str, bool]:
        phone = layout.objects["phone"]
        parts = PhoneParts.of(layout.names["phone"], phone.scale)
        centre = sim.body_position(parts.body)
        held = sim.holds(layout.names["phone"])
        return {"reached_phone": sim.tcp_distance(centre) < REACH_TOLERANCE,
                "grasped": held,
                "lifted": held and centre[2] - parts.thickness / 2 >= LIFT_HEIGHT,
                "carried_to_base": self.over_recess(sim, layout)[0],
                "placed": self.is_success(sim, layout)}
