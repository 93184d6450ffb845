"""RealSense source: the numpy projection path, and a clear error without pyrealsense2."""

import builtins
import importlib.util

import numpy as np
import pytest

from lano3dp.geometry import depth_to_points
from lano3dp.perception.realsense import (
    RealSenseSource,
    RealSenseUnavailableError,
    camera_from_intrinsics,
    frame_from_arrays,
)

# D415-like colour intrinsics at 640x480.
INTRINSICS = dict(width=640, height=480, fx=615.0, fy=615.5, ppx=321.7, ppy=238.2)


def rs2_deproject(u, v, depth, fx, fy, ppx, ppy, **_):
    """librealsense's rs2_deproject_pixel_to_point without distortion (its documented formula)."""
    return np.array([(u - ppx) / fx * depth, (v - ppy) / fy * depth, depth])


def test_raw_depth_becomes_metres_and_points_match_librealsense():
    camera = camera_from_intrinsics(**INTRINSICS)
    raw = np.zeros((480, 640), np.uint16)
    raw[40, 620] = 500  # 0.5 m at 1 mm per unit
    raw[300, 10] = 1234
    frame = frame_from_arrays(np.zeros((480, 640, 3), np.uint8), raw, 0.001, camera, timestamp=2.5)
    assert frame.depth.dtype == np.float32 and frame.depth[40, 620] == pytest.approx(0.5)
    assert frame.depth[0, 0] == 0.0 and frame.timestamp == 2.5
    points = depth_to_points(frame.depth, camera)  # row-major: (40, 620) first, then (300, 10)
    np.testing.assert_allclose(points[0], rs2_deproject(620, 40, 0.5, **INTRINSICS), atol=1e-6)
    np.testing.assert_allclose(points[1], rs2_deproject(10, 300, 1.234, **INTRINSICS), atol=1e-6)


def test_extrinsic_moves_points_into_the_robot_frame():
    cam_to_world = np.eye(4)
    cam_to_world[:3, :3] = np.diag([1.0, -1.0, -1.0])  # looking straight down
    cam_to_world[:3, 3] = [0.4, 0.0, 0.8]
    camera = camera_from_intrinsics(**INTRINSICS, cam_to_world=cam_to_world)
    raw = np.zeros((480, 640), np.uint16)
    raw[238, 321] = 800  # about the principal point, 0.8 m below the camera: the table at z = 0
    (point,) = depth_to_points(frame_from_arrays(np.zeros((480, 640, 3), np.uint8), raw, 0.001, camera).depth, camera)
    np.testing.assert_allclose(point, [0.4, 0.0, 0.0], atol=1e-3)


@pytest.mark.skipif(importlib.util.find_spec("pyrealsense2") is not None, reason="pyrealsense2 is installed")
def test_missing_pyrealsense2_gives_install_instructions():
    with pytest.raises(RealSenseUnavailableError, match=r"pip install 'lano3dp\[realsense\]'.*libusb"):
        RealSenseSource().start()


def test_import_failure_of_libusb_is_reported_the_same_way(monkeypatch):
    real_import = builtins.__import__

    def failing_import(name, *args, **kwargs):
        if name == "pyrealsense2":
            raise ImportError("libusb-1.0.so.0: cannot open shared object file")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", failing_import)
    with pytest.raises(RealSenseUnavailableError, match="libusb-1.0.so.0") as info:
        RealSenseSource().read()
    assert isinstance(info.value, ImportError)
