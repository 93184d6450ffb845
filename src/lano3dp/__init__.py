"""lano3dp: language-guided, object-centric 3D diffusion policies (Lan-o3dp).

The public API, importable from here (see the README's "Use it from Python"):

- policy: DiffusionPolicy (from_pretrained, select_action / reset, predict_action_chunk), PolicyConfig,
  packaged_checkpoint (the policy shipped for a task);
- environment: SimulatorProtocol (what any simulator or robot meets), TabletopEnv (the built-in one);
- planner: OfflineDecomposer, LLMDecomposer (instruction -> TaskPlan);
- runner: PolicyRunner (perception + guided policy, one action per frame), rollout (one episode);
- evaluation: evaluate + EvalConfig (as `lano3dp eval`), run_instruction + RunConfig (as `lano3dp run`), and the
  settings they nest: GuidanceChoice (a preset by name + overrides), PerceptionSettings;
- guidance settings: GuidanceSettings (the tree), guidance_preset / register_guidance_preset (named presets).

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
    "evaluate": "lano3dp.evaluation",
    "EvalConfig": "lano3dp.evaluation",
    "run_instruction": "lano3dp.evaluation",
    "RunConfig": "lano3dp.evaluation",
    "PerceptionSettings": "lano3dp.evaluation",
    "GuidanceChoice": "lano3dp.evaluation",
    "GuidanceSettings": "lano3dp.guidance.settings",
    "guidance_preset": "lano3dp.guidance.settings",
    "register_guidance_preset": "lano3dp.guidance.settings",
}

# literal, so linters see it; test_public_api checks it against _EXPORTS
__all__ = ["DiffusionPolicy", "EvalConfig", "GuidanceChoice", "GuidanceSettings", "LLMDecomposer",
           "OfflineDecomposer", "PerceptionSettings", "PolicyConfig", "PolicyRunner", "RunConfig", "SimulatorProtocol",
           "TabletopEnv", "__version__", "evaluate", "guidance_preset", "packaged_checkpoint",
           "register_guidance_preset", "rollout", "run_instruction"]

if TYPE_CHECKING:  # for type checkers and IDEs; at run time __getattr__ imports on demand
    from lano3dp.evaluation import (
        EvalConfig,
        GuidanceChoice,
        PerceptionSettings,
        RunConfig,
        evaluate,
        run_instruction,
    )
    from lano3dp.guidance.settings import GuidanceSettings, guidance_preset, register_guidance_preset
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
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later look-ups skip __getattr__
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
