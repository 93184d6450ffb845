"""Articulated and composite objects of the RLBench-style tasks: drawer cabinet, hinged-door box
(microwave), phone and phone base, wine bottle with a cap, watering can, potted plant, push broom,
dustpan, and the block of `put_item_in_drawer`.

Builders follow the `primitives` signature

    add_<kind>(builder, name, position, yaw=0.0, color=..., scale=1.0, role="target") -> ObjectInfo

and the naming rule of `lano3dp.sim.objects`: every body of object `name` is `name` or `name/<part>`.
The joints, sites and dimensions a task needs are fixed by the object's name and scale, so a
task recovers them after compiling with `DrawerParts.of(name, scale)` (and the like) instead of
carrying builder state around. Sites sit in `SITE_GROUP` (the renderer hides them); experts and
success checks read them, observations never do.

Static parts have no joint (welded to the world); a drawer slides on one slide joint, a door
turns on one hinge. Geom masses are given explicitly and the compiler infers inertia, which
avoids MjSpec's NaN `ipos` pitfall with explicit inertials.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from lano3dp.sim.objects import ObjectInfo, primitives, rgba, size_word

if TYPE_CHECKING:
    from lano3dp.sim.scene import SceneBuilder

SITE_GROUP = 5
BOX = mujoco.mjtGeom.mjGEOM_BOX
CAPSULE = mujoco.mjtGeom.mjGEOM_CAPSULE


def yaw_quat(yaw: float) -> list[float]:
    return [float(np.cos(yaw / 2)), 0.0, 0.0, float(np.sin(yaw / 2))]


def _box(body, name: str, center, half, color, mass: float = 0.0, **kw):
    if mass > 0:
        kw["mass"] = mass
    return body.add_geom(name=name, type=BOX, pos=[float(c) for c in center], size=[float(h) for h in half],
                         rgba=list(color), **kw)


def _site(body, name: str, pos) -> None:
    body.add_site(name=name, pos=[float(p) for p in pos], size=[0.005, 0, 0], group=SITE_GROUP)


def _shade(color, factor: float) -> list[float]:
    return [min(1.0, c * factor) for c in color[:3]] + [color[3]]


# ------------------------------------------------------------------------------------------- drawer

DRAWER_DEPTH, DRAWER_WIDTH, DRAWER_HEIGHT = 0.16, 0.22, 0.10
DRAWER_WALL, DRAWER_TRAVEL = 0.008, 0.14
HANDLE_STANDOFF, HANDLE_LENGTH, HANDLE_RADIUS = 0.05, 0.10, 0.006
_GAP = 0.002  # clearance between sliding or hinged parts and their carcass


@dataclass(frozen=True)
class DrawerParts:
    """Element names and dimensions of a drawer cabinet built by `add_drawer` (metres).

    Cabinet frame: origin on the table under the cabinet's centre, +x = the direction the drawer
    opens, z up. The footprint and height scale with `scale`; wall, handle and standoff do not,
    so the gripper fits every instance. The drawer's opening (m) is the slide joint's qpos.
    """

    name: str
    depth: float
    width: float
    height: float
    travel: float
    wall: float = DRAWER_WALL

    @classmethod
    def of(cls, name: str, scale: float = 1.0) -> DrawerParts:
        return cls(name, DRAWER_DEPTH * scale, DRAWER_WIDTH * scale, DRAWER_HEIGHT * scale, DRAWER_TRAVEL * scale)

    @property
    def cabinet(self) -> str:
        return f"{self.name}/cabinet"

    @property
    def drawer(self) -> str:
        return f"{self.name}/drawer"

    @property
    def joint(self) -> str:
        return f"{self.name}/slide"

    @property
    def handle_site(self) -> str:
        """On the handle bar's axis, at its middle."""
        return f"{self.name}/handle"

    @property
    def interior_site(self) -> str:
        """Centre of the drawer floor's top surface (moves with the drawer)."""
        return f"{self.name}/interior"

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.cabinet, self.drawer)

    # Derived geometry in the cabinet frame at opening 0.
    @property
    def floor_top(self) -> float:
        return 2 * self.wall + _GAP

    @property
    def inner_x(self) -> tuple[float, float]:
        """(back, front) x of the drawer's inner floor."""
        return -self.depth / 2 + 2 * self.wall + _GAP, self.depth / 2

    @property
    def inner_half_width(self) -> float:
        return self.width / 2 - 2 * self.wall - _GAP

    @property
    def side_wall_top(self) -> float:
        return self.floor_top + 0.6 * (self.height - 2 * self.wall - 2 * _GAP)

    @property
    def handle_x(self) -> float:
        return self.depth / 2 + _GAP + self.wall + HANDLE_STANDOFF

    @property
    def handle_z(self) -> float:
        # A fixed distance below the top, so a hand grasping the bar clears the cabinet at any scale.
        return self.height - 0.04

    @property
    def interior_half(self) -> tuple[float, float]:
        """Half extents (x, y) of the drawer's inner floor."""
        back, front = self.inner_x
        return (front - back) / 2, self.inner_half_width


def add_drawer(builder: SceneBuilder, name: str, position, yaw: float = 0.0, color: str = "brown",
               scale: float = 1.0, role: str = "target", handle_color: str = "grey",
               opening: float = 0.0) -> ObjectInfo:
    """A static cabinet open at its +x face, one drawer on a slide joint, and a bar handle.

    The drawer starts `opening` metres out: the drawer body is built there and the joint's
    reference is set to match, so the model's initial qpos (`qpos0`, what a reset restores) is
    the opening and qpos keeps meaning "metres out" (0 = closed). Cabinet-drawer contacts are
    filtered by MuJoCo's parent-child rule, so the drawer slides freely inside its
    carcass; damping and friction loss keep it where the gripper leaves it.
    """
    p = DrawerParts.of(name, scale)
    d, w, h, t = p.depth, p.width, p.height, p.wall
    colour, handle_colour = rgba(color), rgba(handle_color)
    cab = builder.world.add_body(name=p.cabinet, pos=[float(position[0]), float(position[1]), 0.0],
                                 quat=yaw_quat(yaw))
    _box(cab, f"{name}/bottom", [0, 0, t / 2], [d / 2, w / 2, t / 2], colour)
    _box(cab, f"{name}/top", [0, 0, h - t / 2], [d / 2, w / 2, t / 2], colour)
    for side, sy in (("left", 1), ("right", -1)):
        _box(cab, f"{name}/{side}", [0, sy * (w / 2 - t / 2), h / 2], [d / 2, t / 2, h / 2 - t], colour)
    _box(cab, f"{name}/back", [-d / 2 + t / 2, 0, h / 2], [t / 2, w / 2 - t, h / 2 - t], colour)

    opening = float(np.clip(opening, 0.0, p.travel))
    drawer = cab.add_body(name=p.drawer, pos=[opening, 0, 0])
    drawer.add_joint(name=p.joint, type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1, 0, 0], range=[0.0, p.travel],
                     ref=opening, damping=3.0, frictionloss=0.3, armature=0.05)
    inner = _shade(colour, 1.2)
    back, front = p.inner_x
    x_back = back - t  # outer face of the drawer's back wall
    y_half = p.inner_half_width + t
    wall_half = (p.side_wall_top - p.floor_top) / 2
    wall_z = p.floor_top + wall_half
    _box(drawer, f"{name}/floor", [(x_back + front) / 2, 0, p.floor_top - t / 2], [(front - x_back) / 2, y_half, t / 2],
         inner, mass=0.15)
    for side, sy in (("dleft", 1), ("dright", -1)):
        _box(drawer, f"{name}/{side}", [(x_back + front) / 2, sy * (y_half - t / 2), wall_z],
             [(front - x_back) / 2, t / 2, wall_half], inner, mass=0.05)
    _box(drawer, f"{name}/dback", [back - t / 2, 0, wall_z], [t / 2, y_half - t, wall_half], inner, mass=0.03)
    # The front panel covers the whole cabinet face, just outside it.
    _box(drawer, f"{name}/front", [d / 2 + _GAP + t / 2, 0, h / 2], [t / 2, w / 2, h / 2 - _GAP], inner, mass=0.1)
    x0, x1, zh, half_len = d / 2 + _GAP + t, p.handle_x, p.handle_z, HANDLE_LENGTH / 2
    drawer.add_geom(name=f"{name}/handle_bar", type=CAPSULE, size=[HANDLE_RADIUS, 0, 0], rgba=handle_colour,
                    fromto=[x1, -half_len, zh, x1, half_len, zh], mass=0.02, friction=[1.5, 0.02, 0.0005])
    for i, sy in enumerate((-1, 1)):
        drawer.add_geom(name=f"{name}/handle_stem{i}", type=CAPSULE, size=[HANDLE_RADIUS, 0, 0], rgba=handle_colour,
                        fromto=[x0, sy * half_len, zh, x1, sy * half_len, zh], mass=0.01)
    _site(drawer, p.handle_site, [x1, 0, zh])
    _site(drawer, p.interior_site, [(back + front) / 2, 0, p.floor_top])

    reach = d / 2 + p.travel + t + HANDLE_STANDOFF + HANDLE_RADIUS
    info = ObjectInfo(name, "drawer", color, size_word(scale), p.bodies, float(np.hypot(reach, w / 2)),
                      np.array(cab.pos), role, np.array([reach, w / 2, h]))
    return builder.register(info)


# ---------------------------------------------------------------------------------------- microwave

MICROWAVE_DEPTH, MICROWAVE_WIDTH, MICROWAVE_HEIGHT = 0.16, 0.22, 0.14
DOOR_THICKNESS, DOOR_MAX_ANGLE = 0.012, 2.0


@dataclass(frozen=True)
class MicrowaveParts:
    """Element names and dimensions of a box with a hinged door built by `add_microwave` (metres).

    Box frame: origin on the table under the box's centre, the door on the +x face, hinged on
    its vertical edge at -y. At door angle q (the hinge's qpos, 0 = closed) the door's free edge
    points along (sin q, cos q, 0) from the hinge, and the door's outer face normal is
    (cos q, -sin q, 0), both in the box frame.
    """

    name: str
    depth: float
    width: float
    height: float
    wall: float = DRAWER_WALL
    door_thickness: float = DOOR_THICKNESS

    @classmethod
    def of(cls, name: str, scale: float = 1.0) -> MicrowaveParts:
        return cls(name, MICROWAVE_DEPTH * scale, MICROWAVE_WIDTH * scale, MICROWAVE_HEIGHT * scale)

    @property
    def body(self) -> str:
        return f"{self.name}/body"

    @property
    def door(self) -> str:
        return f"{self.name}/door"

    @property
    def joint(self) -> str:
        return f"{self.name}/hinge"

    @property
    def hinge_site(self) -> str:
        """On the hinge axis at table height (static)."""
        return f"{self.name}/hinge_axis"

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.body, self.door)

    @property
    def hinge_local(self) -> np.ndarray:
        """(3,) hinge axis point at z = 0 in the box frame."""
        return np.array([self.depth / 2 + _GAP + self.door_thickness / 2, -self.width / 2, 0.0])

    @property
    def door_width(self) -> float:
        return self.width - _GAP


def add_microwave(builder: SceneBuilder, name: str, position, yaw: float = 0.0, color: str = "white",
                  scale: float = 1.0, role: str = "target", door_color: str = "black",
                  door_angle: float = 0.0) -> ObjectInfo:
    """A static box open at its +x face, closed by a door on a vertical hinge at the front-left edge.

    The door starts `door_angle` rad open (built rotated, with the joint reference matching, so
    the initial qpos is the angle; see `add_drawer`). A handle block sits on the door's outer
    face near the free edge.
    """
    p = MicrowaveParts.of(name, scale)
    d, w, h, t, dt = p.depth, p.width, p.height, p.wall, p.door_thickness
    colour, door_colour = rgba(color), rgba(door_color)
    box = builder.world.add_body(name=p.body, pos=[float(position[0]), float(position[1]), 0.0], quat=yaw_quat(yaw))
    _box(box, f"{name}/bottom", [0, 0, t / 2], [d / 2, w / 2, t / 2], colour)
    _box(box, f"{name}/top", [0, 0, h - t / 2], [d / 2, w / 2, t / 2], colour)
    for side, sy in (("left", 1), ("right", -1)):
        _box(box, f"{name}/{side}", [0, sy * (w / 2 - t / 2), h / 2], [d / 2, t / 2, h / 2 - t], colour)
    _box(box, f"{name}/back", [-d / 2 + t / 2, 0, h / 2], [t / 2, w / 2 - t, h / 2 - t], colour)
    hinge = p.hinge_local
    angle = float(np.clip(door_angle, 0.0, DOOR_MAX_ANGLE))
    door = box.add_body(name=p.door, pos=list(hinge), quat=yaw_quat(-angle))
    # Axis -z so that a positive angle swings the free edge outward (+x). MjSpec reads hinge
    # ranges and refs in the compiler's angle unit (degrees by default).
    unit = np.degrees if builder.spec.compiler.degree else float
    door.add_joint(name=p.joint, type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, -1],
                   range=[0.0, float(unit(DOOR_MAX_ANGLE))], ref=float(unit(angle)),
                   damping=0.05, frictionloss=0.01, armature=0.005)
    _box(door, f"{name}/panel", [0, p.door_width / 2, h / 2], [dt / 2, p.door_width / 2, h / 2 - _GAP], door_colour,
         mass=0.2)
    _box(door, f"{name}/door_handle", [dt / 2 + 0.008, p.door_width - 0.03, h / 2], [0.008, 0.008, 0.3 * h], colour,
         mass=0.02)
    _site(box, p.hinge_site, hinge)
    reach = d / 2 + w  # an open door sweeps a quarter disc of radius w in front of the box
    info = ObjectInfo(name, "microwave", color, size_word(scale), p.bodies, float(np.hypot(reach, w / 2)),
                      np.array(box.pos), role, np.array([reach, w / 2 + 0.02, h]))
    return builder.register(info)


# --------------------------------------------------------------------------------- phone and base

PHONE_LENGTH, PHONE_WIDTH, PHONE_THICKNESS = 0.13, 0.06, 0.02
BASE_CLEARANCE, BASE_PLATE, BASE_RIM_HEIGHT, BASE_RIM = 0.025, 0.008, 0.012, 0.012


@dataclass(frozen=True)
class PhoneParts:
    """A phone-like slab lying flat: length along its local x, width (the grasp axis) along y."""

    name: str
    length: float
    width: float
    thickness: float = PHONE_THICKNESS

    @classmethod
    def of(cls, name: str, scale: float = 1.0) -> PhoneParts:
        return cls(name, PHONE_LENGTH * scale, PHONE_WIDTH * scale)

    @property
    def body(self) -> str:
        return f"{self.name}/body"

    @property
    def joint(self) -> str:
        return f"{self.name}/free"

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.body,)


def add_phone(builder: SceneBuilder, name: str, position, yaw: float = 0.0, color: str = "black",
              scale: float = 1.0, role: str = "target") -> ObjectInfo:
    """A free phone slab (90 g) with a screen inlay on top; origin at its centre."""
    p = PhoneParts.of(name, scale)
    half = [p.length / 2, p.width / 2, p.thickness / 2]
    body = builder.world.add_body(name=p.body, pos=[float(position[0]), float(position[1]), half[2] + 0.0005],
                                  quat=yaw_quat(yaw))
    body.add_freejoint(name=p.joint)
    _box(body, f"{name}/slab", [0, 0, 0], half, rgba(color), mass=0.09, friction=[1.2, 0.02, 0.0005], condim=4)
    _box(body, f"{name}/screen", [0, 0, half[2] + 0.0005], [half[0] * 0.9, half[1] * 0.85, 0.0005],
         [0.2, 0.35, 0.55, 1.0], contype=0, conaffinity=0, mass=0.001)
    info = ObjectInfo(name, "phone", color, size_word(scale), p.bodies, float(np.hypot(*half[:2])) + 0.005,
                      np.array(body.pos), role, np.array(half))
    return builder.register(info)


@dataclass(frozen=True)
class PhoneBaseParts:
    """A flat base with a raised rim around a recess that fits a phone of the same scale."""

    name: str
    inner_length: float
    inner_width: float
    plate: float = BASE_PLATE
    rim_height: float = BASE_RIM_HEIGHT
    rim: float = BASE_RIM

    @classmethod
    def of(cls, name: str, scale: float = 1.0) -> PhoneBaseParts:
        return cls(name, PHONE_LENGTH * scale + 2 * BASE_CLEARANCE, PHONE_WIDTH * scale + 2 * BASE_CLEARANCE)

    @property
    def body(self) -> str:
        return f"{self.name}/body"

    @property
    def top_site(self) -> str:
        """Centre of the recess floor."""
        return f"{self.name}/top"

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.body,)


def add_phone_base(builder: SceneBuilder, name: str, position, yaw: float = 0.0, color: str = "grey",
                   scale: float = 1.0, role: str = "target") -> ObjectInfo:
    """A static phone base: a plate with a low rim around a recess the phone lies in.

    RLBench's base holds the phone upright in a slot; here the phone lies flat in the recess,
    which keeps the same pick, carry and aligned placement without an in-hand regrasp.
    """
    p = PhoneBaseParts.of(name, scale)
    L, W, t, rh, r = p.inner_length, p.inner_width, p.plate, p.rim_height, p.rim
    colour = rgba(color)
    body = builder.world.add_body(name=p.body, pos=[float(position[0]), float(position[1]), 0.0], quat=yaw_quat(yaw))
    _box(body, f"{name}/plate", [0, 0, t / 2], [L / 2 + r, W / 2 + r, t / 2], colour)
    for i, s in enumerate((-1, 1)):
        _box(body, f"{name}/rim_end{i}", [s * (L / 2 + r / 2), 0, t + rh / 2], [r / 2, W / 2 + r, rh / 2], colour)
        _box(body, f"{name}/rim_side{i}", [0, s * (W / 2 + r / 2), t + rh / 2], [L / 2, r / 2, rh / 2], colour)
    _site(body, p.top_site, [0, 0, t])
    half = np.array([L / 2 + r, W / 2 + r, t + rh])
    info = ObjectInfo(name, "base", color, size_word(scale), p.bodies, float(np.hypot(*half[:2])),
                      np.array(body.pos), role, half)
    return builder.register(info)


# ------------------------------------------------------------------------------ wine bottle + cap

WINE_RADIUS, WINE_BODY_HALF, WINE_NECK_RADIUS, WINE_NECK_HALF = 0.035, 0.085, 0.012, 0.035
CAP_RADIUS, CAP_HALF, CAP_TRAVEL = 0.016, 0.015, 0.06
WINE_MASS, CAP_FRICTION = 1.0, 3.0  # kg, N: pulling the cap must not lift the bottle (9.8 N)


@dataclass(frozen=True)
class WineBottleParts:
    """A wine bottle standing upright with a cap that slides off along the bottle's axis (metres).

    Bottle frame: origin at the bottle's bottom centre, z along the axis. The cap's slide joint
    reads 0 when the cap sits on the neck and the cap's height above it otherwise.
    """

    name: str
    radius: float
    body_half: float
    neck_radius: float
    neck_half: float
    cap_radius: float = CAP_RADIUS
    cap_half: float = CAP_HALF

    @classmethod
    def of(cls, name: str, scale: float = 1.0) -> WineBottleParts:
        # The cap keeps its size so the gripper's grasp does not change with the instance.
        return cls(name, WINE_RADIUS * scale, WINE_BODY_HALF * scale, WINE_NECK_RADIUS, WINE_NECK_HALF * scale)

    @property
    def body(self) -> str:
        return f"{self.name}/body"

    @property
    def cap(self) -> str:
        return f"{self.name}/cap"

    @property
    def joint(self) -> str:
        return f"{self.name}/cap_slide"

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.body, self.cap)

    @property
    def shoulder_top(self) -> float:
        return 2 * self.body_half + 0.02

    @property
    def neck_top(self) -> float:
        return self.shoulder_top + 2 * self.neck_half

    @property
    def cap_bottom(self) -> float:
        """Height of the cap's lower edge above the bottle's bottom when it is on (it overlaps the neck)."""
        return self.neck_top - 0.01


def add_wine_bottle(builder: SceneBuilder, name: str, position, yaw: float = 0.0, color: str = "green",
                    scale: float = 1.0, role: str = "target", cap_color: str = "red") -> ObjectInfo:
    """A free, heavy (1 kg) wine bottle with a cap on a slide joint along its axis.

    The cap is held by 3 N of joint friction, so it comes off only when pulled; the bottle's weight
    keeps it on the table while that happens. RLBench's wine bottle is unscrewed by a twist;
    this one is uncorked by a straight pull.
    """
    p = WineBottleParts.of(name, scale)
    colour = rgba(color)
    body = builder.world.add_body(name=p.body, pos=[float(position[0]), float(position[1]), 0.0005],
                                  quat=yaw_quat(yaw))
    body.add_freejoint(name=f"{name}/free")
    body.add_geom(name=f"{name}/glass", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[p.radius, p.body_half, 0],
                  pos=[0, 0, p.body_half], rgba=colour, mass=WINE_MASS * 0.9, friction=[1.0, 0.02, 0.0005], condim=4)
    body.add_geom(name=f"{name}/shoulder", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.6 * p.radius, 0.01, 0],
                  pos=[0, 0, 2 * p.body_half + 0.01], rgba=colour, mass=WINE_MASS * 0.05)
    body.add_geom(name=f"{name}/neck", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[p.neck_radius, p.neck_half, 0],
                  pos=[0, 0, p.shoulder_top + p.neck_half], rgba=colour, mass=WINE_MASS * 0.05)
    cap = body.add_body(name=p.cap, pos=[0, 0, p.cap_bottom + p.cap_half])
    cap.add_joint(name=p.joint, type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, 0, 1], range=[0.0, CAP_TRAVEL],
                  frictionloss=CAP_FRICTION, damping=1.0, armature=0.01)
    cap.add_geom(name=f"{name}/cap_geom", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[p.cap_radius, p.cap_half, 0],
                 rgba=rgba(cap_color), mass=0.01, friction=[1.5, 0.02, 0.0005])
    top = p.cap_bottom + 2 * p.cap_half
    info = ObjectInfo(name, "bottle", color, size_word(scale), p.bodies, p.radius + 0.01, np.array(body.pos), role,
                      np.array([p.radius, p.radius, top]))
    return builder.register(info)


# ------------------------------------------------------------------------- watering can and plant

CAN_RADIUS, CAN_HEIGHT, CAN_WALLS, CAN_WALL_HALF = 0.045, 0.09, 12, 0.004
POT_RADIUS, POT_HEIGHT, SOIL_HEIGHT = 0.06, 0.07, 0.04
PALETTE_SOIL = (0.30, 0.20, 0.12, 1.0)


def _ring(body, name: str, radius: float, half_height: float, half_thickness: float, count: int, z: float,
          color, mass: float) -> None:
    """`count` wall boxes around a circle: a cylinder shell made of primitives (wall k at angle 2 pi k / count)."""
    half_width = radius * np.tan(np.pi / count) + half_thickness
    for k in range(count):
        angle = 2 * np.pi * k / count
        body.add_geom(name=f"{name}/wall{k}", type=BOX, size=[half_thickness, half_width, half_height],
                      pos=[radius * np.cos(angle), radius * np.sin(angle), z], quat=yaw_quat(angle), rgba=list(color),
                      mass=mass / count)


def add_watering_can(builder: SceneBuilder, name: str, position, yaw: float = 0.0, color: str = "green",
                     scale: float = 1.0, role: str = "target") -> ObjectInfo:
    """A free open can (radius 4.5 cm, 9 cm tall at scale 1, 12 wall boxes on a disc) with a spout
    along its local +x axis. The spout is visual only (no contacts): water leaves over the rim on
    the spout side, and a colliding spout would catch it."""
    radius, height, t = CAN_RADIUS * scale, CAN_HEIGHT * scale, CAN_WALL_HALF
    colour = rgba(color)
    body = builder.world.add_body(name=name, pos=[float(position[0]), float(position[1]), 0.0], quat=yaw_quat(yaw))
    body.add_freejoint(name=f"{name}/free")
    body.add_geom(name=f"{name}/base", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[radius + t, 0.004, 0],
                  pos=[0, 0, 0.004], rgba=colour, mass=0.06)
    _ring(body, name, radius, height / 2, t, CAN_WALLS, height / 2, colour, mass=0.09)
    body.add_geom(name=f"{name}/spout", type=CAPSULE, size=[0.007, 0, 0], rgba=colour, contype=0, conaffinity=0,
                  fromto=[radius, 0, 0.45 * height, radius + 0.06 * scale, 0, 0.45 * height + 0.05 * scale],
                  mass=0.005)
    info = ObjectInfo(name, "watering can", color, size_word(scale), (name,), radius + 0.07 * scale,
                      np.array(body.pos), role, np.array([radius + 0.065 * scale, radius + t, height]))
    return builder.register(info)


def add_plant(builder: SceneBuilder, name: str, position, yaw: float = 0.0, color: str = "orange",
              scale: float = 1.0, role: str = "target") -> ObjectInfo:
    """A static potted plant: a pot (radius 6 cm, 7 cm tall at scale 1) filled with soil to 4 cm,
    and a stem with leaves that are visual only (no contacts), so water poured on the plant
    reaches the soil. `color` is the pot's."""
    radius, height, t = POT_RADIUS * scale, POT_HEIGHT * scale, CAN_WALL_HALF
    body = builder.world.add_body(name=name, pos=[float(position[0]), float(position[1]), 0.0], quat=yaw_quat(yaw))
    colour = rgba(color)
    soil = SOIL_HEIGHT * scale
    body.add_geom(name=f"{name}/soil", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[radius, soil / 2, 0],
                  pos=[0, 0, soil / 2], rgba=list(PALETTE_SOIL))
    _ring(body, name, radius, height / 2, t, 16, height / 2, colour, mass=0.0)
    leaf = rgba("green")
    body.add_geom(name=f"{name}/stem", type=CAPSULE, size=[0.004, 0, 0], rgba=leaf, contype=0, conaffinity=0,
                  fromto=[0, 0, soil, 0.01, 0, soil + 0.1 * scale])
    for i, (dx, dy, dz) in enumerate(((0.025, 0.0, 0.10), (-0.015, 0.02, 0.085), (-0.01, -0.025, 0.115))):
        body.add_geom(name=f"{name}/leaf{i}", type=mujoco.mjtGeom.mjGEOM_ELLIPSOID, rgba=leaf, contype=0,
                      conaffinity=0, size=[0.03 * scale, 0.015 * scale, 0.006 * scale],
                      pos=[dx * scale, dy * scale, soil + dz * scale], quat=yaw_quat(2.1 * i))
    info = ObjectInfo(name, "plant", color, size_word(scale), (name,), radius + 0.02, np.array(body.pos), role,
                      np.array([radius + 2 * t, radius + 2 * t, soil + 0.13 * scale]))
    return builder.register(info)



# ---------------------------------------------------------------------------------- broom, dustpan

BROOM_HEAD_HALF = (0.015, 0.06, 0.01)  # along the handle, across it, up (m, scale 1)
BROOM_HANDLE_LENGTH, BROOM_HANDLE_RADIUS = 0.22, 0.01
BROOM_HEAD_MASS, BROOM_HANDLE_MASS = 0.03, 0.03
DUSTPAN_DEPTH, DUSTPAN_WIDTH, DUSTPAN_WALL_HEIGHT = 0.12, 0.17, 0.03


@dataclass(frozen=True)
class BroomParts:
    """A push broom lying on the table: a head box at its local origin, the handle along local -x.

    Broom frame: origin at the head's centre (which is `head_half[2]` above the table when the
    broom lies flat), +x = the direction the head pushes, z up.
    """

    name: str
    head_half: tuple[float, float, float]
    handle_length: float
    handle_radius: float = BROOM_HANDLE_RADIUS

    @classmethod
    def of(cls, name: str, scale: float = 1.0) -> BroomParts:
        # The head's height and the handle's radius keep their size: both lie flat on the table at
        # every scale and the fingers close on the same 2 cm handle.
        hx, hy, hz = BROOM_HEAD_HALF
        return cls(name, (hx * scale, hy * scale, hz), BROOM_HANDLE_LENGTH * scale)

    @property
    def body(self) -> str:
        return self.name

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.body,)

    @property
    def grasp_x(self) -> float:
        """Local x of the centre of mass on the handle: holding it there puts no torque on the grip."""
        handle_centre = -self.head_half[0] - self.handle_length / 2
        return BROOM_HANDLE_MASS * handle_centre / (BROOM_HANDLE_MASS + BROOM_HEAD_MASS)


def add_broom(builder: SceneBuilder, name: str, position, yaw: float = 0.0, color: str = "yellow",
              scale: float = 1.0, role: str = "target", handle_color: str = "brown") -> ObjectInfo:
    """A free push broom lying flat (60 g): head box with the handle along its local -x axis."""
    p = BroomParts.of(name, scale)
    hx, hy, hz = p.head_half
    body = builder.world.add_body(name=p.body, pos=[float(position[0]), float(position[1]), hz + 0.0005],
                                  quat=yaw_quat(yaw))
    body.add_freejoint(name=f"{name}/free")
    _box(body, f"{name}/head", [0, 0, 0], [hx, hy, hz], rgba(color), mass=BROOM_HEAD_MASS,
         friction=[0.3, 0.01, 0.0005])
    body.add_geom(name=f"{name}/handle", type=CAPSULE, size=[p.handle_radius, 0, 0], rgba=rgba(handle_color),
                  fromto=[-hx - p.handle_radius, 0, 0, -hx - p.handle_length + p.handle_radius, 0, 0],
                  mass=BROOM_HANDLE_MASS, friction=[1.2, 0.02, 0.0005])
    length = hx + p.handle_length
    info = ObjectInfo(name, "broom", color, size_word(scale), p.bodies, length / 2 + 0.02, np.array(body.pos), role,
                      np.array([length, hy, hz]))
    return builder.register(info)


@dataclass(frozen=True)
class DustpanParts:
    """A static dustpan: a floor flush with the table, walls on three sides, open towards local -x.

    Dustpan frame: origin on the table at the middle of the mouth (the open edge), +x into the pan.
    """

    name: str
    depth: float
    width: float
    wall_height: float = DUSTPAN_WALL_HEIGHT
    wall: float = 0.006

    @classmethod
    def of(cls, name: str, scale: float = 1.0) -> DustpanParts:
        return cls(name, DUSTPAN_DEPTH * scale, DUSTPAN_WIDTH * scale)

    @property
    def body(self) -> str:
        return self.name

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.body,)

    @property
    def inner_half_width(self) -> float:
        return self.width / 2 - self.wall


def add_dustpan(builder: SceneBuilder, name: str, position, yaw: float = 0.0, color: str = "blue",
                scale: float = 1.0, role: str = "target") -> ObjectInfo:
    """A static dustpan whose mouth (the open side, at `position`) faces local -x.

    The floor is a 1 mm visual-only plate (the table carries the dirt; RLBench's dustpan has a
    thin sloped lip), so swept dirt slides in without a step.
    """
    p = DustpanParts.of(name, scale)
    d, w, h, t = p.depth, p.width, p.wall_height, p.wall
    colour = rgba(color)
    body = builder.world.add_body(name=p.body, pos=[float(position[0]), float(position[1]), 0.0], quat=yaw_quat(yaw))
    _box(body, f"{name}/floor", [d / 2, 0, 0.0005], [d / 2, w / 2 - t, 0.0005], _shade(colour, 1.3),
         contype=0, conaffinity=0)  # visual only: the table under it carries the dirt
    for i, s in enumerate((-1, 1)):
        _box(body, f"{name}/side{i}", [d / 2, s * (w / 2 - t / 2), h / 2], [d / 2, t / 2, h / 2], colour)
    _box(body, f"{name}/back", [d - t / 2, 0, h / 2], [t / 2, w / 2 - t, h / 2], colour)
    info = ObjectInfo(name, "dustpan", color, size_word(scale), p.bodies, float(np.hypot(d, w)) / 2 + 0.01,
                      np.array(body.pos), role, np.array([d, w / 2, h]))
    return builder.register(info)


# ------------------------------------------------------------------------------------------ block

BLOCK_HALF, BLOCK_MASS = 0.02, 0.06  # m at scale 1, kg


def add_block(builder: SceneBuilder, name: str, position, yaw: float = 0.0, color: str = "blue",
              scale: float = 1.0, role: str = "target") -> ObjectInfo:
    """A free 4 cm cube (60 g) of kind "block", the word the language layer uses for the item."""
    info = primitives.add_cube(builder, name, position, yaw, color, scale, role=role, half_size=BLOCK_HALF,
                               mass=BLOCK_MASS)
    info.kind = "block"
    return info


# Kinds a variation may add as look-alikes ("similar") through `primitives.add_object`, which
# dispatches on `primitives.BUILDERS`; registered here so the core's primitive list stays primitive.
for _kind, _builder in {"block": add_block, "phone": add_phone, "watering can": add_watering_can,
                        "broom": add_broom}.items():
    primitives.BUILDERS.setdefault(_kind, _builder)
