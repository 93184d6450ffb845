"""The path guidance costs starts at the hand, and a chunk left inside the margin is pushed clear (in metres)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lano3dp.guidance import AnchoredPath, Cylinder, Densified, push_clear

OBSTACLE = Cylinder(center=(0.5, 0.0), radius=0.03, margin=0.02, xy_only=True)


def test_the_anchored_cost_sees_the_step_from_the_hand_to_the_first_waypoint():
    hand = np.array([0.4, 0.0, 0.2])
    beyond = torch.tensor([[[0.6, 0.0, 0.2], [0.62, 0.0, 0.2]]], dtype=torch.float64)  # past the obstacle
    waypoints_only = Densified(OBSTACLE, 4)
    anchored = AnchoredPath(waypoints_only, hand)
    assert float(waypoints_only.clearance(beyond).min()) > 0 and float(waypoints_only(beyond)) == 0
    # the hand would cross the obstacle on its way to the first waypoint
    assert float(anchored.clearance(beyond).min()) < 0
    variable = beyond.clone().requires_grad_(True)
    (gradient,) = torch.autograd.grad(anchored(variable).sum(), variable)
    assert gradient[0, 0].norm() > 0  # the first waypoint is pushed; the hand is not a variable
    # every point of the densified path but the hand itself, whose place no waypoint can change
    assert anchored.clearance(beyond).shape == (1, (1 + 2 - 1) * 4)
    hand = torch.tensor([[[0.5, 0.0, 0.2]]], dtype=torch.float64)  # the hand touches the obstacle already
    inside = AnchoredPath(waypoints_only, hand[0, 0].numpy())
    assert float(OBSTACLE.clearance(hand)) < 0
    near = torch.tensor([[[0.5, 0.06, 0.2]]], dtype=torch.float64)  # the way out, not yet clear of the margin
    assert float(inside.clearance(near).min()) > float(OBSTACLE.clearance(hand))
    # so a push can finish: the path out clears though the hand's own place does not
    moved, steps = push_clear(inside, near, clearance=0.01, iterations=20)
    assert 0 < steps < 20 and float(inside.clearance(moved).min()) >= 0.01


def test_push_clear_moves_only_what_is_inside_and_stops_at_the_goal_in_metres():
    xs = np.linspace(0.3, 0.7, 17)
    path = torch.tensor(np.stack([xs, np.full_like(xs, 0.01), np.full_like(xs, 0.2)], -1)[None])  # through it
    assert float(OBSTACLE.clearance(path).min()) < 0
    moved, steps = push_clear(OBSTACLE, path, clearance=0.01, step=0.01, iterations=20)
    assert 0 < steps <= 20
    gaps = OBSTACLE.clearance(moved)[0]
    assert float(gaps.min()) >= 0.01 - 1e-9  # clear of the surface by the goal, in metres
    far = OBSTACLE.clearance(path)[0] >= OBSTACLE.margin  # never inside the margin: not pushed at all
    assert far.any() and torch.equal(moved[0][far], path[0][far])
    # each step moves a waypoint at most `step` metres
    assert float((moved - path).norm(dim=-1).max()) <= steps * 0.01 + 1e-9
    # a path already clear is returned as it is, with no steps taken
    same, none = push_clear(OBSTACLE, moved, clearance=0.01)
    assert none == 0 and torch.equal(same, moved)


def test_push_clear_gives_up_after_its_iterations():
    deep = torch.tensor([[[0.5, 0.001, 0.2]]], dtype=torch.float64)  # 3 cm inside, 5 cm from the goal
    moved, steps = push_clear(OBSTACLE, deep, clearance=0.02, step=0.01, iterations=2)
    assert steps == 2 and float(OBSTACLE.clearance(moved).min()) < 0.02
    assert float((moved - deep).norm()) == pytest.approx(0.02)
