"""bowl_pour: grasp a bowl holding a few small items and pour them into a pan.

Layout: the bowl on the robot's left (y in [0.08, 0.22]), the pan on its right (y in
[-0.25, -0.11]), x in [0.36, 0.56], centres at least 0.30 m apart; 3 items (spheres or
cubes, 10 g) sit in the bowl's half that faces the pan. Instance variation: bowl and pan
scaled 0.8 / 1.2 and recoloured, the bowl 0.8x shallower or 1.3x deeper.

Expert: grasp the bowl wall on the side away from the pan (top-down, fingers straddling the
wall, opened only part-way so the inner finger clears the items), lift to 0.22 m, carry the
bowl until its far lip is over the pan, tilt it 150 degrees about the horizontal axis
tangent to the grasped wall, hold, tilt back.

Success: every item is inside the pan (xy within the pan's radius, at most 2 cm above its rim
as items may stack, not rising faster than 5 cm/s) and none is still inside the bowl.

Stages: reached_bowl (TCP within 3 cm of the bowl's rim), grasped (the bowl held), lifted (held, its
bottom 3 cm above the table), over_pan (held above the pan's rim, bowl and pan overlapping seen from
above), tilted (held with its axis more than 60 degrees from vertical), poured (success).
"""

from __future__ import annotations

import numpy as np

from lano3dp.sim.experts import CLOSED, MotionPlan
from lano3dp.sim.objects import primitives
from lano3dp.sim.objects.primitives import BOWL_HEIGHT, BOWL_RADIUS, BOWL_WALLS, PAN_RADIUS, PAN_WALL_HEIGHT
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
from lano3dp.sim.variations import Variation

CARRY_HEIGHT = 0.24
TILT = np.deg2rad(150.0)
POUR_ANGLE = np.deg2rad(100.0)  # tilt at which the items slide over the lip
GRASP_DEPTH = 0.022  # TCP below the rim: the pads cover the upper ~3 cm of the wall
PREGRASP_GRIP = 0.7  # partly closed: ~2.6 cm between the fingers, enough for the 8 mm wall
ITEM_COLORS = ("yellow", "orange", "red", "green", "purple")


def bowl_height(bowl: Placement) -> float:
    """Wall height of the bowl placement, metres."""
    return BOWL_HEIGHT * bowl.scale * bowl.params.get("height_scale", 1.0)


@register_task
class BowlPour(Task):
    name = "bowl_pour"
    skill = "bowl_pour"  # the language skill registry names skills after their task
    object_slots = ("bowl", "pan")
    instruction = "pour the contents of the {bowl} into the {pan}"
    max_steps = 220
    similar_slots = ("bowl",)
    stages = ("reached_bowl", "grasped", "lifted", "over_pan", "tilted", "poured")
    description = "grasp the bowl and pour its contents into the pan"
    verbs = (
        "pour", "empty", "dump", "tip", "decant", "tilt", "fill", "transfer", "spill", "drain", "tip into", "tip out",
        "pour out", "empty out", "tip over",
    )
    synonyms = {"bowl": ("dish", "basin"), "pan": ("frying pan", "skillet", "pot", "saucepan", "wok")}
    carried = "bowl"
    n_items = 3
    reliable_from_mujoco = (4, 0)
    simulator_note = ("the cube items sink through the bowl's base when the grasp turns the bowl, so the expert and "
                      "policies fail")

    def sample_layout(self, rng: np.random.Generator, variation: Variation) -> Layout:
        instance = variation.has("instance")
        bowl_scale, pan_scale = self.instance_scale(rng, variation), self.instance_scale(rng, variation)
        bowl_color = str(rng.choice(["white", "cyan", "pink"])) if instance else "blue"
        bowl_depth = float(rng.choice([0.8, 1.3])) if instance else 1.0  # shape variant: shallow / deep
        pan_color = str(rng.choice(["grey", "brown", "red"])) if instance else "black"
        while True:
            bowl_xy = rng.uniform([0.36, 0.08], [0.56, 0.22])
            pan_xy = rng.uniform([0.36, -0.25], [0.56, -0.11])
            if np.linalg.norm(bowl_xy - pan_xy) >= 0.30:
                break
        bowl_yaw = float(rng.uniform(0, 2 * np.pi / BOWL_WALLS))
        pan_yaw = float(np.pi / 2 + rng.uniform(-0.4, 0.4))  # handle pointing away from the bowl
        objects = {
            "bowl": Placement("bowl", np.array([*bowl_xy, 0.0]), bowl_yaw, bowl_color, bowl_scale,
                              primitives.FOOTPRINTS["bowl"] * bowl_scale, {"height_scale": bowl_depth}),
            "pan": Placement("pan", np.array([*pan_xy, 0.0]), pan_yaw, pan_color, pan_scale,
                             primitives.FOOTPRINTS["pan"] * pan_scale),
        }
        handle_direction = -np.array([np.cos(pan_yaw), np.sin(pan_yaw)])  # the handle is along local -x
        keepout = [(pan_xy + handle_direction * (PAN_RADIUS + 0.06) * pan_scale, 0.07 * pan_scale)]
        # Items in the bowl half that faces the pan, clear of the inner finger.
        towards_pan = (pan_xy - bowl_xy) / np.linalg.norm(pan_xy - bowl_xy)
        centre = bowl_xy + towards_pan * 0.012 * bowl_scale
        start_angle = rng.uniform(0, 2 * np.pi)
        for i in range(self.n_items):
            angle = start_angle + 2 * np.pi * i / self.n_items
            xy = centre + 0.016 * np.array([np.cos(angle), np.sin(angle)])
            shape = str(rng.choice(["sphere", "cube"]))
            objects[f"item{i}"] = Placement("item", np.array([*xy, 0.008 + 0.012]), 0.0,
                                            str(rng.choice(ITEM_COLORS)), 1.0, 0.0, {"shape": shape})
        layout = Layout(seed=0, objects=objects, keepout=keepout)
        layout.set_names(self.object_slots, variation)
        return layout

    def build(self, builder, layout: Layout) -> None:
        bowl, pan = layout.objects["bowl"], layout.objects["pan"]
        primitives.add_bowl(builder, layout.names["bowl"], bowl.position, bowl.yaw, bowl.color, bowl.scale,
                            height_scale=bowl.params.get("height_scale", 1.0))
        primitives.add_pan(builder, layout.names["pan"], pan.position, pan.yaw, pan.color, pan.scale)
        for key, item in layout.objects.items():
            if item.kind == "item":
                primitives.add_item(builder, key, item.position, item.params["shape"], item.color)

    # ---- expert ----------------------------------------------------------------------------
    def grasp_frame(self, layout: Layout, bowl_xy=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Grasp position (3,), EE rotation (3, 3) and the outward wall direction u (3,)."""
        bowl, pan = layout.objects["bowl"], layout.objects["pan"]
        bowl_xy = bowl.position[:2] if bowl_xy is None else bowl_xy
        away = bowl_xy - pan.position[:2]
        desired = np.arctan2(away[1], away[0])
        step = 2 * np.pi / BOWL_WALLS
        wall_angle = bowl.yaw + step * np.round((desired - bowl.yaw) / step)
        u = np.array([np.cos(wall_angle), np.sin(wall_angle), 0.0])
        radius, height = BOWL_RADIUS * bowl.scale, bowl_height(bowl)
        position = np.array([*(bowl_xy + radius * u[:2]), height - GRASP_DEPTH])
        # EE y (finger axis) along u: top_down(yaw)[:, 1] = (sin yaw, -cos yaw, 0).
        rotation = top_down(np.arctan2(u[0], -u[1]))
        return position, rotation, u

    def plan_expert(self, sim: SimState | None, layout: Layout) -> MotionPlan:
        bowl_xy = None if sim is None else sim.body_position(layout.names["bowl"])[:2]
        grasp, rotation, u = self.grasp_frame(layout, bowl_xy)
        pan = layout.objects["pan"]
        radius = BOWL_RADIUS * layout.objects["bowl"].scale
        axis = np.cross(u, [0.0, 0.0, 1.0])  # tilting about it lowers the far (pan-side) lip
        tilt = rot_axis(axis, TILT)
        lip = -2 * radius * u + np.array([0, 0, 0.012])  # far lip relative to the TCP
        # Items leave the bowl at about POUR_ANGLE: put the lip above the pan centre at that angle.
        lip_target = np.array([*pan.position[:2], PAN_WALL_HEIGHT + 0.07])
        pour_tcp = lip_target - rot_axis(axis, POUR_ANGLE) @ lip
        carry = np.array([*pour_tcp[:2], max(CARRY_HEIGHT, pour_tcp[2])])

        plan = MotionPlan(HOME_POSITION, top_down())
        plan.move_to(grasp + np.array([0, 0, 0.10]), rotation, gripper=PREGRASP_GRIP)
        plan.move_to(grasp, speed=0.15)
        plan.hold(6, gripper=CLOSED)
        plan.move_to(np.array([*grasp[:2], CARRY_HEIGHT]), speed=0.15)
        plan.move_to(carry, speed=0.2)
        plan.move_to(pour_tcp, tilt @ rotation)
        plan.hold(12)
        plan.move_to(carry, rotation)
        plan.hold(10)
        return plan

    def obstacle_region(self, layout: Layout) -> np.ndarray:
        """The transport segment: from above the grasp (after the lift) to above the pour point."""
        path = self.nominal_path(layout)  # home, above grasp, grasp, (close), lift, carry, ...
        return path[4:6]

    # ---- success ---------------------------------------------------------------------------
    def is_success(self, sim: SimState, layout: Layout) -> bool:
        pan, bowl = layout.objects["pan"], layout.objects["bowl"]
        pan_xy = sim.body_position(layout.names["pan"])[:2]
        bowl_position = sim.body_position(layout.names["bowl"])
        bowl_rotation = sim.body_rotation(layout.names["bowl"])
        inner = PAN_RADIUS * pan.scale  # the walls keep resting items inside; z below the rim confirms it
        for key, item in layout.objects.items():
            if item.kind != "item":
                continue
            position = sim.body_position(key)
            # Inside the walls and at most one item height above the rim (items may stack).
            if np.linalg.norm(position[:2] - pan_xy) > inner or position[2] > PAN_WALL_HEIGHT + 0.02:
                return False
            # Still inside the bowl (e.g. the bowl was dropped into the pan) does not count.
            local = bowl_rotation.T @ (position - bowl_position)
            if np.linalg.norm(local[:2]) < BOWL_RADIUS * bowl.scale and -0.01 < local[2] < bowl_height(bowl):
                return False
            if sim.body_velocity(key)[5] > 0.05:  # still bouncing up
                return False
        return True

    def stage_reached(self, sim: SimState, layout: Layout) -> dict[str, bool]:
        bowl, pan = layout.objects["bowl"], layout.objects["pan"]
        name = layout.names["bowl"]
        position, axis = sim.body_position(name), sim.body_rotation(name)[:, 2]
        held = sim.holds(name)
        apart = np.linalg.norm(position[:2] - sim.body_position(layout.names["pan"])[:2])
        return {"reached_bowl": rim_distance(sim, name, BOWL_RADIUS * bowl.scale, bowl_height(bowl)) < REACH_TOLERANCE,
                "grasped": held,
                "lifted": held and position[2] >= LIFT_HEIGHT,
                "over_pan": held and position[2] > PAN_WALL_HEIGHT
                and apart < (PAN_RADIUS * pan.scale + BOWL_RADIUS * bowl.scale),
                "tilted": held and axis[2] < TILT_COS,
                "poured": self.is_success(sim, layout)}
