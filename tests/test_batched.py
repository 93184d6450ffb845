"""Batched rollouts: episodes stepped together sample their chunks in one call, each with its own noise and costs,
and end as they end alone."""

from __future__ import annotations

import subprocess
import sys
import threading

import pytest
import torch

from lano3dp.evaluation import EvalConfig, GuidanceChoice, evaluate
from lano3dp.evaluation.batched import BatchedCost, Batcher, PolicyHandle
from lano3dp.guidance import Cylinder

OUTCOME = ("seed", "success", "steps", "collided", "n_collision_steps", "chunk_executed")


@pytest.mark.slow
def test_batched_episodes_end_as_they_do_one_after_another():
    config = EvalConfig(task="put_item_in_drawer", variation="obstacle", obstacle_scenes_only=True, episodes=3,
                        max_steps=24, guidance=GuidanceChoice("tuned"))
    alone, together = evaluate(config), evaluate(config.replace(batch=3))
    for a, b in zip(alone["episodes"], together["episodes"], strict=True):
        assert {k: a[k] for k in OUTCOME} == {k: b[k] for k in OUTCOME}
        assert a["min_clearance"] == pytest.approx(b["min_clearance"], abs=1e-6)
    assert together["config"]["batch"] == 3 and together["identity"] != alone["identity"]  # another evaluation
    with pytest.raises(ValueError, match="choose one"):
        config.replace(batch=2, workers=2)


class RecordingPolicy:
    """Stands in for a DiffusionPolicy: records each call's batch and returns the windows' states as chunks."""

    def __init__(self):
        from lano3dp.policy import PolicyConfig
        from lano3dp.policy.normalizer import LinearNormalizer

        self.config = PolicyConfig(object_names=("block",), n_obs_steps=1, horizon=4, n_action_steps=2)
        self.normalizer = LinearNormalizer({"action": 10})
        self.device = torch.device("cpu")
        self.calls = []

    def predict_action_chunk(self, obs, *, generator=None, position_cost=None, **options):
        self.calls.append({"batch": obs["state"].shape[0], "generators": generator, "cost": position_cost,
                           "rows": [int(v) for v in obs["state"][:, -1, 0]]})
        from lano3dp.policy import ActionChunk

        trajectory = obs["state"][:, -1:, :10].expand(-1, 4, -1).clone()
        return ActionChunk(trajectory[:, :2], trajectory)


def test_the_batcher_samples_once_every_episode_waits_each_with_its_own_noise_and_cost():
    policy = RecordingPolicy()
    batcher = Batcher(policy)
    handles = [PolicyHandle(policy, batcher) for _ in range(3)]
    generators = [torch.Generator().manual_seed(i) for i in range(3)]
    costs = [Cylinder((0.1 * i, 0.0), 0.05) for i in range(3)]
    chunks = [None] * 3
    for _ in handles:
        batcher.join()

    def episode(i: int) -> None:
        window = {"object_clouds": torch.zeros(1, 1, 1, 64, 3), "state": torch.full((1, 1, 11), float(i))}
        with batcher.turn:  # an episode works in its turn and hands it on while it waits for its chunk
            chunks[i] = handles[i].predict_action_chunk(window, generator=generators[i], position_cost=costs[i],
                                                        guidance="g", scheduler=None, num_inference_steps=None)
            batcher.leave()

    threads = [threading.Thread(target=episode, args=(i,)) for i in range(3)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=30)
    (call,) = policy.calls  # one call for the three, their rows in the order the threads asked
    order = call["rows"]
    assert call["batch"] == 3 and sorted(order) == [0, 1, 2]
    assert call["generators"] == [generators[i] for i in order]  # each row with its own episode's noise
    assert isinstance(call["cost"], BatchedCost) and call["cost"].costs == [costs[i] for i in order]
    for i, chunk in enumerate(chunks):  # each episode got its own row back
        assert chunk.trajectory.shape == (1, 4, 10) and float(chunk.trajectory[0, 0, 0]) == i
    positions = torch.zeros(3, 2, 3)
    per_row = call["cost"](positions)
    assert per_row.shape == (3,) and [float(v) for v in per_row] == [float(costs[i](positions[:1])) for i in order]


LEXICON_LOADS = """
import threading
from lemminflect.codecs.InflectionLUCodec import InflectionLUCodec
from lemminflect.codecs.LemmaLUCodec import LemmaLUCodec
from lano3dp.language.mentions import is_adjective

loads = []
for codec in (LemmaLUCodec, InflectionLUCodec):
    original = codec.load
    codec.load = lambda *args, _original=original: loads.append(1) or _original(*args)
threads = [threading.Thread(target=is_adjective, args=(word,)) for word in ("battered", "kitchen", "lit", "torn")]
for thread in threads:
    thread.start()
for thread in threads:
    thread.join()
print(len(loads))
"""


def test_threads_reading_instructions_at_once_load_the_english_lexicon_once():
    # the episodes of a batched evaluation read their instructions together: lemminflect loads lazily without a
    # lock, so each thread loaded its lexicons (~0.1 CPU-s each) until one lock held the first load
    out = subprocess.run([sys.executable, "-c", LEXICON_LOADS], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["2"]  # one lemma and one inflection lexicon
