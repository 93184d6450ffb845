"""The one cost recipe: from the tracked obstacles and the body to what guidance descends and what filters check.

    guidance_cost    the cost on the sampled waypoints (the paper's obstacle cost on A_0|k), with this project's
                     additions as `CostSettings` chooses: the swept body, the path densified and costed from the
                     hand, the push in metres and turned round each obstacle (`costs.obstacle_guidance_cost`)
    executed_path    the cost on the path the arm will really take through a chunk's executed waypoints
                     (`costs.ExecutedPath`): what the chunk filters repair, cut and follow along
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import torch

from lano3dp.geometry.frame import RGBDFrame
from lano3dp.geometry.rotations import rot6d_to_matrix
from lano3dp.guidance.costs import ExecutedPath, PositionCost, obstacle_guidance_cost
from lano3dp.guidance.obstacles import GRASP_FLAG, ObstacleTracker, hand_balls
from lano3dp.guidance.settings import GuidanceSettings


class CostRecipe:
    """Builds a chunk's costs from the tracker, for one policy.

    Args:
        settings: the cost and obstacle sections are read.
        action_scale: () -> (3,) the policy's action normaliser scale of the position (1/m), for the push in
            metres (read once, when first needed); unused with `cost.metric_push` off (the paper's push in
            normalised units).
        step_limit: metres the end effector moves at most per env step (the env's `max_ee_step`; None: every
            waypoint is reached).
        time_stride: env steps per policy action (a time-strided policy's waypoints are that far apart).
    """

    def __init__(self, settings: GuidanceSettings, action_scale: Callable[[], np.ndarray], *,
                 step_limit: float | None = None, time_stride: int = 1):
        self.cost = settings.cost
        self.obstacles = settings.obstacles
        self._action_scale = action_scale
        self._scale: np.ndarray | None = None
        self.step_limit = None if step_limit is None else step_limit * time_stride

    def guidance_cost(self, tracker: ObstacleTracker, frame: RGBDFrame, state: np.ndarray) -> PositionCost:
        """The cost guidance descends for the next chunk: the tracked obstacles against the body model."""
        body = tracker.body(frame, state) if self.obstacles.body == "swept" else None
        if self.cost.metric_push and self._scale is None:
            self._scale = self._action_scale()
        return obstacle_guidance_cost(tracker.guided, body=body, densify=self.cost.densify,
                                      action_scale=self._scale if self.cost.metric_push else None,
                                      start=state[:3] if self.cost.anchored else None,
                                      turn=math.radians(self.cost.push_turn))

    def executed_path(self, tracker: ObstacleTracker, state: np.ndarray, waypoints: torch.Tensor) -> ExecutedPath:
        """The cost on the path the arm will take from its present pose through `waypoints` ((T, 10) metric
        actions): the body as the guidance cost measured it, posed by each waypoint's rotation (a held object's
        ball turns with the hand), under the arm's step limit."""
        rotations = [np.asarray(state[3:9], dtype=np.float64)] + list(waypoints[:, 3:9].detach().cpu().double().numpy())
        if self.obstacles.body == "swept":
            now = rot6d_to_matrix(rotations[0])
            held = tracker.held_ball if tracker.held_ball is not None and state[GRASP_FLAG] >= 0.5 else None
            poses, radii = [], None
            for rotation in rotations:
                offsets, radii = hand_balls(self.obstacles, rotation)
                if held is not None:  # measured in world axes now: turn it with the hand
                    offsets = np.vstack([offsets, rot6d_to_matrix(rotation) @ now.T @ held[0]])
                    radii = np.append(radii, held[1])
                poses.append(offsets)
            node_offsets = np.stack(poses)
        else:  # the "sphere" body: the obstacles carry the held radius; one ball of radius 0 at the EE point
            node_offsets, radii = np.zeros((len(rotations), 1, 3)), np.zeros(1)
        return ExecutedPath(tracker.guided, state[:3], node_offsets, radii, step_limit=self.step_limit,
                            densify=max(self.cost.densify, 2), margin=self.obstacles.margin)
