"""lano3dp: language-guided, object-centric 3D diffusion policies (Lan-o3dp).

The public API, importable from here (see the README's "Use it from Python"):

- policy: DiffusionPolicy (from_pretrained, select_action / reset, predict_action_chunk), PolicyConfig,
  packaged_checkpoint (the policy shipped for a task);
- environment: SimulatorProtocol (what any simulator or robot meets), TabletopEnv (the built-in one);
- planner: OfflineDecomposer, LLMDecomposer (instruction -> TaskPlan);
- runner: PolicyRunner (perception + guided policy, one action per frame), rollout (one episode);
- evaluation: evaluate + EvalConfig (as `lano3dp eval`), run_instruction + RunConfig (as `lano3dp run`), and the
  settings they nest: GuidanceSettings (GUIDANCE_PRESETS), ObstacleSettings, PerceptionSettings.

Names are imported on first use (module __getattr__), so `import lano3dp` stays light: no torch, no MuJoCo.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

# public name -> module that defines it
_EXPORTS = {
    "DiffusionPolicy": "lano3dp.policy.modeling",
    "PolicyConfig": "lano3dp.policy.config",
    "packaged_checkpoint": "lano3dp.policy.pretrained",
    "SimulatorProtocol": "lano3dp.sim.protocol",
    "TabletopEnv": "lano3dp.sim.env",
    "OfflineDecomposer": "lano3dp.language.offline",
    "LLMDecomposer": "lano3dp.language.llm",
    "PolicyRunner": "lano3dp.runtime",
    "rollout": "lano3dp.runtime",
    "evaluate": "lano3dp.evaluate",
    "EvalConfig": "lano3dp.evaluate",
    "run_instruction": "lano3dp.evaluate",
    "RunConfig": "lano3dp.evaluate",
    "PerceptionSettings": "lano3dp.evaluate",
    "GuidanceSettings": "lano3dp.guidance.settings",
    "GUIDANCE_PRESETS": "lano3dp.guidance.settings",
    "ObstacleSettings": "lano3dp.guidance.settings",
}

__all__ = ["GUIDANCE_PRESETS", "DiffusionPolicy", "EvalConfig", "GuidanceSettings", "LLMDecomposer", "ObstacleSettings",
           "OfflineDecomposer", "PerceptionSettings", "PolicyConfig", "PolicyRunner", "RunConfig", "SimulatorProtocol",
           "TabletopEnv", "__version__", "evaluate", "packaged_checkpoint", "rollout",
           "run_instruction"]  # literal, so linters see it; test_public_api checks it against _EXPORTS

if TYPE_CHECKING:  # for type checkers and IDEs; at run time __getattr__ imports on demand
    from lano3dp.evaluate import EvalConfig, PerceptionSettings, RunConfig, evaluate, run_instruction
    from lano3dp.guidance.settings import GUIDANCE_PRESETS, GuidanceSettings, ObstacleSettings
    from lano3dp.language.llm import LLMDecomposer
    from lano3dp.language.offline import OfflineDecomposer
    from lano3dp.policy.config import PolicyConfig
    from lano3dp.policy.modeling import DiffusionPolicy
    from lano3dp.policy.pretrained import packaged_checkpoint
    from lano3dp.runtime import PolicyRunner, rollout
    from lano3dp.sim.env import TabletopEnv
    from lano3dp.sim.protocol import SimulatorProtocol


# Decomposers whose default skills are the simulator's tasks: language cannot import sim (it is a layer below), so
# the public API imports the task registry first, which installs them (lano3dp.sim.tasks; MuJoCo, no torch).
_NEED_TASK_SKILLS = ("OfflineDecomposer", "LLMDecomposer")


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'lano3dp' has no attribute {name!r}")
    if name in _NEED_TASK_SKILLS:
        importlib.import_module("lano3dp.sim.tasks")
    imported = importlib.import_module(module)
    if module == f"{__name__}.{name}":
        # `evaluate` is both a function and its module's name: importing the module makes the package
        # attribute the module (Python's rule), so the module itself is callable (see evaluate.py's end).
        return imported
    value = getattr(imported, name)
    globals()[name] = value  # later look-ups skip __getattr__
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
