"""TabletopEnv contract: experts succeed, bad actions are rejected or clipped, random actions never crash."""

import warnings

import numpy as np
import pytest

from lano3dp.sim.env import InvalidActionError, TabletopEnv
from lano3dp.sim.protocol import SimulatorProtocol
from simulator_versions import skip_if_mujoco_too_old


@pytest.fixture(scope="module")
def env():
    environment = TabletopEnv("bowl_pour", image_size=64)
    yield environment
    environment.close()


def run_expert(env, seed):
    env.reset(seed=seed)
    actions = env.expert_plan().actions()
    info = {}
    for t in range(env.max_steps):
        _, reward, terminated, truncated, info = env.step(actions[min(t, len(actions) - 1)])
        if terminated or truncated:
            break
    return info["success"], reward


@pytest.mark.parametrize("seed", [0, 1])
def test_bowl_pour_expert_succeeds(env, seed):
    skip_if_mujoco_too_old("bowl_pour")
    success, reward = run_expert(env, seed)
    assert success and reward == 1.0


def test_observation_matches_declared_space(env):
    obs, info = env.reset(seed=3)
    assert env.observation_space.contains(obs)
    assert obs["state"].shape == (11,)
    assert info["instruction"] == "pour the contents of the bowl into the pan"
    np.testing.assert_allclose(obs["state"][:3], [0.30, 0.0, 0.30], atol=0.01)  # home pose
    assert obs["state"][10] == 0.0  # nothing held


def test_nan_action_raises_naming_the_index(env):
    env.reset(seed=0)
    action = env.expert_plan().actions()[0].copy()
    action[4] = np.nan
    with pytest.raises(InvalidActionError, match=r"indices \[4\]"):
        env.step(action)


def test_degenerate_rotation_raises(env):
    env.reset(seed=0)
    action = np.array([0.4, 0, 0.2, 1, 0, 0, 2, 0, 0, 0.0])
    with pytest.raises(InvalidActionError, match="degenerate"):
        env.step(action)


def test_far_away_target_is_clipped_to_the_workspace(env):
    env.reset(seed=0)
    action = np.array([5.0, -5.0, 3.0, 1, 0, 0, 0, -1, 0, 2.0])
    for _ in range(25):  # 0.9 m away at 5 cm per step (the motion limit)
        obs, _, _, _, info = env.step(action)
    assert info["action_clipped"]
    np.testing.assert_allclose(obs["state"][:3], [env.workspace_high[0], env.workspace_low[1], env.workspace_high[2]],
                               atol=0.02)


def test_random_actions_never_crash(env):
    rng = np.random.default_rng(0)
    env.reset(seed=5)
    for _ in range(40):
        action = rng.normal(size=10) * np.array([0.5, 0.5, 0.5, 1, 1, 1, 1, 1, 1, 1]) + [0.45, 0, 0.2, 0, 0, 0, 0, 0,
                                                                                         0, 0.5]
        obs, *_ = env.step(action)
        assert np.all(np.isfinite(obs["state"]))


def test_env_meets_the_simulator_protocol(env):
    assert isinstance(env, SimulatorProtocol)


def test_gymnasium_env_checker_passes():
    from gymnasium.utils.env_checker import check_env

    environment = TabletopEnv("bottle_upright", image_size=32)
    try:
        check_env(environment, skip_render_check=False)
    finally:
        environment.close()


def test_frame_carries_ground_truth_instances(env):
    env.reset(seed=0)
    frame = env.frame()
    assert frame.instance_attributes["bowl"] == {"kind": "bowl", "color": "blue", "size": "medium", "role": "target"}
    assert frame.instance_attributes["gripper"]["role"] == "robot"
    bowl_pixels = np.isin(frame.segmentation, frame.instance_names["bowl"]).sum()
    assert bowl_pixels > 20
    assert frame.depth[frame.segmentation >= 0].min() > 0.3  # metres from the camera


def test_a_frame_taken_for_later_renders_that_moment_and_only_when_asked(env):
    env.reset(seed=0)
    actions = env.expert_plan().actions()
    env.step(actions[0])
    later, now = env.frame_later(), env.frame()
    env.defer_images(True)
    try:
        obs = env.step(actions[1])[0]
        assert set(obs) == {"state"}  # no image rendered for a step nobody looks at
        env.step(actions[2])
        then = later()
    finally:
        env.defer_images(False)
    np.testing.assert_array_equal(then.depth, now.depth)
    np.testing.assert_array_equal(then.segmentation, now.segmentation)
    np.testing.assert_array_equal(then.camera.cam_to_world, now.camera.cam_to_world)
    assert then.timestamp == now.timestamp and later() is then
    assert not np.array_equal(env.frame().depth, now.depth)  # the present is rendered when asked for
    stale = env.frame_later()
    env.reset(seed=1)
    with pytest.raises(RuntimeError, match="earlier episode"):
        stale()


def test_extreme_random_actions_among_obstacles_never_crash():
    environment = TabletopEnv("bowl_pour", variation="obstacle+clutter", image_size=32, render_rgb=False)
    rng = np.random.default_rng(1)
    environment.action_space.seed(8)
    try:
        environment.reset(seed=0)
        assert any(o.role == "obstacle" for o in environment.episode.extras.objects)
        for t in range(60):
            action = environment.action_space.sample() if t % 2 else rng.uniform(-3, 3, size=10)
            obs, _, _, _, info = environment.step(action)
            assert np.all(np.isfinite(obs["state"]))
            assert np.isfinite(info["min_obstacle_clearance"])
            if info["min_obstacle_clearance"] < 0:  # penetration is always reported as a contact event
                assert info["n_obstacle_contacts"] > 0
    finally:
        environment.close()


def test_the_simulator_does_not_import_torch():
    """Layering: sim never imports torch (it would also add seconds to every collect/eval worker start)."""
    import subprocess
    import sys

    code = ("import sys; from lano3dp.sim import TabletopEnv; env = TabletopEnv('bottle_upright', image_size=16); "
            "env.reset(seed=0); env.step(env.expert_plan().actions()[0]); env.close(); "
            "print('torch' in sys.modules)")
    output = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert output.stdout.strip() == "False"


def test_a_task_warns_once_on_a_mujoco_older_than_its_contacts_need(monkeypatch):
    import lano3dp.sim.env as sim_env

    monkeypatch.setattr(sim_env, "mujoco_version", lambda: (3, 3))
    monkeypatch.setattr(sim_env, "_WARNED_TASKS", set())
    with pytest.warns(UserWarning, match=r"bowl_pour on MuJoCo .*cube items sink.*from MuJoCo 4\.0 on"):
        TabletopEnv("bowl_pour", image_size=16, render_rgb=False).close()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        TabletopEnv("bowl_pour", image_size=16, render_rgb=False).close()  # once per task
        TabletopEnv("open_drawer", image_size=16, render_rgb=False).close()  # reliable on every supported MuJoCo
