"""Object builders made of MuJoCo primitives (boxes, cylinders, capsules, spheres).

Every builder has the signature

    add_<kind>(builder, name, position, yaw=0.0, color=..., scale=1.0, role="target", **kind_args) -> ObjectInfo

`position` is (x, y) on the table or (x, y, z) of the object frame's origin; `scale`
multiplies every length (instance variation: 0.8 -> "small", 1.25 -> "large"). Movable
objects get a free joint and masses on their geoms (the compiler infers inertia); static
objects (pan, obstacles) have none. `add_object(builder, kind, ...)` dispatches by kind.

Dimensions at scale 1 (metres): bowl radius 0.06 x height 0.045 (12 straight wall boxes on
a disc base); pan radius 0.10 with 0.03 walls and a handle; bottle body radius 0.025, total
length 0.19 (bottom at local z = -0.06, neck towards +z); items: spheres r 0.011 and cubes
half-side 0.0095.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from lano3dp.sim.objects import ObjectInfo, rgba, size_word

if TYPE_CHECKING:
    from lano3dp.sim.scene import SceneBuilder

BOX = mujoco.mjtGeom.mjGEOM_BOX
CYLINDER = mujoco.mjtGeom.mjGEOM_CYLINDER
CAPSULE = mujoco.mjtGeom.mjGEOM_CAPSULE
SPHERE = mujoco.mjtGeom.mjGEOM_SPHERE

BOWL_RADIUS, BOWL_HEIGHT, BOWL_WALLS, BOWL_WALL_HALF_THICKNESS = 0.06, 0.045, 12, 0.004
PAN_RADIUS, PAN_WALL_HEIGHT = 0.10, 0.03
BOTTLE_RADIUS, BOTTLE_BODY_HALF, BOTTLE_NECK_RADIUS = 0.025, 0.06, 0.011


def yaw_quat(yaw: float) -> list[float]:
    return [float(np.cos(yaw / 2)), 0.0, 0.0, float(np.sin(yaw / 2))]


def _position(position, z: float) -> list[float]:
    position = [float(v) for v in position]
    return position if len(position) == 3 else [*position, z]


def _body(builder: SceneBuilder, name: str, position, quat, free: bool):
    body = builder.world.add_body(name=name, pos=position, quat=quat)
    if free:
        body.add_freejoint(name=f"{name}/free")
    return body


def _ring(body, name: str, radius: float, half_height: float, half_thickness: float, count: int, z: float,
          color, mass: float) -> None:
    """`count` wall boxes around a circle (a cylinder shell made of primitives).

    Callers keep the walls' lower edges above the base's bottom: only the base then touches the
    table, which saves ~50 box-plane contacts per physics step."""
    half_width = radius * np.tan(np.pi / count) + half_thickness
    for k in range(count):
        angle = 2 * np.pi * k / count
        body.add_geom(name=f"{name}/wall{k}", type=BOX, size=[half_thickness, half_width, half_height],
                      pos=[radius * np.cos(angle), radius * np.sin(angle), z], quat=yaw_quat(angle),
                      rgba=color, mass=mass / count)


def add_bowl(builder, name, position, yaw=0.0, color="blue", scale=1.0, role="target", free=True,
             height_scale=1.0) -> ObjectInfo:
    """An open bowl; wall k sits at angle `yaw + 2*pi*k/12` from the bowl's local x axis.
    `height_scale` makes it shallower or deeper than `scale` alone (a shape variant)."""
    radius, height, t = BOWL_RADIUS * scale, BOWL_HEIGHT * scale * height_scale, BOWL_WALL_HALF_THICKNESS
    body = _body(builder, name, _position(position, 0.0), yaw_quat(yaw), free)
    colour = rgba(color)
    body.add_geom(name=f"{name}/base", type=CYLINDER, size=[radius + t, 0.004, 0], pos=[0, 0, 0.004],
                  rgba=colour, mass=0.03)
    _ring(body, name, radius, (height - 0.002) / 2, t, BOWL_WALLS, 0.002 + (height - 0.002) / 2, colour,
          mass=0.04)
    info = ObjectInfo(name, "bowl", color, size_word(scale), (name,), radius + 0.01, np.array(body.pos), role,
                      np.array([radius + 2 * t, radius + 2 * t, height]))
    return builder.register(info)


def add_pan(builder, name, position, yaw=0.0, color="black", scale=1.0, role="target", free=False) -> ObjectInfo:
    """A shallow pan with a handle along its local -x axis. Static unless `free`."""
    radius, wall = PAN_RADIUS * scale, PAN_WALL_HEIGHT
    body = _body(builder, name, _position(position, 0.0), yaw_quat(yaw), free)
    colour = rgba(color)
    body.add_geom(name=f"{name}/base", type=CYLINDER, size=[radius, 0.004, 0], pos=[0, 0, 0.004], rgba=colour,
                  mass=0.4)
    _ring(body, name, radius, wall / 2, 0.004, 16, wall / 2, colour, mass=0.3)
    handle_half = 0.06 * scale
    body.add_geom(name=f"{name}/handle", type=BOX, size=[handle_half, 0.012, 0.006],
                  pos=[-(radius + handle_half), 0, wall - 0.006], rgba=rgba("brown"), mass=0.1)
    info = ObjectInfo(name, "pan", color, size_word(scale), (name,), radius + 0.02, np.array(body.pos), role,
                      np.array([radius + 2 * handle_half, radius + 0.01, wall]))
    return builder.register(info)


def add_bottle(builder, name, position, yaw=0.0, color="green", scale=1.0, role="target", free=True,
               quat=None, radius_scale=1.0) -> ObjectInfo:
    """A bottle: body cylinder + neck + cap along the local z axis, origin at the body's centre.

    `quat` (w, x, y, z) overrides the upright yaw orientation, e.g. to lay the bottle down;
    `radius_scale` makes the body slimmer or stouter than `scale` alone (a shape variant).
    """
    r, half = BOTTLE_RADIUS * scale * radius_scale, BOTTLE_BODY_HALF * scale
    body = _body(builder, name, _position(position, half), list(quat) if quat is not None else yaw_quat(yaw), free)
    colour = rgba(color)
    body.add_geom(name=f"{name}/body", type=CYLINDER, size=[r, half, 0], rgba=colour, mass=0.15,
                  friction=[1.0, 0.02, 0.0005], condim=4)
    neck_half = 0.022 * scale
    body.add_geom(name=f"{name}/shoulder", type=CYLINDER, size=[0.6 * r, 0.008 * scale, 0],
                  pos=[0, 0, half + 0.008 * scale], rgba=colour, mass=0.01)
    body.add_geom(name=f"{name}/neck", type=CYLINDER, size=[BOTTLE_NECK_RADIUS * scale, neck_half, 0],
                  pos=[0, 0, half + 0.016 * scale + neck_half], rgba=colour, mass=0.01)
    body.add_geom(name=f"{name}/cap", type=CYLINDER, size=[0.013 * scale, 0.007 * scale, 0],
                  pos=[0, 0, half + 0.016 * scale + 2 * neck_half + 0.007 * scale], rgba=rgba("white"), mass=0.005)
    length_up = half + 0.016 * scale + 2 * neck_half + 0.014 * scale
    info = ObjectInfo(name, "bottle", color, size_word(scale), (name,), length_up + 0.01, np.array(body.pos), role,
                      np.array([r, r, length_up]))
    return builder.register(info)


def add_mug(builder, name, position, yaw=0.0, color="red", scale=1.0, role="distractor", free=True) -> ObjectInfo:
    r, half = 0.035 * scale, 0.045 * scale
    body = _body(builder, name, _position(position, half), yaw_quat(yaw), free)
    colour = rgba(color)
    body.add_geom(name=f"{name}/cup", type=CYLINDER, size=[r, half, 0], rgba=colour, mass=0.15)
    body.add_geom(name=f"{name}/handle", type=BOX, size=[0.012 * scale, 0.005 * scale, 0.028 * scale],
                  pos=[r + 0.012 * scale, 0, 0], rgba=colour, mass=0.01)
    info = ObjectInfo(name, "mug", color, size_word(scale), (name,), r + 0.03 * scale, np.array(body.pos), role,
                      np.array([r + 0.024 * scale, r, half]))
    return builder.register(info)


def add_cube(builder, name, position, yaw=0.0, color="red", scale=1.0, role="distractor", free=True,
             half_size=0.025, mass=0.08, friction=1.0, solref_damping=1.0) -> ObjectInfo:
    h = half_size * scale
    body = _body(builder, name, _position(position, h), yaw_quat(yaw), free)
    body.add_geom(name=f"{name}/box", type=BOX, size=[h, h, h], rgba=rgba(color), mass=mass,
                  friction=[friction, 0.005, 0.0001], solref=[0.02, solref_damping])
    info = ObjectInfo(name, "cube", color, size_word(scale), (name,), h * 1.5, np.array(body.pos), role,
                      np.array([h, h, h]))
    return builder.register(info)


def add_plate(builder, name, position, yaw=0.0, color="white", scale=1.0, role="distractor", free=True) -> ObjectInfo:
    r = 0.075 * scale
    body = _body(builder, name, _position(position, 0.006), yaw_quat(yaw), free)
    body.add_geom(name=f"{name}/disc", type=CYLINDER, size=[r, 0.006, 0], rgba=rgba(color), mass=0.1)
    info = ObjectInfo(name, "plate", color, size_word(scale), (name,), r + 0.005, np.array(body.pos), role,
                      np.array([r, r, 0.006]))
    return builder.register(info)


def add_can(builder, name, position, yaw=0.0, color="orange", scale=1.0, role="distractor", free=True) -> ObjectInfo:
    r, half = 0.03 * scale, 0.055 * scale
    body = _body(builder, name, _position(position, half), yaw_quat(yaw), free)
    body.add_geom(name=f"{name}/can", type=CYLINDER, size=[r, half, 0], rgba=rgba(color), mass=0.12)
    info = ObjectInfo(name, "can", color, size_word(scale), (name,), r + 0.01, np.array(body.pos), role,
                      np.array([r, r, half]))
    return builder.register(info)


def add_ball(builder, name, position, yaw=0.0, color="purple", scale=1.0, role="distractor", free=True,
             radius=0.03, mass=0.05, friction=0.8, solref_damping=1.0) -> ObjectInfo:
    r = radius * scale
    body = _body(builder, name, _position(position, r), yaw_quat(yaw), free)
    # condim 6 enables rolling friction, so a ball comes to rest instead of rolling for seconds.
    body.add_geom(name=f"{name}/ball", type=SPHERE, size=[r, 0, 0], rgba=rgba(color), mass=mass,
                  friction=[friction, 0.005, 0.001], solref=[0.02, solref_damping], condim=6)
    info = ObjectInfo(name, "ball", color, size_word(scale), (name,), r + 0.005, np.array(body.pos), role,
                      np.array([r, r, r]))
    return builder.register(info)


def add_item(builder, name, position, shape="sphere", color="yellow", scale=1.0, role="item") -> ObjectInfo:
    """A small pourable item (sphere r 0.011 or cube half-side 0.0095, 10 g, low friction so it slides
    out, over-damped contacts so it does not bounce out of the pan)."""
    if shape == "sphere":
        info = add_ball(builder, name, position, color=color, scale=scale, role=role, radius=0.011, mass=0.01,
                        friction=0.3, solref_damping=2.0)
    elif shape == "cube":
        info = add_cube(builder, name, position, color=color, scale=scale, role=role, half_size=0.0095, mass=0.01,
                        friction=0.3, solref_damping=2.0)
    else:
        raise ValueError(f"unknown item shape {shape!r}; use 'sphere' or 'cube'")
    info.kind = "item"
    return info


def add_cylinder_obstacle(builder, name, position, radius=0.03, height=0.3, color="grey",
                          role="obstacle", moving=False) -> ObjectInfo:
    """A static upright cylinder standing on the table (the paper's obstacle model); `moving` makes it a
    mocap body the env slides over the table."""
    body = builder.world.add_body(name=name, pos=_position(position, 0.0), mocap=bool(moving))
    body.add_geom(name=f"{name}/cyl", type=CYLINDER, size=[radius, height / 2, 0], pos=[0, 0, height / 2],
                  rgba=rgba(color))
    info = ObjectInfo(name, "cylinder", color, size_word(radius / 0.03), (name,), radius, np.array(body.pos), role,
                      np.array([radius, radius, height]))
    return builder.register(info)


def add_box_obstacle(builder, name, position, half_extents=(0.03, 0.04), yaw=0.0, height=0.3, color="grey",
                     role="obstacle", moving=False) -> ObjectInfo:
    """A static upright box (xy half extents, yaw about z) standing on the table."""
    hx, hy = (float(h) for h in half_extents)
    body = builder.world.add_body(name=name, pos=_position(position, 0.0), quat=yaw_quat(yaw), mocap=bool(moving))
    body.add_geom(name=f"{name}/box", type=BOX, size=[hx, hy, height / 2], pos=[0, 0, height / 2], rgba=rgba(color))
    info = ObjectInfo(name, "box", color, size_word(max(hx, hy) / 0.03), (name,), float(np.hypot(hx, hy)),
                      np.array(body.pos), role, np.array([hx, hy, height]))
    return builder.register(info)


BUILDERS: dict[str, Callable[..., ObjectInfo]] = {
    "bowl": add_bowl,
    "pan": add_pan,
    "bottle": add_bottle,
    "mug": add_mug,
    "cube": add_cube,
    "plate": add_plate,
    "can": add_can,
    "ball": add_ball,
}

# Footprint radius (m) at scale 1 of each kind, for placement before building.
FOOTPRINTS = {"bowl": 0.07, "pan": 0.12, "bottle": 0.04, "mug": 0.065, "cube": 0.038, "plate": 0.08,
              "can": 0.04, "ball": 0.035}


def add_object(builder, kind: str, name: str, position, yaw=0.0, color="red", scale=1.0, role="distractor",
               **kwargs) -> ObjectInfo:
    """Build an object of `kind` (one of `BUILDERS`)."""
    if kind not in BUILDERS:
        raise KeyError(f"no primitive builder for kind {kind!r}; known kinds: {sorted(BUILDERS)}")
    return BUILDERS[kind](builder, name, position, yaw=yaw, color=color, scale=scale, role=role, **kwargs)
