"""open_drawer: pull a drawer open by its handle (RLBench `open_drawer`).

Layout: a one-drawer cabinet (`objects.articulated.add_drawer`) on one side of the table
(centre x in [0.44, 0.54], |y| in [0.14, 0.20]) with its front towards the table's middle,
turned 0.2-0.6 rad towards the camera, so the drawer opens across the table in the camera's
view; the drawer starts closed or up to 2 cm ajar. Instance
variation: scale 0.8 / 1.2 and another colour.

Expert: turn the fingers' closing axis along the pull direction, descend around the handle bar
with the fingers half closed (so they fit between bar and drawer front), close, pull straight
out to 95% of the travel, release and lift.

Success: the drawer is out by at least 60% of its travel (8.4 cm at scale 1).

Stages: reached_handle (TCP within 3 cm of the handle bar's middle), grasped_handle (that, with the
drawer held), pulled (out 2 cm beyond where it started), opened (success).

Differences from RLBench: one drawer instead of three (RLBench picks the bottom, middle or
top one by the instruction), and a free-floating gripper instead of an arm.
"""

from __future__ import annotations

import numpy as np

from lano3dp.sim.experts import CLOSED, MotionPlan
from lano3dp.sim.objects.articulated import DrawerParts, add_drawer
from lano3dp.sim.robot import HOME_POSITION, rot_z, top_down
from lano3dp.sim.tasks import register_task
from lano3dp.sim.tasks.base import REACH_TOLERANCE, Layout, Placement, SimState, Task
from lano3dp.sim.variations import Variation

OPEN_FRACTION = 0.6  # success threshold, fraction of the drawer's travel
DRAWER_COLORS = ("white", "blue", "green", "grey")
# Fingers pre-closed to a 4.4 cm gap before descending: centred on the bar, they then clear the
# drawer front by 1.4 cm and reach the bar together. Fully open (9 cm) and offset outward instead,
# the inner finger met the bar first and rammed the drawer shut before the outer one arrived.
PREGRASP_GRIP = 0.5
PULLED = 0.02  # m beyond the initial opening: the drawer moved under the hand, not by a brush
CLEARANCE_KEY = "drawer_clearance"  # layout entry that only reserves the pulled-out drawer's footprint


def sample_drawer(rng: np.random.Generator, variation: Variation, opening: tuple[float, float],
                  x_range=(0.44, 0.54), y_range=(0.14, 0.20)) -> dict[str, Placement]:
    """Cabinet placement plus a clearance disc over the swept drawer, as layout entries.

    The cabinet stands on one side of the table (|y| in `y_range`) with its front towards the
    middle, turned 0.2-0.6 rad towards the camera (+x): the drawer then opens across the table,
    inside the camera's view, and the approach from the home pose passes beside the cabinet.
    `opening` is the (low, high) range of the initial opening as a fraction of the travel.
    """
    scale = Task.instance_scale(rng, variation)
    color = str(rng.choice(DRAWER_COLORS)) if variation.has("instance") else "brown"
    side = rng.choice([-1.0, 1.0])
    xy = np.array([rng.uniform(*x_range), side * rng.uniform(*y_range)])
    yaw = float(-side * (np.pi / 2 - rng.uniform(0.2, 0.6)))
    parts = DrawerParts.of("drawer", scale)
    start = float(rng.uniform(*opening)) * parts.travel
    cabinet = Placement("drawer", np.array([*xy, 0.0]), yaw, color, scale,
                        float(np.hypot(parts.depth, parts.width)) / 2 + 0.01, {"opening": start})
    # The drawer pulled fully out, its handle and the hand around it: a disc in front of the cabinet.
    reach = parts.handle_x + parts.travel + 0.04
    front = xy + rot_z(yaw)[:2, 0] * (parts.depth / 2 + reach) / 2
    clearance = Placement("clearance", np.array([*front, 0.0]), yaw, color, scale,
                          float(np.hypot((reach - parts.depth / 2) / 2, parts.width / 2)) + 0.01)
    return {"drawer": cabinet, CLEARANCE_KEY: clearance}


def close_gently(plan: MotionPlan, start: float, steps: int = 5, settle: int = 3) -> MotionPlan:
    """Ramp the gripper command from `start` to closed over `steps` control steps, then hold `settle`.

    A step to "closed" drives the fingers at up to ~2 m/s; at the 4 ms physics step they then pass
    through thin parts (the 12 mm handle bar, a bottle neck) before the contact can stop them.
    Ramping the position target keeps the fingers' speed at a few cm per physics step.
    """
    for grip in np.linspace(start, CLOSED, steps + 1)[1:]:
        plan.hold(1, gripper=float(grip))
    return plan.hold(settle, gripper=CLOSED)


def sample_beside(rng: np.random.Generator, objects: dict[str, Placement], radius: float, x_range, y_range,
                  margin: float = 0.05) -> np.ndarray | None:
    """(2,) table position for a loose object of footprint `radius`, clear of every placed footprint
    by `margin` (room for the fingers): preferably on the side of the table (sign of y) opposite the
    drawer within the given ranges, else anywhere in the camera's view of the table; None if the
    drawer leaves no room (the caller samples a new drawer)."""
    side = -np.sign(objects["drawer"].position[1])
    regions = [(np.array([x_range[0], side * y_range[0]]), np.array([x_range[1], side * y_range[1]])),
               (np.array([0.22, -0.30]), np.array([0.64, 0.30]))]
    for low, high in regions:
        for _ in range(300):
            xy = rng.uniform(np.minimum(low, high), np.maximum(low, high))
            if all(np.linalg.norm(xy - p.position[:2]) >= p.radius + radius + margin for p in objects.values()):
                return xy
    return None


def build_drawer(builder, layout: Layout) -> None:
    drawer = layout.objects["drawer"]
    add_drawer(builder, layout.names["drawer"], drawer.position, drawer.yaw, drawer.color, drawer.scale,
               opening=drawer.params["opening"])


def drawer_frame(layout: Layout) -> tuple[DrawerParts, np.ndarray, np.ndarray]:
    """(parts, cabinet origin (3,), cabinet rotation (3, 3)) of the layout's drawer."""
    drawer = layout.objects["drawer"]
    return DrawerParts.of(layout.names["drawer"], drawer.scale), np.asarray(drawer.position, float), rot_z(drawer.yaw)


def drawer_opening(sim: SimState | None, layout: Layout) -> float:
    """Current opening (m): the slide joint's qpos, or the layout's initial opening without a scene."""
    parts, _, _ = drawer_frame(layout)
    return layout.objects["drawer"].params["opening"] if sim is None else sim.joint_qpos(parts.joint)


def approach_clear_of(path_start: np.ndarray, goal: np.ndarray, layout: Layout, margin: float = 0.06) -> np.ndarray:
    """(2, 3) the longest run of the segment path_start -> goal whose xy stays `margin` clear of every
    footprint in the layout (both ends of it if there is none).

    Obstacles stand on the table and the variation rejects spots that touch a footprint, so on an
    approach that ends over an object only the stretch before it can hold one.
    """
    ts = np.linspace(0.0, 1.0, 201)
    points = path_start + ts[:, None] * (goal - path_start)
    clear = np.ones(len(points), bool)
    for centre, radius in layout.footprints():
        clear &= np.linalg.norm(points[:, :2] - centre, axis=1) > radius + margin
    best, run_start = (0, 0), None
    for i, ok in enumerate([*clear, False]):
        if ok and run_start is None:
            run_start = i
        elif not ok and run_start is not None:
            best = max(best, (run_start, i - 1), key=lambda r: r[1] - r[0])
            run_start = None
    return points[[best[0], best[1]]]


@register_task
class OpenDrawer(Task):
    name = "open_drawer"
    skill = "open_drawer"
    object_slots = ("drawer",)
    instruction = "open the {drawer}"
    max_steps = 100
    stages = ("reached_handle", "grasped_handle", "pulled", "opened")
    description = "pull the drawer open"
    verbs = (
        "open", "pull", "slide", "yank", "tug", "pull out", "pull open", "slide out", "slide open", "yank open",
        "draw out",
    )

    def sample_layout(self, rng: np.random.Generator, variation: Variation) -> Layout:
        layout = Layout(seed=0, objects=sample_drawer(rng, variation, opening=(0.0, 0.15)))
        layout.set_names(self.object_slots, variation)
        return layout

    def build(self, builder, layout: Layout) -> None:
        build_drawer(builder, layout)

    def handle_grasp(self, sim: SimState | None, layout: Layout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Grasp position (3,), EE rotation (3, 3) and the pull direction (3,) for the current opening."""
        parts, origin, rotation = drawer_frame(layout)
        pull = rotation[:, 0]
        handle = origin + rotation @ np.array([parts.handle_x + drawer_opening(sim, layout), 0.0, parts.handle_z])
        # Closing axis (EE y = (sin psi, -cos psi, 0)) along the pull direction.
        ee_rotation = top_down(float(np.arctan2(pull[0], -pull[1])))
        return handle, ee_rotation, pull

    def plan_expert(self, sim: SimState | None, layout: Layout) -> MotionPlan:
        parts, _, _ = drawer_frame(layout)
        grasp, rotation, pull = self.handle_grasp(sim, layout)
        out = grasp + pull * max(0.0, 0.95 * parts.travel - drawer_opening(sim, layout))
        plan = MotionPlan(HOME_POSITION, top_down())
        plan.move_to(grasp + np.array([0, 0, 0.10]), rotation, gripper=PREGRASP_GRIP)
        plan.move_to(grasp, speed=0.15)
        close_gently(plan, PREGRASP_GRIP)
        plan.move_to(out, speed=0.12)
        plan.release()
        plan.retreat(0.10)
        return plan

    def obstacle_region(self, layout: Layout) -> np.ndarray:
        """The approach from home to above the handle, where it is not over the cabinet."""
        path = self.nominal_path(layout)
        return approach_clear_of(path[0], path[1], layout)

    def is_success(self, sim: SimState, layout: Layout) -> bool:
        parts, _, _ = drawer_frame(layout)
        return sim.joint_qpos(parts.joint) >= OPEN_FRACTION * parts.travel

    def stage_reached(self, sim: SimState, layout: Layout) -> dict[str, bool]:
        parts, _, _ = drawer_frame(layout)
        at_handle = sim.tcp_distance(sim.site_position(parts.handle_site)) < REACH_TOLERANCE
        pulled = sim.joint_qpos(parts.joint) - layout.objects["drawer"].params["opening"]
        return {"reached_handle": at_handle,
                "grasped_handle": at_handle and sim.holds(layout.names["drawer"]),
                "pulled": pulled >= PULLED,
                "opened": self.is_success(sim, layout)}
