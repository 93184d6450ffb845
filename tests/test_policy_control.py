"""The control contract: reset() / select_action(obs), one observation in and one action out (LeRobot's)."""

import numpy as np
import pytest
import torch

from lano3dp.guidance import GuidanceConfig
from test_policy import make_policy

FAST = dict(scheduler="ddim", num_inference_steps=2)


def one_step(config, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    return {"object_clouds": rng.uniform(-0.3, 0.3, (1, config.n_slots, config.n_points, 3)).astype(np.float32),
            "state": rng.uniform(-1, 1, (1, config.state_dim)).astype(np.float32)}


def window(*steps: dict) -> dict:
    return {key: np.stack([step[key] for step in steps], axis=1) for key in steps[0]}


class CountingPolicy:
    """Wraps predict_action_chunk to record every window it samples from."""

    def __init__(self, policy):
        self.windows, original = [], policy.predict_action_chunk

        def spy(obs, **kwargs):
            self.windows.append({key: torch.as_tensor(value).clone() for key, value in obs.items()})
            return original(obs, **kwargs)

        policy.predict_action_chunk = spy


def test_one_chunk_is_sampled_per_n_action_steps_calls_and_its_actions_are_returned_in_order():
    policy = make_policy()  # n_obs_steps 2, n_action_steps 8
    calls = CountingPolicy(policy)
    noise = torch.randn(1, 16, 10, generator=torch.Generator().manual_seed(0))
    observations = [one_step(policy.config, seed) for seed in range(17)]
    actions = [policy.select_action(obs, initial_noise=noise, **FAST) for obs in observations]
    assert len(calls.windows) == 3  # calls 0, 8 and 16 sample; the 14 others pop the queue
    first = policy.predict_action_chunk(window(observations[0], observations[0]), initial_noise=noise, **FAST)
    second = policy.predict_action_chunk(window(observations[7], observations[8]), initial_noise=noise, **FAST)
    for i in range(8):
        assert actions[i].shape == (1, 10)
        assert torch.equal(actions[i], first.actions[:, i])
        assert torch.equal(actions[8 + i], second.actions[:, i])
    third = policy.predict_action_chunk(window(observations[15], observations[16]), initial_noise=noise, **FAST)
    assert torch.equal(actions[16], third.actions[:, 0])
    assert torch.equal(policy.last_chunk.trajectory, third.trajectory)  # kept for drawing or checking


def test_the_first_observation_fills_the_window():
    policy = make_policy()
    calls = CountingPolicy(policy)
    obs = one_step(policy.config, 0)
    policy.select_action(obs, **FAST)
    sampled = calls.windows[0]
    assert sampled["state"].shape == (1, 2, 11) and sampled["object_clouds"].shape == (1, 2, 2, 32, 3)
    for key in ("state", "object_clouds"):
        assert torch.equal(sampled[key][:, 0], torch.as_tensor(obs[key]))
        assert torch.equal(sampled[key][:, 1], torch.as_tensor(obs[key]))


def test_reset_clears_both_queues_so_the_next_call_samples_from_the_new_episode():
    policy = make_policy()
    calls = CountingPolicy(policy)
    policy.select_action(one_step(policy.config, 0), **FAST)
    policy.select_action(one_step(policy.config, 1), **FAST)
    assert len(calls.windows) == 1
    policy.reset()
    assert policy.last_chunk is None
    fresh = one_step(policy.config, 2)
    policy.select_action(fresh, **FAST)
    assert len(calls.windows) == 2  # the 6 actions still queued from the old episode were dropped
    assert torch.equal(calls.windows[1]["state"][:, 0], torch.as_tensor(fresh["state"]))  # no old observation


def test_numpy_and_torch_observations_give_the_same_action():
    policy = make_policy()
    obs = one_step(policy.config, 0)
    noise = torch.randn(1, 16, 10, generator=torch.Generator().manual_seed(1))
    from_numpy = policy.select_action(obs, initial_noise=noise, **FAST)
    policy.reset()
    from_torch = policy.select_action({k: torch.from_numpy(v) for k, v in obs.items()}, initial_noise=noise, **FAST)
    assert torch.equal(from_numpy, from_torch)


def test_generator_and_guidance_keywords_reach_the_sampler():
    policy = make_policy()
    obs = one_step(policy.config, 0)
    a = policy.select_action(obs, generator=torch.Generator().manual_seed(4), **FAST)
    policy.reset()
    b = policy.select_action(obs, generator=torch.Generator().manual_seed(4), **FAST)
    assert torch.equal(a, b)
    policy.reset()
    with pytest.raises(ValueError, match="no position_cost"):
        policy.select_action(obs, guidance=GuidanceConfig(scale=1.0), **FAST)
    policy.reset()

    def push_x_down(positions):  # metric EE positions (B, H, 3) -> (B,)
        return positions[..., 0].sum(dim=-1)

    guided = policy.select_action(obs, guidance=GuidanceConfig(scale=5.0), position_cost=push_x_down,
                                  generator=torch.Generator().manual_seed(4), **FAST)
    assert float(guided[0, 0]) < float(a[0, 0])


def test_a_window_or_a_changed_batch_is_refused_with_what_to_do():
    policy = make_policy()
    obs = one_step(policy.config, 0)
    with pytest.raises(ValueError, match="one step: state must be \\(batch, 11\\)"):
        policy.select_action(window(obs, obs), **FAST)
    policy.select_action(obs, **FAST)
    bigger = {key: np.concatenate([value, value]) for key, value in obs.items()}
    with pytest.raises(ValueError, match="call reset\\(\\) first"):
        policy.select_action(bigger, **FAST)
    with pytest.raises(KeyError, match="missing 'state'"):
        policy.select_action({"object_clouds": obs["object_clouds"]}, **FAST)


def test_a_sample_function_replaces_the_sampler_and_decides_how_many_actions_are_queued():
    """A control loop that guides or checks its chunks passes `sample`: the window is still the policy's."""
    policy = make_policy()
    calls = CountingPolicy(policy)
    noise = torch.randn(1, 16, 10, generator=torch.Generator().manual_seed(0))
    windows = []

    def sample(obs_window):
        windows.append(obs_window)
        chunk = policy.predict_action_chunk(obs_window, initial_noise=noise, **FAST)
        return chunk._replace(actions=chunk.actions[:, :3])  # run 3 actions, then re-plan

    observations = [one_step(policy.config, seed) for seed in range(4)]
    actions = [policy.select_action(obs, sample=sample) for obs in observations]
    assert len(windows) == 2  # calls 0 and 3
    assert torch.equal(windows[0]["state"], torch.as_tensor(window(observations[0], observations[0])["state"]))
    assert torch.equal(windows[1]["state"], torch.as_tensor(window(observations[2], observations[3])["state"]))
    first = policy.predict_action_chunk(window(observations[0], observations[0]), initial_noise=noise, **FAST)
    assert all(torch.equal(actions[i], first.actions[:, i]) for i in range(3))
    assert policy.last_chunk.actions.shape == (1, 3, 10)  # what the sample function returned
    assert len(calls.windows) == 3  # through `sample` (2 chunks) and `first`: select_action sampled nothing itself
    with pytest.raises(TypeError, match="give the options to the sample function"):
        policy.select_action(observations[0], sample=sample, generator=torch.Generator())


def test_chunked_control_gives_any_chunk_sampler_the_control_contract():
    """A wrapper or a test double with config, device and predict_action_chunk gets reset / select_action."""
    from lano3dp.policy import ChunkedControl, DiffusionPolicy

    inner = make_policy()

    class Wrapper(ChunkedControl):
        def __init__(self):
            self.config, self.device = inner.config, inner.device
            self.reset()

        def predict_action_chunk(self, obs, **kwargs):
            return inner.predict_action_chunk(obs, **kwargs)

    noise = torch.randn(1, 16, 10, generator=torch.Generator().manual_seed(2))
    observations = [one_step(inner.config, seed) for seed in range(9)]
    wrapper = Wrapper()
    wrapped = [wrapper.select_action(obs, initial_noise=noise, **FAST) for obs in observations]
    own = [inner.select_action(obs, initial_noise=noise, **FAST) for obs in observations]
    assert all(torch.equal(a, b) for a, b in zip(wrapped, own, strict=True))
    assert isinstance(inner, ChunkedControl) and DiffusionPolicy.select_action is ChunkedControl.select_action
