"""The closed-loop runtime against a fake env and a fake policy (fast, no simulator, no training).

The scene is analytic (perception.synthetic boxes seen from above) and goes through the real
ground-truth segmenter and ObjectObserver, so the obstacle -> cylinder -> Q* wiring is the real one.
The fake policy draws a straight line from the EE to the pan; when guided it descends the cost it is
handed, as the guided sampler would, so guidance visibly bends the path. Its observation window and action
queue are the real ones (`ChunkedControl`), as the runner drives every policy through `select_action`.
"""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from lano3dp.errors import Lano3dpError
from lano3dp.geometry.frame import observe, resize_rgb
from lano3dp.geometry.rotations import matrix_to_rot6d
from lano3dp.guidance import AnchoredPath, Cylinder, Densified, MetricGradient
from lano3dp.guidance.execution import Escape, FilterContext, Follow, Hold, Proposal, run_filters
from lano3dp.guidance.execution.escape import retreat
from lano3dp.guidance.obstacles import hand_balls
from lano3dp.guidance.settings import GuidanceSettings, ObstacleSettings, guidance_preset
from lano3dp.perception import ObjectNotFoundError, ObjectObserver, SimOracleSegmenter
from lano3dp.perception.synthetic import Box, render_boxes, top_down_camera
from lano3dp.policy import ActionChunk, ChunkedControl, PolicyConfig
from lano3dp.policy.normalizer import LinearNormalizer
from lano3dp.runtime import ClosedLoopError, PolicyRunner, path_length, rollout, scene_obstacles

BOWL = Box("bowl", (-0.25, 0.0), (0.10, 0.10, 0.05), {"kind": "bowl", "color": "red", "role": "target"})
PAN = Box("pan", (0.30, 0.0), (0.14, 0.14, 0.03), {"kind": "pan", "color": "black", "role": "target"})
OBSTACLE = Box("obstacle_0", (0.02, 0.0), (0.06, 0.06, 0.30), {"kind": "cylinder", "color": "grey",
                                                                 "role": "obstacle"})
START = np.array([-0.25, 0.0, 0.25])
ROT6D = matrix_to_rot6d(np.eye(3)).astype(np.float32)
# the paper's body: a ball round the EE point, here of a fixed 3 cm
SPHERE = {"obstacles.body": "sphere", "obstacles.held_radius": 0.03}


def settings(preset: str = "none", changes: dict | None = None) -> GuidanceSettings:
    """A preset with dotted changes, as `--guidance-preset` and `--set guidance.<path>=...` give it."""
    return guidance_preset(preset).with_changes(changes or {})


def guided(rho: float, changes: dict | None = None) -> GuidanceSettings:
    """The recommended guidance with rho, S = 10 and the sphere body (what these scenes measure), plus changes."""
    return settings("recommended", {"sampler.rho": rho, "sampler.last_steps": 10, **SPHERE, **(changes or {})})


class FakeEnv:
    """A point end effector over a static table: each action's position is reached exactly.

    Contact: the EE (a sphere of `body_radius`) overlaps the obstacle's footprint in xy; clearance is the
    xy gap to the obstacle's square footprint minus `body_radius`.
    """

    def __init__(self, boxes, max_steps: int = 40, body_radius: float = 0.02, success_radius: float = 0.03):
        self.frame_ = render_boxes(top_down_camera(size=64, height=1.2, fovy_deg=50, tilt_deg=25), boxes)
        self.obstacles = [b for b in boxes if b.attributes.get("role") == "obstacle"]
        self.goal = np.array([*PAN.center_xy, 0.25])
        self.max_steps, self.body_radius, self.success_radius = max_steps, body_radius, success_radius
        self.resets: list[int] = []

    def _clearance(self) -> float:
        gaps = []
        for box in self.obstacles:
            d = np.maximum(np.abs(self.position[:2] - np.array(box.center_xy)) - np.array(box.size[:2]) / 2, 0)
            gaps.append(float(np.linalg.norm(d)) - self.body_radius)
        return min(gaps) if gaps else math.inf

    def _obs(self):
        state = np.concatenate([self.position, ROT6D, [0.04, 1.0]]).astype(np.float32)
        return {"frame": self.frame_, "state": state}

    def _info(self):
        clearance = self._clearance()
        contacts = [{"obstacle": "obstacle_0"}] if clearance < 0 else []
        success = bool(np.linalg.norm(self.position - self.goal) < self.success_radius)
        return {"success": success, "obstacle_contacts": contacts, "min_obstacle_clearance": clearance}

    def reset(self, *, seed=None, options=None):
        self.resets.append(seed)
        self.position, self.steps = START.copy(), 0
        return self._obs(), self._info()

    def step(self, action):
        assert np.asarray(action).shape == (10,)
        self.position = np.asarray(action[:3], dtype=np.float64)
        self.steps += 1
        info = self._info()
        return self._obs(), float(info["success"]), info["success"], self.steps >= self.max_steps, info


class FakePolicy(ChunkedControl):
    """Straight line from the current EE position to the pan centroid, STEP metres per waypoint.

    With guidance it runs gradient descent on the given position cost over the waypoints (a stand-in for
    the guided sampler), so the wiring of obstacles into `position_cost` is what decides collisions.
    """

    STEP = 0.05
    device = torch.device("cpu")

    def __init__(self, obs_type: str = "objects", n_action_steps: int = 8):
        kwargs = {"object_names": ("bowl", "pan")} if obs_type == "objects" else {}
        self.config = PolicyConfig(obs_type=obs_type, n_obs_steps=2, horizon=16, n_action_steps=n_action_steps,
                                   **kwargs)
        self.calls: list[dict] = []
        low, high = np.array([0.2, -0.3, 0.1] + [-1] * 6 + [0]), np.array([0.6, 0.3, 0.4] + [1] * 6 + [1])
        self.normalizer = LinearNormalizer({"action": 10})
        self.normalizer.set_stats({"action": {"min": low, "max": high}})
        self.reset()

    def predict_action_chunk(self, obs, *, guidance=None, position_cost=None, scheduler=None,
                             num_inference_steps=None, generator=None):
        self.calls.append({"obs": obs, "guidance": guidance, "cost": position_cost, "scheduler": scheduler,
                           "steps": num_inference_steps})
        state = torch.as_tensor(obs["state"])[0, -1]
        if self.config.obs_type == "objects":
            goal_xy = torch.as_tensor(obs["object_clouds"])[0, -1, 1].mean(0)[:2]
        else:
            goal_xy = torch.tensor(PAN.center_xy)
        start = state[:3].double()
        goal = torch.cat([goal_xy.double(), start[2:3]])
        distance = torch.linalg.norm(goal - start)
        horizon = self.config.horizon
        # waypoint i of the horizon; index To-1 is "now", so the first executed waypoint is one STEP away
        s = torch.clamp((torch.arange(horizon, dtype=torch.float64) - (self.config.n_obs_steps - 2)) * self.STEP
                        / torch.clamp(distance, min=1e-9), 0, 1)
        positions = (start + s[:, None] * (goal - start))[None]
        if guidance is not None and position_cost is not None:
            positions = positions.clone().requires_grad_(True)
            for _ in range(200):
                cost = position_cost(positions).sum()
                if not cost.requires_grad or cost.item() == 0:
                    break
                (grad,) = torch.autograd.grad(cost, positions)
                positions = (positions - 0.2 * guidance.scale * grad).detach().requires_grad_(True)
            positions = positions.detach()
        trajectory = torch.cat([positions.float(), torch.as_tensor(ROT6D).expand(1, horizon, 6),
                                torch.ones(1, horizon, 1)], -1)
        start_index = self.config.n_obs_steps - 1
        return ActionChunk(trajectory[:, start_index:start_index + self.config.n_action_steps], trajectory)


@pytest.fixture
def observer():
    return ObjectObserver(SimOracleSegmenter(), n_points=64, min_points=5)


def test_the_policy_samples_from_its_window_of_the_runners_observations(observer):
    """The window is the policy's (`select_action`): the first observation fills it, later ones slide it."""
    env = FakeEnv([BOWL, PAN])
    policy = FakePolicy()
    runner = PolicyRunner(policy, observer, n_action_steps=1)  # a chunk every step
    obs, _ = env.reset(seed=0)
    frame, state = observe(env, obs)
    runner.act(frame, state)
    window = policy.calls[0]["obs"]
    assert window["object_clouds"].shape == (1, 2, 2, 64, 3)
    assert window["state"].shape == (1, 2, 11)
    np.testing.assert_array_equal(window["state"][0, 0], window["state"][0, 1])
    for x in (0.1, 0.2):
        runner.act(frame, np.concatenate([[x, 0, 0.25], ROT6D, [0.04, 1.0]]).astype(np.float32))
    np.testing.assert_allclose(policy.calls[-1]["obs"]["state"][0, :, 0], [0.1, 0.2])
    # slot order is the policy's: slot 1 is the pan, whose cloud is centred on the pan
    np.testing.assert_allclose(window["object_clouds"][0, -1, 1].mean(0)[:2], PAN.center_xy, atol=0.02)
    # one step in: the runner's input is the frame's clouds and the state, batch 1
    step = runner.policy_input(frame, state)
    assert step["object_clouds"].shape == (1, 2, 64, 3) and step["state"].shape == (1, 11)


def test_the_runner_executes_what_the_policy_queues_and_resets_it_each_episode(observer):
    env = FakeEnv([BOWL, PAN], max_steps=5, success_radius=-1.0)
    policy = FakePolicy()
    runner = PolicyRunner(policy, observer)
    policy.select_action({"object_clouds": np.zeros((1, 2, 64, 3), np.float32),  # left over from elsewhere
                          "state": np.zeros((1, 11), np.float32)})
    path = rollout(env, runner, seed=0, success_at="end").ee_path
    assert len(policy.calls) == 2 and runner.chunks[0].step == 0  # the runner's first step sampled afresh
    np.testing.assert_array_equal(policy.last_chunk.trajectory[0].numpy(), runner.chunks[-1].trajectory)
    np.testing.assert_array_equal(path[1:], policy.last_chunk.actions[0, :5, :3].numpy())  # in order, as queued
    rollout(env, runner, seed=0, success_at="end")
    assert len(policy.calls) == 3  # the next episode's first step sampled again: reset dropped the queue


def test_one_chunk_is_executed_for_n_action_steps_before_replanning(observer):
    env = FakeEnv([BOWL, PAN], max_steps=20, success_radius=-1.0)  # never succeeds: runs to the limit
    policy = FakePolicy(n_action_steps=8)
    runner = PolicyRunner(policy, observer)
    result = rollout(env, runner, seed=3, success_at="end")
    assert result.steps == 20
    assert len(policy.calls) == 3  # steps 0, 8, 16
    assert [c.step for c in runner.chunks] == [0, 8, 16]
    assert len(result.chunk_latency_s) == 3 and all(t > 0 for t in result.chunk_latency_s)
    assert env.resets == [3]

    runner = PolicyRunner(FakePolicy(), observer, n_action_steps=4)
    assert len(rollout(env, runner, seed=3, success_at="end").chunk_latency_s) == 5


def test_more_actions_per_chunk_than_the_policy_was_trained_with_are_taken_from_its_horizon(observer):
    """n_action_steps may exceed the policy's (up to what the horizon holds): the extra actions
    are the horizon's next waypoints, not silently dropped (the runner re-planned every policy Ta steps)."""
    env = FakeEnv([BOWL, PAN], max_steps=16, success_radius=-1.0)
    policy = FakePolicy(n_action_steps=4)
    runner = PolicyRunner(policy, observer, n_action_steps=8)
    result = rollout(env, runner, seed=0, success_at="end")
    assert [c.step for c in runner.chunks] == [0, 8]
    np.testing.assert_array_equal(result.ee_path[1:9], runner.chunks[0].trajectory[1:9, :3])  # To - 1 = 1 is now
    assert policy.last_chunk.actions.shape == (1, 8, 10)


def test_unobstructed_episode_succeeds_and_measures_the_path(observer):
    env = FakeEnv([BOWL, PAN])
    result = rollout(env, PolicyRunner(FakePolicy(), observer), seed=0)
    assert result.success
    assert not result.collided and result.min_clearance is None  # no obstacle in the scene
    # straight line bowl -> pan centroid (the top-view cloud's centroid is the pan centre within 1 cm)
    assert result.path_length == pytest.approx(0.55, abs=0.02)
    assert result.ee_path.shape == (result.steps + 1, 3)
    # 5 cm per step, success within 3 cm of the goal: the episode stops at the first step that gets there
    assert result.steps == math.ceil((0.55 - 0.03) / FakePolicy.STEP)


def test_obstacle_is_fitted_as_a_cylinder_with_q_star_from_the_held_object(observer):
    env = FakeEnv([BOWL, PAN, OBSTACLE])
    obs, _ = env.reset(seed=0)
    frame, state = observe(env, obs)
    assert scene_obstacles(frame) == ["obstacle_0"]
    runner = PolicyRunner(FakePolicy(), observer, settings("none", {"obstacles.body": "sphere"}),
                          obstacle_phrases=["obstacle_0"], held_object="bowl")
    tracker = runner.tracker
    tracker.update(frame, step=0)
    (cylinder,) = list(tracker.obstacles)
    assert isinstance(cylinder, Cylinder) and cylinder.xy_only
    # a 6 cm square post seen at 64x64 from one side: the covering circle sits within ~1.5 cm of its axis
    # and covers every seen point (radius >= half the side, at most a bit over half the diagonal + offset)
    np.testing.assert_allclose(cylinder.center.numpy(), OBSTACLE.center_xy, atol=0.015)
    assert 0.03 <= cylinder.radius <= 0.06
    # held extent = the bowl's diameter (paper): its covering radius is ~5-7 cm, so ~10-14 cm
    assert 0.09 <= tracker.held_radius <= 0.15
    assert cylinder.safety_distance == pytest.approx(cylinder.radius + tracker.held_radius + 0.02)

    fixed = PolicyRunner(FakePolicy(), observer, settings("none", {**SPHERE, "obstacles.held_radius": 0.05}),
                         obstacle_phrases=["obstacle_0"])
    fixed.tracker.update(frame, step=0)
    assert fixed.tracker.held_radius == 0.05


def test_a_target_that_is_not_carried_leaves_only_the_gripper_in_q_star(observer):
    """A door is pushed, not carried: its 40 cm extent in Q* once pushed every path out of the workspace."""
    env = FakeEnv([BOWL, PAN, OBSTACLE])
    obs, _ = env.reset(seed=0)
    frame, state = observe(env, obs)
    sphere = settings("none", {"obstacles.body": "sphere", "obstacles.gripper_radius": 0.02})
    runner = PolicyRunner(FakePolicy(), observer, sphere, obstacle_phrases=["obstacle_0"])
    tracker = runner.tracker
    tracker.update(frame, step=0)
    assert tracker.held_object is None and tracker.held_radius == 0.02
    runner.set_objects(held_object="bowl")
    tracker.update(frame, step=0)
    assert tracker.held_radius > 0.09
    runner.set_objects(obstacle_phrases=["obstacle_0"])  # what is carried stays unless it is named
    assert tracker.held_object == "bowl"


def test_a_phrase_naming_several_obstacles_fits_one_cylinder_each(observer):
    mugs = [Box(f"mug_{i}", (0.02, y), (0.05, 0.05, 0.10), {"kind": "mug", "color": "white", "role": "obstacle"})
            for i, y in enumerate((-0.12, 0.12))]
    env = FakeEnv([BOWL, PAN, *mugs])
    obs, _ = env.reset(seed=0)
    runner = PolicyRunner(FakePolicy(), observer, obstacle_phrases=["mug"])
    runner.tracker.update(observe(env, obs)[0], step=0)
    centres = sorted(float(c.center[1]) for c in runner.tracker.obstacles)
    assert len(centres) == 2  # "avoid the mugs": never merged into one cloud, never ambiguous
    np.testing.assert_allclose(centres, [-0.12, 0.12], atol=0.015)


def test_the_cost_can_be_densified_and_pushed_isotropically_in_metres(observer):
    env = FakeEnv([BOWL, PAN, OBSTACLE])
    obs, _ = env.reset(seed=0)
    frame, state = observe(env, obs)
    config = settings("none", {**SPHERE, "cost.metric_push": True, "cost.densify": 4})
    runner = PolicyRunner(FakePolicy(), observer, config, obstacle_phrases=["obstacle_0"])
    runner.tracker.update(frame, step=0)
    cost = runner.recipe.guidance_cost(runner.tracker, frame, state)
    # the path is costed from the hand (anchored, the recommended default), densified x4, pushed in metres
    assert isinstance(cost, MetricGradient) and isinstance(cost.cost, AnchoredPath)
    np.testing.assert_allclose(cost.cost.start.numpy(), state[:3])
    assert isinstance(cost.cost.cost, Densified) and cost.cost.cost.factor == 4
    # the MetricGradient weight is the normaliser scale squared: (2 / span)^2 per position axis
    np.testing.assert_allclose(cost.weight.numpy(), (2 / np.array([0.4, 0.6, 0.3])) ** 2, rtol=1e-5)
    # two waypoints either side of the obstacle: both clear, but the segment between them is not
    straddle = torch.tensor([[[OBSTACLE.center_xy[0], -0.2, 0.2], [OBSTACLE.center_xy[0], 0.2, 0.2]]])
    assert runner.tracker.obstacles.clearance(straddle).min() > 0
    assert cost.cost.cost.clearance(straddle).min() < 0
    with pytest.raises(ValueError, match="densify"):
        settings("none", {"cost.densify": 0})


def test_guidance_reaches_the_policy_only_with_obstacles_and_bends_the_path_clear(observer):
    env = FakeEnv([BOWL, PAN, OBSTACLE])
    plain_policy = FakePolicy()
    plain = rollout(env, PolicyRunner(plain_policy, observer, settings("none", SPHERE),
                                      obstacle_phrases=["obstacle_0"]), seed=0)
    assert all(call["guidance"] is None and call["cost"] is None for call in plain_policy.calls)
    assert plain.collided and plain.n_collision_steps >= 1 and plain.min_clearance < 0

    guided_policy = FakePolicy()
    config = guided(1.0, {"sampler.scheduler": "ddim", "sampler.steps": 10})
    result = rollout(env, PolicyRunner(guided_policy, observer, config, obstacle_phrases=["obstacle_0"]), seed=0)
    assert all(call["guidance"].scale == 1.0 and call["guidance"].last_steps == 10 and call["cost"] is not None
               for call in guided_policy.calls)
    assert guided_policy.calls[0]["scheduler"] == "ddim" and guided_policy.calls[0]["steps"] == 10
    assert not result.collided and result.min_clearance > 0
    assert result.path_length > plain.path_length  # the detour
    assert all(c is not None and c >= 0 for c in result.chunk_predicted_clearance)

    # guidance without obstacles is a no-op: nothing to push against
    free_policy = FakePolicy()
    rollout(FakeEnv([BOWL, PAN]), PolicyRunner(free_policy, observer, config), seed=0)
    assert all(call["guidance"] is None for call in free_policy.calls)


def test_the_guidance_cost_turns_each_obstacles_push_as_configured(observer):
    env = FakeEnv([BOWL, PAN, OBSTACLE])
    costs = {}
    for turn in (0.0, 60.0):
        policy = FakePolicy()
        config = guided(0.04, {"cost.push_turn": turn})
        rollout(env, PolicyRunner(policy, observer, config, obstacle_phrases=["obstacle_0"]), seed=0)
        costs[turn] = repr(policy.calls[0]["cost"])
    assert "TurnedPush" not in costs[0.0]
    assert "TurnedPush" in costs[60.0] and "angle=1.047" in costs[60.0]


def test_a_chunk_guidance_left_inside_the_margin_is_pushed_clear_after_sampling(observer):
    env = FakeEnv([BOWL, PAN, OBSTACLE])
    # a push far too weak to bend the straight line round the obstacle
    results = {}
    for filters in ([], ["repair"]):
        config = guided(1e-6, {"execution.filters": filters})
        runner = PolicyRunner(FakePolicy(), observer, config, obstacle_phrases=["obstacle_0"])
        results[bool(filters)] = (rollout(env, runner, seed=0), runner.chunks)
    unrepaired, chunks = results[False]
    assert unrepaired.collided and all(not c.notes for c in chunks)
    repaired, chunks = results[True]
    steps = [c.notes.get("repair", {}).get("steps", 0) for c in chunks]
    assert any(s > 0 for s in steps) and all(s <= 20 for s in steps)
    # the simulator's own contact test: the pushed path clears, and each chunk was predicted to
    assert not repaired.collided and repaired.min_clearance > 0
    assert min(repaired.chunk_predicted_clearance) >= 0


def test_a_chunk_predicted_to_collide_runs_only_its_clear_start_and_the_hand_holds_short(observer):
    env = FakeEnv([BOWL, PAN, OBSTACLE])
    # a push too weak to leave the straight line through it
    config = guided(1e-6, {"execution.filters": ["hold", "escape"]})
    runner = PolicyRunner(FakePolicy(), observer, config, obstacle_phrases=["obstacle_0"])
    result = rollout(env, runner, seed=0)
    assert not result.collided and result.min_clearance > 0
    cut = [c.executed for c in runner.chunks if c.executed is not None]
    assert cut and 0 in cut  # cut short, then held still where every way on comes too close
    assert not result.success  # the pan is beyond the obstacle: a hand that stops short never gets there
    plain = PolicyRunner(FakePolicy(), observer, settings("none", SPHERE), obstacle_phrases=["obstacle_0"])
    assert rollout(env, plain, seed=0).collided  # unguided runs stay the baseline
    assert all(c.executed is None for c in plain.chunks)
    with pytest.raises(ValueError, match="act on guided chunks"):  # a filter cannot act without guidance
        settings("none", {"execution.filters": ["hold"]})


def test_a_hand_held_at_an_obstacle_follows_its_boundary_round_it_and_then_the_policy_again(observer):
    """The scene above, where the held hand never reached the pan: after `after_holds` holds it steps round the
    obstacle's side, keeping clear, until the policy's straight line to the pan runs."""
    env = FakeEnv([BOWL, PAN, OBSTACLE], max_steps=60)
    config = guided(1e-6, {"execution.filters": ["hold", "escape", "follow"]})
    runner = PolicyRunner(FakePolicy(), observer, config, obstacle_phrases=["obstacle_0"])
    result = rollout(env, runner, seed=0)
    assert result.success and not result.collided and result.min_clearance > 0
    assert 1 <= result.filters["follow"]["steps"] <= Follow.Options().max_steps
    # it went round the side, not through: the path left the start-to-pan line by more than the obstacle's width
    assert np.abs(result.ee_path[:, 1]).max() > OBSTACLE.size[1] / 2 + SPHERE["obstacles.held_radius"]


def test_checked_execution_resamples_with_guidance_until_the_chunk_is_clear(observer):
    env = FakeEnv([BOWL, PAN, OBSTACLE])
    policy = FakePolicy()
    # checked execution starting unguided: it escalates from rho (here 1) whenever the executed part collides
    config = settings("none", {**SPHERE, "sampler.strategy": "checked", "sampler.rho": 1.0})
    result = rollout(env, PolicyRunner(policy, observer, config, obstacle_phrases=["obstacle_0"]), seed=0)
    assert not result.collided
    assert max(result.chunk_tries) >= 2  # the straight line hit the obstacle at least once
    assert policy.calls[0]["guidance"] is None  # first try unguided, then escalated
    assert any(call["guidance"] is not None for call in policy.calls)


def test_checked_execution_can_stop_an_episode_that_cannot_be_cleared(observer):
    env = FakeEnv([BOWL, PAN, OBSTACLE])
    config = settings("none", {**SPHERE, "sampler.strategy": "checked", "sampler.rho": 1e-6,
                               "sampler.on_unclear": "stop"})
    runner = PolicyRunner(FakePolicy(), observer, config, obstacle_phrases=["obstacle_0"])
    runner.sampler.check = dataclasses.replace(runner.sampler.check, initial_scale=1e-6, max_tries=2, growth=1.0)
    result = rollout(env, runner, seed=0)
    assert not result.success
    assert result.error.startswith("ClosedLoopError: no collision-free chunk")


def test_a_missing_target_ends_the_episode_with_a_named_error(observer):
    env = FakeEnv([PAN])  # no bowl
    result = rollout(env, PolicyRunner(FakePolicy(), observer), seed=0)
    assert result.steps == 0 and not result.success
    assert "ObjectNotFoundError" in result.error and "'bowl'" in result.error


def test_runner_checks_its_inputs(observer):
    with pytest.raises(ValueError, match="2 object slots"):
        PolicyRunner(FakePolicy(), observer, target_phrases=["bowl"])
    with pytest.raises(ValueError, match="needs an observer"):
        PolicyRunner(FakePolicy(), None)
    with pytest.raises(ValueError, match="exceeds what one chunk holds"):
        PolicyRunner(FakePolicy(), observer, n_action_steps=16)
    with pytest.raises(ValueError, match="obstacle shape"):
        ObstacleSettings(shape="cone")
    assert issubclass(ClosedLoopError, Lano3dpError)  # rollout turns it into a failed episode, not a crash


def test_image_and_scene_policies_get_their_own_inputs(observer):
    env = FakeEnv([BOWL, PAN])
    obs, _ = env.reset(seed=0)
    frame, state = observe(env, obs)
    image_runner = PolicyRunner(FakePolicy("image"), None)
    step = image_runner.policy_input(frame, state)
    assert step["rgb"].shape == (1, 96, 96, 3) and step["rgb"].dtype == np.uint8
    scene_runner = PolicyRunner(FakePolicy("scene"), observer)
    cloud = scene_runner.policy_input(frame, state)["scene_cloud"]
    assert cloud.shape == (1, 512, 3)
    assert (cloud[..., 2] > 0).all()  # the table is removed


@pytest.mark.parametrize("obs_type", ["objects", "scene", "image"])
def test_every_policy_samples_the_same_windows_whether_or_not_unobserved_frames_are_built(observer, obs_type):
    def sampled_windows(build_every_frame: bool) -> list[dict]:
        policy = FakePolicy(obs_type)
        # an own visual function (the type's, here): the runner cannot know it keeps no state, so builds every one
        runner = PolicyRunner(policy, observer, visual_fn=(lambda frame: policy.config.observation.runtime_input(
            runner, frame)) if build_every_frame else None)
        rollout(FakeEnv([BOWL, PAN]), runner, seed=0, max_steps=20)
        return [call["obs"] for call in policy.calls]

    built, skipped = sampled_windows(True), sampled_windows(False)
    assert len(built) == len(skipped) >= 2
    for ours, theirs in zip(skipped, built, strict=True):
        assert ours.keys() == theirs.keys()
        for key in ours:
            torch.testing.assert_close(torch.as_tensor(ours[key]), torch.as_tensor(theirs[key]))


def test_a_target_hidden_after_the_first_frame_keeps_its_previous_cloud(observer):
    env = FakeEnv([BOWL, PAN])
    obs, _ = env.reset(seed=0)
    frame, state = observe(env, obs)
    runner = PolicyRunner(FakePolicy(), observer)
    first = runner.policy_input(frame, state)["object_clouds"][0]
    hidden_pan = render_boxes(frame.camera, [BOWL])  # the pan is gone from view (occluded)
    second = runner.policy_input(hidden_pan, state)["object_clouds"][0]
    np.testing.assert_array_equal(second[1], first[1])
    assert runner.targets.held_clouds == 1

    fresh = PolicyRunner(FakePolicy(), observer)
    with pytest.raises(ObjectNotFoundError, match="'pan'"):  # never seen: nothing to hold
        fresh.policy_input(hidden_pan, state)


def test_a_frame_no_window_holds_is_perceived_only_when_a_later_hidden_target_needs_it(observer):
    env = FakeEnv([BOWL, PAN])
    obs, _ = env.reset(seed=0)
    first, state = observe(env, obs)
    moved = render_boxes(first.camera, [BOWL, Box("pan", (0.26, 0.05), PAN.size, PAN.attributes)])
    hidden = render_boxes(first.camera, [BOWL])  # the pan is gone from view
    eager = PolicyRunner(FakePolicy(), observer)
    for frame in (first, moved):
        eager.object_clouds(frame)
    expected = eager.object_clouds(hidden)  # the pan keeps its cloud from the frame before

    asked = []

    def later(frame):
        return lambda: asked.append(frame) or frame

    deferring = PolicyRunner(FakePolicy(), observer)
    deferring.object_clouds(first)
    assert deferring.targets.can_defer(deferring.target_phrases)
    deferring.targets.defer(later(moved), step=1)
    np.testing.assert_array_equal(deferring.object_clouds(first), eager.object_clouds(first))
    assert asked == []  # every target in view: the frame in between is never rendered
    deferring.targets.defer(later(moved), step=3)
    np.testing.assert_array_equal(deferring.object_clouds(hidden), expected)
    assert asked == [moved] and deferring.targets.deferred == []


def test_a_step_whose_observation_no_window_holds_takes_the_queued_action_without_it():
    policy, eager = FakePolicy(n_action_steps=5), FakePolicy(n_action_steps=5)  # two observation steps each
    states = [np.concatenate([[0.01 * t, 0.0, 0.25], ROT6D, [0.04, 1.0]]).astype(np.float32) for t in range(12)]
    clouds = np.zeros((1, 2, 64, 3), np.float32)
    for t, state in enumerate(states):
        observation = {"object_clouds": clouds + t, "state": state[None]}
        expected = eager.select_action(observation)
        if policy.observation_needed():
            action = policy.select_action(observation)
        else:
            action = policy.select_queued_action()
        torch.testing.assert_close(action, expected)
    assert len(policy.calls) == len(eager.calls) == 3
    for ours, theirs in zip(policy.calls, eager.calls, strict=True):  # the windows sampled from are the same
        torch.testing.assert_close(ours["obs"]["state"], theirs["obs"]["state"])
    with pytest.raises(RuntimeError, match="reaches a sampled window"):
        FakePolicy().select_queued_action()


def test_the_collector_and_the_runtime_share_one_resize_and_one_observe():
    from lano3dp import collect
    from lano3dp.policy.observations import image

    # the image type's one module both records the images and makes them at run time
    assert image.resize_rgb is resize_rgb and collect.observe is observe


def test_resize_rgb_averages_areas():
    image = np.zeros((64, 64, 3), np.uint8)
    image[:, 32:] = 200
    small = resize_rgb(image, 8)
    assert small.shape == (8, 8, 3)
    assert small[0, 0, 0] == 0 and small[0, -1, 0] == 200
    np.testing.assert_array_equal(resize_rgb(small, 8), small)  # already the right size: unchanged


def test_path_length():
    assert path_length(np.array([[0, 0, 0], [0.3, 0.4, 0], [0.3, 0.4, 1.0]])) == pytest.approx(1.5)
    assert path_length(np.zeros((1, 3))) == 0.0


def test_observe_builds_a_frame_from_raw_arrays_when_the_env_has_none():
    frame = render_boxes(top_down_camera(size=32), [BOWL])
    raw = {"depth": frame.depth, "rgb": frame.rgb, "intrinsics": frame.camera.K,
           "cam_to_world": frame.camera.cam_to_world, "state": np.zeros(11)}
    built, state = observe(SimpleNamespace(), raw)
    np.testing.assert_array_equal(built.depth, frame.depth)
    assert state.dtype == np.float32
    with pytest.raises(ValueError, match="11"):
        observe(SimpleNamespace(), {**raw, "state": np.zeros(10)})


def test_the_swept_body_is_the_hand_plus_the_held_object_while_it_is_grasped(observer):
    env = FakeEnv([BOWL, PAN, OBSTACLE])
    obs, _ = env.reset(seed=0)
    frame, _ = observe(env, obs)
    runner = PolicyRunner(FakePolicy(), observer, obstacle_phrases=["obstacle_0"], held_object="bowl")
    tracker, model = runner.tracker, runner.guidance.obstacles
    assert model.body == "swept"
    # the EE 3 cm above the bowl's rim, fingers along world y, gripper open: the hand alone
    at_rim = np.array([BOWL.center_xy[0] + 0.05, BOWL.center_xy[1], 0.08])
    free = np.concatenate([at_rim, ROT6D, [0.08, 0.0]]).astype(np.float32)
    tracker.update(frame, step=0)
    offsets, radii = tracker.body(frame, free)
    assert np.allclose(offsets[:, [0, 2]], 0) and np.abs(offsets[:, 1]).max() == pytest.approx(0.04)
    assert tracker.held_radius == pytest.approx(model.hand_half_span)
    # grasped: one more ball, at the bowl's centre (5 cm behind the EE in x) with the bowl's radius
    held = free.copy()
    held[10] = 1.0
    offsets, radii = tracker.body(frame, held)
    assert len(radii) == len(hand_balls(model, ROT6D)[1]) + 1
    np.testing.assert_allclose(offsets[-1, :2], [-0.05, 0.0], atol=0.015)
    assert 0.04 <= radii[-1] <= 0.075
    # a stale flag far from the bowl does not drag a ball across the table
    far = held.copy()
    far[:3] = [0.3, 0.2, 0.3]
    assert len(tracker.body(frame, far)[1]) == len(hand_balls(model, ROT6D)[1])
    with pytest.raises(ValueError, match="sphere"):
        ObstacleSettings(held_radius=0.05)


def test_a_target_the_obstacle_mostly_covers_in_the_first_frame_keeps_the_cloud_of_what_shows(observer):
    """A post over the bowl leaves 4 of its pixels in view (the observer wants 10): the first cloud is taken
    from those, and every later frame, where the bowl stays hidden, keeps it instead of failing."""
    post = Box("obstacle_0", BOWL.center_xy, (0.10, 0.12, 0.30), {"kind": "cylinder", "color": "grey",
                                                                  "role": "obstacle"})
    env = FakeEnv([BOWL, PAN, post], max_steps=6, success_radius=-1.0)
    visible = np.isin(env.frame_.segmentation, env.frame_.instance_names["bowl"]).sum()
    assert 3 <= visible < observer.min_points
    runner = PolicyRunner(FakePolicy(), observer, n_action_steps=2)
    result = rollout(env, runner, seed=0, success_at="end")
    assert result.error is None and result.steps == 6
    assert result.partly_hidden == ["bowl"]
    assert result.held_clouds >= 2  # the re-plans kept the first cloud
    # the few points are the bowl's own: its first centroid is within the bowl's half-size of its centre
    assert np.linalg.norm(np.array(result.targets["bowl"][:2]) - BOWL.center_xy) < 0.06

    hidden = Box("obstacle_0", (BOWL.center_xy[0] + 0.005, 0.0), (0.10, 0.12, 0.30), post.attributes)
    env = FakeEnv([BOWL, PAN, hidden], max_steps=6)
    assert not np.isin(env.frame_.segmentation, env.frame_.instance_names.get("bowl", [-1])).any()
    result = rollout(env, PolicyRunner(FakePolicy(), observer), seed=0)
    assert result.steps == 0 and "ObjectNotFoundError" in result.error  # nothing to keep: an honest failure


class TwoCameraEnv(FakeEnv):
    """FakeEnv with a second camera across the table (tilted the other way), as `other_views` gives it."""

    def __init__(self, boxes, **kwargs):
        super().__init__(boxes, **kwargs)
        self.other_frame = render_boxes(top_down_camera(size=64, height=1.2, fovy_deg=50, tilt_deg=-25), boxes)
        self.other_views_rendered = 0

    def other_views(self):
        self.other_views_rendered += 1
        return [self.other_frame]


def test_a_target_hidden_from_the_camera_in_the_first_frame_is_taken_from_another_view(observer):
    """A wall between the camera and the bowl hides all of it, and a low post between the two; the camera
    across the table sees both. The bowl's cloud comes from there in every frame (it stays hidden), the post is
    fitted from there, instead of failing the episode."""
    obstacle = {"kind": "box", "color": "grey", "role": "obstacle"}
    wall = Box("obstacle_0", (BOWL.center_xy[0], -0.08), (0.24, 0.02, 0.30), obstacle)
    post = Box("obstacle_1", (BOWL.center_xy[0], -0.06), (0.10, 0.015, 0.06), obstacle)
    env = TwoCameraEnv([BOWL, PAN, wall, post], max_steps=6, success_radius=-1.0)
    for hidden in ("bowl", "obstacle_1"):
        assert not np.isin(env.frame_.segmentation, env.frame_.instance_names[hidden]).any()
        seen = np.isin(env.other_frame.segmentation, env.other_frame.instance_names[hidden]).sum()
        assert seen >= observer.min_points
    runner = PolicyRunner(FakePolicy(), observer, n_action_steps=2, obstacle_phrases=["obstacle_0", "obstacle_1"])
    result = rollout(env, runner, seed=0, success_at="end")
    assert result.error is None and result.steps == 6
    assert result.seen_from_other_views == ["bowl", "obstacle_1"] and result.held_clouds == 0
    assert len(result.obstacles) == 2 and abs(result.obstacles[1]["center"][1] + 0.06) < 0.02
    # once per frame the bowl is hidden in; the post's only fit looks in the first frame's views again
    assert env.other_views_rendered == result.steps
    # the other camera's cloud is the bowl's own, not the wall's
    assert np.linalg.norm(np.array(result.targets["bowl"][:2]) - BOWL.center_xy) < 0.06
    # the paper's body measures the held bowl's extent before the grasp: from the other camera too
    sphere = settings("none", {"obstacles.body": "sphere"})
    result = rollout(env, PolicyRunner(FakePolicy(), observer, sphere, n_action_steps=2,
                                       obstacle_phrases=["obstacle_0"], held_object="bowl"), seed=0, success_at="end")
    assert result.error is None and 0.08 < result.held_radius < 0.16  # twice the bowl's fitted radius

    env_without = FakeEnv([BOWL, PAN, wall], max_steps=6)  # one camera: nowhere else to look
    result = rollout(env_without, PolicyRunner(FakePolicy(), observer), seed=0)
    assert result.steps == 0 and "'bowl' was not found" in result.error


def test_guide_when_needed_keeps_the_policys_own_chunk_while_it_clears_the_obstacle(observer):
    config = guided(1.0, {"sampler.strategy": "when_needed"})
    side_post = Box("obstacle_0", (0.02, 0.25), (0.06, 0.06, 0.30), OBSTACLE.attributes)  # far off the line
    policy = FakePolicy()
    clear = rollout(FakeEnv([BOWL, PAN, side_post]), PolicyRunner(policy, observer, config,
                                                                   obstacle_phrases=["obstacle_0"]), seed=0)
    assert clear.success and all(call["guidance"] is None for call in policy.calls)  # never guided
    assert all(tries == 1 for tries in clear.chunk_tries)

    policy = FakePolicy()
    blocked = rollout(FakeEnv([BOWL, PAN, OBSTACLE]), PolicyRunner(policy, observer, config,
                                                                   obstacle_phrases=["obstacle_0"]), seed=0)
    assert not blocked.collided and blocked.min_clearance > 0  # guided where the own chunk would hit
    assert any(call["guidance"] is not None for call in policy.calls) and 2 in blocked.chunk_tries


def test_a_hand_already_inside_the_margin_may_move_away_but_not_closer_when_escape_is_on(observer):
    # a moving obstacle came within a millimetre of the hand: holding still there lets it walk into the hand
    env = FakeEnv([BOWL, PAN, OBSTACLE])
    obs, _ = env.reset(seed=0)
    frame, state = observe(env, obs)
    state = state.copy()
    runner = PolicyRunner(FakePolicy(), observer, settings("none", SPHERE), obstacle_phrases=["obstacle_0"])
    runner.tracker.update(frame, step=0)
    (cylinder,) = runner.tracker.obstacles
    axis = cylinder.center.numpy()
    margin = runner.guidance.obstacles.margin
    state[:3] = [axis[0] - cylinder.safety_distance + 0.019, axis[1], 0.25]  # 1 mm from the held sphere
    kept = {}
    for filters in ([Hold()], [Hold(), Escape()]):
        for name, step in (("away", -0.01), ("closer", 0.01)):
            waypoints = np.array([[state[0] + step * i, state[1], 0.25] for i in range(1, 5)])
            actions = torch.cat([torch.as_tensor(waypoints, dtype=torch.float32),
                                 torch.as_tensor(ROT6D).expand(4, 6), torch.ones(4, 1)], -1)[None]
            path = runner.recipe.executed_path(runner.tracker, state, actions[0])
            assert path.present_clearance() < margin / 2
            context = FilterContext(state, start=0, n_action_steps=4, path=path, margin=margin)
            proposal, notes = run_filters(filters, Proposal(actions, actions), context)
            kept[len(filters) == 2, name] = 4 if proposal.executed is None else proposal.executed
    assert kept[False, "away"] == kept[False, "closer"] == 0  # held still either way
    assert kept[True, "away"] == 4 and kept[True, "closer"] == 0


def test_a_hand_inside_an_obstacle_with_no_way_forward_steps_straight_out(observer):
    env = FakeEnv([BOWL, PAN, OBSTACLE])
    obs, _ = env.reset(seed=0)
    frame, state = observe(env, obs)
    runner = PolicyRunner(FakePolicy(), observer, settings("none", SPHERE), obstacle_phrases=["obstacle_0"])
    runner.tracker.update(frame, step=0)
    (cylinder,) = runner.tracker.obstacles
    axis = cylinder.center.numpy()
    margin = runner.guidance.obstacles.margin

    def retreat_from(x: float, step: float) -> tuple[np.ndarray, np.ndarray, float]:
        here = state.copy()
        here[:3] = [x, axis[1], 0.25]
        waypoints = np.array([[x + step * i, axis[1], 0.25] for i in range(1, 5)])
        actions = np.hstack([waypoints, np.tile(ROT6D, (4, 1)), np.ones((4, 1))])
        cost = runner.recipe.executed_path(runner.tracker, here, torch.as_tensor(actions, dtype=torch.float32))
        return here[:3], retreat(here, cost, margin / 2).numpy(), cost.present_clearance()

    # 2 cm into the held sphere's reach, every step of the chunk deeper: straight back, away from the axis
    here, out, gap = retreat_from(axis[0] - cylinder.safety_distance + 0.04, step=0.01)
    assert gap < -0.01 and out[0] < here[0] - 0.02 and abs(out[1] - here[1]) < 1e-6
    assert float(cylinder.clearance(torch.as_tensor(out)[None, None])) > gap + 0.02
    # not inside: an ordinary hold
    here, out, _ = retreat_from(axis[0] - cylinder.safety_distance - 0.05, step=0.0)
    np.testing.assert_allclose(out, here, atol=1e-6)
