"""A calibrated `RGBDFrame` with ground-truth instances from any MuJoCo model: your own simulator's camera.

    renderer = mujoco.Renderer(model, 96, 96)              # once; reused every step
    frame = mujoco_frame(model, data, "front", {"block": ["block"], "drawer": ["drawer_body"]},
                         96, 96, renderer=renderer, attributes={"block": {"color": "red"}})
    free = mujoco.MjvCamera()                              # or a camera the model does not have
    free.lookat, free.distance, free.azimuth, free.elevation = [1.3, 0.75, 0.45], 1.2, 180.0, -45.0
    frame = mujoco_frame(model, data, free, {"block": ["object0"]}, 96, 96, renderer=renderer)

Each slot names MuJoCo bodies or geoms; a body covers its own geoms and those of every body below it (a drawer
with its handle). The frame's `segmentation` holds the slot's index where a slot's geom is seen and -1
elsewhere, `instance_names` maps each slot to its index, and `instance_attributes` carries the words given
(kind, color, size; role "obstacle" marks what guidance keeps clear of), so `perception.SimOracleSegmenter`
resolves "the red block" or "block" as it does in the built-in simulator.

It uses the public `mujoco.Renderer` (three passes: colour, depth, segmentation), not the built-in simulator's
fused renderer, so it works with whatever MuJoCo version a user's simulator pins.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from lano3dp.errors import Lano3dpError
from lano3dp.geometry.camera import PinholeCamera
from lano3dp.geometry.frame import RGBDFrame


class MujocoFrameError(Lano3dpError, ValueError):
    """A camera, body or geom named for a frame is not in the model, or the renderer does not fit it."""


def mujoco_camera(model, data, camera, width: int, height: int) -> PinholeCamera:
    """Intrinsics and OpenCV camera-to-world pose of a model camera (name or id), or of a free `mujoco.MjvCamera`
    (lookat, distance, azimuth, elevation; the model's visual fovy), as `data` holds it (after mj_forward)."""
    import mujoco

    if isinstance(camera, mujoco.MjvCamera):
        scene = mujoco.MjvScene(model, maxgeom=1)
        mujoco.mjv_updateCamera(model, data, camera, scene)
        eyes = scene.camera  # two eyes, apart only in stereo: their midpoint is the head
        position = (np.asarray(eyes[0].pos) + np.asarray(eyes[1].pos)) / 2
        forward, up = np.asarray(eyes[0].forward, dtype=np.float64), np.asarray(eyes[0].up, dtype=np.float64)
        pose = PinholeCamera.opengl_pose_to_cam_to_world(position, np.column_stack([np.cross(forward, up), up,
                                                                                    -forward]))
        return PinholeCamera.from_fovy(width, height, float(model.vis.global_.fovy), pose)
    camera_id = _camera_id(model, camera)
    pose = PinholeCamera.opengl_pose_to_cam_to_world(data.cam_xpos[camera_id], data.cam_xmat[camera_id].reshape(3, 3))
    return PinholeCamera.from_fovy(width, height, float(model.cam_fovy[camera_id]), pose)


def slot_geoms(model, slots: Mapping[str, Sequence[str]]) -> dict[str, np.ndarray]:
    """{slot: body or geom names} -> {slot: (G,) int geom ids}; a body brings the geoms of its whole subtree.

    Raises:
        MujocoFrameError: a name that is neither a body nor a geom of the model (the error lists some of both).
    """
    import mujoco

    parents = np.asarray(model.body_parentid)
    geoms: dict[str, np.ndarray] = {}
    for slot, names in slots.items():
        ids: set[int] = set()
        for name in [names] if isinstance(names, str) else names:
            body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
            if body >= 0:
                ids.update(int(g) for g in np.flatnonzero(_in_subtree(parents, body)[model.geom_bodyid]))
                continue
            geom = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)
            if geom < 0:
                bodies = [model.body(i).name for i in range(1, min(model.nbody, 12))]
                raise MujocoFrameError(f"slot {slot!r}: the model has no body or geom named {name!r} (bodies: "
                                       f"{', '.join(b for b in bodies if b) or 'none named'})")
            ids.add(int(geom))
        if not ids:
            raise MujocoFrameError(f"slot {slot!r}: {names!r} holds no geoms")
        geoms[slot] = np.array(sorted(ids), dtype=np.int64)
    return geoms


def mujoco_frame(model, data, camera, slots: Mapping[str, Sequence[str]], width: int, height: int,
                 renderer=None, *, attributes: Mapping[str, Mapping[str, str]] | None = None, rgb: bool = True,
                 timestamp: float | None = None) -> RGBDFrame:
    """Render one camera of `model` as an `RGBDFrame` with the slots' instance segmentation.

    Args:
        model, data: the MuJoCo model and its current state (`mj_forward` or `mj_step` ran since the last change).
        camera: a camera name or id of the model, or a free `mujoco.MjvCamera` (a model without a camera on the
            scene: the view a gymnasium MuJoCo env's viewer uses).
        slots: {slot name: body or geom names}; the slot names are what the policy's slots and phrases say.
        width, height: image size in pixels (at most the model's offscreen buffer, <visual><global offwidth>).
        renderer: a `mujoco.Renderer(model, height, width)` to reuse (keep one per env); None makes and closes
            one for this call (a GL context each time: slow in a loop).
        attributes: per slot, words such as {"kind": "block", "color": "red", "role": "obstacle"}.
        rgb: render colour (False: black, one pass fewer; for point-cloud policies without videos).
        timestamp: seconds (default data.time).

    Returns:
        rgb (H, W, 3) uint8; depth (H, W) float32 z-depth in metres, 0 where no geom is seen; the calibrated
        camera; segmentation (H, W) int32, the slot index per pixel or -1; instance_names {slot: [index]}.
    """
    import mujoco

    camera_id = camera if isinstance(camera, mujoco.MjvCamera) else _camera_id(model, camera)
    own = renderer is None
    if own:
        _check_buffer(model, width, height)
        renderer = mujoco.Renderer(model, int(height), int(width))
    elif (renderer.height, renderer.width) != (height, width):
        raise MujocoFrameError(f"the renderer is {renderer.width}x{renderer.height}, the frame asked for "
                               f"{width}x{height}")
    try:
        renderer.update_scene(data, camera=camera_id)
        colour = renderer.render().copy() if rgb else np.zeros((height, width, 3), np.uint8)
        renderer.enable_depth_rendering()
        try:
            depth = renderer.render().astype(np.float32)
        finally:
            renderer.disable_depth_rendering()
        renderer.enable_segmentation_rendering()
        try:
            ids = renderer.render()  # (H, W, 2): object id, object type; -1 for the background
        finally:
            renderer.disable_segmentation_rendering()
    finally:
        if own:
            renderer.close()
    is_geom = ids[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM)
    geom_ids = np.where(is_geom, ids[..., 0], -1)
    segmentation = np.full((height, width), -1, dtype=np.int32)
    names = list(slots)
    for index, geoms in enumerate(slot_geoms(model, slots).values()):
        segmentation[np.isin(geom_ids, geoms)] = index
    depth[~is_geom] = 0.0  # sky or a site: no surface
    described = {name: {"kind": name} | dict((attributes or {}).get(name, {})) for name in names}
    return RGBDFrame(rgb=colour, depth=depth, camera=mujoco_camera(model, data, camera_id, width, height),
                     segmentation=segmentation, instance_names={name: [i] for i, name in enumerate(names)},
                     instance_attributes=described, timestamp=float(data.time if timestamp is None else timestamp))


def _camera_id(model, camera: str | int) -> int:
    import mujoco

    camera_id = camera if isinstance(camera, int) else mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
    if not 0 <= camera_id < model.ncam:
        cameras = [model.camera(i).name or str(i) for i in range(model.ncam)]
        raise MujocoFrameError(f"the model has no camera {camera!r} (cameras: {', '.join(cameras) or 'none'}); "
                               "add <camera name=... pos=... xyaxes=.../> to the model")
    return int(camera_id)


def _check_buffer(model, width: int, height: int) -> None:
    offwidth, offheight = model.vis.global_.offwidth, model.vis.global_.offheight
    if width > offwidth or height > offheight:
        raise MujocoFrameError(f"image {width}x{height} exceeds the model's offscreen buffer {offwidth}x{offheight}; "
                               f"add <visual><global offwidth=\"{width}\" offheight=\"{height}\"/></visual>")


def _in_subtree(parents: np.ndarray, root: int) -> np.ndarray:
    """(nbody,) bool: the body is `root` or below it (parents come before their children in MuJoCo)."""
    inside = np.zeros(len(parents), dtype=bool)
    inside[root] = True
    for body in range(root + 1, len(parents)):
        inside[body] = inside[parents[body]]
    return inside
