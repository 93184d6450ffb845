"""Fixtures of the fault-injection suite: tiny checkpoints and datasets (evaluation and training need files of
the right form, not good ones). Every test in this folder injects one fault and asserts its exact outcome."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from test_policy import TINY, stats_for
from test_train import write_reach_store


@pytest.fixture(scope="session")
def tiny_checkpoint(tmp_path_factory) -> Path:
    """An untrained tiny open_drawer policy (the built-in simulator's task)."""
    from lano3dp.policy import DiffusionPolicy, PolicyConfig

    torch.manual_seed(0)
    policy = DiffusionPolicy(PolicyConfig(**({"object_names": ("drawer",),
                                              "extra": {"skill": "open_drawer", "task": "open_drawer"}} | TINY)))
    policy.set_normalizer(stats_for(policy.config))
    return policy.save_pretrained(tmp_path_factory.mktemp("tiny") / "policy")


@pytest.fixture(scope="session")
def reach_checkpoint(tmp_path_factory) -> Path:
    """An untrained tiny policy for the example env's one slot, "block" (examples/own_env.py)."""
    from lano3dp.policy import DiffusionPolicy, PolicyConfig

    torch.manual_seed(0)
    config = PolicyConfig(**({"object_names": ("block",), "extra": {
        "skill": "reach_block", "task": "reach_block",
        "observation": {"image_size": 48, "n_points": 32, "crop_low": [-0.5, -0.5, 0.005],
                        "crop_high": [0.5, 0.5, 0.6]}}} | TINY))
    policy = DiffusionPolicy(config)
    policy.set_normalizer(stats_for(policy.config))
    return policy.save_pretrained(tmp_path_factory.mktemp("reach") / "policy")


@pytest.fixture(scope="session")
def reach_data(tmp_path_factory) -> Path:
    """Eight short episodes of a one-slot reach (test_train's), for training runs."""
    return write_reach_store(tmp_path_factory.mktemp("faults") / "reach.zarr")
