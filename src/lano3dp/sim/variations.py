"""Generalisation axes, selectable per episode and combinable.

    clean       the training distribution: only the task's objects, default colours and camera
    clutter     distractor objects of other kinds on the table
    similar     extra instances of the target kinds in other colours; targets are then named by colour
                ("blue_bowl") and the instruction phrase says the colour ("blue bowl")
    instance    size / shape variants of the task objects (scale 0.8 "small" or 1.2 "large", other colours)
    camera      the shifted camera pose (never used for training data)
    background  table, floor and sky colours and a checker table texture
    obstacle    static cylinders standing on or near the expert's path (never in training data)

`Variation.parse("clutter+camera")` (also "," separated, or an iterable of names) builds one.
Extras (distractors, similar instances, obstacles, style) are sampled here from the episode's
generator after the task's own layout, avoiding the task objects' footprints and, for
distractors, the expert's path corridor, so a variation never makes the expert's task impossible
(obstacles excepted: they are meant to be in the way).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from lano3dp.errors import Lano3dpError
from lano3dp.sim.objects import PALETTE
from lano3dp.sim.objects.primitives import FOOTPRINTS
from lano3dp.sim.robot import GRIPPER_FOOTPRINT_RADIUS, HOME_POSITION
from lano3dp.sim.scene import FRONT_CAMERA, SHIFTED_CAMERA, CameraPose, SceneStyle

VARIATION_AXES = ("clutter", "similar", "instance", "camera", "background", "obstacle")
DISTRACTOR_KINDS = ("mug", "cube", "plate", "can", "ball", "bowl", "bottle")
# Where loose objects may be placed (x, y), metres, world frame; all of it is in the front camera's view.
PLACEMENT_LOW = np.array([0.22, -0.36])
PLACEMENT_HIGH = np.array([0.64, 0.36])
# Free xy distance (m) between an obstacle and the gripper's footprint at its start pose: room to steer round.
START_CLEARANCE = 0.01


class VariationError(Lano3dpError, ValueError):
    """An unknown variation axis was asked for."""


OBSTACLE_KINDS = ("cylinder", "box", "cluster")
MOVING_SPEED = 0.04  # m/s, the peak speed of a moving obstacle (the bound is 5 cm/s)
MOVING_AMPLITUDE = 0.06  # m, how far a moving obstacle swings either side of its spot on the path


@dataclass(frozen=True)
class Variation:
    """A set of variation axes plus how many extra objects each adds.

    The obstacle axis takes modifiers after colons: "obstacle:2" (two obstacles), "obstacle:box" (an upright
    box), "obstacle:cluster" (two cylinders side by side, too close for the hand to pass between),
    "obstacle:moving" (it swings across the path at up to MOVING_SPEED); e.g. "obstacle:box:moving".
    """

    axes: frozenset[str] = frozenset()
    n_distractors: tuple[int, int] = (2, 4)  # inclusive range
    n_similar: int = 2
    n_obstacles: int = 1
    obstacle_kind: str = "cylinder"
    obstacle_speed: float = 0.0

    def __post_init__(self):
        unknown = set(self.axes) - set(VARIATION_AXES)
        if unknown:
            raise VariationError(f"unknown variation axes {sorted(unknown)}; known: clean, {', '.join(VARIATION_AXES)}")
        if self.obstacle_kind not in OBSTACLE_KINDS:
            raise VariationError(f"unknown obstacle kind {self.obstacle_kind!r}; known: {', '.join(OBSTACLE_KINDS)}")
        if self.n_obstacles < 1 or not 0 <= self.obstacle_speed <= 0.05:
            raise VariationError(f"need n_obstacles >= 1 and an obstacle speed of 0-0.05 m/s, got "
                                 f"{self.n_obstacles}, {self.obstacle_speed}")
        object.__setattr__(self, "axes", frozenset(self.axes))

    @classmethod
    def parse(cls, value: str | Iterable[str] | Variation | None) -> Variation:
        if isinstance(value, Variation):
            return value
        if value is None:
            return cls()
        if isinstance(value, str):
            value = value.replace(",", "+").split("+")
        names = {v.strip().lower() for v in value if v.strip()} - {"clean", "none"}
        options: dict = {}
        for name in [n for n in names if n.startswith("obstacle:")]:
            names.discard(name)
            names.add("obstacle")
            for modifier in name.split(":")[1:]:
                if modifier.isdigit():
                    options["n_obstacles"] = int(modifier)
                elif modifier in OBSTACLE_KINDS:
                    options["obstacle_kind"] = modifier
                elif modifier == "moving":
                    options["obstacle_speed"] = MOVING_SPEED
                else:
                    raise VariationError(f"unknown obstacle modifier {modifier!r} in {name!r}; use a count, "
                                         f"{', '.join(OBSTACLE_KINDS)} or moving (e.g. obstacle:box:moving)")
        return cls(frozenset(names), **options)

    def has(self, axis: str) -> bool:
        if axis not in VARIATION_AXES:
            raise VariationError(f"unknown variation axis {axis!r}; known: {', '.join(VARIATION_AXES)}")
        return axis in self.axes

    @property
    def name(self) -> str:
        return "+".join(self._axis_name(a) for a in VARIATION_AXES if a in self.axes) or "clean"

    def _axis_name(self, axis: str) -> str:
        if axis != "obstacle":
            return axis
        modifiers = ([str(self.n_obstacles)] if self.n_obstacles > 1 else []) + (
            [self.obstacle_kind] if self.obstacle_kind != "cylinder" else []) + (
            ["moving"] if self.obstacle_speed > 0 else [])
        return ":".join(["obstacle", *modifiers])

    def __str__(self) -> str:
        return self.name


@dataclass
class ExtraObject:
    """An object a variation adds: built with `primitives.add_object` (or as an obstacle cylinder)."""

    name: str
    kind: str
    position: np.ndarray
    yaw: float
    color: str
    scale: float = 1.0
    role: str = "distractor"
    radius: float = 0.03  # obstacles: cylinder radius (a box's: its footprint's circumradius)
    height: float = 0.3   # obstacles: cylinder height
    half_extents: tuple[float, float] | None = None  # box obstacles: xy half sizes (yaw above)
    # moving obstacles: (unit direction (2,), amplitude m, angular frequency rad/s, phase rad) of the swing
    # xy(t) = position + direction * amplitude * sin(omega * t + phase)
    motion: tuple[np.ndarray, float, float, float] | None = None

    def position_at(self, time_s: float) -> np.ndarray:
        if self.motion is None:
            return np.asarray(self.position)
        direction, amplitude, omega, phase = self.motion
        position = np.array(self.position, dtype=float)
        position[:2] += direction * amplitude * np.sin(omega * time_s + phase)
        return position


@dataclass
class SceneExtras:
    style: SceneStyle = field(default_factory=SceneStyle)
    camera: CameraPose = FRONT_CAMERA
    objects: list[ExtraObject] = field(default_factory=list)


# ---- placement ------------------------------------------------------------------------------
def distance_to_polyline(point_xy: np.ndarray, path_xy: np.ndarray) -> float:
    """Smallest distance from a point (2,) to a polyline (M, 2), metres."""
    if len(path_xy) == 1:
        return float(np.linalg.norm(point_xy - path_xy[0]))
    a, b = path_xy[:-1], path_xy[1:]
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", point_xy - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12), 0, 1)
    closest = a + t[:, None] * ab
    return float(np.min(np.linalg.norm(point_xy - closest, axis=1)))


def sample_free_xy(rng: np.random.Generator, footprints: list[tuple[np.ndarray, float]], radius: float,
                   low=PLACEMENT_LOW, high=PLACEMENT_HIGH, corridor: np.ndarray | None = None,
                   corridor_width: float = 0.0, margin: float = 0.01, tries: int = 200) -> np.ndarray | None:
    """Rejection-sample an (x, y) whose disc of `radius` clears every footprint disc (and the corridor).

    Returns None when no free spot was found in `tries` draws (the caller skips that object).
    """
    low, high = np.asarray(low, float) + radius, np.asarray(high, float) - radius
    for _ in range(tries):
        xy = rng.uniform(low, high)
        if any(np.linalg.norm(xy - c) < r + radius + margin for c, r in footprints):
            continue
        if corridor is not None and distance_to_polyline(xy, corridor) < corridor_width + radius:
            continue
        return xy
    return None


# ---- background -----------------------------------------------------------------------------
_TABLE_COLOURS = [(0.30, 0.45, 0.62), (0.78, 0.78, 0.74), (0.25, 0.25, 0.27), (0.55, 0.65, 0.45), (0.72, 0.36, 0.30)]
_FLOOR_COLOURS = [(0.6, 0.55, 0.45), (0.2, 0.3, 0.25), (0.75, 0.75, 0.8), (0.3, 0.2, 0.2)]
_SKIES = [((0.9, 0.8, 0.6), (0.4, 0.3, 0.2)), ((0.3, 0.3, 0.35), (0.05, 0.05, 0.08)),
          ((0.6, 0.85, 0.6), (0.1, 0.3, 0.1))]


def sample_style(rng: np.random.Generator) -> SceneStyle:
    table = _TABLE_COLOURS[rng.integers(len(_TABLE_COLOURS))]
    checker = None
    if rng.random() < 0.5:
        checker = tuple(float(c) for c in np.clip(np.array(table) * rng.uniform(0.5, 0.8), 0, 1)) + (1.0,)
    return SceneStyle(
        table_rgba=(*table, 1.0),
        table_texture_rgba=checker,
        floor_rgba=(*_FLOOR_COLOURS[rng.integers(len(_FLOOR_COLOURS))], 1.0),
        sky_rgb=_SKIES[rng.integers(len(_SKIES))],
        light_diffuse=float(rng.uniform(0.5, 0.9)),
    )


def other_colors(exclude: Iterable[str]) -> list[str]:
    exclude = set(exclude)
    return [c for c in PALETTE if c not in exclude]


def sample_extras(task, layout, rng: np.random.Generator, variation: Variation) -> SceneExtras:
    """Everything the variation adds on top of the task layout. `task` is a `tasks.base.Task`."""
    extras = SceneExtras()
    if variation.has("background"):
        extras.style = sample_style(rng)
    if variation.has("camera"):
        extras.camera = SHIFTED_CAMERA
    footprints = layout.footprints()
    path = task.nominal_path(layout)
    corridor = path[:, :2]
    used_colors = {p.color for p in layout.objects.values()}
    # Obstacles first: they must sit on the path, and the other extras then keep clear of them.
    if variation.has("obstacle"):
        extras.objects.extend(sample_obstacles(task, layout, rng, variation.n_obstacles, footprints,
                                               kind=variation.obstacle_kind, speed=variation.obstacle_speed))
    if variation.has("similar"):
        for slot in task.similar_slots:
            target = layout.objects[slot]
            colors = other_colors(used_colors | {"black", "grey"})
            rng.shuffle(colors)
            radius = FOOTPRINTS.get(target.kind, target.radius / max(target.scale, 1e-6)) * target.scale
            for color in colors[: variation.n_similar]:
                xy = sample_free_xy(rng, footprints, radius, corridor=corridor, corridor_width=0.05)
                if xy is None:
                    continue
                used_colors.add(color)
                footprints.append((xy, radius))
                extras.objects.append(ExtraObject(f"{color}_{target.kind}", target.kind, xy,
                                                  float(rng.uniform(-np.pi, np.pi)), color, target.scale, "similar"))
    if variation.has("clutter"):
        task_kinds = {p.kind for p in layout.objects.values()}
        kinds = [k for k in DISTRACTOR_KINDS if k not in task_kinds]
        count = int(rng.integers(variation.n_distractors[0], variation.n_distractors[1] + 1))
        for i in range(count):
            kind = kinds[rng.integers(len(kinds))]
            radius = FOOTPRINTS[kind]
            xy = sample_free_xy(rng, footprints, radius, corridor=corridor, corridor_width=0.05)
            if xy is None:
                continue
            footprints.append((xy, radius))
            color = other_colors(used_colors)[rng.integers(len(other_colors(used_colors)))]
            extras.objects.append(ExtraObject(f"distractor_{kind}_{i}", kind, xy, float(rng.uniform(-np.pi, np.pi)),
                                              color, 1.0, "distractor"))
    return extras


def sample_obstacles(task, layout, rng: np.random.Generator, count: int,
                     footprints: list[tuple[np.ndarray, float]], *, kind: str = "cylinder",
                     speed: float = 0.0) -> list[ExtraObject]:
    """Obstacles standing on the expert's path, clear of every object footprint by 1.5 cm.

    First within 2 cm of the task's `obstacle_region` (its transport segment); where that has no
    free spot (e.g. a task whose path only rises and falls over its objects), within 5 cm of any
    segment of the nominal path. Fewer than `count` obstacles are returned when neither has room.
    No obstacle comes within START_CLEARANCE of the gripper at its start pose: one standing there was
    touched in the first step whatever the policy did (4 of 4 close_microwave episodes checked). Nor of
    the gripper where the region starts and ends (the grasp and the release): an obstacle 5 cm from a
    block is inside the 13 cm palm's reach as it closes on the block, so no path could avoid it (in 16
    put_item_in_drawer scenes placed without this rule, the unguided hand touched it in all 16 and grasped
    the block in 4; guided, it kept clear and grasped in 6).

    kind: "cylinder" (the paper's), "box" (an upright box, yaw free) or "cluster" (a second cylinder 0.5-1.5 cm
    beside the first). speed > 0: each obstacle swings across the path by MOVING_AMPLITUDE at that peak speed,
    and its whole swing keeps the clearances above. The plain cylinder makes the same random draws as before
    the other kinds existed (so a seed's layout and candidates are unchanged; the keep-outs decide which is taken).
    """
    attempts = [(task.obstacle_region(layout), 0.02, 200), (task.nominal_path(layout), 0.05, 300)]
    keep_out = GRIPPER_FOOTPRINT_RADIUS + START_CLEARANCE - 0.015  # 1.5 cm added below
    start = (HOME_POSITION[:2], keep_out)
    ends = [(region[end, :2], keep_out) for region, _, _ in attempts for end in (0, -1)]
    swing = np.linspace(-1.0, 1.0, 7) * (MOVING_AMPLITUDE if speed > 0 else 0.0)

    def clear(xy: np.ndarray, radius: float, across: np.ndarray) -> bool:
        # in Python floats: it runs up to 500 times per obstacle where a scene has no room, on 2-vectors, and
        # numpy's per-call overhead was half of the search (1.7x faster; the chosen seeds are unchanged)
        low_x, low_y = PLACEMENT_LOW
        high_x, high_y = PLACEMENT_HIGH
        keep_outs = [(float(c[0]), float(c[1]), float(r) + radius + 0.015) for c, r in [*footprints, start, *ends]]
        for spot_x, spot_y in (xy + swing[:, None] * across).tolist():
            if not (low_x <= spot_x <= high_x and low_y <= spot_y <= high_y):
                return False
            if any(math.hypot(spot_x - x, spot_y - y) < reach for x, y, reach in keep_outs):
                return False
        return True

    obstacles: list[ExtraObject] = []
    for _ in range(count):
        placed = False
        for region, offset, tries in attempts:
            for _ in range(tries):
                radius = float(rng.uniform(0.025, 0.04))
                half_extents = (radius, float(rng.uniform(0.02, 0.05))) if kind == "box" else None
                footprint = float(np.hypot(*half_extents)) if half_extents else radius
                segment = int(rng.integers(len(region) - 1)) if len(region) > 1 else 0
                a, b = region[segment, :2], region[min(segment + 1, len(region) - 1), :2]
                direction = b - a
                if np.linalg.norm(direction) < 1e-3:
                    continue
                normal = np.array([-direction[1], direction[0]]) / np.linalg.norm(direction)
                xy = a + rng.uniform(0.1, 0.9) * direction + normal * rng.uniform(-offset, offset)
                if not clear(xy, footprint, normal):
                    continue
                height = float(rng.uniform(0.3, 0.4))
                motion = (normal, MOVING_AMPLITUDE, speed / MOVING_AMPLITUDE, float(rng.uniform(0, 2 * np.pi))) \
                    if speed > 0 else None
                group = [ExtraObject("", "box" if half_extents else "cylinder", xy,
                                     float(rng.uniform(0, np.pi)) if half_extents else 0.0, "grey", 1.0, "obstacle",
                                     radius=footprint, height=height, half_extents=half_extents, motion=motion)]
                footprints.append((xy, footprint))
                if kind == "cluster":
                    group += _cluster_mate(rng, xy, radius, height, motion, clear, footprints)
                for extra in group:
                    extra.name = f"obstacle_{len(obstacles)}"
                    obstacles.append(extra)
                placed = True
                break
            if placed:
                break
    return obstacles


def _cluster_mate(rng, xy, radius, height, motion, clear, footprints) -> list[ExtraObject]:
    """A second cylinder just beside the first (a gap narrower than the hand), or none where none fits."""
    across = motion[0] if motion is not None else np.zeros(2)
    for _ in range(24):
        mate_radius = float(rng.uniform(0.025, 0.04))
        angle = float(rng.uniform(-np.pi, np.pi))
        mate = xy + (radius + mate_radius + float(rng.uniform(0.005, 0.015))) * np.array([np.cos(angle), np.sin(angle)])
        # the first cylinder is in `footprints` now: leave it out of the mate's check, it is meant to be close
        others, footprints[:] = footprints[:], footprints[:-1]
        fits = clear(mate, mate_radius, across)
        footprints[:] = others
        if fits:
            footprints.append((mate, mate_radius))
            return [ExtraObject("", "cylinder", mate, 0.0, "grey", 1.0, "obstacle", radius=mate_radius,
                                height=float(rng.uniform(0.3, 0.4)), motion=motion)]
    return []
