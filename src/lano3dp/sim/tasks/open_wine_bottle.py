"""open_wine_bottle: take the cap off a wine bottle (RLBench `open_wine_bottle`, simplified).

Layout: a 1 kg wine bottle (`objects.articulated.add_wine_bottle`, 29 cm tall at scale 1)
standing upright at x in [0.36, 0.56], y in [-0.2, 0.2]; its cap sits on the neck, held by 3 N
of friction on a slide joint along the bottle's axis. Instance variation: the bottle scaled
0.8 / 1.2 (the cap keeps its size) and recoloured.

Expert: top-down over the cap with the fingers part-closed, descend until the fingertips are
2 mm above the cap's lower edge, close gently, pull straight up 5 cm, release, retreat.

Success: the cap is at least 3 cm up the neck (it is off the bottle: it overlaps the neck by
1 cm when on) and the bottle still stands upright.

Stages: reached_cap (TCP within 3 cm of the cap's centre), grasped_cap (the cap itself held),
pulled (the cap 1 cm up the neck), opened (success).

Differences from RLBench: RLBench's cap is unscrewed (a twist of the wrist, then a lift); here
it comes off with a straight pull, like a cork. The skill is still "grasp a small part of an
object that must stay put and move it relative to the rest".
"""

from __future__ import annotations

import numpy as np

from lano3dp.sim.experts import MotionPlan
from lano3dp.sim.objects.articulated import WineBottleParts, add_wine_bottle
from lano3dp.sim.robot import HOME_POSITION, top_down
from lano3dp.sim.tasks import register_task
from lano3dp.sim.tasks.base import REACH_TOLERANCE, Layout, Placement, SimState, Task
from lano3dp.sim.tasks.open_drawer import close_gently
from lano3dp.sim.variations import Variation

OFF_HEIGHT = 0.03  # m the cap must have moved up the neck
PULL = 0.05  # m the expert pulls
PREGRASP_GRIP = 0.35  # ~5.8 cm between the fingers around the 3.2 cm cap
PULLED = 0.01  # m up the neck: the cap moved, but is still on
BOTTLE_COLORS = ("red", "blue", "brown", "purple")


@register_task
class OpenWineBottle(Task):
    name = "open_wine_bottle"
    skill = "open_wine_bottle"
    object_slots = ("bottle",)
    instruction = "open the {bottle}"
    max_steps = 90
    stages = ("reached_cap", "grasped_cap", "pulled", "opened")
    description = "take the cork or cap off the wine bottle"
    verbs = (
        "open", "uncork", "uncap", "unscrew", "pop", "decork", "remove", "pop open", "twist off", "twist open",
        "pull out", "take off", "pull off",
    )
    synonyms = {"bottle": ("wine bottle", "wine")}

    def sample_layout(self, rng: np.random.Generator, variation: Variation) -> Layout:
        scale = self.instance_scale(rng, variation)
        color = str(rng.choice(BOTTLE_COLORS)) if variation.has("instance") else "green"
        xy = rng.uniform([0.36, -0.2], [0.56, 0.2])
        parts = WineBottleParts.of("bottle", scale)
        bottle = Placement("bottle", np.array([*xy, 0.0]), float(rng.uniform(-np.pi, np.pi)), color, scale,
                           parts.radius + 0.03)
        layout = Layout(seed=0, objects={"bottle": bottle})
        layout.set_names(self.object_slots, variation)
        return layout

    def build(self, builder, layout: Layout) -> None:
        bottle = layout.objects["bottle"]
        add_wine_bottle(builder, layout.names["bottle"], bottle.position, bottle.yaw, bottle.color, bottle.scale)

    def plan_expert(self, sim: SimState | None, layout: Layout) -> MotionPlan:
        bottle = layout.objects["bottle"]
        parts = WineBottleParts.of(layout.names["bottle"], bottle.scale)
        if sim is None:
            cap_bottom = np.array([*bottle.position[:2], parts.cap_bottom])
        else:
            cap_bottom = sim.body_position(parts.cap) - np.array([0.0, 0.0, parts.cap_half])
        # Fingertips (1 cm below the TCP) 2 mm above the cap's lower edge: the pads hold the cap only.
        grasp = cap_bottom + np.array([0.0, 0.0, 0.012])
        rotation = top_down(float(bottle.yaw) % np.pi - np.pi / 2)
        plan = MotionPlan(HOME_POSITION, top_down())
        plan.move_to(grasp + np.array([0, 0, 0.08]), rotation, gripper=PREGRASP_GRIP)
        plan.move_to(grasp, speed=0.12)
        close_gently(plan, PREGRASP_GRIP)
        plan.move_to(grasp + np.array([0, 0, PULL]), speed=0.06)
        plan.release()
        plan.retreat(0.08)
        return plan

    def obstacle_region(self, layout: Layout) -> np.ndarray:
        """The approach from home to above the cap (the only transport in this task)."""
        return self.nominal_path(layout)[:2]

    def is_success(self, sim: SimState, layout: Layout) -> bool:
        parts = WineBottleParts.of(layout.names["bottle"], layout.objects["bottle"].scale)
        upright = sim.body_rotation(parts.body)[2, 2] > 0.95
        return bool(upright and sim.joint_qpos(parts.joint) >= OFF_HEIGHT)

    def stage_reached(self, sim: SimState, layout: Layout) -> dict[str, bool]:
        parts = WineBottleParts.of(layout.names["bottle"], layout.objects["bottle"].scale)
        return {"reached_cap": sim.tcp_distance(sim.body_position(parts.cap)) < REACH_TOLERANCE,
                "grasped_cap": sim.holds(parts.cap),
                "pulled": sim.joint_qpos(parts.joint) >= PULLED,
                "opened": self.is_success(sim, layout)}
