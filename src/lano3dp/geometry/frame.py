"""The one frame type every image source yields (simulator, RealSense, a user's robot)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lano3dp.geometry.camera import PinholeCamera


@dataclass
class RGBDFrame:
    """An aligned colour + depth image from one calibrated camera.

    Attributes:
        rgb: (H, W, 3) uint8.
        depth: (H, W) float32 z-depth in metres; 0 or NaN marks a hole.
        camera: intrinsics and camera-to-world pose.
        segmentation: optional (H, W) int32 instance ids (simulator ground truth), -1 = background.
        instance_names: for `segmentation`, a map from object name to the instance ids it covers.
        instance_attributes: per object name, descriptive words (e.g. {"bowl_1": {"color": "red", "kind": "bowl"}}).
        timestamp: seconds.
    """

    rgb: np.ndarray
    depth: np.ndarray
    camera: PinholeCamera
    segmentation: np.ndarray | None = None
    instance_names: dict[str, list[int]] = field(default_factory=dict)
    instance_attributes: dict[str, dict[str, str]] = field(default_factory=dict)
    timestamp: float = 0.0

    def __post_init__(self):
        h, w = self.depth.shape[:2]
        if self.depth.ndim != 2:
            raise ValueError(f"depth must be (H, W), got {self.depth.shape}")
        if self.rgb.shape[:2] != (h, w):
            raise ValueError(f"rgb {self.rgb.shape} and depth {self.depth.shape} are not aligned")
        if (self.camera.height, self.camera.width) != (h, w):
            raise ValueError(
                f"camera is {self.camera.width}x{self.camera.height} but the image is {w}x{h}"
            )
        if self.segmentation is not None and self.segmentation.shape[:2] != (h, w):
            raise ValueError(f"segmentation {self.segmentation.shape} does not match depth {self.depth.shape}")
