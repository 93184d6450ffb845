"""Task registry. Each task module defines a `Task` subclass (see `base.py`) and registers it
with the `@register_task` decorator; importing the module below adds it to `TASKS`.

A task also declares how language asks for it (description, verbs, slot synonyms, the carried slot;
see `base.py`), and the skill registry is derived from `TASKS` (`skill_registry`), so the task module
is the one place a task's words are written.

Why the derivation lives here: language (the decomposers, `default_registry`) sits below sim and
never imports it, yet its default skills are the simulator's tasks. So sim hands them down:
importing this package installs `skill_registry` as `lano3dp.language.default_registry`'s source
(`set_default_skills`). Layers above sim (evaluate, the CLI) call `skill_registry` directly, and the
public `lano3dp.OfflineDecomposer` / `LLMDecomposer` import this package first, so the README's
`OfflineDecomposer()` plans with the built-in tasks. Skill data in a module below language would
have kept the default import-free, but then adding a task would touch two modules.

To add a task: write `tasks/<name>.py` with `@register_task class MyTask(Task): ...` and add
one import line at the bottom of this file.
"""

from __future__ import annotations

from lano3dp.language.registry import SkillRegistry, set_default_skills
from lano3dp.sim.tasks.base import Layout, Placement, SimState, Task

TASKS: dict[str, type[Task]] = {}


def register_task(cls: type[Task]) -> type[Task]:
    """Add a task (a class decorator). Its skill declaration is checked here, so a task whose words do
    not fit its slots fails when its module is imported, not when an instruction is first planned."""
    if cls.name in TASKS and TASKS[cls.name] is not cls:
        raise ValueError(f"task name {cls.name!r} is registered twice")
    cls.skill_spec()
    TASKS[cls.name] = cls
    return cls


def make_task(name: str) -> Task:
    if name not in TASKS:
        raise KeyError(f"unknown task {name!r}; registered tasks: {', '.join(sorted(TASKS))}")
    return TASKS[name]()


def task_names() -> list[str]:
    return sorted(TASKS)


def skill_registry() -> SkillRegistry:
    """The skills of the registered tasks, one per task, in `task_names()` order; built on each call, so a
    task registered later is in it."""
    return SkillRegistry(TASKS[name].skill_spec() for name in task_names())


set_default_skills(skill_registry)


__all__ = ["TASKS", "Layout", "Placement", "SimState", "Task", "make_task", "register_task", "skill_registry",
           "task_names"]

# Task modules register themselves on import (one line per task).
from lano3dp.sim.tasks import (  # noqa: E402,F401
    bottle_in_drawer,
    bottle_upright,
    bowl_pour,
    close_microwave,
    open_drawer,
    open_wine_bottle,
    phone_on_base,
    put_item_in_drawer,
    sweep_to_dustpan,
    water_plants,
)
