"""MotionPlan: timed waypoints become smooth absolute actions within the speed limits."""

import numpy as np
import pytest

from lano3dp.sim.experts import CLOSED, OPEN, MotionPlan, PlanFollower, slerp
from lano3dp.sim.robot import rot_axis, top_down


def test_actions_reach_each_waypoint_with_a_unit_rotation():
    plan = MotionPlan([0.3, 0.0, 0.3], top_down(), control_hz=10.0, speed=0.2)
    plan.move_to([0.5, 0.1, 0.1], top_down(0.5)).hold(3, gripper=CLOSED).move_to([0.5, 0.1, 0.3])
    actions = plan.actions()
    assert actions.shape == (len(plan), 10) and actions.dtype == np.float32
    first_segment = plan.segments[0].steps
    np.testing.assert_allclose(actions[first_segment - 1, :3], [0.5, 0.1, 0.1], atol=1e-6)
    np.testing.assert_allclose(actions[first_segment - 1, 3:9], np.concatenate(
        [top_down(0.5)[:, 0], top_down(0.5)[:, 1]]), atol=1e-5)
    np.testing.assert_allclose(actions[-1, :3], [0.5, 0.1, 0.3], atol=1e-6)
    assert actions[first_segment, 9] == CLOSED and actions[0, 9] == OPEN
    columns = actions[:, 3:9].reshape(-1, 2, 3)
    np.testing.assert_allclose(np.linalg.norm(columns, axis=-1), 1.0, atol=1e-5)
    np.testing.assert_allclose(np.einsum("ij,ij->i", columns[:, 0], columns[:, 1]), 0.0, atol=1e-5)


def test_peak_speed_respects_the_limit():
    plan = MotionPlan([0.3, 0.0, 0.3], top_down(), control_hz=10.0, speed=0.25)
    plan.move_to([0.6, 0.2, 0.1])
    positions = np.vstack([[0.3, 0.0, 0.3], plan.actions()[:, :3]])
    speeds = np.linalg.norm(np.diff(positions, axis=0), axis=1) * 10.0
    assert speeds.max() <= 0.25 * 1.01


def test_grasp_descends_along_the_approach_axis_then_lifts():
    plan = MotionPlan([0.3, 0.0, 0.3], top_down())
    plan.grasp([0.45, 0.1, 0.02], top_down(), approach=0.1, lift=0.15)
    path = plan.path()
    np.testing.assert_allclose(path[1], [0.45, 0.1, 0.12])  # above: -approach axis = +z for top-down
    np.testing.assert_allclose(path[2], [0.45, 0.1, 0.02])
    np.testing.assert_allclose(path[-1], [0.45, 0.1, 0.17])
    assert [s.gripper for s in plan.segments] == [OPEN, OPEN, CLOSED, CLOSED]


def test_slerp_takes_the_short_way_and_follower_holds_the_last_action():
    q0 = np.array([1.0, 0, 0, 0])
    q1 = -np.array([np.cos(0.25), 0, 0, np.sin(0.25)])  # same rotation as +q, opposite sign
    mid = slerp(q0, q1, 0.5)
    assert abs(abs(mid[3]) - np.sin(0.125)) < 1e-9
    plan = MotionPlan([0.3, 0, 0.3], rot_axis([1, 0, 0], np.pi)).hold(2)
    follower = PlanFollower(plan)
    actions = [follower() for _ in range(4)]
    assert follower.done
    np.testing.assert_array_equal(actions[2], actions[3])


@pytest.mark.parametrize("speed", [0.1, 0.3])
def test_slower_plans_take_more_steps(speed):
    plan = MotionPlan([0.3, 0.0, 0.3], top_down(), speed=speed).move_to([0.6, 0.0, 0.3])
    assert len(plan) == int(np.ceil(0.3 / speed * 10 * 1.5))
