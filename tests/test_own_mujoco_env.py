"""A user's own MuJoCo environment goes through collect, train and evaluate with lano3dp's public pieces only.

The environment below is what a user already has: a MuJoCo scene (a table, a red block, a mocap hand) whose
step takes delta actions (position change, axis-angle rotation change, gripper). Nothing of lano3dp.sim is
imported. What lano3dp needs beyond it is below the GLUE line: an observation with `mujoco_frame`, the
`AbsoluteActions` wrapper in the factory, and a closed-loop scripted expert.
"""

from __future__ import annotations

import ast
import time
from pathlib import Path

import mujoco
import numpy as np
import pytest

from lano3dp import EvalConfig, evaluate
from lano3dp.collect import CollectionError, collect_from_env
from lano3dp.data import EpisodeStore
from lano3dp.geometry.rotations import matrix_to_rot6d, rot6d_to_matrix
from lano3dp.mujoco_frame import MujocoFrameError, mujoco_frame
from lano3dp.perception import ObjectObserver, SimOracleSegmenter
from lano3dp.train import TrainConfig, policy_config_for_dataset, train
from lano3dp.wrappers import AbsoluteActions, rotation_to_axis_angle

SCENE = """
<mujoco>
  <visual><global offwidth="96" offheight="96"/></visual>
  <worldbody>
    <light pos="0 0 1.5" dir="0 0 -1"/>
    <camera name="front" pos="0.55 0 0.55" xyaxes="0 1 0 -0.707 0 0.707" fovy="50"/>
    <geom name="table" type="box" size="0.4 0.4 0.02" pos="0 0 -0.02" rgba="0.8 0.7 0.6 1"/>
    <body name="block" pos="0 0 0.04"><geom name="block_box" type="box" size="0.04 0.04 0.04" rgba="1 0 0 1"/></body>
    <body name="hand" mocap="true" pos="0 0 0.3">
      <geom name="palm" type="sphere" size="0.015" rgba="0.2 0.2 0.2 1" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
</mujoco>
"""


class TouchBlockSim:
    """The user's own simulator: touch the top of a block with a hand. step(delta (7,)): position change (m,
    at most 5 cm), axis-angle rotation change (rad, the point hand ignores it), gripper (0 open .. 1 closed)."""

    control_hz = 10.0

    def __init__(self, image_size: int = 64, max_steps: int = 30):
        self.model = mujoco.MjModel.from_xml_string(SCENE)
        self.data = mujoco.MjData(self.model)
        self.renderer = mujoco.Renderer(self.model, image_size, image_size)
        self.image_size, self.max_steps, self.steps = image_size, max_steps, 0

    def reset(self, *, seed=None, options=None):
        rng = np.random.default_rng(seed)
        mujoco.mj_resetData(self.model, self.data)
        self.model.body("block").pos[:2] = rng.uniform(-0.1, 0.1, 2)
        self.data.mocap_pos[0] = [*rng.uniform(-0.15, 0.15, 2), rng.uniform(0.25, 0.35)]
        mujoco.mj_forward(self.model, self.data)
        self.steps = 0
        return self.observation(), self.info()

    def step(self, delta):
        move = np.asarray(delta[:3], dtype=np.float64)
        self.data.mocap_pos[0] += move * min(1.0, 0.05 / (np.linalg.norm(move) + 1e-12))
        for _ in range(5):
            mujoco.mj_step(self.model, self.data)
        self.steps += 1
        info = self.info()
        return self.observation(), 0.0, info["success"], self.steps >= self.max_steps, info

    def block_top(self) -> np.ndarray:
        return self.data.body("block").xpos + [0.0, 0.0, 0.04]

    def info(self) -> dict:
        return {"success": bool(np.linalg.norm(self.data.mocap_pos[0] - self.block_top()) < 0.03)}

    def observation(self) -> dict:
        return {"hand": self.data.mocap_pos[0].copy(), "image": self.renderer.render()}

    def close(self):
        self.renderer.close()


# ---- GLUE: what lano3dp needs beyond the simulator ----------------------------------------------
class TouchBlockEnv(TouchBlockSim):
    def observation(self) -> dict:  # state (11,): EE position, rotation 6D, gripper opening (m), grasp flag
        state = np.r_[self.data.mocap_pos[0], matrix_to_rot6d(np.eye(3)), 0.08, 0.0].astype(np.float32)
        frame = mujoco_frame(self.model, self.data, "front", {"block": ["block"]}, self.image_size,
                             self.image_size, self.renderer, attributes={"block": {"color": "red"}})
        return {"state": state, "frame": frame}


def make_env(image_size=64, max_steps=None, **options):
    return AbsoluteActions(TouchBlockEnv(image_size, max_steps or 30), rotation="axis_angle")


def touch_expert(env, obs, info):  # closed loop: 4 cm a step towards 1 cm above the block's top
    hand = obs["state"][:3]
    way = env.block_top() + [0.0, 0.0, 0.01] - hand
    way *= min(1.0, 0.04 / (np.linalg.norm(way) + 1e-12))
    return np.r_[hand + way, matrix_to_rot6d(np.eye(3)), 0.0]


def collect_touch_block(out: Path, episodes: int = 3):
    return collect_from_env(make_env, touch_expert, episodes, out, slots=["block"], task="touch_block",
                            n_points=32, image_size=64, progress=False)
# ---- end of GLUE --------------------------------------------------------------------------------


TINY = dict(down_dims=(16, 32), diffusion_step_embed_dim=16, n_groups=4, point_hidden_dims=(16, 32),
            encoder_out=16, state_feature_dim=16, n_obs_steps=2, horizon=8, n_action_steps=4)


@pytest.fixture(scope="module")
def touch_data(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("touch") / "touch.zarr"
    result = collect_touch_block(out)
    assert (result.added, result.total) == (3, 3)
    return out


def test_the_closed_loop_expert_is_recorded_with_the_envs_slots_rate_and_camera(touch_data):
    store = EpisodeStore.open(touch_data)
    attrs = store.attrs
    assert attrs["task"] == attrs["skill"] == "touch_block" and attrs["object_names"] == ["block"]
    assert attrs["control_hz"] == 10.0 and attrs["episode_seeds"] == [0, 1, 2]
    assert attrs["env"] == "test_own_mujoco_env:make_env" and attrs["expert"] == "test_own_mujoco_env:touch_expert"
    assert attrs["camera"]["width"] == 64 and attrs["crop_low"] is None
    for index in range(3):
        episode = store.get_episode(index)
        length = len(episode["action"])
        assert 13 <= length <= 25  # 4 cm a step from 25-35 cm above the table, then 1 s of follow-through
        assert episode["object_clouds"].shape == (length, 1, 32, 3) and episode["state"].shape == (length, 11)
        # the block's cloud lies on the block (a 8 cm cube on the table), the last action at its top
        cloud = episode["object_clouds"][0, 0]
        assert 0.0 < cloud[:, 2].min() and cloud[:, 2].max() < 0.085
        assert np.linalg.norm(episode["action"][-1, :2] - cloud[:, :2].mean(0)) < 0.03
        assert np.all(episode["scene_cloud"][:, :, 2] > 0.0)  # the table (z = 0) is left out
        # closed loop: every recorded action is 4 cm or less from the state it was chosen in
        assert np.linalg.norm(episode["action"][:, :3] - episode["state"][:, :3], axis=1).max() < 0.0401


def test_collection_resumes_and_refuses_other_settings(touch_data, tmp_path):
    import shutil

    copy = tmp_path / "resume.zarr"
    shutil.copytree(touch_data, copy)
    result = collect_touch_block(copy, episodes=4)
    assert (result.added, result.total) == (1, 4)
    assert EpisodeStore.open(copy).attrs["episode_seeds"] == [0, 1, 2, 3]
    with pytest.raises(CollectionError, match="n_points=32, not 16"):
        collect_from_env(make_env, touch_expert, 5, copy, slots=["block"], task="touch_block", n_points=16,
                         image_size=64)
    with pytest.raises(CollectionError, match="give the policy's object slots"):
        collect_from_env(make_env, touch_expert, 1, tmp_path / "noslots.zarr", task="touch_block", image_size=64)
    assert not (tmp_path / "noslots.zarr").exists()


def test_a_tiny_policy_trained_on_it_evaluates_in_the_same_env(touch_data, tmp_path):
    started = time.perf_counter()
    policy = policy_config_for_dataset(touch_data, **TINY)
    assert policy.object_names == ("block",) and policy.n_points == 32
    checkpoint = train(TrainConfig(data=str(touch_data), out=str(tmp_path / "run"), policy=policy, steps=4,
                                   batch_size=4, warmup_steps=1, val_ratio=0.0, ckpt_every=4, val_every=4,
                                   progress=False))
    report = evaluate(EvalConfig(checkpoint=str(checkpoint), env=make_env, episodes=1, max_steps=4))
    (episode,) = report["episodes"]
    assert report["env"] == "test_own_mujoco_env:make_env" and episode["error"] is None
    assert episode["success_reported"] is True and 1 <= episode["steps"] <= 4
    assert set(episode["targets"]) == {"block"}
    assert time.perf_counter() - started < 60


def test_the_collect_command_takes_the_env_and_the_expert_by_name(tmp_path):
    from typer.testing import CliRunner

    from lano3dp.cli import app

    here = Path(__file__)
    out = tmp_path / "cli.zarr"
    command = ["collect", "--env", f"{here}:make_env", "--expert", f"{here}:touch_expert", "--slots", "block",
               "--task", "touch_block", "--episodes", "1", "--out", str(out), "--image-size", "64", "--n-points",
               "16", "--no-progress"]
    result = CliRunner().invoke(app, command)
    assert result.exit_code == 0, (result.output, result.exception)
    assert "added 1 episodes" in result.output
    store = EpisodeStore.open(out)
    assert store.attrs["object_names"] == ["block"] and store.attrs["expert"] == f"{here}:touch_expert"
    assert store.get_episode(0)["object_clouds"].shape[1:] == (1, 16, 3)
    wrong = CliRunner().invoke(app, command[:4] + [f"{here}:no_expert"] + command[5:])
    assert wrong.exit_code == 2 and "has no attribute 'no_expert'" in wrong.output
    built_in_only = CliRunner().invoke(app, ["collect", "--task", "bottle_upright", "--slots", "bottle", "--out",
                                             str(tmp_path / "b.zarr")])
    assert built_in_only.exit_code == 2 and "need --env" in built_in_only.output


def test_mujoco_frame_is_metric_calibrated_and_segmented():
    env = TouchBlockEnv(image_size=64)
    try:
        obs, _ = env.reset(seed=3)
        frame = obs["frame"]
        assert frame.instance_names == {"block": [0]}
        assert frame.instance_attributes == {"block": {"kind": "block", "color": "red"}}
        # "the red block" resolves through the sim oracle; its points sit inside the 8 cm cube
        clouds = ObjectObserver(SimOracleSegmenter(), n_points=64).observe(frame, ["the red block"])
        centre = env.data.body("block").xpos
        assert np.abs(clouds.points[0] - centre).max() < 0.041 + 2e-3
        # depth is metric z-depth: the camera's distance to the block top along its axis
        camera = frame.camera
        u, v = np.floor(camera.project(env.block_top()[None])[0][0]).astype(int)
        z = (np.linalg.inv(camera.cam_to_world) @ np.r_[env.block_top(), 1.0])[2]
        assert frame.depth[v, u] == pytest.approx(z, abs=5e-3) and frame.segmentation[v, u] == 0
        with pytest.raises(MujocoFrameError, match="no body or geom named 'cup'"):
            mujoco_frame(env.model, env.data, "front", {"cup": ["cup"]}, 64, 64, env.renderer)
        with pytest.raises(MujocoFrameError, match="no camera 'side'"):
            mujoco_frame(env.model, env.data, "side", {"block": ["block"]}, 64, 64, env.renderer)
        geom_only = mujoco_frame(env.model, env.data, 0, {"block": ["block_box"]}, 64, 64, env.renderer)
        np.testing.assert_array_equal(geom_only.segmentation, frame.segmentation)
    finally:
        env.close()


def test_a_free_camera_frame_is_calibrated_like_a_model_camera():
    env = TouchBlockEnv(image_size=64)
    try:
        env.reset(seed=3)
        free = mujoco.MjvCamera()  # a view the model has no camera for, as a gymnasium env's viewer uses
        free.lookat, free.distance, free.azimuth, free.elevation = env.data.body("block").xpos, 0.6, 30.0, -50.0
        frame = mujoco_frame(env.model, env.data, free, {"block": ["block"]}, 64, 64, env.renderer)
        centre = env.data.body("block").xpos
        # the camera sits 0.6 m from the look-at point, and what it sees of the block lies on the 8 cm cube
        assert np.linalg.norm(frame.camera.cam_to_world[:3, 3] - centre) == pytest.approx(0.6, abs=1e-6)
        clouds = ObjectObserver(SimOracleSegmenter(), n_points=64).observe(frame, ["block"])
        assert np.abs(clouds.points[0] - centre).max() < 0.041 + 2e-3
    finally:
        env.close()


def test_absolute_actions_become_the_deltas_that_reach_them():
    class Recorder:
        def __init__(self):
            self.sent, self.state = [], np.r_[0.1, 0.2, 0.3, matrix_to_rot6d(np.eye(3)), 0.08, 0.0]

        def reset(self, *, seed=None, options=None):
            return {"state": self.state}, {}

        def step(self, action):
            self.sent.append(action)
            return {"state": self.state}, 0.0, False, False, {}

    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # a quarter turn about z
    target = np.r_[0.15, 0.2, 0.25, matrix_to_rot6d(turn), 1.0]
    inner = Recorder()
    env = AbsoluteActions(inner, rotation="axis_angle")
    env.reset(seed=0)
    env.step(target)
    np.testing.assert_allclose(inner.sent[-1], [0.05, 0.0, -0.05, 0.0, 0.0, np.pi / 2, 1.0], atol=1e-6)
    six = AbsoluteActions(inner, rotation="rot6d", max_position_delta=0.01, gripper=lambda g: 0.04 * (1 - g))
    six.reset()
    six.step(target)
    np.testing.assert_allclose(inner.sent[-1][:3], np.array([0.05, 0.0, -0.05]) / np.sqrt(0.005) * 0.01, atol=1e-6)
    np.testing.assert_allclose(rot6d_to_matrix(inner.sent[-1][3:9]), turn, atol=1e-6)
    assert inner.sent[-1][9] == pytest.approx(0.0)
    half = rotation_to_axis_angle(np.diag([-1.0, -1.0, 1.0]))
    assert np.linalg.norm(half) == pytest.approx(np.pi) and abs(half[2]) == pytest.approx(np.pi)
    with pytest.raises(ValueError, match="takes \\(10,\\) absolute actions"):
        env.step(np.zeros(7))


def test_the_glue_is_at_most_30_lines_and_imports_no_simulator():
    source = Path(__file__).read_text()
    glue = source.split("# ---- GLUE", 1)[1].split("# ---- end of GLUE", 1)[0].splitlines()[1:]
    code = [line for line in glue if line.strip() and not line.strip().startswith(("#", '"""'))]
    assert len(code) == 16  # the acceptance: at most 30, the expert included
    imported = {node.module for node in ast.walk(ast.parse(source)) if isinstance(node, ast.ImportFrom)}
    assert not any(name and name.startswith("lano3dp.sim") for name in imported)
