"""Language: instruction -> validated TaskPlan (skill, ordered target objects, obstacles).

The rule-based `OfflineDecomposer` is the default and needs no model; `LLMDecomposer` asks any
OpenAI-compatible endpoint and falls back to the rules. The embedding matcher is optional.
"""

from lano3dp.language.exceptions import (
    ContradictionError,
    InputRejectedError,
    InstructionNotUnderstoodError,
    LanguageError,
    NegatedCommandError,
    PlanValidationError,
    SeveralTasksError,
    SlotMismatchError,
    TargetNotInSceneError,
    UncertainObstacleError,
    UnknownObjectError,
    UnknownSkillError,
    UnknownVerbError,
)
from lano3dp.language.offline import OfflineDecomposer
from lano3dp.language.plan import ObjectRef, PlanReply, TaskPlan, plan_json_schema
from lano3dp.language.registry import SkillRegistry, SkillSpec, Slot, default_registry

__all__ = [
    "ContradictionError",
    "InputRejectedError",
    "InstructionNotUnderstoodError",
    "LanguageError",
    "NegatedCommandError",
    "ObjectRef",
    "OfflineDecomposer",
    "PlanReply",
    "PlanValidationError",
    "SkillRegistry",
    "SeveralTasksError",
    "SkillSpec",
    "Slot",
    "SlotMismatchError",
    "TargetNotInSceneError",
    "TaskPlan",
    "UncertainObstacleError",
    "UnknownObjectError",
    "UnknownSkillError",
    "UnknownVerbError",
    "default_registry",
    "plan_json_schema",
]
