"""Choosing obstacle scenes (`sim.env.obstacle_scene_seeds`): the same seeds as ever where a task has room, and one
clear error within seconds where its layout leaves none."""

import json
from pathlib import Path

import pytest

from lano3dp.sim import env as sim_env
from lano3dp.sim.env import NoObstacleRoomError, obstacle_scene_seeds

CHOSEN_BEFORE = json.loads((Path(__file__).parent / "data" / "obstacle_scene_seeds.json").read_text())["seeds"]


@pytest.mark.parametrize("key", sorted(CHOSEN_BEFORE))
def test_tasks_with_room_get_the_scenes_their_results_were_measured_on(key):
    task, variation = key.split()
    assert obstacle_scene_seeds(task, variation, 0, 50) == CHOSEN_BEFORE[key]


def test_a_task_without_room_fails_after_a_bounded_search_with_one_line(monkeypatch):
    """open_drawer's short path leaves no spot clear of the start, the handle and the drawer (0 of 400 scenes)."""
    sampled = []
    sample_episode = sim_env.sample_episode
    monkeypatch.setattr(sim_env, "sample_episode", lambda *args: sampled.append(args[1]) or sample_episode(*args))
    monkeypatch.setattr(sim_env, "NO_ROOM_SEEDS", 40)  # 1000 in use: ~6-15 CPU-s; the rule is the same
    with pytest.raises(NoObstacleRoomError) as raised:
        obstacle_scene_seeds("open_drawer", "obstacle:2", 7, 3)
    message = str(raised.value)
    assert "\n" not in message
    assert message.startswith("none of 40 open_drawer scenes (seeds 7-46) has room for obstacle:2")
    assert "another task" in message and "--obstacle-scenes-only" in message
    assert sampled == list(range(7, 47))
    assert isinstance(raised.value, ValueError)  # the command line's error boundary prints it as one line


def test_the_bound_only_applies_before_the_first_scene_with_room(monkeypatch):
    """A task with rare room keeps searching past NO_ROOM_SEEDS once it has found one: its seeds do not change."""
    monkeypatch.setattr(sim_env, "NO_ROOM_SEEDS", 6)
    chosen = CHOSEN_BEFORE["put_item_in_drawer obstacle:2"][:4]  # 5, 7, 11, 20: the first within 6 seeds
    assert obstacle_scene_seeds("put_item_in_drawer", "obstacle:2", 0, 4) == chosen
    assert chosen[0] < 6 and max(b - a for a, b in zip(chosen, chosen[1:], strict=False)) > 6
