"""Task registry. Each task module defines a `Task` subclass (see `base.py`) and registers it
with the `@register_task` decorator; importing this package imports every task module, adding
its task to `TASKS`.

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

To add a task: write `tasks/<name>.py` with `@register_task class MyTask(Task): ...`; every
module in this package is imported (below), so that file is the whole change.
"""

from __future__ import annotations

import importlib
import pkgutil

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

# Task modules register themselves on import. Every module of this package is one (base.py aside), so a new task
# is its module alone: no list here to extend.
for _module in pkgutil.iter_modules(__path__):
    if _module.name != "base":
        importlib.import_module(f"{__name__}.{_module.name}")
del _module
