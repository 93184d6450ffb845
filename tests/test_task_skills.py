"""The skill registry is derived from the task registry: a task module declares its own skill, and adding a task
touches that module alone."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from lano3dp.language import OfflineDecomposer, default_registry
from lano3dp.sim.tasks import TASKS, register_task, skill_registry, task_names
from lano3dp.sim.tasks.base import Task

SRC = Path(__file__).resolve().parents[1] / "src"


def test_every_task_has_exactly_one_skill_and_every_skill_a_task():
    registry = skill_registry()
    assert registry.names == tuple(task_names())
    for name, cls in TASKS.items():
        skill = registry.get(name)
        assert cls.skill == name and skill.slot_words == cls.object_slots
    assert default_registry().to_json() == registry.to_json()  # what sim installed as language's default


def test_every_module_of_the_tasks_package_is_a_registered_task():
    # The package imports its modules itself, so a new task file needs no import line anywhere.
    modules = {path.stem for path in (SRC / "lano3dp" / "sim" / "tasks").glob("*.py")} - {"__init__", "base"}
    assert {cls.__module__.rsplit(".", 1)[-1] for cls in TASKS.values()} == modules


class _StackCups(Task):
    """A task declared the way a task module declares one; it is never simulated here."""

    name = "stack_cups"
    skill = "stack_cups"
    object_slots = ("cup", "saucer")
    instruction = "put the {cup} on the {saucer}"
    description = "put the cup on its saucer"
    verbs = ("stack", "nest", "stack up")
    synonyms = {"cup": ("teacup", "mug")}
    carried = "cup"

    def sample_layout(self, rng, variation): ...

    def build(self, builder, layout): ...

    def plan_expert(self, sim, layout): ...

    def is_success(self, sim, layout): ...


@pytest.fixture
def stack_cups():
    register_task(_StackCups)
    yield _StackCups
    del TASKS[_StackCups.name]  # the task registry's own dict: unregistering the task unregisters its skill
    assert "stack_cups" not in skill_registry()


def test_a_registered_task_is_a_skill_the_planner_knows(stack_cups):
    skill = skill_registry().get("stack_cups")
    assert skill.verbs == ("stack", "nest", "stack up") and skill.slot_words == ("cup", "saucer")
    assert skill.slots[0].synonyms == ("cup", "teacup", "mug") and skill.carried_slot == 0
    assert "stack_cups" in default_registry()
    plan = OfflineDecomposer().decompose("stack the teacup up on the saucer and avoid the bowl")  # teacup: the cup
    assert (plan.skill, plan.target_phrases, plan.obstacle_phrases) == ("stack_cups", ["cup", "saucer"], ["bowl"])


def test_a_skill_that_names_a_slot_the_task_lacks_fails_at_registration():
    class Broken(_StackCups):
        name = skill = "broken_cups"
        synonyms = {"mug": ("cup",)}

    with pytest.raises(ValueError, match=r"name \['mug'\], which are not among its object_slots"):
        register_task(Broken)
    assert "broken_cups" not in TASKS


def test_language_alone_has_no_default_skills_and_the_public_api_installs_them():
    # Language sits below sim, so the built-in skills reach it only once sim is imported; the README's
    # `from lano3dp import OfflineDecomposer` does that.
    probe = (
        "import sys\n"
        "from lano3dp.language import LanguageError, OfflineDecomposer\n"
        "try:\n    OfflineDecomposer()\nexcept LanguageError as error:\n    print('refused:', error)\n"
        "assert 'lano3dp.sim' not in sys.modules\n"
        "from lano3dp import OfflineDecomposer\n"
        "print(OfflineDecomposer().decompose('put the block in the drawer and keep clear of the mug').summary())\n"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True,
                         env={"PYTHONPATH": str(SRC), "MUJOCO_GL": "egl", "PATH": ""}).stdout
    assert "refused: no default skills: they are the simulator's tasks" in out
    assert out.strip().splitlines()[-1] == "put_item_in_drawer(block, drawer); avoid mug"
