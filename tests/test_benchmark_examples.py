"""The benchmark adapters of examples/ meet the env protocol and their experts succeed, where the benchmark is
installed (CI's second venv has Meta-World; Gymnasium-Robotics needs a venv of its own, see the example)."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from lano3dp.env_factory import CheckedEnv
from lano3dp.perception import ObjectObserver, SimOracleSegmenter

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def load_example(name: str, needs: str):
    pytest.importorskip(needs)
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("name,needs,slot,steps", [("metaworld_pick_place", "metaworld", "puck", 120),
                                                   ("fetch_pick_and_place", "gymnasium_robotics", "block", 50)])
def test_the_expert_reaches_the_goal_the_env_hands_over(name, needs, slot, steps):
    example = load_example(name, needs)
    env = CheckedEnv(example.make_env(image_size=64), name)
    try:
        obs, info = env.reset(seed=3)
        first_goal = obs["goal"].copy()
        assert obs["state"].shape == (11,) and obs["goal"].shape == (3,)
        cloud = ObjectObserver(SimOracleSegmenter(), n_points=16).observe(obs["frame"], [slot]).points[0]
        assert cloud.shape == (16, 3)
        for _ in range(steps):
            obs, _, terminated, truncated, info = env.step(example.expert(env, obs, info))
            if info["success"] or terminated or truncated:
                break
        assert info["success"]
        assert not np.allclose(env.reset(seed=4)[0]["goal"], first_goal)  # a goal per episode
    finally:
        env.close()
