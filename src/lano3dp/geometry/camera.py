"""Pinhole camera: intrinsics K and a camera-to-world extrinsic.

Camera frame convention is OpenCV's: x right, y down, z forward (depth > 0).
MuJoCo and OpenGL cameras look along -z with y up; `from_opengl_pose` converts.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# OpenGL camera axes (x right, y up, looking along -z) expressed in OpenCV axes.
_OPENGL_TO_OPENCV = np.diag([1.0, -1.0, -1.0])


@dataclass(frozen=True)
class PinholeCamera:
    """Intrinsics and pose of one camera.

    Attributes:
        width, height: image size in pixels.
        K: (3, 3) intrinsic matrix, pixels.
        cam_to_world: (4, 4) homogeneous transform from the OpenCV camera frame to the world, metres.
    """

    width: int
    height: int
    K: np.ndarray
    cam_to_world: np.ndarray = field(default_factory=lambda: np.eye(4))

    def __post_init__(self):
        K = np.asarray(self.K, dtype=np.float64)
        T = np.asarray(self.cam_to_world, dtype=np.float64)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ValueError(f"camera intrinsics must be a finite 3x3 matrix with positive focal lengths, got {K}")
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ValueError(f"cam_to_world must be a finite 4x4 matrix, got shape {T.shape}")
        rotation = T[:3, :3]
        if not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-4):
            raise ValueError("cam_to_world rotation is not orthonormal; is the extrinsic calibration valid?")
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"image size must be positive, got {self.width}x{self.height}")
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "cam_to_world", T)

    @classmethod
    def from_fovy(cls, width: int, height: int, fovy_deg: float, cam_to_world=None) -> PinholeCamera:
        """Square-pixel camera with vertical field of view `fovy_deg`, principal point at the centre."""
        if not 0.0 < fovy_deg < 180.0:
            raise ValueError(f"fovy must be in (0, 180) degrees, got {fovy_deg}")
        focal = 0.5 * height / np.tan(np.deg2rad(fovy_deg) / 2.0)
        K = np.array([[focal, 0.0, width / 2.0], [0.0, focal, height / 2.0], [0.0, 0.0, 1.0]])
        return cls(width, height, K, np.eye(4) if cam_to_world is None else cam_to_world)

    @staticmethod
    def opengl_pose_to_cam_to_world(position, rotation_opengl) -> np.ndarray:
        """(4, 4) OpenCV camera-to-world from an OpenGL/MuJoCo camera pose (columns = camera axes)."""
        T = np.eye(4)
        T[:3, :3] = np.asarray(rotation_opengl, dtype=np.float64).reshape(3, 3) @ _OPENGL_TO_OPENCV
        T[:3, 3] = np.asarray(position, dtype=np.float64)
        return T

    @property
    def position(self) -> np.ndarray:
        return self.cam_to_world[:3, 3]

    def with_pose(self, cam_to_world) -> PinholeCamera:
        return PinholeCamera(self.width, self.height, self.K, cam_to_world)

    def pixel_rays(self) -> np.ndarray:
        """(H, W, 3) camera-frame rays with z = 1 through pixel centres."""
        u = np.arange(self.width) + 0.5
        v = np.arange(self.height) + 0.5
        uu, vv = np.meshgrid(u, v)
        fx, fy, cx, cy = self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2]
        return np.stack([(uu - cx) / fx, (vv - cy) / fy, np.ones_like(uu)], axis=-1)

    def project(self, points_world) -> tuple[np.ndarray, np.ndarray]:
        """Project world points (N, 3) to pixels.

        Returns:
            uv: (N, 2) pixel coordinates (u right, v down).
            depth: (N,) z in the camera frame, metres (<= 0 means behind the camera).
        """
        pts = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        world_to_cam = np.linalg.inv(self.cam_to_world)
        cam = pts @ world_to_cam[:3, :3].T + world_to_cam[:3, 3]
        z = cam[:, 2]
        safe_z = np.where(np.abs(z) < 1e-9, 1e-9, z)
        uv = (cam[:, :2] / safe_z[:, None]) * np.array([self.K[0, 0], self.K[1, 1]]) + self.K[:2, 2]
        return uv, z

    def to_dict(self) -> dict:
        return {
            "width": int(self.width),
            "height": int(self.height),
            "K": self.K.tolist(),
            "cam_to_world": self.cam_to_world.tolist(),
        }

    @classmethod
    def from_dict(cls, data: dict) -> PinholeCamera:
        return cls(int(data["width"]), int(data["height"]), np.array(data["K"]), np.array(data["cam_to_world"]))
