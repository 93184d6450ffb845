"""Analytic RGB-D frames of boxes on a table, for tests, examples and perception checks.

A few axis-aligned boxes ray-cast exactly (slab method) from any `PinholeCamera`: depth,
colour and an instance map with names and attributes, without a simulator.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from lano3dp.geometry.camera import PinholeCamera
from lano3dp.geometry.frame import RGBDFrame

_NAMED_RGB = {
    "red": (200, 30, 30), "green": (30, 170, 40), "blue": (30, 60, 200), "yellow": (220, 200, 30),
    "white": (235, 235, 235), "black": (20, 20, 20), "grey": (128, 128, 128), "orange": (240, 130, 20),
}  # fmt: skip
_TABLE_RGB = (150, 110, 70)


@dataclass(frozen=True)
class Box:
    """An axis-aligned box resting on the table (z = 0).

    Attributes:
        name: object name (becomes a key of `instance_names`).
        center_xy: (2,) centre of the footprint in the world frame, metres.
        size: (3,) full extents along x, y, z, metres.
        attributes: e.g. {"kind": "bowl", "color": "red", "size": "small"}.
    """

    name: str
    center_xy: tuple[float, float]
    size: tuple[float, float, float]
    attributes: dict[str, str] = field(default_factory=dict)

    @property
    def low(self) -> np.ndarray:
        return np.array([self.center_xy[0] - self.size[0] / 2, self.center_xy[1] - self.size[1] / 2, 0.0])

    @property
    def high(self) -> np.ndarray:
        return np.array([self.center_xy[0] + self.size[0] / 2, self.center_xy[1] + self.size[1] / 2, self.size[2]])


def top_down_camera(
    size: int = 96, height: float = 1.0, fovy_deg: float = 60.0, tilt_deg: float = 0.0
) -> PinholeCamera:
    """A camera `height` m above the origin looking down (optionally tilted about world x)."""
    tilt = np.deg2rad(tilt_deg)
    # OpenCV axes in the world: x right = world x, y down = world -y, z forward = world -z; then tilt.
    down = np.diag([1.0, -1.0, -1.0])
    c, s = np.cos(tilt), np.sin(tilt)
    rot_x = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    T = np.eye(4)
    T[:3, :3] = rot_x @ down
    T[:3, 3] = rot_x @ np.array([0.0, 0.0, height])
    return PinholeCamera.from_fovy(size, size, fovy_deg, T)


def render_boxes(
    camera: PinholeCamera,
    boxes: Sequence[Box],
    table_half_extent: float = 1.0,
) -> RGBDFrame:
    """Ray-cast `boxes` and a square table top at z = 0.

    Returns:
        An RGBDFrame: depth (H, W) float32 z-depth in metres (0 where a ray misses everything),
        rgb from each box's "color" attribute, segmentation (H, W) int32 with box i as id i and
        -1 for the table and empty space, `instance_names` {name: [i]}, `instance_attributes`.
    """
    rays_cam = camera.pixel_rays().reshape(-1, 3)
    rotation, origin = camera.cam_to_world[:3, :3], camera.cam_to_world[:3, 3]
    rays = rays_cam @ rotation.T  # world directions scaled so that t is the camera z-depth
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / rays
    depth = np.full(len(rays), np.inf)
    ids = np.full(len(rays), -1, dtype=np.int32)
    colours = np.tile(np.array(_TABLE_RGB, dtype=np.uint8), (len(rays), 1))

    with np.errstate(invalid="ignore"):
        t_table = np.where(rays[:, 2] < 0, -origin[2] / rays[:, 2], np.inf)
    hit = origin[:2] + t_table[:, None] * rays[:, :2]
    on_table = np.all(np.abs(hit) <= table_half_extent, axis=1) & np.isfinite(t_table)
    depth[on_table] = t_table[on_table]

    for index, box in enumerate(boxes):
        with np.errstate(invalid="ignore"):
            t1 = (box.low - origin) * inv
            t2 = (box.high - origin) * inv
        t_near = np.nanmax(np.minimum(t1, t2), axis=1)
        t_far = np.nanmin(np.maximum(t1, t2), axis=1)
        hit = (t_near <= t_far) & (t_near > 0) & (t_near < depth)
        depth[hit] = t_near[hit]
        ids[hit] = index
        colours[hit] = _NAMED_RGB.get(box.attributes.get("color", ""), (100, 100, 100))

    depth[~np.isfinite(depth)] = 0.0
    shape = (camera.height, camera.width)
    return RGBDFrame(
        rgb=colours.reshape(*shape, 3),
        depth=depth.reshape(shape).astype(np.float32),
        camera=camera,
        segmentation=ids.reshape(shape),
        instance_names={box.name: [i] for i, box in enumerate(boxes)},
        instance_attributes={box.name: dict(box.attributes) for box in boxes},
    )
