"""Camera model, back-projection, cropping, FPS and rotations."""

import numpy as np
import pytest
import torch

from lano3dp.errors import EmptyCloudError
from lano3dp.geometry import (
    PinholeCamera,
    RGBDFrame,
    crop_to_box,
    depth_to_points,
    farthest_point_sample,
    mask_to_points,
    matrix_to_quat,
    matrix_to_rot6d,
    quat_to_matrix,
    rot6d_to_matrix,
)
from lano3dp.geometry.rotations import quat_to_rot6d, rot6d_to_quat


def random_rotations(count, seed=0):
    quats = np.random.default_rng(seed).normal(size=(count, 4))
    return quat_to_matrix(quats / np.linalg.norm(quats, axis=-1, keepdims=True))


def looking_down_camera(height=1.0, width=64, rows=48, fovy=60.0):
    """A camera at (0, 0, height) looking straight down at the z = 0 plane."""
    cam_to_world = np.eye(4)
    cam_to_world[:3, :3] = np.diag([1.0, -1.0, -1.0])  # OpenCV z forward = world -z
    cam_to_world[2, 3] = height
    return PinholeCamera.from_fovy(width, rows, fovy, cam_to_world)


def test_intrinsics_from_fovy_put_the_principal_point_at_the_centre():
    camera = PinholeCamera.from_fovy(320, 240, 90.0)
    assert camera.K[0, 0] == pytest.approx(120.0)  # 0.5 * 240 / tan(45 deg)
    assert camera.K[:2, 2] == pytest.approx([160.0, 120.0])


def test_bad_calibration_is_rejected_with_a_reason():
    with pytest.raises(ValueError, match="orthonormal"):
        PinholeCamera(10, 10, np.eye(3) * 5 + np.diag([0, 0, -4]), np.diag([2.0, 1, 1, 1]))
    with pytest.raises(ValueError, match="focal"):
        PinholeCamera(10, 10, np.zeros((3, 3)))


def test_flat_depth_back_projects_onto_the_plane_and_inside_the_view_frustum():
    camera = looking_down_camera(height=1.0)
    points = depth_to_points(np.ones((48, 64), np.float32), camera)
    assert points.shape == (48 * 64, 3)
    assert np.allclose(points[:, 2], 0.0, atol=1e-6)
    half_height = np.tan(np.deg2rad(30.0))  # fovy 60 at 1 m
    assert np.abs(points[:, 1]).max() < half_height
    assert np.abs(points[:, 1]).max() > 0.95 * half_height


def test_projection_inverts_back_projection():
    camera = looking_down_camera(height=0.8)
    depth = np.random.default_rng(1).uniform(0.3, 0.8, size=(48, 64)).astype(np.float32)
    points = depth_to_points(depth, camera)
    uv, z = camera.project(points)
    rows, cols = np.divmod(np.arange(48 * 64), 64)
    assert np.allclose(uv, np.stack([cols + 0.5, rows + 0.5], -1), atol=1e-3)
    assert np.allclose(z, depth.reshape(-1), atol=1e-5)


def test_opengl_pose_conversion_matches_a_mujoco_style_camera():
    # An OpenGL camera at z = 1 with identity rotation looks down the world -z axis.
    camera = PinholeCamera.from_fovy(8, 8, 60.0, PinholeCamera.opengl_pose_to_cam_to_world([0, 0, 1], np.eye(3)))
    centre = depth_to_points(np.full((8, 8), 0.5, np.float32), camera).mean(0)
    assert np.allclose(centre, [0, 0, 0.5], atol=1e-6)


def test_holes_nan_and_masks_are_dropped():
    camera = looking_down_camera()
    depth = np.ones((48, 64), np.float32)
    depth[0, :] = 0.0
    depth[1, :] = np.nan
    depth[2, :] = -1.0
    assert len(depth_to_points(depth, camera)) == 45 * 64
    mask = np.zeros((48, 64), bool)
    mask[10:12, 5:8] = True
    assert len(depth_to_points(depth, camera, mask)) == 6


def test_mask_without_valid_depth_names_the_object():
    camera = looking_down_camera()
    depth = np.zeros((48, 64), np.float32)
    mask = np.ones((48, 64), bool)
    with pytest.raises(EmptyCloudError, match="red bowl"):
        mask_to_points(depth, camera, mask, name="red bowl")


def test_crop_keeps_only_points_in_the_box():
    points = np.array([[0, 0, 0], [1, 1, 1], [0.5, 0.2, 0.9], [2, 0, 0]], np.float32)
    kept = crop_to_box(points, [0, 0, 0], [1, 1, 1])
    assert len(kept) == 3
    with pytest.raises(ValueError, match="inverted"):
        crop_to_box(points, [1, 0, 0], [0, 1, 1])


def test_fps_returns_spread_out_points_and_is_seeded():
    rng = np.random.default_rng(0)
    # Two tight clusters far apart: FPS must sample both; a random subset of 2 rarely would.
    cloud = np.concatenate([rng.normal(0, 0.01, (5000, 3)), rng.normal(1, 0.01, (20, 3))]).astype(np.float32)
    sample = farthest_point_sample(cloud, 8, seed=3)
    assert sample.shape == (8, 3) and sample.dtype == np.float32
    assert (sample[:, 0] > 0.5).any() and (sample[:, 0] < 0.5).any()
    assert np.array_equal(sample, farthest_point_sample(cloud, 8, seed=3))
    big = rng.uniform(size=(20000, 3)).astype(np.float32)  # the bucket (QuickFPS) path
    sample = farthest_point_sample(big, 256, seed=0)
    coverage = np.sqrt(((big[:, None, :] - sample[None, :32]) ** 2).sum(-1)).min(1).max()
    assert sample.shape == (256, 3) and coverage < 0.6


def test_fps_with_fewer_points_than_asked_repeats_input_points():
    cloud = np.arange(12, dtype=np.float32).reshape(4, 3)
    sample = farthest_point_sample(cloud, 10, seed=0)
    assert sample.shape == (10, 3)
    assert {tuple(p) for p in sample} == {tuple(p) for p in cloud}  # every input kept, nothing invented


def test_fps_of_an_empty_or_all_nan_cloud_is_an_error():
    with pytest.raises(EmptyCloudError, match="pan"):
        farthest_point_sample(np.zeros((0, 3)), 4, name="pan")
    with pytest.raises(EmptyCloudError):
        farthest_point_sample(np.full((5, 3), np.nan), 4)


def test_rotation_round_trips_numpy_and_torch():
    matrices = random_rotations(50)
    assert np.allclose(rot6d_to_matrix(matrix_to_rot6d(matrices)), matrices, atol=1e-9)
    quats = matrix_to_quat(matrices)
    assert np.allclose(quat_to_matrix(quats), matrices, atol=1e-9)
    assert np.all(quats[:, 0] >= 0)
    assert np.allclose(rot6d_to_quat(quat_to_rot6d(quats)), quats, atol=1e-9)
    as_torch = torch.tensor(matrices, dtype=torch.float64)
    assert torch.allclose(rot6d_to_matrix(matrix_to_rot6d(as_torch)), as_torch, atol=1e-9)


def test_rot6d_to_matrix_orthonormalises_a_noisy_prediction():
    noisy = matrix_to_rot6d(random_rotations(10)) + np.random.default_rng(2).normal(0, 0.05, (10, 6))
    matrices = rot6d_to_matrix(noisy)
    assert np.allclose(matrices @ np.swapaxes(matrices, -1, -2), np.eye(3), atol=1e-9)
    assert np.allclose(np.linalg.det(matrices), 1.0)


def test_frame_rejects_misaligned_images():
    camera = PinholeCamera.from_fovy(64, 48, 60)
    with pytest.raises(ValueError, match="not aligned"):
        RGBDFrame(np.zeros((10, 10, 3), np.uint8), np.zeros((48, 64), np.float32), camera)
    with pytest.raises(ValueError, match="camera is 64x48"):
        RGBDFrame(np.zeros((10, 10, 3), np.uint8), np.zeros((10, 10), np.float32), camera)
