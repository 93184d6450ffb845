"""Language: instruction -> validated TaskPlan (skill, ordered target objects, obstacles).

The rule-based `OfflineDecomposer` is the default and needs no model; `LLMDecomposer` asks any
OpenAI-compatible endpoint and falls back to the rules. The embedding matcher is optional.
"""

from lano3dp.language.exceptions import (
    InstructionNotUnderstoodError,
    LanguageError,
    PlanValidationError,
    SlotMismatchError,
    UncertainObstacleError,
    UnknownObjectError,
    UnknownSkillError,
)
from lano3dp.language.offline import OfflineDecomposer
from lano3dp.language.plan import ObjectRef, PlanReply, TaskPlan, plan_json_schema
from lano3dp.language.registry import SkillRegistry, SkillSpec, Slot, default_registry

__all__ = [
    "InstructionNotUnderstoodError",
    "LanguageError",
    "ObjectRef",
    "OfflineDecomposer",
    "PlanReply",
    "PlanValidationError",
    "SkillRegistry",
    "SkillSpec",
    "Slot",
    "SlotMismatchError",
    "TaskPlan",
    "UncertainObstacleError",
    "UnknownObjectError",
    "UnknownSkillError",
    "default_registry",
    "plan_json_schema",
]
