"""The path guidance costs starts at the hand; the path a chunk is checked on is the one the arm will take; a chunk
left inside the margin is pushed clear (in metres), and only its clear start is executed."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lano3dp.guidance import (
    AnchoredPath,
    Cylinder,
    Densified,
    ExecutedPath,
    clear_prefix,
    push_clear,
    reached_positions,
)

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


def test_a_motion_limited_arm_cuts_across_what_the_waypoints_go_round():
    hand = np.array([0.4, 0.0, 0.2])
    # waypoints that go round the obstacle in two 16 cm legs: the segments clear it by 4 cm and more
    legs = torch.tensor([[[0.5, 0.12, 0.2], [0.6, 0.0, 0.2]]], dtype=torch.float64)
    ball = np.zeros((3, 1, 3))  # the EE point alone, posed the same at the hand and both waypoints
    straight = ExecutedPath([OBSTACLE], hand, ball, [0.0], step_limit=None)
    limited = ExecutedPath([OBSTACLE], hand, ball, [0.0], step_limit=0.05)
    assert float(straight.clearance(legs).min()) > 0.04
    # 5 cm a step: the arm gets 5 cm towards the first waypoint, then turns for the second from there
    reached = reached_positions(torch.as_tensor(hand), legs, 0.05)[0].numpy()
    np.testing.assert_allclose(np.linalg.norm(reached[0] - hand), 0.05, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(reached[1] - reached[0]), 0.05, atol=1e-6)
    assert float(limited.clearance(legs).min()) < float(straight.clearance(legs).min()) - 0.03
    # short steps are reached exactly, so the two models agree on them
    short = torch.tensor([[[0.42, 0.03, 0.2], [0.44, 0.06, 0.2]]], dtype=torch.float64)
    torch.testing.assert_close(limited.clearance(short), straight.clearance(short))


def test_the_body_turns_with_each_waypoint_and_a_segment_carries_both_ends():
    hand = np.array([0.4, 0.0, 0.2])
    still = torch.tensor([[[0.4, 0.0, 0.2]]], dtype=torch.float64)  # the hand stays; only its rotation changes
    toward = [[0.0, 0.0, 0.0], [0.08, 0.0, 0.0]]  # a held ball 8 cm along x (towards the obstacle) ...
    away = [[0.0, 0.0, 0.0], [0.0, 0.08, 0.0]]  # ... or turned to +y
    turned_to = ExecutedPath([OBSTACLE], hand, np.array([away, toward]), [0.0, 0.03])
    turned_away = ExecutedPath([OBSTACLE], hand, np.array([away, away]), [0.0, 0.03])
    assert float(turned_away.clearance(still).min()) > 0.02
    assert float(turned_to.clearance(still).min()) < 0  # the turn swings the ball into the obstacle
    with pytest.raises(ValueError, match="body poses"):
        turned_to.clearance(torch.zeros(1, 2, 3, dtype=torch.float64))


def test_only_the_clear_start_of_a_chunk_is_kept():
    hand = torch.tensor([[0.3, 0.0, 0.2]], dtype=torch.float64)
    into = torch.tensor([[[0.3 + 0.04 * (i + 1), 0.0, 0.2] for i in range(6)]], dtype=torch.float64)
    cost = ExecutedPath([OBSTACLE], hand[0].numpy(), np.zeros((7, 1, 3)), [0.0])
    kept = clear_prefix(cost, into, hand, clearance=0.01)
    assert 0 < kept.shape[1] < into.shape[1]
    assert float(cost.clearance(kept).min()) >= 0.01
    # whole waypoints first, then the last one part of the way: it stops short of the obstacle's margin
    torch.testing.assert_close(kept[:, :-1], into[:, :kept.shape[1] - 1])
    assert float(OBSTACLE.clearance(kept[:, -1:]).min()) >= 0.01
    clear = torch.tensor([[[0.3, 0.04 * (i + 1), 0.2] for i in range(6)]], dtype=torch.float64)
    assert clear_prefix(cost, clear, hand, clearance=0.01) is clear
    # a hand already at the margin that would go straight in keeps nothing: the runner holds it still
    touching = torch.tensor([[0.465, 0.0, 0.2]], dtype=torch.float64)  # 5 mm from the surface
    inward = torch.tensor([[[0.47, 0.0, 0.2]]], dtype=torch.float64)
    cost = ExecutedPath([OBSTACLE], touching[0].numpy(), np.zeros((2, 1, 3)), [0.0])
    assert clear_prefix(cost, inward, touching, clearance=0.01).shape[1] == 0
