"""The body guidance keeps clear, and one obstacle's fit, from `ObstacleSettings` (pure functions)."""

from __future__ import annotations

import numpy as np

from lano3dp.guidance.costs import PositionCost
from lano3dp.guidance.settings import ObstacleSettings
from lano3dp.guidance.shapes import fit_obstacle


def hand_balls(settings: ObstacleSettings, rotation6d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K, 3) world offsets from the EE point and (K,) radii (m) of the hand's balls for an EE rotation (6D: x
    then y column): a row along the finger axis covering `hand_half_span`, each of `hand_radius`."""
    finger_axis = np.asarray(rotation6d[3:6], dtype=np.float64)
    finger_axis = finger_axis / max(np.linalg.norm(finger_axis), 1e-9)
    reach = settings.hand_half_span - settings.hand_radius
    # balls 2 cm apart at most, so the hand's outline between two of them dips by a few mm only
    count = 2 * int(np.ceil(reach / 0.02)) + 1
    along = np.linspace(-reach, reach, count)
    return along[:, None] * finger_axis, np.full(count, settings.hand_radius)


def passable_gap(settings: ObstacleSettings, held_radius: float) -> float:
    """The narrowest gap (m) between two obstacle surfaces the body passes keeping the margin on both sides: the
    hand's thickness (it can turn its long side along the gap) or, with the "sphere" body, the ball's diameter."""
    half = settings.hand_radius if settings.body == "swept" else held_radius
    return 2 * (half + settings.margin)


def fit_obstacle_shape(settings: ObstacleSettings, points: np.ndarray, held_radius: float) -> PositionCost:
    """(N, 3) world-frame obstacle points -> the registered shape's cost, its safety distance holding
    `held_radius` (m) and the margin; EmptyCloudError when the points are too few for it."""
    return fit_obstacle(settings.shape, points, held_radius=held_radius, margin=settings.margin,
                        xy_only=settings.xy_only)
