"""Differentiable obstacle costs on metric end-effector positions (the paper's D, Eq. 4).

Every obstacle shares one small protocol:

    clearance(positions (B, T, 3)) -> (B, T)   signed gap in metres between what the gripper holds
                                                (a sphere of `held_radius` around the EE point) and the
                                                obstacle surface; < 0 means collision
    __call__(positions (B, T, 3))  -> (B,)     sum over waypoints of relu(margin - clearance)

so the cost, and its gradient, is non-zero only for waypoints closer than the safety distance
(Eq. 4), and descending it pushes exactly those waypoints away from the obstacle. An obstacle
object therefore plugs straight into `DiffusionPolicy.predict_action_chunk(position_cost=...)`.

The paper's cost is `Cylinder`: the xy distance d_i from each waypoint to the obstacle centre,
hinged at the safety distance

    Q* = obstacle radius + held radius + margin          (`Cylinder.safety_distance`)

so that relu(Q* - d_i) = relu(margin - clearance_i). The paper's bowl-pouring setup used
Q* = bowl diameter + obstacle radius. For the other shapes the same hinge is applied to a signed
distance function, i.e. the safety distance is measured from the obstacle surface.

    obstacles   the protocol, the shapes (Cylinder, Sphere, OrientedBox, PointCloudObstacle) and ObstacleSet
    wrappers    the body swept along the path, densified segments, the path anchored at the hand, the push in
                metres (MetricGradient) and turned round each obstacle (TurnedPush)
    path        the path the arm really takes (ExecutedPath), push_clear, clear_prefix, and the one recipe
                `obstacle_guidance_cost`

Positions may be float32 or float64 and live on any device; obstacle parameters follow them.
"""

from lano3dp.guidance.costs.obstacles import (
    Cylinder,
    Obstacle,
    ObstacleSet,
    OrientedBox,
    PointCloudObstacle,
    PositionCost,
    Sphere,
    body_reach,
)
from lano3dp.guidance.costs.path import (
    ExecutedPath,
    clear_prefix,
    min_clearance,
    obstacle_guidance_cost,
    push_clear,
)
from lano3dp.guidance.costs.wrappers import (
    AnchoredPath,
    Densified,
    MetricGradient,
    SweptBody,
    TurnedPush,
    densify,
    obstacle_axis_xy,
    reached_positions,
)

__all__ = ["AnchoredPath", "Cylinder", "Densified", "ExecutedPath", "MetricGradient", "Obstacle", "ObstacleSet",
           "OrientedBox", "PointCloudObstacle", "PositionCost", "Sphere", "SweptBody", "TurnedPush", "body_reach",
           "clear_prefix", "densify", "min_clearance", "obstacle_axis_xy", "obstacle_guidance_cost", "push_clear",
           "reached_positions"]
