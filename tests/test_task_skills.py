"""The skill registry is derived from the task registry: each task module declares its own skill."""

from __future__ import annotations

import json

from lano3dp.language import default_registry
from lano3dp.sim.tasks import skill_registry


def test_the_derived_registry_is_the_hand_written_one():
    # Order aside: the derived registry follows task_names() (alphabetical), the hand-written one listed the
    # paper's real tasks first. Ties between skills are refused, not broken by order, so plans do not change.
    derived = {entry["name"]: entry for entry in json.loads(skill_registry().to_json())}
    written = {entry["name"]: entry for entry in json.loads(default_registry().to_json())}
    assert derived == written
