"""Intel RealSense source yielding `RGBDFrame`s (optional extra: `pip install 'lano3dp[realsense]'`).

`pyrealsense2` is imported only when a camera is opened; it also needs the system library
libusb-1.0 (Debian/Ubuntu: `apt-get install libusb-1.0-0`). The conversion from raw streams to an
RGBDFrame is plain numpy (`camera_from_intrinsics`, `frame_from_arrays`) and is what the tests check.

Pixel convention: librealsense (like OpenCV) puts pixel centres at integer coordinates, while
`PinholeCamera` puts them at +0.5; hence cx = ppx + 0.5 and cy = ppy + 0.5.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np

from lano3dp.geometry.camera import PinholeCamera
from lano3dp.geometry.frame import RGBDFrame
from lano3dp.perception.exceptions import PerceptionError


class RealSenseUnavailableError(PerceptionError, ImportError):
    """pyrealsense2 (or its libusb dependency) is missing, or no camera is connected."""


def camera_from_intrinsics(
    width: int, height: int, fx: float, fy: float, ppx: float, ppy: float, cam_to_world=None
) -> PinholeCamera:
    """PinholeCamera from librealsense intrinsics (rs.intrinsics fields), distortion ignored
    (the D400 colour stream reports Brown-Conrady with zero coefficients)."""
    K = np.array([[fx, 0.0, ppx + 0.5], [0.0, fy, ppy + 0.5], [0.0, 0.0, 1.0]])
    return PinholeCamera(int(width), int(height), K, np.eye(4) if cam_to_world is None else cam_to_world)


def frame_from_arrays(
    color: np.ndarray, depth_raw: np.ndarray, depth_scale: float, camera: PinholeCamera, timestamp: float = 0.0
) -> RGBDFrame:
    """RGBDFrame from a colour image (H, W, 3) uint8 RGB and a raw z16 depth image (H, W) uint16 aligned
    to it; `depth_scale` is metres per unit (0.001 on D400). Raw 0 (no data) stays 0, a hole."""
    depth = np.asarray(depth_raw).astype(np.float32) * np.float32(depth_scale)
    return RGBDFrame(rgb=np.ascontiguousarray(color, dtype=np.uint8), depth=depth, camera=camera, timestamp=timestamp)


def _import_pyrealsense2():
    try:
        import pyrealsense2 as rs
    except ImportError as error:
        raise RealSenseUnavailableError(
            f"the RealSense source needs pyrealsense2 ({error}); install it with "
            "pip install 'lano3dp[realsense]' and the system library libusb-1.0 (apt-get install libusb-1.0-0)"
        ) from error
    return rs


class RealSenseSource:
    """Streams aligned colour + depth from one RealSense camera.

    Args:
        width, height, fps: stream settings (both streams).
        cam_to_world: (4, 4) extrinsic calibration of the camera in the robot base frame.
        serial: a specific camera's serial number (None: the first one found).
    """

    def __init__(
        self, width: int = 640, height: int = 480, fps: int = 30, cam_to_world=None, serial: str | None = None
    ):
        self.width, self.height, self.fps = width, height, fps
        self.cam_to_world = np.eye(4) if cam_to_world is None else np.asarray(cam_to_world, dtype=np.float64)
        self.serial = serial
        self._pipeline = None

    def start(self) -> RealSenseSource:
        rs = _import_pyrealsense2()
        config = rs.config()
        if self.serial:
            config.enable_device(self.serial)
        config.enable_stream(rs.stream.color, self.width, self.height, rs.format.rgb8, self.fps)
        config.enable_stream(rs.stream.depth, self.width, self.height, rs.format.z16, self.fps)
        pipeline = rs.pipeline()
        try:
            profile = pipeline.start(config)
        except RuntimeError as error:
            raise RealSenseUnavailableError(f"cannot start the RealSense camera: {error}") from error
        self._rs = rs
        self._align = rs.align(rs.stream.color)
        self._depth_scale = profile.get_device().first_depth_sensor().get_depth_scale()
        intr = profile.get_stream(rs.stream.color).as_video_stream_profile().get_intrinsics()
        self.camera = camera_from_intrinsics(
            intr.width, intr.height, intr.fx, intr.fy, intr.ppx, intr.ppy, self.cam_to_world
        )
        self._pipeline = pipeline
        return self

    def read(self, timeout_ms: int = 5000) -> RGBDFrame:
        """The next aligned frame."""
        if self._pipeline is None:
            self.start()
        frames = self._align.process(self._pipeline.wait_for_frames(timeout_ms))
        color, depth = frames.get_color_frame(), frames.get_depth_frame()
        return frame_from_arrays(
            np.asanyarray(color.get_data()),
            np.asanyarray(depth.get_data()),
            self._depth_scale,
            self.camera,
            timestamp=time.monotonic(),
        )

    def __iter__(self) -> Iterator[RGBDFrame]:
        while True:
            yield self.read()

    def stop(self) -> None:
        if self._pipeline is not None:
            self._pipeline.stop()
            self._pipeline = None

    def __enter__(self) -> RealSenseSource:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
