"""Chunk filters are parts: one added from outside the package (in this file alone) is named in the settings, runs
in order on guided chunks, reports what it did, travels to worker processes, and is refused where it cannot work."""

from __future__ import annotations

import pickle
from dataclasses import dataclass

import numpy as np
import pytest
import torch

from lano3dp.config_tree import SettingsError
from lano3dp.guidance.execution import (
    ChunkFilter,
    FilterResult,
    build_filters,
    chunk_filter_names,
    filters_for_workers,
    register_chunk_filter,
    register_worker_filters,
)
from lano3dp.guidance.settings import ExecutionSettings, guidance_preset, resolve_guidance
from lano3dp.runtime import PolicyRunner, rollout
from test_runtime import BOWL, OBSTACLE, PAN, SPHERE, FakeEnv, FakePolicy, observer  # noqa: F401 (a fixture)


class Slower(ChunkFilter):
    """Runs only the first `keep` actions of every chunk (a slower robot, say): a whole new filter in a few lines."""

    name = "slower_test"
    requires = ("hold",)

    @dataclass(frozen=True)
    class Options:
        keep: int = 2

    def reset(self):
        self.shortened = 0

    def __call__(self, proposal, context):
        if proposal.actions.shape[1] <= self.options.keep:
            return FilterResult(proposal, {})
        self.shortened += 1
        executed = self.options.keep if self.options.keep < context.n_action_steps else None
        return FilterResult(proposal._replace(actions=proposal.actions[:, :self.options.keep], executed=executed),
                            {"kept": self.options.keep})

    def episode_note(self):
        return {"shortened": self.shortened}


@pytest.fixture(scope="module", autouse=True)
def slower():
    register_chunk_filter(Slower)
    yield


def test_a_filter_from_outside_runs_where_the_settings_put_it_and_reports_what_it_did(observer):  # noqa: F811
    assert "slower_test" in chunk_filter_names()
    settings = guidance_preset("recommended").with_changes({
        "sampler.rho": 1.0, "sampler.last_steps": 10, **SPHERE,
        "execution.filters": ["repair", "hold", "slower_test"], "execution.options": {"slower_test": {"keep": 3}}})
    runner = PolicyRunner(FakePolicy(), observer, settings, obstacle_phrases=["obstacle_0"])
    assert [f.name for f in runner.filters] == ["repair", "hold", "slower_test"]
    result = rollout(FakeEnv([BOWL, PAN, OBSTACLE], max_steps=12), runner, seed=0, success_at="end")
    # every guided chunk ran 3 of its 8 actions: a chunk every 3 steps
    assert [c.step for c in runner.chunks] == [0, 3, 6, 9]
    assert all(note.get("slower_test") == {"kept": 3} for note in result.chunk_notes)
    assert result.filters["slower_test"] == {"shortened": 4} and result.chunk_executed == [3, 3, 3, 3]
    # unguided chunks pass no filter: the plain policy runs whole chunks
    plain = PolicyRunner(FakePolicy(), observer, guidance_preset("none").with_changes(SPHERE),
                         obstacle_phrases=["obstacle_0"])
    rollout(FakeEnv([BOWL, PAN, OBSTACLE], max_steps=12), plain, seed=0, success_at="end")
    assert [c.step for c in plain.chunks] == [0, 8]


def test_a_filter_is_refused_where_it_cannot_work_naming_both(observer):  # noqa: F811
    with pytest.raises(SettingsError, match=r"slower_test acts on what hold decided, so it needs hold earlier"):
        resolve_guidance("recommended", {"execution.filters": ["repair", "slower_test"]})
    with pytest.raises(SettingsError, match=r"options.slower_test.speed: no such setting \(settings here: keep\)"):
        resolve_guidance("recommended", {"execution.filters": ["hold", "slower_test"],
                                         "execution.options": {"slower_test": {"speed": 2}}})
    with pytest.raises(SettingsError, match="unknown guidance.execution.filters entry 'slowest'; registered: .*"
                                            "slower_test"):
        build_filters(ExecutionSettings(filters=("hold", "slowest")))
    with pytest.raises(TypeError, match="must be a ChunkFilter"):
        register_chunk_filter(type("NotAFilter", (), {"name": "x", "Options": Slower.Options, "reset": print,
                                                      "__call__": print}))


def test_a_filter_from_outside_travels_to_spawned_workers():
    assert filters_for_workers(["repair", "hold"]) == {}  # built in: every worker has them
    payload = filters_for_workers(["hold", "slower_test"])
    assert isinstance(pickle.loads(payload["slower_test"]), Slower)
    register_worker_filters(payload)  # what a worker does before it builds its runner
    _, built = build_filters(ExecutionSettings(filters=("hold", "slower_test"), options={"slower_test": {"keep": 5}}))
    assert isinstance(built, Slower) and built.options.keep == 5


def test_the_built_in_filters_keep_the_dtype_of_the_chunk(observer):  # noqa: F811
    """Filters act on the sampled tensors as they come (a float64 policy gives float64 chunks)."""
    from lano3dp.geometry.frame import observe
    from lano3dp.guidance.execution import FilterContext, Proposal, run_filters
    from lano3dp.guidance.execution.escape import Escape
    from lano3dp.guidance.execution.hold import Hold
    from lano3dp.guidance.execution.repair import Repair

    env = FakeEnv([BOWL, PAN, OBSTACLE])
    frame, state = observe(env, env.reset(seed=0)[0])
    runner = PolicyRunner(FakePolicy(), observer, guidance_preset("none").with_changes(SPHERE),
                          obstacle_phrases=["obstacle_0"])
    runner.tracker.update(frame, step=0)
    axis = runner.tracker.obstacles.obstacles[0].center.numpy()
    # a straight line through the obstacle
    xs = np.linspace(state[0], axis[0] + 0.2, 16)
    trajectory = torch.zeros(1, 16, 10, dtype=torch.float64)
    trajectory[0, :, 0], trajectory[0, :, 1], trajectory[0, :, 2] = torch.as_tensor(xs), float(axis[1]), 0.25
    trajectory[0, :, 3:9] = torch.as_tensor(state[3:9], dtype=torch.float64)
    path = runner.recipe.executed_path(runner.tracker, state, trajectory[0, 1:9])
    context = FilterContext(state, start=1, n_action_steps=8, path=path, margin=0.02)
    proposal, notes = run_filters([Repair(), Hold(), Escape()], Proposal(trajectory, trajectory[:, 1:9]), context)
    assert proposal.trajectory.dtype == torch.float64 and proposal.actions.dtype == torch.float64
    assert "repair" in notes
