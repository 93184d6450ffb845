"""Policy building blocks: config, normaliser, encoders, ConditionalUnet1D, sampling and checkpoints."""

import json

import numpy as np
import pytest
import torch

from lano3dp.errors import CorruptFileError
from lano3dp.guidance import GuidanceConfig
from lano3dp.policy import DiffusionPolicy, LinearNormalizer, NormalizerNotFittedError, PolicyConfig
from lano3dp.policy.encoders import ObjectCloudsEncoder, PointMLPEncoder, ResidualPointEncoder
from lano3dp.policy.unet import ConditionalUnet1D

TINY = dict(down_dims=(16, 32), diffusion_step_embed_dim=16, n_groups=4, point_hidden_dims=(16, 32),
            encoder_out=16, state_feature_dim=16, n_points=32, n_obs_steps=2)  # two steps: the windowing paths


def tiny_config(**changes) -> PolicyConfig:
    return PolicyConfig(**({"object_names": ("red bowl", "pan")} | TINY | changes))


def stats_for(config: PolicyConfig) -> dict:
    rng = np.random.default_rng(0)
    stats = {"action": {"min": -1 - rng.random(config.action_dim), "max": 1 + rng.random(config.action_dim)},
             "state": {"min": -np.ones(config.state_dim), "max": np.ones(config.state_dim)}}
    if config.obs_type != "image":
        stats[config.visual_key] = {"min": np.array([-0.5, -0.5, 0.0]), "max": np.array([0.5, 0.5, 0.3])}
    return stats


def make_policy(seed: int = 0, **changes) -> DiffusionPolicy:
    torch.manual_seed(seed)
    policy = DiffusionPolicy(tiny_config(**changes))
    policy.set_normalizer(stats_for(policy.config))
    return policy


def random_obs(config: PolicyConfig, batch: int = 2, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    steps = config.n_obs_steps
    visual = {
        "objects": lambda: rng.uniform(-0.3, 0.3, (batch, steps, config.n_slots, config.n_points, 3)),
        "scene": lambda: rng.uniform(-0.3, 0.3, (batch, steps, config.scene_points, 3)),
        "image": lambda: rng.integers(0, 256, (batch, steps, config.image_size, config.image_size, 3)),
    }[config.obs_type]()
    visual = visual.astype(np.uint8 if config.obs_type == "image" else np.float32)
    return {config.visual_key: visual, "state": rng.uniform(-1, 1, (batch, steps, config.state_dim)).astype(np.float32)}


# ---- config --------------------------------------------------------------------------------
def test_config_round_trips_through_json_and_keeps_tuples():
    config = tiny_config(point_encoder="mlp", inference_scheduler="ddpm", num_inference_steps=None)
    again = PolicyConfig.from_json(config.to_json())
    assert again == config
    assert again.object_names == ("red bowl", "pan") and again.down_dims == (16, 32)
    assert json.loads(config.to_json())["down_dims"] == [16, 32]


def test_config_defaults_follow_the_paper_and_the_cpu_budget():
    config = PolicyConfig(object_names=("bowl",))
    assert (config.n_obs_steps, config.horizon, config.n_action_steps) == (1, 16, 8)
    assert config.down_dims == (48, 96, 192) and config.kernel_size == 5 and config.n_groups == 8
    assert config.point_encoder == "residual" and config.encoder_out == 64 and config.n_points == 64
    assert config.action_frame == "absolute"
    assert (config.num_train_timesteps, config.beta_schedule, config.prediction_type) == (
        100, "squaredcos_cap_v2", "epsilon")


@pytest.mark.parametrize("obs_type, slots", [("objects", ("bowl", "pan", "mug")), ("scene", ()), ("image", ())])
def test_a_default_policy_fits_a_packaged_checkpoint_in_fp16(obs_type, slots):
    """Packaged checkpoints hold fp16 weights of at most 6 MB each."""
    policy = DiffusionPolicy(PolicyConfig(obs_type=obs_type, object_names=slots))
    assert 2 * sum(p.numel() for p in policy.parameters()) <= 6 * 2**20


@pytest.mark.parametrize("changes, message", [
    (dict(obs_type="lidar"), "obs_type"),
    (dict(object_names=()), "object_names"),
    (dict(object_names=("bowl", "bowl")), "distinct"),
    (dict(point_encoder="pointnet"), "point_encoder"),
    (dict(horizon=10, down_dims=(16, 32, 64)), "divisible by 2"),
    (dict(n_obs_steps=2, n_action_steps=16), "n_action_steps"),
    (dict(prediction_type="sample"), "epsilon"),
    (dict(down_dims=(10, 20)), "n_groups"),
])
def test_config_rejects_bad_values_with_a_named_reason(changes, message):
    with pytest.raises(ValueError, match=message):
        tiny_config(**changes)


def test_config_rejects_unknown_json_fields():
    data = tiny_config().to_dict() | {"dropout": 0.1}
    with pytest.raises(ValueError, match="dropout"):
        PolicyConfig.from_dict(data)


# ---- normaliser ----------------------------------------------------------------------------
def test_normalizer_maps_the_fitted_range_to_minus_one_one_and_back():
    rng = np.random.default_rng(1)
    actions = rng.normal([0.4, -0.2, 0.1], [0.1, 0.3, 0.02], (500, 3)).astype(np.float32)
    constant = np.full((500, 1), 0.7, np.float32)
    data = np.concatenate([actions, constant], axis=1)
    normalizer = LinearNormalizer({"action": 4})
    normalizer.fit({"action": data})
    normalised = normalizer.normalize("action", torch.from_numpy(data))
    assert torch.allclose(normalised[:, :3].min(0).values, torch.full((3,), -1.0), atol=1e-5)
    assert torch.allclose(normalised[:, :3].max(0).values, torch.full((3,), 1.0), atol=1e-5)
    assert torch.allclose(normalised[:, 3], torch.zeros(500))  # a constant dimension maps to 0, as in DP
    back = normalizer.unnormalize("action", normalised)
    assert torch.allclose(back, torch.from_numpy(data), atol=1e-6)
    assert np.allclose(normalizer.stats()["action"]["min"], data.min(0))


def test_normalizer_keeps_a_nearly_constant_dimension_at_a_sane_scale():
    # Roll/pitch components of yaw-only demonstrations vary by ~5e-4; a closed-loop hand tilts ~1 cm.
    rng = np.random.default_rng(2)
    data = np.stack([rng.uniform(0.2, 0.5, 400), rng.uniform(-2.5e-4, 2.5e-4, 400)], axis=1).astype(np.float32)
    normalizer = LinearNormalizer({"state": 2})
    normalizer.fit({"state": data})
    tilted = normalizer.normalize("state", torch.tensor([[0.35, 0.01]]))
    assert abs(float(tilted[0, 1])) <= 1.0  # inside the training range's scale, not +-40
    assert abs(float(tilted[0, 1])) > 0.1  # yet not flattened: the tilt is still visible
    back = normalizer.unnormalize("state", normalizer.normalize("state", torch.from_numpy(data)))
    assert torch.allclose(back, torch.from_numpy(data), atol=1e-6)


def test_normalizer_clouds_share_one_xyz_range_across_slots_and_points():
    clouds = np.zeros((10, 2, 5, 3), np.float32)
    clouds[:, 0] = [0.0, 0.0, 0.0]
    clouds[:, 1] = [0.2, 0.4, 0.1]
    normalizer = LinearNormalizer({"object_clouds": 3})
    normalizer.fit({"object_clouds": clouds})
    out = normalizer.normalize("object_clouds", torch.from_numpy(clouds))
    assert torch.allclose(out[:, 0], torch.tensor(-1.0)) and torch.allclose(out[:, 1], torch.tensor(1.0))


def test_unnormalize_is_differentiable():
    normalizer = LinearNormalizer({"action": 2})
    normalizer.set_stats({"action": {"min": np.array([0.0, -1.0]), "max": np.array([0.5, 3.0])}})
    x = torch.zeros(1, 2, requires_grad=True)
    normalizer.unnormalize("action", x).sum().backward()
    assert torch.allclose(x.grad, torch.tensor([[0.25, 2.0]]))  # half of each range


def test_an_unfitted_normalizer_says_what_to_do():
    policy = DiffusionPolicy(tiny_config())
    with pytest.raises(NormalizerNotFittedError, match="fit_normalizer"):
        policy.predict_action_chunk(random_obs(policy.config))


# ---- encoders ------------------------------------------------------------------------------
@pytest.mark.parametrize("encoder_cls", [PointMLPEncoder, ResidualPointEncoder])
def test_point_encoders_are_invariant_to_point_order_and_count_agnostic(encoder_cls):
    torch.manual_seed(0)
    encoder = encoder_cls((16, 32), 8)
    points = torch.randn(3, 50, 3)
    shuffled = points[:, torch.randperm(50)]
    assert torch.allclose(encoder(points), encoder(shuffled), atol=1e-6)
    assert encoder(points[:, :20]).shape == (3, 8)


def test_slot_order_matters_swapping_two_object_clouds_changes_the_features():
    torch.manual_seed(0)
    encoder = ObjectCloudsEncoder(tiny_config())
    bowl, pan = torch.randn(1, 32, 3) * 0.1, torch.randn(1, 32, 3) * 0.1 + 0.5
    features = encoder(torch.stack([bowl, pan], dim=1))
    swapped = encoder(torch.stack([pan, bowl], dim=1))
    assert features.shape == (1, 2 * 16)
    assert (features - swapped).abs().max() > 0.1
    # The two halves are the per-slot features, in slot order.
    assert torch.allclose(features[:, :16], swapped[:, 16:]) and torch.allclose(features[:, 16:], swapped[:, :16])


def test_wrong_number_of_slots_is_a_clear_error():
    policy = make_policy()
    obs = random_obs(tiny_config(object_names=("a", "b", "c")))
    with pytest.raises(ValueError, match="2 slots"):
        policy.predict_action_chunk(obs)


# ---- UNet ----------------------------------------------------------------------------------
@pytest.mark.parametrize("horizon", [4, 8, 16, 32])
def test_unet_keeps_the_trajectory_shape(horizon):
    unet = ConditionalUnet1D(10, 24, 16, down_dims=(16, 32, 64), kernel_size=5, n_groups=8)
    sample = torch.randn(3, horizon, 10)
    out = unet(sample, torch.tensor([0, 50, 99]), torch.randn(3, 24))
    assert out.shape == sample.shape


def test_unet_rejects_a_horizon_it_cannot_halve():
    unet = ConditionalUnet1D(10, 24, 16, down_dims=(16, 32, 64), n_groups=8)
    with pytest.raises(ValueError, match="divisible by 2\\^\\(levels-1\\) = 4"):
        unet(torch.randn(1, 10, 10), torch.tensor([3]), torch.randn(1, 24))


def test_film_conditioning_changes_the_output():
    torch.manual_seed(0)
    unet = ConditionalUnet1D(10, 24, 16, down_dims=(16, 32), n_groups=8)
    sample, step = torch.randn(1, 8, 10), torch.tensor([10])
    assert (unet(sample, step, torch.zeros(1, 24)) - unet(sample, step, torch.ones(1, 24))).abs().max() > 1e-3


# ---- policy --------------------------------------------------------------------------------
@pytest.mark.parametrize("obs_type", ["objects", "scene", "image"])
def test_every_obs_type_trains_and_samples_with_the_same_backbone(obs_type):
    policy = make_policy(obs_type=obs_type, scene_points=64, image_size=32)
    obs = random_obs(policy.config, batch=3)
    batch = {"obs": {k: torch.as_tensor(v) for k, v in obs.items()}, "action": torch.randn(3, 16, 10)}
    loss = policy.compute_loss(batch, generator=torch.Generator().manual_seed(0))
    loss.backward()
    assert loss.ndim == 0 and torch.isfinite(loss)
    assert all(p.grad is not None for p in policy.obs_encoder.parameters())
    chunk = policy.predict_action_chunk(obs, num_inference_steps=3, generator=torch.Generator().manual_seed(0))
    assert chunk.actions.shape == (3, 8, 10) and chunk.trajectory.shape == (3, 16, 10)


def test_chunk_actions_start_at_the_last_observation_step():
    policy = make_policy()
    chunk = policy.predict_action_chunk(random_obs(policy.config), generator=torch.Generator().manual_seed(0))
    assert torch.equal(chunk.actions, chunk.trajectory[:, 1:9])  # To - 1 = 1, Ta = 8
    as_numpy = chunk.numpy()
    assert isinstance(as_numpy.actions, np.ndarray) and as_numpy.trajectory.shape == (2, 16, 10)


def test_sampling_is_reproducible_from_a_seed_or_initial_noise():
    policy = make_policy()
    obs = random_obs(policy.config)
    for scheduler in ("ddim", "ddpm"):
        first = policy.predict_action_chunk(obs, scheduler=scheduler, num_inference_steps=5,
                                            generator=torch.Generator().manual_seed(3))
        again = policy.predict_action_chunk(obs, scheduler=scheduler, num_inference_steps=5,
                                            generator=torch.Generator().manual_seed(3))
        assert torch.equal(first.trajectory, again.trajectory)
    noise = torch.randn(2, 16, 10, generator=torch.Generator().manual_seed(5))
    a = policy.predict_action_chunk(obs, scheduler="ddim", initial_noise=noise)
    b = policy.predict_action_chunk(obs, scheduler="ddim", initial_noise=noise)
    assert torch.equal(a.trajectory, b.trajectory)


def test_guidance_cost_sees_metric_positions_and_pushes_the_trajectory():
    policy = make_policy()
    obs = random_obs(policy.config)
    noise = torch.randn(2, 16, 10, generator=torch.Generator().manual_seed(0))
    seen = []

    def push_x_down(positions):  # cost grows with x, so guidance must lower x
        seen.append(positions.detach().clone())
        return positions[..., 0].sum(-1)

    plain = policy.predict_action_chunk(obs, scheduler="ddim", num_inference_steps=10, initial_noise=noise)
    steps = []
    guided = policy.predict_action_chunk(obs, scheduler="ddim", num_inference_steps=10, initial_noise=noise,
                                         guidance=GuidanceConfig(scale=0.05, last_steps=100),
                                         position_cost=push_x_down, on_step=steps.append)
    assert len(seen) == 10 and seen[0].shape == (2, 16, 3)
    # The cost saw the un-normalised clean estimate A_0|k, positions only.
    for positions, step in zip(seen, steps, strict=True):
        assert step.guided
        assert torch.allclose(positions, policy.unnormalize_actions(step.clean_estimate, obs["state"])[..., :3],
                              atol=1e-4)
    assert not torch.allclose(guided.trajectory, plain.trajectory)

    # Guiding only the last step (k = 1): A_0 = plain A_0 - rho * d(sum x)/dA, and the derivative goes
    # through the un-normalisation, so x drops by rho / scale_x^2 metres; y and z barely move.
    last_only = policy.predict_action_chunk(obs, scheduler="ddim", num_inference_steps=10, initial_noise=noise,
                                            guidance=GuidanceConfig(scale=0.05, last_steps=1),
                                            position_cost=push_x_down)
    scale_x = 2.0 / float(np.ptp([stats_for(policy.config)["action"][k][0] for k in ("min", "max")]))
    drop = plain.trajectory[..., 0] - last_only.trajectory[..., 0]
    assert torch.allclose(drop, torch.full_like(drop, 0.05 / scale_x**2), rtol=0.05)
    assert (last_only.trajectory[..., 1:3] - plain.trajectory[..., 1:3]).abs().max() < 0.1 * 0.05 / scale_x**2
    with pytest.raises(ValueError, match="position_cost"):
        policy.predict_action_chunk(obs, guidance=GuidanceConfig(scale=1.0))


def test_missing_observation_key_is_named():
    policy = make_policy()
    with pytest.raises(KeyError, match="object_clouds"):
        policy.predict_action_chunk({"state": np.zeros((1, 2, 11), np.float32)})


# ---- checkpoints ---------------------------------------------------------------------------
def test_save_and_load_give_identical_predictions(tmp_path):
    policy = make_policy(seed=4)
    obs = random_obs(policy.config)
    before = policy.predict_action_chunk(obs, generator=torch.Generator().manual_seed(9))
    policy.save_pretrained(tmp_path / "ckpt")
    assert {p.name for p in (tmp_path / "ckpt").iterdir()} == {"config.json", "model.safetensors",
                                                               "normalizer.json", "manifest.json"}
    loaded = DiffusionPolicy.from_pretrained(tmp_path / "ckpt")
    assert loaded.config == policy.config
    after = loaded.predict_action_chunk(obs, generator=torch.Generator().manual_seed(9))
    assert torch.equal(before.trajectory, after.trajectory)
    stats = json.loads((tmp_path / "ckpt" / "normalizer.json").read_text())
    assert np.allclose(stats["action"]["max"], policy.normalizer_stats()["action"]["max"])


def test_truncated_weights_are_a_corrupt_file_error_naming_the_file(tmp_path):
    make_policy().save_pretrained(tmp_path / "ckpt")
    weights = tmp_path / "ckpt" / "model.safetensors"
    weights.write_bytes(weights.read_bytes()[: weights.stat().st_size // 2])
    with pytest.raises(CorruptFileError, match="model.safetensors"):
        DiffusionPolicy.from_pretrained(tmp_path / "ckpt")


def test_garbage_config_is_a_corrupt_file_error_naming_the_file(tmp_path):
    make_policy().save_pretrained(tmp_path / "ckpt")
    (tmp_path / "ckpt" / "config.json").write_text('{"obs_type": "objects", "horiz')
    with pytest.raises(CorruptFileError, match="config.json"):
        DiffusionPolicy.from_pretrained(tmp_path / "ckpt")


def test_weights_from_another_architecture_are_a_corrupt_file_error(tmp_path):
    make_policy().save_pretrained(tmp_path / "ckpt")
    (tmp_path / "ckpt" / "config.json").write_text(tiny_config(down_dims=(16, 32, 64)).to_json())
    with pytest.raises(CorruptFileError, match="do not match config.json"):
        DiffusionPolicy.from_pretrained(tmp_path / "ckpt")


def test_checkpoint_from_a_newer_format_is_refused_and_unversioned_ones_load(tmp_path):
    from safetensors.torch import load_file, save_file

    from lano3dp.errors import IncompatibleFormatError
    from lano3dp.policy.integrity import seal
    from lano3dp.policy.modeling import CHECKPOINT_FORMAT_VERSION

    make_policy().save_pretrained(tmp_path / "ckpt")
    weights = tmp_path / "ckpt" / "model.safetensors"
    state = load_file(str(weights))
    save_file(state, str(weights), metadata={"format": "lano3dp-policy"})  # as written before versions existed
    seal(tmp_path / "ckpt")  # as an old checkpoint is migrated: `lano3dp checkpoint seal` (docs/compat.md)
    DiffusionPolicy.from_pretrained(tmp_path / "ckpt")
    newer = str(CHECKPOINT_FORMAT_VERSION + 1)
    save_file(state, str(weights), metadata={"format": "lano3dp-policy", "format_version": newer})
    with pytest.raises(IncompatibleFormatError, match=f"format version {newer}.*upgrade lano3dp"):
        DiffusionPolicy.from_pretrained(tmp_path / "ckpt")


def test_missing_checkpoint_is_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError, match="no policy checkpoint"):
        DiffusionPolicy.from_pretrained(tmp_path)


# ---- relative action frame -------------------------------------------------------------
def test_relative_actions_are_world_frame_outside_the_policy_and_follow_the_hand():
    """The UNet's offsets are anchored at the last observed EE position: moving the hand moves the whole chunk
    by the same amount (same noise, same clouds), and the guidance cost still sees world positions."""
    policy = make_policy(action_frame="relative")
    obs = random_obs(policy.config)
    noise = torch.randn(2, 16, 10, generator=torch.Generator().manual_seed(0))
    moved = {key: value.copy() for key, value in obs.items()}
    shift = np.array([0.05, -0.03, 0.02], np.float32)
    moved["state"][:, -1, :3] += shift  # "now" anchors the chunk
    for module in policy.obs_encoder.state.modules():  # blind the state encoder: the anchor alone moves
        if isinstance(module, torch.nn.Linear):
            module.weight.data.zero_()
    before = policy.predict_action_chunk(obs, scheduler="ddim", initial_noise=noise).trajectory
    after = policy.predict_action_chunk(moved, scheduler="ddim", initial_noise=noise).trajectory
    assert torch.allclose(after[..., :3] - before[..., :3], torch.as_tensor(shift).expand(2, 16, 3), atol=1e-5)
    assert torch.allclose(after[..., 3:], before[..., 3:], atol=1e-5)
    seen = []
    def cost(positions):
        seen.append(positions.detach())
        return positions.sum((1, 2))

    policy.predict_action_chunk(moved, scheduler="ddim", initial_noise=noise, guidance=GuidanceConfig(scale=1e-9),
                                position_cost=cost)
    assert torch.allclose(seen[-1], after[..., :3], atol=1e-4)


def test_relative_normaliser_is_fitted_on_the_offsets_of_training_windows():
    from lano3dp.policy.modeling import relative_action_rows

    states, actions = np.zeros((5, 11)), np.zeros((5, 10))
    states[:, 0] = np.arange(5.0)  # the hand moves 1 m per step along x
    actions[:, 0] = np.arange(5.0) + 1.0  # each action one step ahead
    rows = relative_action_rows([actions], [states], n_obs_steps=2, horizon=4)
    # window of "now" t holds actions t-1 .. t+2 (edge-padded): offsets 0, 1, 2, 3 away from the edges
    assert rows.shape == (5 * 4, 10)
    assert rows[:4, 0].tolist() == [1.0, 1.0, 2.0, 3.0]  # t = 0: actions 0, 0, 1, 2 minus x = 0
    assert rows[-4:, 0].tolist() == [0.0, 1.0, 1.0, 1.0]  # t = 4: actions 3, 4, 4, 4 minus x = 4


def test_a_relative_checkpoint_round_trips_and_carries_format_version_two(tmp_path):
    from safetensors import safe_open

    policy = make_policy(seed=1, action_frame="relative")
    obs = random_obs(policy.config)
    before = policy.predict_action_chunk(obs, generator=torch.Generator().manual_seed(2)).trajectory
    policy.save_pretrained(tmp_path / "ckpt")
    with safe_open(str(tmp_path / "ckpt" / "model.safetensors"), framework="pt") as handle:
        assert handle.metadata()["format_version"] == "2"
    make_policy(action_frame="absolute").save_pretrained(tmp_path / "absolute")  # older releases read these
    with safe_open(str(tmp_path / "absolute" / "model.safetensors"), framework="pt") as handle:
        assert handle.metadata()["format_version"] == "1"
    loaded = DiffusionPolicy.from_pretrained(tmp_path / "ckpt")
    assert loaded.config.action_frame == "relative"
    assert torch.equal(loaded.predict_action_chunk(obs, generator=torch.Generator().manual_seed(2)).trajectory, before)


def test_a_config_written_before_action_frame_existed_reads_as_absolute():
    data = tiny_config().to_dict()
    del data["action_frame"]
    assert PolicyConfig.from_dict(data).action_frame == "absolute"
    with pytest.raises(ValueError, match="action_frame must be one of"):
        tiny_config(action_frame="delta")


def _slab(yaw: float, centre=(0.4, -0.1, 0.01)) -> torch.Tensor:
    """Points (a 1 cm grid) of a 13 x 6 x 2 cm slab (the phone) lying at `yaw` rad."""
    axes = [np.linspace(-0.065, 0.065, 14), np.linspace(-0.03, 0.03, 7), np.linspace(-0.01, 0.01, 3)]
    local = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    c, s = np.cos(yaw), np.sin(yaw)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return torch.tensor(local @ rotation.T + np.asarray(centre), dtype=torch.float32)


@pytest.mark.parametrize("yaw", [0.0, 0.4, 1.2, -1.0, 2.9])
def test_pose_features_give_the_centroid_and_the_axis_of_a_slab_as_a_doubled_angle(yaw):
    features = ObjectCloudsEncoder.pose_features(_slab(yaw)[None])[0].numpy()
    assert np.allclose(features[:3], [0.4, -0.1, 0.01], atol=1e-5)
    var_x, var_y = np.linspace(-0.065, 0.065, 14).var(), np.linspace(-0.03, 0.03, 7).var()
    elongation = (var_x - var_y) / (var_x + var_y)  # 0.6 for this grid
    assert np.allclose(features[3:], elongation * np.array([np.cos(2 * yaw), np.sin(2 * yaw)]), atol=1e-4)
    # the slab turned half a turn is the same cloud: the same features
    turned = ObjectCloudsEncoder.pose_features(_slab(yaw + np.pi)[None])[0].numpy()
    assert np.allclose(features, turned, atol=1e-5)


def test_pose_features_of_a_round_object_carry_no_angle():
    rng = np.random.default_rng(0)
    angle, radius = rng.uniform(0, 2 * np.pi, 2000), 0.05 * np.sqrt(rng.uniform(0, 1, 2000))
    disc = np.stack([radius * np.cos(angle), radius * np.sin(angle), rng.uniform(0, 0.04, 2000)], -1)
    features = ObjectCloudsEncoder.pose_features(torch.tensor(disc, dtype=torch.float32)[None])[0]
    assert float(features[3:].norm()) < 0.05


def _broom(yaw: float) -> torch.Tensor:
    """Points (a 1 cm grid) of a push broom lying at `yaw` rad: a 3 x 12 cm head at the origin, a 22 cm handle
    along its local -x."""
    head = np.stack(np.meshgrid(np.linspace(-0.015, 0.015, 4), np.linspace(-0.06, 0.06, 13), indexing="ij"), -1)
    handle = np.stack([np.linspace(-0.235, -0.015, 23), np.zeros(23)], -1)
    local = np.vstack([head.reshape(-1, 2), handle])
    c, s = np.cos(yaw), np.sin(yaw)
    xy = local @ np.array([[c, -s], [s, c]]).T + np.array([0.45, 0.1])
    return torch.tensor(np.column_stack([xy, np.full(len(xy), 0.01)]), dtype=torch.float32)


@pytest.mark.parametrize("yaw", [0.0, 0.7, 2.0, -2.6])
def test_skew_features_point_from_a_brooms_head_along_its_handle_and_turn_with_it(yaw):
    skew = ObjectCloudsEncoder.skew_features(_broom(yaw)[None])[0].numpy()
    handle_direction = -np.array([np.cos(yaw), np.sin(yaw)])
    assert float(np.linalg.norm(skew)) > 0.5
    assert float(skew @ handle_direction) / float(np.linalg.norm(skew)) > 0.99
    # the doubled-angle axis is the same for the broom turned half a turn; the third moment is reversed
    turned = ObjectCloudsEncoder.skew_features(_broom(yaw + np.pi)[None])[0].numpy()
    assert np.allclose(turned, -skew, atol=1e-4)
    assert np.allclose(ObjectCloudsEncoder.pose_features(_broom(yaw + np.pi)[None])[0, 3:].numpy(),
                       ObjectCloudsEncoder.pose_features(_broom(yaw)[None])[0, 3:].numpy(), atol=1e-4)
    # a slab is symmetric about its centre: no direction
    assert float(ObjectCloudsEncoder.skew_features(_slab(yaw)[None]).norm()) < 1e-4


def _round_trips_with_format(tmp_path, policy, version: str) -> DiffusionPolicy:
    """Save `policy`, check its weights' format version, and load it back acting identically."""
    from safetensors import safe_open

    obs = random_obs(policy.config, batch=1)
    before = policy.predict_action_chunk(obs, generator=torch.Generator().manual_seed(2)).trajectory
    policy.save_pretrained(tmp_path / "ckpt")
    with safe_open(str(tmp_path / "ckpt" / "model.safetensors"), framework="pt") as handle:
        assert handle.metadata()["format_version"] == version
    loaded = DiffusionPolicy.from_pretrained(tmp_path / "ckpt")
    assert torch.equal(loaded.predict_action_chunk(obs, generator=torch.Generator().manual_seed(2)).trajectory, before)
    return loaded


def test_a_policy_with_skew_features_round_trips_as_format_four(tmp_path):
    policy = make_policy(seed=3, object_pose_features=True, object_pose_skew=True, n_obs_steps=1)
    plain = make_policy(seed=3, object_pose_features=True, n_obs_steps=1)
    assert policy.obs_encoder.out_dim == plain.obs_encoder.out_dim + 2 * ObjectCloudsEncoder.SKEW_DIM
    assert _round_trips_with_format(tmp_path, policy, "4").config.object_pose_skew
    with pytest.raises(ValueError, match="object_pose_skew needs object_pose_features"):
        tiny_config(object_pose_skew=True)
    data = tiny_config(object_pose_features=True).to_dict()
    del data["object_pose_skew"]  # a config written before the field existed has none
    assert PolicyConfig.from_dict(data).object_pose_skew is False


def test_a_policy_with_pose_features_sees_the_yaw_and_round_trips_as_format_three(tmp_path):
    policy = make_policy(seed=3, object_pose_features=True, n_obs_steps=1)
    plain = make_policy(seed=3, n_obs_steps=1)
    assert policy.obs_encoder.out_dim == plain.obs_encoder.out_dim + 2 * ObjectCloudsEncoder.POSE_DIM
    assert _round_trips_with_format(tmp_path, policy, "3").config.object_pose_features
    with pytest.raises(ValueError, match="object_pose_features needs obs_type 'objects'"):
        tiny_config(obs_type="scene", object_pose_features=True)
    data = tiny_config().to_dict()
    del data["object_pose_features"]  # a config written before the field existed has none
    assert PolicyConfig.from_dict(data).object_pose_features is False
