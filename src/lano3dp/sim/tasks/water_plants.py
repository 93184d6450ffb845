"""water_plants: pour water from a watering can onto a potted plant (RLBench `water_plants`, simplified).

Layout: an open watering can (`objects.articulated.add_watering_can`, radius 4.5 cm, 9 cm tall)
holding 4 "water" spheres (r 1.1 cm, 10 g) on one side of the table and a potted plant
(`add_plant`: pot radius 6 cm, soil 4 cm deep, visual-only leaves) on the other side, both at
x in [0.36, 0.56], |y| in [0.11, 0.24], centres at least 0.30 m apart. The can's spout points
towards the plant within +-0.3 rad. Instance variation: the pot scaled 0.8 / 1.2, the can 1.2
(no small can: its inner finger would land on the water), both recoloured.

Expert (as `bowl_pour`): grasp the can's wall opposite the spout top-down with the fingers
part-closed, lift to 0.24 m, carry until the spout-side lip is over the pot, tilt 150 degrees
about the horizontal axis along the grasped wall (the water slides out over the spout-side lip
at about 100 degrees), hold, tilt back.

Success: at least 3 of the 4 water spheres rest in the pot (xy within its radius, below its rim
plus 2 cm, out of the can, slower than 5 cm/s).

Stages: reached_can (TCP within 3 cm of the can's rim), grasped (the can held), lifted (held, its
bottom 3 cm above the table), over_plant (held above the pot's rim, can and pot overlapping seen
from above), tilted (held with its axis more than 60 degrees from vertical), watered (success).

Differences from RLBench: water is 4 rigid spheres instead of particles, it leaves over the rim
on the spout's side (the spout is visual only), and the can is held by its back wall rather than
by a handle.
"""

from __future__ import annotations

import numpy as np

from lano3dp.sim.experts import MotionPlan
from lano3dp.sim.objects import primitives
from lano3dp.sim.objects.articulated import (
    CAN_HEIGHT,
    CAN_RADIUS,
    CAN_WALLS,
    POT_HEIGHT,
    POT_RADIUS,
    add_plant,
    add_watering_can,
)
from lano3dp.sim.robot import HOME_POSITION, rot_axis, top_down
from lano3dp.sim.tasks import register_task
from lano3dp.sim.tasks.base import (
    LIFT_HEIGHT,
    REACH_TOLERANCE,
    TILT_COS,
    Layout,
    Placement,
    SimState,
    Task,
    rim_distance,
)
from lano3dp.sim.tasks.open_drawer import close_gently
from lano3dp.sim.variations import Variation

CARRY_HEIGHT = 0.24
TILT = np.deg2rad(150.0)
POUR_ANGLE = np.deg2rad(100.0)  # tilt at which the water slides over the lip
GRASP_DEPTH = 0.022  # TCP below the rim: the pads cover the upper ~3 cm of the wall
PREGRASP_GRIP = 0.7  # ~2.6 cm between the fingers around the 8 mm wall
N_WATER = 4
MIN_WATERED = 3
CAN_COLORS = ("red", "blue", "yellow", "grey")
POT_COLORS = ("brown", "white", "purple", "pink")


@register_task
class WaterPlants(Task):
    name = "water_plants"
    skill = "water_plants"
    object_slots = ("watering can", "plant")
    instruction = "water the {plant} with the {watering can}"
    max_steps = 150
    similar_slots = ("watering can",)
    stages = ("reached_can", "grasped", "lifted", "over_plant", "tilted", "watered")
    description = "pour water on the plant with the watering can"
    verbs = ("water", "irrigate", "sprinkle", "give water", "pour water")
    # what people water: kinds of plant by name ("water the roses"); a name missing here is avoided, not watered
    synonyms = {"watering can": ("sprinkler", "watering jug"), "plant": (
        "flower", "houseplant", "potted plant", "fern", "succulent", "cactus", "orchid", "herb", "basil", "bonsai",
        "seedling", "sapling", "rose", "tulip", "daisy", "ivy", "sunflower", "geranium", "begonia", "petunia", "pansy",
        "marigold", "lavender", "hydrangea", "azalea", "aloe", "aloe vera", "monstera", "pothos", "bamboo", "mint",
        "rosemary", "thyme", "parsley", "shrub", "bush", "sprout", "vine")}
    carried = "watering can"

    def sample_layout(self, rng: np.random.Generator, variation: Variation) -> Layout:
        instance = variation.has("instance")
        # The can has no small variant: in a 0.8x can (3.6 cm radius) the inner finger of the wall grasp
        # reaches the middle and lands on the 2.2 cm water spheres (15/100 episodes failed).
        can_scale = 1.2 if instance else 1.0
        pot_scale = self.instance_scale(rng, variation)
        can_color = str(rng.choice(CAN_COLORS)) if instance else "green"
        pot_color = str(rng.choice(POT_COLORS)) if instance else "orange"
        side = rng.choice([-1.0, 1.0])
        while True:
            can_xy = np.array([rng.uniform(0.36, 0.56), side * rng.uniform(0.11, 0.24)])
            pot_xy = np.array([rng.uniform(0.36, 0.56), -side * rng.uniform(0.11, 0.24)])
            if np.linalg.norm(can_xy - pot_xy) >= 0.30:
                break
        towards = pot_xy - can_xy
        can_yaw = float(np.arctan2(towards[1], towards[0]) + rng.uniform(-0.3, 0.3))
        objects = {
            "watering can": Placement("watering can", np.array([*can_xy, 0.0]), can_yaw, can_color, can_scale,
                                      (CAN_RADIUS + 0.07) * can_scale),
            "plant": Placement("plant", np.array([*pot_xy, 0.0]), float(rng.uniform(-np.pi, np.pi)), pot_color,
                               pot_scale, POT_RADIUS * pot_scale + 0.02),
        }
        # Water on the spout side of the can, clear of the inner finger at the back wall.
        spout = np.array([np.cos(can_yaw), np.sin(can_yaw)])
        centre = can_xy + spout * 0.012 * can_scale
        start = rng.uniform(0, 2 * np.pi)
        for i in range(N_WATER):
            angle = start + 2 * np.pi * i / N_WATER
            xy = centre + 0.016 * np.array([np.cos(angle), np.sin(angle)])
            objects[f"water{i}"] = Placement("item", np.array([*xy, 0.008 + 0.012]), 0.0,
                                             str(rng.choice(["cyan", "blue"])), 1.0, 0.0)
        layout = Layout(seed=0, objects=objects)
        layout.set_names(self.object_slots, variation)
        return layout

    def build(self, builder, layout: Layout) -> None:
        can, pot = layout.objects["watering can"], layout.objects["plant"]
        add_watering_can(builder, layout.names["watering can"], can.position, can.yaw, can.color, can.scale)
        add_plant(builder, layout.names["plant"], pot.position, pot.yaw, pot.color, pot.scale)
        for key, water in layout.objects.items():
            if water.kind == "item":
                primitives.add_item(builder, key, water.position, "sphere", water.color)

    def grasp_frame(self, layout: Layout, can_xy=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Grasp position (3,), EE rotation (3, 3) and the grasped wall's outward normal u (3,)."""
        can = layout.objects["watering can"]
        can_xy = can.position[:2] if can_xy is None else can_xy
        step = 2 * np.pi / CAN_WALLS
        wall_angle = can.yaw + np.pi  # the wall opposite the spout (wall 6 of 12)
        wall_angle = can.yaw + step * np.round((wall_angle - can.yaw) / step)
        u = np.array([np.cos(wall_angle), np.sin(wall_angle), 0.0])
        radius, height = CAN_RADIUS * can.scale, CAN_HEIGHT * can.scale
        position = np.array([*(can_xy + radius * u[:2]), height - GRASP_DEPTH])
        return position, top_down(float(np.arctan2(u[0], -u[1]))), u

    def plan_expert(self, sim: SimState | None, layout: Layout) -> MotionPlan:
        can_xy = None if sim is None else sim.body_position(layout.names["watering can"])[:2]
        grasp, rotation, u = self.grasp_frame(layout, can_xy)
        can, pot = layout.objects["watering can"], layout.objects["plant"]
        radius, height = CAN_RADIUS * can.scale, CAN_HEIGHT * can.scale
        axis = np.cross(u, [0.0, 0.0, 1.0])  # tilting about it lowers the far (spout-side) lip
        lip = -2 * radius * u + np.array([0.0, 0.0, GRASP_DEPTH])  # spout-side lip relative to the TCP
        lip_target = np.array([*pot.position[:2], POT_HEIGHT * pot.scale + 0.07])
        pour_tcp = lip_target - rot_axis(axis, POUR_ANGLE) @ lip
        carry = np.array([*pour_tcp[:2], max(CARRY_HEIGHT, pour_tcp[2], height + 0.15)])

        plan = MotionPlan(HOME_POSITION, top_down())
        plan.move_to(grasp + np.array([0, 0, 0.10]), rotation, gripper=PREGRASP_GRIP)
        plan.move_to(grasp, speed=0.15)
        close_gently(plan, PREGRASP_GRIP)
        plan.move_to(np.array([*grasp[:2], carry[2]]), speed=0.15)
        plan.move_to(carry, speed=0.2)
        plan.move_to(pour_tcp, rot_axis(axis, TILT) @ rotation)
        plan.hold(12)
        plan.move_to(carry, rotation)
        plan.hold(10)
        return plan

    def obstacle_region(self, layout: Layout) -> np.ndarray:
        """The carry from above the grasp (after the lift) to above the pour point."""
        return self.nominal_path(layout)[3:5]

    def is_success(self, sim: SimState, layout: Layout) -> bool:
        can, pot = layout.objects["watering can"], layout.objects["plant"]
        pot_xy = sim.body_position(layout.names["plant"])[:2]
        can_position = sim.body_position(layout.names["watering can"])
        can_rotation = sim.body_rotation(layout.names["watering can"])
        watered = 0
        for key, water in layout.objects.items():
            if water.kind != "item":
                continue
            position = sim.body_position(key)
            in_pot = (np.linalg.norm(position[:2] - pot_xy) < POT_RADIUS * pot.scale
                      and position[2] < POT_HEIGHT * pot.scale + 0.02)
            local = can_rotation.T @ (position - can_position)
            in_can = np.linalg.norm(local[:2]) < CAN_RADIUS * can.scale and -0.01 < local[2] < CAN_HEIGHT * can.scale
            resting = np.linalg.norm(sim.body_velocity(key)[3:]) < 0.05
            watered += bool(in_pot and not in_can and resting)
        return watered >= MIN_WATERED

    def stage_reached(self, sim: SimState, layout: Layout) -> dict[str, bool]:
        can, pot = layout.objects["watering can"], layout.objects["plant"]
        name = layout.names["watering can"]
        position, axis = sim.body_position(name), sim.body_rotation(name)[:, 2]
        held = sim.holds(name)
        apart = np.linalg.norm(position[:2] - sim.body_position(layout.names["plant"])[:2])
        rim = rim_distance(sim, name, CAN_RADIUS * can.scale, CAN_HEIGHT * can.scale)
        return {"reached_can": rim < REACH_TOLERANCE,
                "grasped": held,
                "lifted": held and position[2] >= LIFT_HEIGHT,
                "over_plant": held and position[2] > POT_HEIGHT * pot.scale
                and apart < (POT_RADIUS * pot.scale + CAN_RADIUS * can.scale),
                "tilted": held and axis[2] < TILT_COS,
                "watered": self.is_success(sim, layout)}

