"""Obstacle costs (Eq. 4) and shape fitting: values and gradients against hand-computed cases."""

import math

import numpy as np
import pytest
import torch

from lano3dp.errors import EmptyCloudError
from lano3dp.guidance.costs import (
    Cylinder,
    Densified,
    ObstacleSet,
    OrientedBox,
    PointCloudObstacle,
    PositionCost,
    Sphere,
    SweptBody,
    TurnedPush,
    densify,
    obstacle_axis_xy,
    obstacle_guidance_cost,
)
from lano3dp.guidance.fitting import bridge_narrow_gaps, fit_box, fit_cylinder


def pts(*xyz):
    """Waypoints as a (1, T, 3) float64 batch."""
    return torch.tensor([xyz], dtype=torch.float64)


def test_cylinder_is_the_papers_xy_hinge_at_q_star():
    cylinder = Cylinder((0.1, 0.2), radius=0.05, held_radius=0.02, margin=0.01)
    assert cylinder.safety_distance == pytest.approx(0.08)  # Q* = obstacle + held + margin
    # waypoints at xy distance 0.10 (outside Q*), 0.06 (inside Q*, colliding) and 0.075 (inside Q*, clear)
    positions = pts((0.2, 0.2, 0.3), (0.1, 0.26, 0.0), (0.1, 0.125, 1.0))
    np.testing.assert_allclose(cylinder.clearance(positions)[0], [0.03, -0.01, 0.005], atol=1e-9)
    # sum_i relu(Q* - d_i) = 0 + 0.02 + 0.005
    assert cylinder(positions).item() == pytest.approx(0.025, abs=1e-9)


def test_cylinder_gradient_is_zero_beyond_q_star_and_points_toward_the_axis_inside():
    cylinder = Cylinder((0.0, 0.0), radius=0.05, held_radius=0.02, margin=0.01)
    positions = pts((0.2, 0.0, 0.0), (0.03, 0.04, 0.1)).requires_grad_(True)
    cylinder(positions).sum().backward()
    gradient = positions.grad[0]
    np.testing.assert_allclose(gradient[0], [0, 0, 0])
    # d relu(Q* - |xy|)/d xy = -xy/|xy|: descending the cost moves the waypoint radially out; z untouched
    np.testing.assert_allclose(gradient[1], [-0.6, -0.8, 0.0], atol=1e-9)


def test_xy_only_ignores_height_and_a_finite_cylinder_does_not():
    low, high = pts((0.1, 0.0, 0.0)), pts((0.1, 0.0, 0.5))
    column = Cylinder((0.0, 0.0), 0.05, z_min=0.0, z_max=0.2, xy_only=True)
    assert column.clearance(low).item() == pytest.approx(column.clearance(high).item())
    finite = Cylinder((0.0, 0.0), 0.05, z_min=0.0, z_max=0.2, xy_only=False, held_radius=0.01)
    assert finite.clearance(pts((0.0, 0.0, 0.5))).item() == pytest.approx(0.3 - 0.01)  # straight above the top
    assert finite.clearance(pts((0.1, 0.0, 0.1))).item() == pytest.approx(0.05 - 0.01)  # beside it
    assert finite.clearance(pts((0.08, 0.0, 0.24))).item() == pytest.approx(0.05 - 0.01)  # off the rim: 3-4-5
    assert finite.clearance(pts((0.0, 0.0, 0.1))).item() == pytest.approx(-0.05 - 0.01)  # on the axis, inside


def test_sphere_distance_in_3d_and_as_a_disc_with_xy_only():
    ball = Sphere((0.0, 0.0, 0.1), 0.05)
    assert ball.clearance(pts((0.0, 0.0, 0.3))).item() == pytest.approx(0.15)
    disc = Sphere((0.0, 0.0, 0.1), 0.05, xy_only=True)
    assert disc.clearance(pts((0.0, 0.0, 0.3))).item() == pytest.approx(-0.05)


def test_box_signed_distance_inside_outside_and_at_a_corner():
    box = OrientedBox((0.0, 0.0, 0.1), (0.1, 0.05, 0.1))
    assert box.clearance(pts((0.0, 0.0, 0.1))).item() == pytest.approx(-0.05)  # centre: nearest face is y
    assert box.clearance(pts((0.0, 0.04, 0.1))).item() == pytest.approx(-0.01)
    assert box.clearance(pts((0.3, 0.0, 0.1))).item() == pytest.approx(0.2)
    assert box.clearance(pts((0.13, 0.09, 0.1))).item() == pytest.approx(0.05, abs=1e-6)  # corner: hypot(.03, .04)
    assert box.clearance(pts((0.0, 0.0, 0.5))).item() == pytest.approx(0.3)
    assert OrientedBox((0, 0, 0.1), (0.1, 0.05, 0.1), xy_only=True).clearance(pts((0.0, 0.0, 0.5))).item() == \
        pytest.approx(-0.05)


def test_box_yaw_rotates_its_footprint():
    box = OrientedBox((1.0, 0.0, 0.0), (0.2, 0.02, 0.5), yaw=math.pi / 2)  # long axis now along world y
    assert box.clearance(pts((1.0, 0.15, 0.0))).item() < 0
    assert box.clearance(pts((1.15, 0.0, 0.0))).item() == pytest.approx(0.13, abs=1e-6)
    np.testing.assert_allclose(np.sort(box.corners_xy()[:, 1]), [-0.2, -0.2, 0.2, 0.2], atol=1e-9)


def test_point_cloud_obstacle_uses_the_nearest_point():
    cloud = PointCloudObstacle(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 2.0]]), point_radius=0.01,
                               xy_only=False)
    assert cloud.clearance(pts((0.7, 0.0, 0.0))).item() == pytest.approx(0.3 - 0.01)
    assert cloud.clearance(pts((0.0, 0.0, 1.8))).item() == pytest.approx(0.2 - 0.01)
    flat = PointCloudObstacle(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), point_radius=0.0, xy_only=True)
    assert flat.clearance(pts((0.0, 0.1, 5.0))).item() == pytest.approx(0.1)


def test_point_cloud_obstacle_without_points_is_an_error():
    with pytest.raises(EmptyCloudError, match="0 finite points"):
        PointCloudObstacle(np.full((5, 3), np.nan))


@pytest.mark.parametrize("obstacle", [
    Cylinder((0.0, 0.0), 0.05, margin=0.03),
    Cylinder((0.0, 0.0), 0.05, z_min=0.0, z_max=0.3, xy_only=False, margin=0.03),
    Sphere((0.0, 0.0, 0.1), 0.05, margin=0.03),
    OrientedBox((0.0, 0.0, 0.1), (0.05, 0.08, 0.1), yaw=0.3, margin=0.03),
    PointCloudObstacle(np.random.default_rng(0).normal(0, 0.02, (64, 3)) + [0, 0, 0.1], xy_only=False),
], ids=["cylinder", "finite-cylinder", "sphere", "box", "cloud"])
def test_a_step_down_the_cost_gradient_raises_the_clearance_of_close_waypoints_only(obstacle):
    positions = torch.tensor([[[0.03, 0.02, 0.12], [-0.04, 0.03, 0.08], [0.15, -0.12, 0.15]]], dtype=torch.float64)
    positions.requires_grad_(True)
    cost = obstacle(positions)
    assert cost.item() > 0
    (gradient,) = torch.autograd.grad(cost.sum(), positions)
    assert torch.isfinite(gradient).all()
    before = obstacle.clearance(positions.detach())
    after = obstacle.clearance(positions.detach() - 1e-3 * gradient)
    close = before < obstacle.margin
    assert close.sum() == 2  # the first two waypoints; the third is beyond the margin
    assert (after[close] > before[close]).all()
    assert torch.equal(after[~close], before[~close])
    assert isinstance(obstacle, PositionCost)


def test_cost_follows_the_positions_dtype_and_batches():
    cylinder = Cylinder((0.0, 0.0), 0.05)
    positions = torch.zeros(4, 16, 3, dtype=torch.float32)
    assert cylinder(positions).shape == (4,) and cylinder(positions).dtype == torch.float32
    with pytest.raises(ValueError, match=r"\(B, T, 3\)"):
        cylinder(torch.zeros(16, 3))


def test_a_waypoint_on_the_axis_gets_a_finite_gradient():
    positions = pts((0.0, 0.0, 0.0)).requires_grad_(True)
    Cylinder((0.0, 0.0), 0.05)(positions).backward()
    assert torch.isfinite(positions.grad).all()


def test_obstacle_set_sums_costs_and_takes_the_smallest_clearance():
    a, b = Cylinder((0.0, 0.0), 0.05, margin=0.02), Sphere((0.2, 0.0, 0.0), 0.05, margin=0.02)
    both = a + b
    assert isinstance(both, ObstacleSet) and len(both) == 2
    positions = pts((0.06, 0.0, 0.0), (0.14, 0.0, 0.0), (0.5, 0.0, 0.0))
    assert both(positions).item() == pytest.approx(a(positions).item() + b(positions).item())
    np.testing.assert_allclose(both.clearance(positions)[0], [0.01, 0.01, 0.25], atol=1e-9)


def test_densify_catches_a_segment_that_cuts_through_a_thin_obstacle():
    positions = pts((0.0, -0.1, 0.0), (0.0, 0.1, 0.0))
    dense = densify(positions, 4)
    assert dense.shape == (1, 5, 3)
    np.testing.assert_allclose(dense[0, :, 1], [-0.1, -0.05, 0.0, 0.05, 0.1])
    pole = Cylinder((0.0, 0.0), 0.03, margin=0.0)
    assert pole.clearance(positions).min() > 0  # both waypoints are clear...
    assert Densified(pole, 4).clearance(positions).min() < 0  # ...the segment between them is not
    assert Densified(pole, 4)(positions).item() > 0


def half_cylinder_cloud(center, radius, height, rng, noise=0.002, n=300):
    """The points a camera on the -y side sees of a vertical cylinder: the near half of its side."""
    angle = rng.uniform(-np.pi, 0.0, n)
    z = rng.uniform(0.0, height, n)
    cloud = np.column_stack([center[0] + radius * np.cos(angle), center[1] + radius * np.sin(angle), z])
    return cloud + rng.normal(0, noise, cloud.shape)


def test_fit_cylinder_recovers_axis_and_radius_from_the_visible_half():
    rng = np.random.default_rng(0)
    cloud = half_cylinder_cloud((0.3, -0.1), 0.04, 0.15, rng)
    cylinder = fit_cylinder(cloud, held_radius=0.03, margin=0.01, coverage=0.99)
    np.testing.assert_allclose(cylinder.center.numpy(), [0.3, -0.1], atol=0.004)
    assert cylinder.radius == pytest.approx(0.04, abs=0.005)
    assert cylinder.z_min == pytest.approx(0.0, abs=0.01) and cylinder.z_max == pytest.approx(0.15, abs=0.01)
    assert cylinder.safety_distance == pytest.approx(cylinder.radius + 0.04)
    # the centroid of a half shell sits 2r/pi toward the camera: why the fit uses a circle
    assert abs(cloud[:, 1].mean() - (-0.1)) > 0.02


def test_fit_cylinder_covers_every_point_by_default():
    rng = np.random.default_rng(1)
    cloud = rng.normal(0, 0.03, (200, 3))  # a blob, not an arc
    cylinder = fit_cylinder(cloud)
    assert (cylinder.clearance(torch.tensor(cloud[None])) <= 1e-9).all()


def test_fit_cylinder_to_a_flat_top_seen_from_above():
    angle = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    top = np.column_stack([0.5 + 0.03 * np.cos(angle), 0.03 * np.sin(angle), np.full(60, 0.2)])
    cylinder = fit_cylinder(top, xy_only=False)
    np.testing.assert_allclose(cylinder.center.numpy(), [0.5, 0.0], atol=1e-6)
    assert cylinder.z_min < 0.2 < cylinder.z_max and cylinder.z_max - cylinder.z_min == pytest.approx(0.002)


def test_fit_box_recovers_yaw_extents_and_centre():
    rng = np.random.default_rng(2)
    half = np.array([0.08, 0.03, 0.05])
    faces = []
    for axis in range(3):
        for sign in (-1, 1):
            face = rng.uniform(-1, 1, (200, 3)) * half
            face[:, axis] = sign * half[axis]
            faces.append(face)
    local = np.concatenate(faces)
    yaw = 0.4
    rotation = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
    cloud = local @ rotation.T + [0.5, 0.1, 0.05]
    box = fit_box(cloud)
    assert box.yaw == pytest.approx(yaw, abs=np.deg2rad(1.0))
    np.testing.assert_allclose(box.half_extents.numpy(), half, atol=0.003)
    np.testing.assert_allclose(box.center.numpy(), [0.5, 0.1, 0.05], atol=0.003)


@pytest.mark.parametrize("fit", [fit_cylinder, fit_box])
def test_fitting_too_few_points_raises_empty_cloud_error(fit):
    with pytest.raises(EmptyCloudError, match="3 finite points"):
        fit(np.zeros((3, 3)))
    with pytest.raises(EmptyCloudError):
        fit(np.full((50, 3), np.nan))


def test_metric_gradient_makes_the_push_isotropic_in_metres():
    """With a = s * x (s = 25/m in x, 4/m in y), descending the cost in normalised units moves a waypoint
    by the metric gradient times 1/s^2 per axis; MetricGradient rescales it to exactly the metric gradient."""
    from lano3dp.guidance.costs import MetricGradient

    scale = torch.tensor([25.0, 4.0, 10.0], dtype=torch.float64)
    cylinder = Cylinder((0.0, 0.0), 0.05, margin=0.05)
    normalised = (pts((0.03, -0.04, 0.1)) * scale).requires_grad_(True)
    for cost, expected in ((cylinder, torch.tensor([-0.6 / 625, 0.8 / 16, 0.0])),
                           (MetricGradient(cylinder, scale), torch.tensor([-0.6, 0.8, 0.0]))):
        (gradient,) = torch.autograd.grad(cost(normalised / scale).sum(), normalised)
        metric_push = gradient[0, 0] / scale  # how far (m) a unit step in normalised units moves the waypoint
        np.testing.assert_allclose(metric_push, expected.double(), atol=1e-9)
    wrapped = MetricGradient(cylinder, scale)
    assert wrapped.clearance(pts((0.1, 0.0, 0.0))).item() == pytest.approx(0.05)


def _descend(cost, positions: torch.Tensor, steps: int = 300, lr: float = 0.002) -> torch.Tensor:
    """Plain gradient descent on metric waypoints: what guidance does to them, without a network."""
    positions = positions.clone().requires_grad_(True)
    for _ in range(steps):
        (gradient,) = torch.autograd.grad(cost(positions).sum(), positions)
        with torch.no_grad():
            positions -= lr * gradient
    return positions.detach()


def test_swept_body_pushes_a_held_object_clear_in_metres():
    """A bowl held by its rim hangs 7 cm beside the EE: the EE path clears the post, the bowl does not."""
    post = Cylinder((0.0, 0.0), 0.03, margin=0.02)
    offset, radius = torch.tensor([[-0.07, 0.0, 0.0]], dtype=torch.float64), 0.05
    body = SweptBody(post, offset, [radius])
    path = torch.stack([torch.full((21,), 0.12), torch.linspace(-0.3, 0.3, 21), torch.full((21,), 0.2)], -1)[None]
    path = path.double()

    def bowl_gap(positions):  # true gap (m) of the held ball to the post, from the geometry alone
        centres = positions[0, :, :2] + offset[0, :2]
        return (centres.norm(dim=-1) - 0.03 - radius).min().item()

    assert post.clearance(path).min() > 0.08  # the EE point alone would never be pushed
    assert bowl_gap(path) == pytest.approx(0.12 - 0.07 - 0.03 - 0.05)  # but the bowl cuts 3 cm into the post
    assert body.clearance(path).min().item() == pytest.approx(bowl_gap(path), abs=1e-9)
    pushed = _descend(body, path)
    assert bowl_gap(pushed) >= 0.0  # clear, measured in metres
    assert bowl_gap(pushed) >= 0.02 - 0.005  # and to within 5 mm of the margin
    assert (pushed[0, :, 0] - path[0, :, 0]).max() > 0.04  # by moving the EE away from the post


def test_swept_body_leaves_a_path_whose_held_object_hangs_away_from_the_obstacle():
    """The same bowl hanging on the far side: clear, so nothing moves (the old ball of its diameter round
    the EE pushed this path by the bowl's whole diameter)."""
    post = Cylinder((0.0, 0.0), 0.03, margin=0.02)
    body = SweptBody(post, [[0.07, 0.0, 0.0]], [0.05])
    path = torch.stack([torch.full((21,), 0.12), torch.linspace(-0.3, 0.3, 21), torch.full((21,), 0.2)], -1)[None]
    assert body(path.double()).abs().max().item() == 0.0
    ball = Cylinder((0.0, 0.0), 0.03, margin=0.02, held_radius=body.reach)
    assert ball(path.double()).max().item() > 0  # the sphere model of the same reach would push it
    with pytest.raises(ValueError, match="radii"):
        SweptBody(post, [[0.0, 0.0, 0.0]], [0.01, 0.02])


def test_turned_push_turns_the_gradient_round_the_obstacle_and_keeps_the_cost():
    cylinder = Cylinder((0.5, 0.01), radius=0.03, margin=0.02)  # a hair left of the way along +x
    start = (0.0, 0.0, 0.2)
    waypoints = pts((0.25, 0.0, 0.2), (0.46, 0.0, 0.2), (0.9, 0.0, 0.2)).requires_grad_(True)
    turned = TurnedPush(cylinder, obstacle_axis_xy(cylinder), start, math.radians(45))
    (plain,) = torch.autograd.grad(cylinder(waypoints).sum(), waypoints)
    (bent,) = torch.autograd.grad(turned(waypoints).sum(), waypoints)
    assert torch.equal(turned(waypoints), cylinder(waypoints))
    assert torch.equal(turned.clearance(waypoints), cylinder.clearance(waypoints))
    push, bent_push = -plain[0, 1, :2], -bent[0, 1, :2]
    assert push[0] < 0 and abs(push[1]) < abs(push[0])  # straight back, along the way
    assert bent_push.norm() == pytest.approx(float(push.norm()))
    angle = math.atan2(bent_push[1], bent_push[0]) - math.atan2(push[1], push[0])
    assert math.degrees(angle) == pytest.approx(45.0)  # counter-clockwise: round the obstacle's right
    assert bent_push[1] < 0
    mirrored = TurnedPush(Cylinder((0.5, -0.01), 0.03, margin=0.02), (0.5, -0.01), start, math.radians(45))
    (other,) = torch.autograd.grad(mirrored(waypoints).sum(), waypoints)
    assert -other[0, 1, 1] > 0  # an obstacle on the right is passed on the left


def _descend_to_goal(cost, goal: torch.Tensor, steps: int = 400, keep_path: bool = False) -> torch.Tensor:
    """A point pulled 1 cm a step towards `goal` and pushed 1.5 cm a step by `cost`: a policy's pull and the
    guidance's push on one waypoint, as the chunk is re-planned from wherever the hand got. Its last position,
    or with `keep_path` every one (steps, 3)."""
    position = torch.tensor([[[0.0, 0.0, 0.2]]], dtype=torch.float64)
    path = []
    for _ in range(steps):
        variable = position.clone().requires_grad_(True)
        (gradient,) = torch.autograd.grad(cost(variable).sum(), variable)
        pull = goal - position
        push = -gradient / gradient.norm().clamp_min(1e-12) * (gradient.norm() > 0)
        position = position + 0.01 * pull / pull.norm().clamp_min(1e-12) + 0.015 * push
        position[..., 2] = 0.2
        path.append(position[0, 0])
    return torch.stack(path) if keep_path else position[0, 0]


def test_a_head_on_path_goes_round_with_the_turned_push_and_stalls_without():
    # dead ahead: the straight push is exactly against the pull, the symmetric case a policy's pull (which
    # returns a pushed chunk to the demonstrations' way) keeps the path in
    cylinder = Cylinder((0.5, 0.0), radius=0.03, margin=0.02)
    goal = torch.tensor([1.0, 0.0, 0.2], dtype=torch.float64)
    stalled = _descend_to_goal(obstacle_guidance_cost([cylinder]), goal)
    assert float(stalled[0]) < 0.5  # held in front of the obstacle
    # the turned cost reads its side from the path to the goal, as a chunk's end would give it
    for turn in (math.radians(30), math.radians(60)):
        def cost(position, turn=turn):
            path = torch.cat([position, goal.reshape(1, 1, 3)], 1)
            start = position[0, 0].detach().numpy()
            return obstacle_guidance_cost([cylinder], start=start, turn=turn)(path)
        reached = _descend_to_goal(cost, goal)
        assert float((reached - goal).norm()) < 0.02, turn


def test_a_wall_bridges_only_a_gap_too_narrow_to_pass_and_stays_inside_the_pair():
    left, right = Cylinder((0.5, 0.045), 0.03), Cylinder((0.5, -0.03), 0.02)  # 2.5 cm apart
    far = Cylinder((0.9, 0.0), 0.03)
    (wall,) = bridge_narrow_gaps([left, right, far], passable=0.04)
    assert bridge_narrow_gaps([left, right], passable=0.024) == []  # passable: left open
    corners = torch.as_tensor(wall.corners_xy())
    inside = [min(float((corner - o.center).norm()) - o.radius for o in (left, right)) for corner in corners]
    assert max(inside) <= 1e-9  # every corner within one of the pair: the wall fills the gap, nothing else
    middle = torch.tensor([[0.5, 0.0025, 0.3]], dtype=torch.float64)
    assert float(wall.surface_distance(middle)) < 0 < float(ObstacleSet([left, right]).clearance(middle[None]))
    low = Cylinder((0.5, 0.1), 0.03, xy_only=False, z_min=0.0, z_max=0.1)  # may be passed over: not bridged
    assert bridge_narrow_gaps([left, low], passable=0.1) == []


def test_with_a_wall_across_a_narrow_gap_the_turned_push_goes_round_the_pair_not_through_it():
    # two obstacles 3 cm apart dead ahead: in the gap their turned pushes cancel sideways, so the path heads
    # through it (where the runtime holds a hand that cannot pass); the wall's push carries it round the pair
    pair = [Cylinder((0.5, 0.045), 0.03, margin=0.02), Cylinder((0.5, -0.045), 0.03, margin=0.02)]
    goal = torch.tensor([1.0, 0.0, 0.2], dtype=torch.float64)

    def turned(obstacles):
        def cost(position):
            path = torch.cat([position, goal.reshape(1, 1, 3)], 1)
            start = position[0, 0].detach().numpy()
            return obstacle_guidance_cost(obstacles, start=start, turn=math.radians(60))(path)
        return cost

    crossings = []
    for obstacles in (pair, pair + bridge_narrow_gaps(pair, passable=2 * 0.02)):
        path = _descend_to_goal(turned(obstacles), goal, keep_path=True)
        assert float((path[-1] - goal).norm()) < 0.02
        crossings.append(float(path[int(torch.nonzero(path[:, 0] >= 0.5)[0]), 1]))
    assert abs(crossings[0]) < 0.015  # through the gap
    assert abs(crossings[1]) > 0.045 + 0.03  # beyond either obstacle
