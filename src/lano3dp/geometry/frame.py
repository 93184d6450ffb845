"""The one frame type every image source yields (simulator, RealSense, a user's robot), and how an env's
observation becomes one (`observe`, shared by collection and the runtime)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

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


def observe(env, obs: Any) -> tuple[RGBDFrame, np.ndarray]:
    """The env's observation -> (frame, state (11,) float32).

    The frame is `obs["frame"]` when the observation carries one, else `env.frame()` (the simulator's
    RGBDFrame with ground-truth instances), else it is assembled from the observation's "rgb", "depth",
    "intrinsics" and "cam_to_world" (and "segmentation" when present).
    """
    state = observed_state(obs)
    if isinstance(obs, Mapping):
        if "frame" in obs:
            frame = obs["frame"]
        elif callable(getattr(env, "frame", None)):
            frame = env.frame()
        else:
            depth = np.asarray(obs["depth"], dtype=np.float32)
            height, width = depth.shape
            rgb = obs.get("rgb")
            frame = RGBDFrame(rgb=np.zeros((height, width, 3), np.uint8) if rgb is None else rgb, depth=depth,
                              camera=PinholeCamera(width, height, obs["intrinsics"], obs["cam_to_world"]),
                              segmentation=obs.get("segmentation"))
    else:
        frame = obs.frame
    if not isinstance(frame, RGBDFrame):
        raise TypeError(f"observation 'frame' must be an RGBDFrame, got {type(frame).__name__}")
    return frame, state


def observed_state(obs: Any) -> np.ndarray:
    """The robot state (11,) float32 of an observation: its "state", or its `state` attribute."""
    if isinstance(obs, Mapping):
        if "state" not in obs:
            raise KeyError(f"observation needs a 'state' (11,), got keys {sorted(obs)}")
        state = obs["state"]
    else:
        state = obs.state
    state = np.asarray(state, dtype=np.float32)
    if state.shape != (11,):
        raise ValueError(f"robot state must be (11,), got {state.shape}")
    return state


def resize_rgb(rgb: np.ndarray, size: int) -> np.ndarray:
    """(H, W, 3) uint8 -> (size, size, 3) uint8, area-averaged with PIL's box filter: what the demonstration
    collector stores and the runtime feeds the image baseline: one function, so both see the same pixels."""
    if rgb.shape[:2] == (size, size):
        return np.ascontiguousarray(rgb, dtype=np.uint8)
    from PIL import Image

    return np.asarray(Image.fromarray(np.ascontiguousarray(rgb, dtype=np.uint8)).resize(
        (size, size), Image.Resampling.BOX))
