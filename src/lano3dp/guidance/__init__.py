"""Training-free, cost-guided sampling (the paper's Algorithm 1), obstacle costs and checked execution."""

from lano3dp.guidance.checked import CheckConfig, CheckedResult, checked_sample
from lano3dp.guidance.costs import (
    Cylinder,
    Densified,
    MetricGradient,
    Obstacle,
    ObstacleSet,
    OrientedBox,
    PointCloudObstacle,
    PositionCost,
    Sphere,
    SweptBody,
    densify,
    min_clearance,
)
from lano3dp.guidance.exceptions import CollisionError, GuidanceError
from lano3dp.guidance.fitting import fit_box, fit_cylinder
from lano3dp.guidance.sampler import DenoiseStep, GuidanceConfig, GuidanceMode, denoise

__all__ = [
    "CheckConfig", "CheckedResult", "CollisionError", "Cylinder", "DenoiseStep", "Densified", "GuidanceConfig",
    "GuidanceError", "GuidanceMode", "MetricGradient", "Obstacle", "ObstacleSet", "OrientedBox", "PointCloudObstacle",
    "PositionCost", "Sphere", "SweptBody", "checked_sample", "denoise", "densify", "fit_box", "fit_cylinder", "min_clearance",
]
