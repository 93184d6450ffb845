"""Task stages: where an episode got to. Every task's scripted expert passes its stages in order and
its last stage is success; a hand that stays home passes none; the env latches them; evaluation
reports the per-stage breakdown in its results JSON and `lano3dp eval` prints it.

Episodes run at 16x16 pixels (the physics is what is tested), one seed per task.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from lano3dp.evaluation.results import stage_breakdown, summarize
from lano3dp.geometry.rotations import matrix_to_rot6d
from lano3dp.sim import task_names
from lano3dp.sim.robot import HOME_POSITION, top_down
from lano3dp.sim.tasks import TASKS, Task
from simulator_versions import skip_if_mujoco_too_old
from test_policy import TINY, stats_for
from test_tasks_common import make_env

EXPECTED_STAGES = {
    "open_drawer": ("reached_handle", "grasped_handle", "pulled", "opened"),
    "put_item_in_drawer": ("reached_block", "grasped", "lifted", "carried_to_drawer", "placed"),
    "bowl_pour": ("reached_bowl", "grasped", "lifted", "over_pan", "tilted", "poured"),
}
HOME_ACTION = np.concatenate([HOME_POSITION, matrix_to_rot6d(top_down()), [0.0]])


def expert_episode(env, seed: int = 0, extra_steps: int = 15) -> tuple[dict[str, int], int | None, list[dict]]:
    """(stage -> first step its latched flag was set, the success step or None, every step's info)."""
    env.reset(seed=seed)
    actions = env.expert_plan().actions()
    actions = np.concatenate([actions, np.repeat(actions[-1:], extra_steps, axis=0)])
    first, infos = {}, []
    for step, action in enumerate(actions, start=1):
        _, _, terminated, truncated, info = env.step(action)
        infos.append(info)
        for stage, reached in info["stages"].items():
            if reached:
                first.setdefault(stage, step)
        if terminated or truncated:
            return first, step if terminated else None, infos
    return first, None, infos


def test_every_task_declares_its_own_ordered_stages():
    for name, cls in TASKS.items():
        assert cls.stage_reached is not Task.stage_reached, f"{name} does not judge its stages"
        assert len(cls.stages) >= 3 and len(set(cls.stages)) == len(cls.stages), name
    for name, stages in EXPECTED_STAGES.items():
        assert TASKS[name].stages == stages


@pytest.mark.parametrize("task", task_names())
def test_the_expert_reaches_every_stage_in_order_and_the_last_one_with_success(task):
    skip_if_mujoco_too_old(task)
    env = make_env(task)
    try:
        first, success_step, infos = expert_episode(env)
    finally:
        env.close()
    stages = env.task.stages
    assert success_step is not None, f"{task}: the expert failed"
    assert set(first) == set(stages), f"{task}: stages never reached: {set(stages) - set(first)}"
    steps = [first[stage] for stage in stages]
    assert steps == sorted(steps), f"{task}: stages reached out of order: {first}"
    # The last stage is success: it is first reached at the step the env reports success, not before.
    assert first[stages[-1]] == success_step
    assert all(info["stages"][stages[-1]] == info["success"] for info in infos)
    assert infos[-1]["stage"] == stages[-1]
    # The expert takes steps between milestones: reaching is not grasping, grasping is not lifting.
    assert steps[0] < steps[1]


@pytest.mark.parametrize("task", task_names())
def test_a_hand_that_stays_at_home_reaches_no_stage(task):
    env = make_env(task)
    try:
        _, info = env.reset(seed=0)
        assert list(info["stages"]) == list(env.task.stages) and not any(info["stages"].values())
        for _ in range(10):
            _, _, terminated, _, info = env.step(HOME_ACTION)
        assert not terminated
        assert not any(info["stages"].values()), f"{task} at home: {info['stages']}"
        assert info["stage"] is None
    finally:
        env.close()


def test_the_env_latches_stages_over_an_episode_and_reset_clears_them():
    env = make_env("put_item_in_drawer")
    try:
        _, success_step, infos = expert_episode(env)
        assert success_step is not None
        # At success the block is released, so "grasped" and "lifted" no longer hold, yet stay reached.
        now = env.task.stage_reached(env.sim, env.episode.layout)
        assert not now["grasped"] and not now["lifted"] and now["placed"]
        assert infos[-1]["stages"] == dict.fromkeys(env.task.stages, True)
        _, info = env.reset(seed=1)
        assert info["stages"] == dict.fromkeys(env.task.stages, False) and info["stage"] is None
    finally:
        env.close()


def test_a_task_that_reports_undeclared_stages_is_told_what_to_return(monkeypatch):
    env = make_env("open_drawer")
    try:
        env.reset(seed=0)
        monkeypatch.setattr(env.task, "stage_reached", lambda sim, layout: {"opened": False})
        with pytest.raises(ValueError, match=r"exactly its declared `stages` \('reached_handle'"):
            env.step(HOME_ACTION)
    finally:
        env.close()


def record(stages: dict[str, bool]) -> dict:
    reached = [stage for stage, flag in stages.items() if flag]
    return {"stages": stages, "stage": reached[-1] if reached else None}


def test_the_breakdown_gives_the_share_reaching_each_stage_and_where_episodes_stopped():
    order = ("reached_handle", "grasped_handle", "pulled", "opened")
    flags = [(1, 1, 1, 1), (1, 1, 1, 1), (1, 1, 0, 0), (1, 0, 0, 0), (0, 0, 0, 0)]
    episodes = [record(dict(zip(order, map(bool, f), strict=True))) for f in flags]
    rates, furthest = stage_breakdown(episodes)
    assert list(rates) == list(order)
    assert rates == {"reached_handle": 0.8, "grasped_handle": 0.6, "pulled": 0.4, "opened": 0.4}
    assert furthest == {"none": 1, "reached_handle": 1, "grasped_handle": 1, "pulled": 0, "opened": 2}
    # Results recorded before tasks had stages: no breakdown, and summarize still works on them.
    assert stage_breakdown([{"success": True}]) == ({}, {})
    old = {"success": True, "collided": False, "n_collision_steps": 0, "min_clearance": None, "path_length": 1.0,
           "steps": 10, "chunk_latency_s": [0.1], "chunk_tries": [1], "error": None}
    summary = summarize([old])
    assert summary["stage_rates"] == {} and summary["success_rate"] == 1.0


@pytest.fixture(scope="module")
def tiny_checkpoint(tmp_path_factory):
    """An untrained tiny object policy for open_drawer: evaluation needs a checkpoint, not a good one."""
    from lano3dp.policy import DiffusionPolicy, PolicyConfig

    torch.manual_seed(0)
    policy = DiffusionPolicy(PolicyConfig(**({"object_names": ("drawer",)} | TINY)))
    policy.set_normalizer(stats_for(policy.config))
    folder = tmp_path_factory.mktemp("stages") / "policy"
    policy.save_pretrained(folder)
    return folder


def test_lano3dp_eval_reports_the_stage_breakdown_in_its_json_and_output(tiny_checkpoint, tmp_path):
    from lano3dp.cli import app

    out = tmp_path / "results.json"
    result = CliRunner().invoke(app, ["eval", "--checkpoint", str(tiny_checkpoint), "--task", "open_drawer",
                                      "--episodes", "2", "--max-steps", "8", "--out", str(out)])
    assert result.exit_code == 0, result.output + repr(result.exception)
    data = json.loads(out.read_text())
    stages = list(TASKS["open_drawer"].stages)
    for episode in data["episodes"]:
        assert list(episode["stages"]) == stages
        assert episode["stages"]["opened"] == episode["success"]
    summary = data["summary"]
    assert list(summary["stage_rates"]) == stages
    assert all(0.0 <= rate <= 1.0 for rate in summary["stage_rates"].values())
    assert summary["stage_rates"]["opened"] == summary["success_rate"]
    assert list(summary["furthest_stages"]) == ["none", *stages]
    assert sum(summary["furthest_stages"].values()) == 2
    assert "stages reached: reached_handle " in result.output and "> opened " in result.output
