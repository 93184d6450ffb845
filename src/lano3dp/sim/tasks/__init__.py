"""Task registry. Each task module defines a `Task` subclass (see `base.py`) and registers it
with the `@register_task` decorator; importing the module below adds it to `TASKS`.

To add a task: write `tasks/<name>.py` with `@register_task class MyTask(Task): ...` and add
one import line at the bottom of this file.
"""

from __future__ import annotations

from lano3dp.sim.tasks.base import Layout, Placement, SimState, Task

TASKS: dict[str, type[Task]] = {}


def register_task(cls: type[Task]) -> type[Task]:
    if cls.name in TASKS and TASKS[cls.name] is not cls:
        raise ValueError(f"task name {cls.name!r} is registered twice")
    TASKS[cls.name] = cls
    return cls


def make_task(name: str) -> Task:
    if name not in TASKS:
        raise KeyError(f"unknown task {name!r}; registered tasks: {', '.join(sorted(TASKS))}")
    return TASKS[name]()


def task_names() -> list[str]:
    return sorted(TASKS)


__all__ = ["TASKS", "Layout", "Placement", "SimState", "Task", "make_task", "register_task", "task_names"]

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
