"""Obstacles as the runtime keeps them: named phrases -> instance clouds -> fitted shapes, kept up to date.

    ObstacleTracker   fits every instance of each obstacle phrase on the first frame (or before every chunk with
                      `ObstacleSettings.refit`), adds walls across gaps too narrow for the body, and measures the
                      body that must keep clear (the hand and the held object, or the paper's ball)
    body              that body's geometry from the settings: the hand's balls, the narrowest passable gap
"""

from lano3dp.guidance.obstacles.body import fit_obstacle_shape, hand_balls, passable_gap
from lano3dp.guidance.obstacles.tracker import GRASP_FLAG, ObstacleTracker

__all__ = ["GRASP_FLAG", "ObstacleTracker", "fit_obstacle_shape", "hand_balls", "passable_gap"]
