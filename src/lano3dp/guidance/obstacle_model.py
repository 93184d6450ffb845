"""How an obstacle's segmented points become a guidance cost, and what moving body the cost keeps clear.

`runtime.PolicyRunner` fits one per obstacle before a chunk (`fit`) and, with the swept body, measures the hand's
balls from the EE rotation (`hand_balls`); `costs.obstacle_guidance_cost` turns both into the cost guidance descends.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lano3dp.guidance.costs import PositionCost
from lano3dp.guidance.settings import BODY_MODELS, SAFETY_MARGIN, ObstacleSettings
from lano3dp.guidance.shapes import fit_obstacle, get_obstacle_shape


@dataclass(frozen=True)
class ObstacleModel:
    """How an obstacle's segmented points become a guidance cost.

    Attributes:
        shape: a registered obstacle shape (`guidance.shapes`): "cylinder" (the paper: vertical cylinder, xy
            hinge), "box" (yaw-oriented box), "points" (nearest segmented point), or one registered with
            `guidance.register_obstacle_shape`.
        margin: metres beyond contact at which the cost starts pushing (part of Q*).
        body: what must stay clear. "swept" (default, beyond the paper): the hand as a row of balls along the
            EE's finger axis, plus, while the state's grasp flag is set, the held object as a ball at its fitted
            centre; re-measured before every chunk (`guidance.costs.SweptBody`). "sphere" (the paper): one ball of
            `held_radius` round the EE point for the whole episode.
        held_radius: ("sphere") metres around the EE point that must stay clear (gripper + held object). None:
            measure it from the held object's cloud (`held_object` of the runner) as `held_extent` x its radius.
        held_extent: ("sphere") multiple of the held object's fitted radius; 2.0 = its diameter (the paper's
            choice, as a rim grasp puts the object's far side a diameter away from the EE).
        gripper_radius: ("sphere") lower bound of the held radius (m): the open hand's half-span about the EE
            axis (the simulator's palm is 13 cm wide; with 2 cm, the fingers alone, the palm hit obstacles).
        hand_half_span, hand_radius: ("swept") the hand's half length along the EE y (finger) axis and its
            half thickness, m; the defaults cover the simulator's 13 x 4 cm palm and its fingers.
        xy_only: measure distances in the horizontal plane only (the paper's setting).
        refit_every_chunk: re-segment and re-fit obstacles before every chunk (moving obstacles); by default
            they are fitted once, on the first frame of the episode, before the arm can occlude them.
    """

    shape: str = ObstacleSettings.shape
    margin: float = SAFETY_MARGIN
    body: str = ObstacleSettings.body
    held_radius: float | None = None
    held_extent: float = 2.0
    gripper_radius: float = 0.07
    hand_half_span: float = 0.065
    hand_radius: float = 0.025
    xy_only: bool = True
    refit_every_chunk: bool = False

    def __post_init__(self):
        get_obstacle_shape(self.shape)  # an unknown name fails here, naming the registered ones
        if self.body not in BODY_MODELS:
            raise ValueError(f"obstacle body model must be one of {BODY_MODELS}, got {self.body!r}")
        if self.body == "swept" and self.held_radius is not None:
            raise ValueError("held_radius sizes the 'sphere' body model; the 'swept' body measures the hand and "
                             "the held object itself (pass body='sphere' to fix a radius)")
        if not 0 < self.hand_radius <= self.hand_half_span:
            raise ValueError(f"need 0 < hand_radius <= hand_half_span, got {self.hand_radius}, {self.hand_half_span}")
        if self.margin < 0 or self.gripper_radius < 0 or self.held_extent < 0:
            raise ValueError(f"margin, gripper_radius and held_extent must be >= 0 in {self}")
        if self.held_radius is not None and self.held_radius < 0:
            raise ValueError(f"held_radius must be >= 0, got {self.held_radius}")

    def hand_balls(self, rotation6d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(K, 3) world offsets and (K,) radii of the hand's balls for an EE rotation (6D: x then y column)."""
        finger_axis = np.asarray(rotation6d[3:6], dtype=np.float64)
        finger_axis = finger_axis / max(np.linalg.norm(finger_axis), 1e-9)
        reach = self.hand_half_span - self.hand_radius
        # balls 2 cm apart at most, so the hand's outline between two of them dips by a few mm only
        count = 2 * int(np.ceil(reach / 0.02)) + 1
        along = np.linspace(-reach, reach, count)
        return along[:, None] * finger_axis, np.full(count, self.hand_radius)

    def passable_gap(self, held_radius: float) -> float:
        """The narrowest gap (m) between two obstacle surfaces the body can pass keeping the margin on both sides:
        the hand's thickness (it can turn its long side along the gap) or, with the "sphere" body, the ball's
        diameter."""
        half = self.hand_radius if self.body == "swept" else held_radius
        return 2 * (half + self.margin)

    def fit(self, points: np.ndarray, held_radius: float) -> PositionCost:
        """(N, 3) world-frame obstacle points -> a cost whose safety distance includes `held_radius` (m), fitted
        by the registered shape; EmptyCloudError when the points are too few for it."""
        return fit_obstacle(self.shape, points, held_radius=held_radius, margin=self.margin, xy_only=self.xy_only)
