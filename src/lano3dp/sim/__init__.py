"""MuJoCo tabletop simulator: scene builder, objects, tasks with scripted experts, variations, env.

`MUJOCO_GL` must be chosen before mujoco is first imported; offscreen EGL is the only backend
that works on a headless CPU machine, so it is the default (an explicit setting wins). The
same holds for `LP_NUM_THREADS` (llvmpipe render threads, default 1 here).

Layering: this package never imports torch or `lano3dp.policy`.

Entry points:
    TabletopEnv            gymnasium env (absolute 10-D EE actions), see `env.py`
    Variation              generalisation axes, see `variations.py`
    make_task / TASKS      task registry, see `tasks/__init__.py`
    SimulatorProtocol      what a user's own simulator or robot implements, see `protocol.py`
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
# Mesa's llvmpipe rasteriser spawns a thread per core by default; on a shared CPU box (and with
# one simulator per worker process) a single thread renders 128x128 faster than contended ones.
os.environ.setdefault("LP_NUM_THREADS", "1")

import mujoco  # noqa: E402,F401  (imported here so MUJOCO_GL above takes effect first)

_EXPORTS = {
    "TabletopEnv": "lano3dp.sim.env",
    "SimulatorProtocol": "lano3dp.sim.protocol",
    "TASKS": "lano3dp.sim.tasks",
    "make_task": "lano3dp.sim.tasks",
    "task_names": "lano3dp.sim.tasks",
    "Variation": "lano3dp.sim.variations",
    "VARIATION_AXES": "lano3dp.sim.variations",
}


def __getattr__(name: str):
    # Lazy so that importing a submodule (e.g. sim.scene from a task file) never cycles.
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'lano3dp.sim' has no attribute {name!r}")


__all__ = sorted(_EXPORTS)
