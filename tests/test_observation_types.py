"""Observation types as a registry (policy.observations): a type defined in this file alone, outside the package,
is recorded by `collect`, trained by `train`, saved and loaded as a checkpoint, and acts in an env through
`evaluate`; the built-in types are registry entries too; an unknown obs_type fails once, naming the registered ones.

The type, "object_tops": per object slot its cloud's centroid and highest point, (K, 4) per step, under its own
dataset key with its own encoder and normaliser rule.
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import numpy as np
import pytest
import torch
from torch import nn
from typer.testing import CliRunner

from lano3dp import EvalConfig, evaluate
from lano3dp.cli import app
from lano3dp.collect import collect_from_env
from lano3dp.data import EpisodeStore
from lano3dp.env_factory import load_factory
from lano3dp.evaluation import GuidanceChoice, PerceptionSettings
from lano3dp.geometry.rotations import matrix_to_rot6d
from lano3dp.guidance.settings import guidance_preset
from lano3dp.policy import (
    DiffusionPolicy,
    ObservationType,
    PolicyConfig,
    UnknownObservationTypeError,
    get_observation_type,
    observation_type_names,
    register_observation_type,
    unregister_observation_type,
)
from lano3dp.policy.observations import observation_type_for_workers as observation_types_for_workers
from lano3dp.train import TrainConfig, policy_config_for_dataset, train

ROOT = Path(__file__).resolve().parents[1]
ENV = f"{ROOT / 'examples' / 'own_env.py'}:make_env"  # a numpy reach-the-block scene, no simulator
MICRO = dict(down_dims=(8, 16), diffusion_step_embed_dim=8, n_groups=4, point_hidden_dims=(8, 16), encoder_out=8,
             state_feature_dim=8, horizon=8, n_action_steps=4)


def tops(clouds: np.ndarray) -> np.ndarray:
    """(K, N, 3) object clouds -> (K, 4): each cloud's centroid and its highest z."""
    clouds = np.asarray(clouds, dtype=np.float32)
    return np.concatenate([clouds.mean(1), clouds[..., 2].max(1, keepdims=True)], axis=1)


class TopsEncoder(nn.Module):
    """(M, K, 4) normalised tops -> (M, encoder_out)."""

    def __init__(self, config: PolicyConfig):
        super().__init__()
        self.mlp = nn.Sequential(nn.Linear(4 * config.n_slots, config.encoder_out), nn.LayerNorm(config.encoder_out))
        self.out_dim = config.encoder_out

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.mlp(x.flatten(1))


class ObjectTops(ObservationType):
    key = "object_tops"
    object_slots = True  # one row per slot: the runner and eval give it the scene's target phrases

    def encoder(self, config):
        return TopsEncoder(config)

    def runtime_input(self, runner, frame):
        return tops(runner.object_clouds(frame))

    def recorder(self, context):
        observer, phrases = context.observer, list(context.phrases)
        return lambda frame: tops(observer.observe(frame, phrases).points)

    def normalizer_dim(self, config):
        return 4

    def validate(self, config):
        if not config.object_names:
            raise ValueError("obs_type 'object_tops' needs object_names")


@pytest.fixture
def object_tops():
    spec = register_observation_type("object_tops", ObjectTops)
    yield spec
    unregister_observation_type("object_tops")  # later tests' collections record the built-in keys alone


def reach_expert(env, obs, info):
    """Closed loop: 5 cm a step towards 1 cm above the block's top."""
    block = getattr(env, "env", env).scene.boxes[0]
    hand = obs["state"][:3]
    way = np.array([*block.center_xy, block.size[2] + 0.01]) - hand
    way *= min(1.0, 0.05 / (np.linalg.norm(way) + 1e-12))
    return np.r_[hand + way, matrix_to_rot6d(np.eye(3)), 0.0].astype(np.float32)


def test_a_type_defined_outside_the_package_is_recorded_trained_saved_and_acts(object_tops, tmp_path):
    assert get_observation_type("object_tops") is object_tops
    assert observation_type_names()[:3] == ("objects", "scene", "image")

    data = tmp_path / "reach.zarr"
    result = collect_from_env(load_factory(ENV), reach_expert, 2, data, slots=["block"], task="reach_block",
                              n_points=16, image_size=48, progress=False, follow_through_s=0.0)
    assert result.total == 2
    store = EpisodeStore.open(data)
    assert {"object_tops", "object_clouds", "scene_cloud", "rgb"} <= set(store.keys)  # its recorder ran
    episode = store.get_episode(0, ["object_tops", "object_clouds"])
    np.testing.assert_allclose(episode["object_tops"], np.stack([tops(c) for c in episode["object_clouds"]]),
                               atol=1e-6)  # the same frames, the same observer

    policy_config = policy_config_for_dataset(data, obs_type="object_tops", **MICRO)
    assert policy_config.visual_key == "object_tops" and policy_config.n_slots == 1
    run = tmp_path / "run"
    final = train(TrainConfig(data=str(data), out=str(run), policy=policy_config, steps=2, batch_size=4, lr=1e-3,
                              warmup_steps=1, val_ratio=0.0, ckpt_every=2, progress=False))
    assert json.loads((final / "config.json").read_text())["obs_type"] == "object_tops"

    policy = DiffusionPolicy.from_pretrained(final)
    assert isinstance(policy.obs_encoder.visual, TopsEncoder)  # the user's encoder, with its trained weights
    assert policy.normalizer.keys == ("action", "state", "object_tops")
    assert policy.normalizer_stats()["object_tops"]["max"].shape == (4,)
    obs = {key: value[None] for key, value in store.get_episode(0, ["object_tops", "state"]).items()}
    chunk = policy.predict_action_chunk(obs, num_inference_steps=2)
    assert chunk.actions.shape == (1, 4, 10) and chunk.trajectory.shape == (1, 8, 10)
    assert torch.isfinite(chunk.trajectory).all()

    # in the env through evaluate: the runner makes each step's input with the type's runtime_input
    results = evaluate(EvalConfig(checkpoint=str(final), env=ENV, episodes=1, max_steps=3,
                                  guidance=GuidanceChoice("none", {"sampler.steps": 2}),
                                  perception=PerceptionSettings(image_size=48)))
    (record,) = results["episodes"]
    assert results["policy"]["obs_type"] == "object_tops"
    assert record["error"] is None and record["steps"] == 3 and len(record["chunk_latency_s"]) >= 1
    assert list(record["targets"]) == ["block"]  # object_slots: eval named the slot, the runner observed it


def test_the_built_in_types_are_registry_entries():
    for name, key, encoder in (("objects", "object_clouds", "ObjectCloudsEncoder"),
                               ("scene", "scene_cloud", "SceneCloudEncoder"), ("image", "rgb", "ImageEncoder")):
        config = PolicyConfig(obs_type=name, object_names=("bowl",) if name == "objects" else (), **MICRO)
        assert config.observation is get_observation_type(name) and config.visual_key == key
        assert type(DiffusionPolicy(config).obs_encoder.visual).__name__ == encoder
    with pytest.raises(ValueError, match="cannot be removed"):
        unregister_observation_type("objects")
    with pytest.raises(ValueError, match="already registered"):
        register_observation_type("objects", ObjectTops)  # another class over a built-in needs replace=True


def test_an_unknown_obs_type_is_one_error_naming_the_registered_ones(object_tops, tmp_path):
    with pytest.raises(ValueError, match=r"unknown obs_type 'lidar'; registered: objects, scene, image, goal, "
                                         r"object_tops"):
        PolicyConfig(obs_type="lidar")
    with pytest.raises(UnknownObservationTypeError, match="registered: objects, scene, image, goal, object_tops"):
        get_observation_type("lidar")
    result = CliRunner().invoke(app, ["train", "--data", str(tmp_path), "--out", str(tmp_path / "run"),
                                      "--obs-type", "lidar"])
    assert result.exit_code == 2 and "unknown obs_type 'lidar'" in result.output


def test_eval_workers_get_the_registered_type(object_tops):
    import queue

    from lano3dp.evaluation.pool import Job, _worker_main

    assert observation_types_for_workers("objects") == {}
    # spawned eval workers start with the built-in types: the parent's registered one travels to them pickled
    payloads = observation_types_for_workers("object_tops")
    assert isinstance(pickle.loads(payloads["object_tops"]), ObjectTops)
    unregister_observation_type("object_tops")
    todo, done = queue.Queue(), queue.Queue()
    for job in (Job(0, 7), None):
        todo.put(job)
    _worker_main({"checkpoint": "no-such-run"}, guidance_preset("none").to_dict(),
                 {"shapes": {}, "observation_types": payloads, "filters": {}}, todo, done)
    assert isinstance(get_observation_type("object_tops"), ObjectTops)
    index, record, error = done.get_nowait()  # what stopped it, reported with the job: the missing checkpoint
    assert (index, record) == (0, None) and error.startswith("FileNotFoundError")

    class Local(ObjectTops):  # defined inside a function: a worker could not import it
        pass

    register_observation_type("object_tops", Local(), replace=True)
    with pytest.raises(ValueError, match="'object_tops' cannot be sent to worker processes"):
        observation_types_for_workers("object_tops")
