"""Camera models, back-projection, cropping, farthest-point sampling and rotations."""

from lano3dp.geometry.camera import PinholeCamera
from lano3dp.geometry.frame import RGBDFrame
from lano3dp.geometry.pointcloud import (
    crop_to_box,
    depth_to_points,
    farthest_point_sample,
    mask_to_points,
)
from lano3dp.geometry.rotations import (
    matrix_to_quat,
    matrix_to_rot6d,
    quat_to_matrix,
    rot6d_to_matrix,
)

__all__ = [
    "PinholeCamera",
    "RGBDFrame",
    "crop_to_box",
    "depth_to_points",
    "farthest_point_sample",
    "mask_to_points",
    "matrix_to_quat",
    "matrix_to_rot6d",
    "quat_to_matrix",
    "rot6d_to_matrix",
]
