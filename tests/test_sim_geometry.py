"""Rendered depth + segmentation back-project onto the right objects (intrinsics, extrinsics, ids)."""

import mujoco
import numpy as np
import pytest

from lano3dp.geometry import depth_to_points
from lano3dp.sim import TabletopEnv
from lano3dp.sim.scene import FRONT_CAMERA

TOLERANCE = 0.003  # metres


def body_box(model, body_id):
    """(low, high) of an axis-aligned box in the body frame that contains every geom of the body."""
    corners = []
    signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
    for g in np.flatnonzero(model.geom_bodyid == body_id):
        centre, half = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
        rotation = np.zeros(9)
        mujoco.mju_quat2Mat(rotation, model.geom_quat[g])
        local = (centre + signs * half) @ rotation.reshape(3, 3).T + model.geom_pos[g]
        corners.append(local)
    corners = np.concatenate(corners)
    return corners.min(0), corners.max(0)


@pytest.mark.parametrize("task,variation", [("bowl_pour", "clean"), ("bowl_pour", "clutter+camera"),
                                            ("bottle_upright", "similar")])
def test_object_points_lie_inside_their_object(task, variation):
    env = TabletopEnv(task, variation=variation, image_size=128, render_rgb=False)
    try:
        env.reset(seed=1)
        actions = env.expert_plan().actions()
        for action in actions[:40]:  # gripper above/at the object: occlusions and contacts included
            env.step(action)
        frame = env.frame()
        checked = 0
        for name, ids in frame.instance_names.items():
            mask = np.isin(frame.segmentation, ids)
            if mask.sum() < 5:
                continue
            points = depth_to_points(frame.depth, frame.camera, mask)
            bodies = frame.segmentation[mask & (frame.depth > 0)]
            inside = np.zeros(len(points), bool)
            for body in ids:
                sel = bodies == body
                low, high = body_box(env.model, body)
                local = (points[sel] - env.data.xpos[body]) @ env.data.xmat[body].reshape(3, 3)
                inside[sel] = np.all((local >= low - TOLERANCE) & (local <= high + TOLERANCE), axis=1)
            assert inside.mean() >= 0.99, f"{name}: only {inside.mean():.3f} of {len(points)} points inside"
            checked += 1
        assert checked >= 2
    finally:
        env.close()


def test_camera_model_matches_mujoco():
    env = TabletopEnv("bowl_pour", image_size=96, render_rgb=False)
    try:
        env.reset(seed=0)
        camera = env.camera
        np.testing.assert_allclose(camera.position, FRONT_CAMERA.position, atol=1e-9)
        # The optical axis (OpenCV +z) points at the look-at target.
        forward = camera.cam_to_world[:3, 2]
        to_target = np.subtract(FRONT_CAMERA.target, FRONT_CAMERA.position)
        np.testing.assert_allclose(forward, to_target / np.linalg.norm(to_target), atol=1e-6)
        assert camera.K[0, 0] == pytest.approx(0.5 * 96 / np.tan(np.deg2rad(FRONT_CAMERA.fovy) / 2))
        # The bowl's origin projects onto a bowl pixel (or right beside it).
        uv, depth = camera.project(env.sim.body_position("bowl")[None])
        u, v = np.round(uv[0]).astype(int)
        window = env.frame().segmentation[v - 2:v + 3, u - 2:u + 3]
        assert depth[0] > 0 and np.isin(window, env.instance_names["bowl"]).any()
    finally:
        env.close()
