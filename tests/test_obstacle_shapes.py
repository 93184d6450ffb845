"""Obstacle shapes as a registry (guidance.shapes): a shape added from outside the package, in this file alone,
is fitted, described and drawn, chosen by ObstacleSettings and `--set guidance.obstacles.shape=NAME`; the
built-in shapes keep their numbers; unknown names fail in one line naming the registered ones."""

from __future__ import annotations

import json

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import torch  # noqa: E402
from typer.testing import CliRunner  # noqa: E402

from lano3dp.cli import app  # noqa: E402
from lano3dp.errors import EmptyCloudError  # noqa: E402
from lano3dp.evaluation import EvalConfig, GuidanceChoice  # noqa: E402
from lano3dp.guidance import (  # noqa: E402
    ObstacleSettings,
    ObstacleShape,
    Sphere,
    UnknownObstacleShapeError,
    fit_box,
    fit_cylinder,
    get_obstacle_shape,
    obstacle_shape_names,
    register_obstacle_shape,
    unregister_obstacle_shape,
)
from lano3dp.guidance.obstacles import fit_obstacle_shape  # noqa: E402
from lano3dp.guidance.settings import guidance_preset  # noqa: E402
from lano3dp.guidance.shapes import describe_obstacle, draw_obstacle, shape_for_workers  # noqa: E402
from lano3dp.report import plot_top_view  # noqa: E402

CENTER, RADIUS = np.array([0.40, 0.10, 0.20]), 0.05


class BallShape(ObstacleShape):
    """A ball round the cloud's centroid, its radius the farthest point's distance: a whole new shape in ~20 lines."""

    drawn: list[dict] = []

    def fit(self, points, *, held_radius, margin, xy_only):
        points = np.asarray(points, dtype=np.float64)
        points = points[np.isfinite(points).all(-1)]
        if len(points) < 3:
            return None  # too few points: the runner treats it as a cloud perception lost
        center = points.mean(0)
        radius = max(float(np.linalg.norm(points - center, axis=1).max()), 1e-3)
        return Sphere(center.tolist(), radius, xy_only=xy_only, held_radius=held_radius, margin=margin)

    def describe(self, obstacle):
        x, y, z = obstacle.center.tolist()
        return f"ball at ({x:.2f}, {y:.2f}, {z:.2f}) m, radius {100 * obstacle.radius:.1f} cm"

    def plot_data(self, obstacle):
        return {"center": obstacle.center.tolist(), "radius": obstacle.radius}

    def draw(self, ax, data, *, label=None):
        from matplotlib.patches import Circle

        self.drawn.append(dict(data))
        return [ax.add_patch(Circle(data["center"][:2], data["radius"], color="tab:purple", label=label))]


@pytest.fixture
def ball():
    shape = register_obstacle_shape("sphere", BallShape())
    BallShape.drawn.clear()
    yield shape
    unregister_obstacle_shape("sphere")


def ball_cloud(count: int = 200, seed: int = 0) -> np.ndarray:
    """Points on a 5 cm sphere round CENTER, in opposite pairs so that their centroid is its centre."""
    directions = np.random.default_rng(seed).normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return CENTER + RADIUS * np.concatenate([directions, -directions])


def at(*xyz) -> torch.Tensor:
    return torch.tensor([[list(xyz)]], dtype=torch.float64)  # (B=1, T=1, 3)


def test_a_shape_registered_from_outside_is_fitted_as_the_settings_name_it(ball):
    assert obstacle_shape_names() == ("cylinder", "box", "points", "sphere")
    model = ObstacleSettings(shape="sphere", margin=0.02, xy_only=False)
    cost = fit_obstacle_shape(model, ball_cloud(), held_radius=0.03)
    assert isinstance(cost, Sphere)
    np.testing.assert_allclose(cost.center.numpy(), CENTER, atol=5e-3)
    assert cost.radius == pytest.approx(RADIUS, abs=1e-6)
    # metres: inside the ball the clearance is minus its radius and held radius, and the cost pushes;
    # 1 cm short of Q* (5 + 3 + 2 cm) it still pushes by that 1 cm; 1 m away it is zero
    x, y, z = CENTER
    assert cost.clearance(at(x, y, z)).item() == pytest.approx(-(RADIUS + 0.03), abs=5e-3)
    assert cost(at(x, y, z)).item() == pytest.approx(RADIUS + 0.03 + 0.02, abs=5e-3)
    assert cost(at(x + 0.09, y, z)).item() == pytest.approx(0.01, abs=5e-3)
    assert cost(at(x + 1.0, y, z)).item() == 0.0
    # too few points: None from the shape, EmptyCloudError (naming the shape) from the model, as a lost cloud
    with pytest.raises(EmptyCloudError, match="'sphere' cannot fit"):
        fit_obstacle_shape(model, ball_cloud()[:2], held_radius=0.0)


def test_the_new_shape_is_described_in_results_and_drawn_in_the_top_view(ball, tmp_path):
    cost = fit_obstacle_shape(ObstacleSettings(shape="sphere"), ball_cloud(), held_radius=0.0)
    data = json.loads(json.dumps(describe_obstacle(cost, "sphere")))  # as results JSON holds it
    assert data["kind"] == "sphere" and data["shape"] == "Sphere"
    assert data["description"] == "ball at (0.40, 0.10, 0.20) m, radius 5.0 cm"
    fig, ax = plt.subplots()
    try:
        before = len(ax.patches)
        artists = draw_obstacle(ax, data, label="obstacle")
        assert len(artists) == 1 and len(ax.patches) == before + 1 and artists[0].get_label() == "obstacle"
    finally:
        plt.close(fig)
    # `lano3dp run`'s top view draws results' obstacles through their shape
    png = plot_top_view(tmp_path / "top.png", [("run", np.array([[0.3, 0.0, 0.2], [0.5, 0.2, 0.2]]))],
                        obstacles=[data])
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and BallShape.drawn[-1] == data


def test_a_closed_loop_episode_guides_against_the_new_shape_and_reports_it(ball):
    from lano3dp.geometry.rotations import matrix_to_rot6d
    from lano3dp.perception import ObjectObserver, SimOracleSegmenter
    from lano3dp.perception.synthetic import Box, render_boxes, top_down_camera
    from lano3dp.policy import ActionChunk, ChunkedControl, PolicyConfig
    from lano3dp.runtime import PolicyRunner, rollout

    boxes = [Box("bowl", (-0.25, 0.0), (0.10, 0.10, 0.05), {"kind": "bowl", "role": "target"}),
             Box("obstacle_0", (0.02, 0.0), (0.06, 0.06, 0.30), {"kind": "cylinder", "role": "obstacle"})]
    frame = render_boxes(top_down_camera(size=64, height=1.2, fovy_deg=50, tilt_deg=25), boxes)
    state = np.concatenate([[-0.25, 0.0, 0.25], matrix_to_rot6d(np.eye(3)), [0.04, 0.0]]).astype(np.float32)

    class StillEnv:  # the hand stays where it is
        def reset(self, *, seed=None, options=None):
            return {"frame": frame, "state": state}, {}

        def step(self, action):
            return {"frame": frame, "state": state}, 0.0, False, False, {}

    class StillPolicy(ChunkedControl):
        config = PolicyConfig(obs_type="objects", object_names=("bowl",), n_obs_steps=1, horizon=8, n_action_steps=4)
        device = torch.device("cpu")
        costs: list = []

        def predict_action_chunk(self, obs, *, position_cost=None, **_):
            self.costs.append(position_cost)
            trajectory = torch.as_tensor(state[:10]).expand(1, 8, 10).clone()
            return ActionChunk(trajectory[:, :4], trajectory)

    policy = StillPolicy()
    # the fitted shape's bare cost (no metric push: this policy has no normaliser; waypoints only)
    config = guidance_preset("recommended").with_changes(
        {"sampler.last_steps": 10, "obstacles.shape": "sphere", "cost.metric_push": False, "cost.densify": 1})
    runner = PolicyRunner(policy, ObjectObserver(SimOracleSegmenter(), n_points=32, min_points=5), config,
                          obstacle_phrases=["obstacle_0"])
    result = rollout(StillEnv(), runner, seed=0, max_steps=2)
    assert result.error is None
    (fitted,) = runner.tracker.obstacles
    assert isinstance(fitted, Sphere)  # segmented, then fitted by the registered shape
    # round the 6 cm obstacle (the centroid of the points in view leans toward the tilted camera)
    assert np.linalg.norm(fitted.center[:2].numpy() - [0.02, 0.0]) < 0.04
    (data,) = result.to_dict()["obstacles"]
    assert data["kind"] == "sphere" and data["description"] == get_obstacle_shape("sphere").describe(fitted)
    # guidance got a cost that is the fitted ball's (seen through the swept hand): it pushes at the ball's centre
    assert policy.costs[0] is not None and policy.costs[0](fitted.center.reshape(1, 1, 3)).item() > 0


def test_the_configs_and_the_command_line_take_a_registered_shape(ball, tmp_path):
    config = EvalConfig(task="bowl_pour", guidance=GuidanceChoice("recommended", {"obstacles.shape": "sphere"}))
    assert config.guidance.resolve(None).obstacles.shape == "sphere"
    assert shape_for_workers("cylinder") == {}
    runner = CliRunner()
    for command in (["eval", "--task", "bowl_pour"], ["run", "pour the bowl into the pan"]):
        result = runner.invoke(app, [*command, "--set", "guidance.obstacles.shape=sphere", "--checkpoint",
                                     str(tmp_path / "none")])
        # the shape is accepted: the next check, the missing checkpoint, is what stops the command
        assert result.exit_code == 2 and "--checkpoint" in result.output and "obstacle shape" not in result.output


def test_eval_workers_get_the_registered_shape(ball):
    import queue

    from lano3dp.evaluation.pool import Job, _worker_main

    # spawned eval workers start with the built-in shapes: the parent's registered one travels to them pickled
    payloads = shape_for_workers("sphere")
    guidance = guidance_preset("recommended").with_changes({"obstacles.shape": "sphere"}).to_dict()
    unregister_obstacle_shape("sphere")
    todo, done = queue.Queue(), queue.Queue()
    for job in (Job(0, 7), None):
        todo.put(job)
    _worker_main({"checkpoint": "no-such-run"}, guidance, {"shapes": payloads, "observation_types": {}, "filters": {}},
                 todo, done)
    assert isinstance(get_obstacle_shape("sphere"), BallShape)
    # the settings were accepted: what stopped this worker is the missing checkpoint, not the shape
    assert done.get_nowait()[2].startswith("FileNotFoundError")

    class Local(BallShape):  # defined inside a function: a worker could not import it
        pass

    register_obstacle_shape("sphere", Local(), replace=True)
    with pytest.raises(ValueError, match="'sphere' cannot be sent to worker processes"):
        shape_for_workers("sphere")


def test_a_shape_registered_by_the_env_module_is_accepted_by_the_command_line(tmp_path):
    module = tmp_path / "my_env.py"
    module.write_text(
        "from lano3dp.guidance import ObstacleShape, register_obstacle_shape\n"
        "class Cone(ObstacleShape):\n"
        "    def fit(self, points, *, held_radius, margin, xy_only):\n"
        "        return None\n"
        "register_obstacle_shape('cone', Cone)\n"
        "def make(task):\n"
        "    raise RuntimeError('not called')\n")
    try:
        result = CliRunner().invoke(app, ["eval", "--env", f"{module}:make", "--task", "t", "--set",
                                          "guidance.obstacles.shape=cone", "--checkpoint", str(tmp_path / "none")])
        assert result.exit_code == 2 and "--checkpoint" in result.output and "obstacle shape" not in result.output
    finally:
        if "cone" in obstacle_shape_names():
            unregister_obstacle_shape("cone")


def test_unknown_shapes_fail_in_one_line_naming_the_registered_ones():
    with pytest.raises(UnknownObstacleShapeError, match=r"^unknown obstacle shape 'cone'; registered: cylinder, box, "
                                                        r"points$"):
        ObstacleSettings(shape="cone")
    with pytest.raises(ValueError, match="unknown obstacle shape 'cone'"):
        EvalConfig(task="bowl_pour", guidance=GuidanceChoice("recommended", {"obstacles.shape": "cone"}))
    for command in (["eval", "--task", "bowl_pour"], ["run", "pour the bowl into the pan"]):
        result = CliRunner().invoke(app, [*command, "--set", "guidance.obstacles.shape=cone"])
        assert result.exit_code == 2
        lines = [line for line in result.output.splitlines() if line.strip()]
        assert len(lines) == 1 and "unknown obstacle shape 'cone'; registered: cylinder, box, points" in lines[0]
        assert "guidance.obstacles" in lines[0]
    listing = CliRunner().invoke(app, ["settings"]).output
    assert "obstacle shapes (guidance.obstacles.shape): cylinder, box, points" in listing


def test_registering_is_checked():
    with pytest.raises(ValueError, match="without spaces"):
        register_obstacle_shape("my shape", BallShape())
    with pytest.raises(TypeError, match="lacks fit"):
        register_obstacle_shape("odd", object())
    with pytest.raises(ValueError, match="already registered"):
        register_obstacle_shape("cylinder", BallShape())  # a built-in is not taken over by accident
    with pytest.raises(ValueError, match="cannot be removed"):
        unregister_obstacle_shape("cylinder")
    with pytest.raises(UnknownObstacleShapeError):
        unregister_obstacle_shape("never-registered")


def test_the_built_in_shapes_fit_as_the_fitting_functions_do():
    cloud = ball_cloud()
    for name, fit in (("cylinder", fit_cylinder), ("box", fit_box)):
        cost = fit_obstacle_shape(ObstacleSettings(shape=name, margin=0.03), cloud, held_radius=0.04)
        expected = fit(cloud, held_radius=0.04, margin=0.03, xy_only=True)
        assert repr(cost) == repr(expected)
        positions = torch.as_tensor(cloud[None, ::7] * 1.3)
        torch.testing.assert_close(cost.clearance(positions), expected.clearance(positions))
    points = fit_obstacle_shape(ObstacleSettings(shape="points"), cloud, held_radius=0.04)
    assert type(points).__name__ == "PointCloudObstacle" and len(points.points) == len(cloud)
    assert get_obstacle_shape("points").plot_data(points) == {}  # too many numbers for results, drawn as before


def test_an_obstacle_is_described_with_its_builtin_shape_and_drawn_by_the_kind_it_names():
    cylinder = fit_cylinder(ball_cloud(), held_radius=0.03)
    data = describe_obstacle(cylinder)  # no shape given: the built-in one of its class
    assert {key: data[key] for key in ("shape", "center", "radius", "safety_distance")} == {
        "shape": "Cylinder", "center": [round(float(c), 5) for c in cylinder.center],
        "radius": round(cylinder.radius, 5), "safety_distance": round(cylinder.safety_distance, 5)}
    assert data["kind"] == "cylinder" and data["description"] == (
        f"vertical cylinder at ({cylinder.center[0]:.3f}, {cylinder.center[1]:.3f}) m, radius "
        f"{100 * cylinder.radius:.1f} cm, Q* {100 * cylinder.safety_distance:.1f} cm")
    box = describe_obstacle(fit_box(ball_cloud()), "box")
    unregistered = {"shape": "Sphere", "kind": "not-imported-here", "center": [0, 0], "radius": 0.1}
    fig, ax = plt.subplots()
    try:
        assert len(draw_obstacle(ax, data, label="obstacle (fitted)")) == 2  # the body and the dashed Q* circle
        assert [a.get_label() for a in ax.patches] == ["obstacle (fitted)", "safety distance Q*"]
        assert len(draw_obstacle(ax, box)) == 1  # the footprint
        assert draw_obstacle(ax, unregistered) == []  # a plug-in this process lacks is not guessed at
        assert draw_obstacle(ax, {k: v for k, v in box.items() if k != "kind"}) == []  # `lano3dp migrate` names it
    finally:
        plt.close(fig)
