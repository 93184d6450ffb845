"""TaskPlan: what an instruction decomposes into (skill, ordered targets, obstacles)."""

from __future__ import annotations

import copy
from collections.abc import Sequence

from pydantic import BaseModel, ConfigDict, Field, field_validator

# Bounds on any plan, from the rules or a model: no skill has more than 3 slots, no tabletop scene dozens of
# obstacles, and no object name is a paragraph. A reply beyond them is refused, not truncated silently.
MAX_TARGETS = 8
MAX_OBSTACLES = 16
MAX_NAME_CHARS = 64
MAX_WORD_CHARS = 32


def _clean(value: str | None) -> str | None:
    if value is None:
        return None
    value = " ".join(value.strip().lower().replace("_", " ").split())
    return value or None


class ObjectRef(BaseModel):
    """An object named in an instruction.

    Attributes:
        name: the kind noun, possibly a compound ("bowl", "watering can", "coffee mug").
        color: colour word or None.
        size: size word ("small", "medium", "large", "tall", ...) or None.
        position: position or relation word ("top", "left", "nearest", "other", ...) or None; like a
            colour it narrows which instance is meant and is resolved at perception time.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    name: str = Field(min_length=1, max_length=MAX_NAME_CHARS,
                      description="kind noun of the object, e.g. 'bowl' or 'watering can'")
    color: str | None = Field(default=None, max_length=MAX_WORD_CHARS,
                              description="colour word, e.g. 'red', or null")
    size: str | None = Field(default=None, max_length=MAX_WORD_CHARS,
                             description="size word, e.g. 'small' or 'large', or null")
    position: str | None = Field(
        default=None, max_length=MAX_WORD_CHARS,
        description="position word said for the object, e.g. 'top', 'left', 'nearest', or null"
    )

    @field_validator("name", "color", "size", "position", mode="before")
    @classmethod
    def _normalise(cls, value):
        return _clean(value) if isinstance(value, str) else value

    @property
    def phrase(self) -> str:
        """'position size colour name', e.g. 'left small red bowl': what the segmenter is asked for."""
        return " ".join(w for w in (self.position, self.size, self.color, self.name) if w)

    def __str__(self) -> str:
        return self.phrase


class TaskPlan(BaseModel):
    """A decomposed instruction.

    Attributes:
        skill: registry name of the policy to run.
        targets: objects the policy observes, in the order of the skill's slots.
        obstacles: objects to avoid; they become guidance costs, never policy inputs.
        warnings: what the decomposer was unsure of (an ambiguous "it", a cue that named no object, an
            LLM reply that was rejected); a caller shows them, a model never writes them.
    """

    model_config = ConfigDict(extra="forbid")

    skill: str = Field(min_length=1, max_length=MAX_NAME_CHARS,
                       description="name of the skill to run, from the skill list")
    targets: list[ObjectRef] = Field(max_length=MAX_TARGETS,
                                     description="task objects, in the order of the skill's object slots")
    obstacles: list[ObjectRef] = Field(default_factory=list, description="objects to keep away from")
    warnings: list[str] = Field(default_factory=list, description="what the decomposer was unsure of")

    @field_validator("obstacles")
    @classmethod
    def _distinct_and_bounded(cls, obstacles: list[ObjectRef]) -> list[ObjectRef]:
        distinct = list(dict.fromkeys(obstacles))  # the same obstacle twice is one cost, not two
        if len(distinct) > MAX_OBSTACLES:
            raise ValueError(f"{len(distinct)} distinct obstacles; at most {MAX_OBSTACLES} are accepted")
        return distinct

    @property
    def target_phrases(self) -> list[str]:
        return [t.phrase for t in self.targets]

    @property
    def obstacle_phrases(self) -> list[str]:
        return [o.phrase for o in self.obstacles]

    def summary(self) -> str:
        avoid = f"; avoid {', '.join(self.obstacle_phrases)}" if self.obstacles else ""
        return f"{self.skill}({', '.join(self.target_phrases)}){avoid}"


class PlanReply(BaseModel):
    """What a language model answers: a plan, or an explicit refusal with its reason.

    A model that cannot map the instruction onto a skill must be able to say so; without
    `refusal` the only way out of a required skill enum is a guess.
    """

    model_config = ConfigDict(extra="forbid")

    refusal: str | None = Field(
        default=None, description="why no listed skill can do the instruction; null when giving a plan"
    )
    skill: str | None = Field(
        default=None, description="name of the skill to run, from the skill list; null if refusing"
    )
    targets: list[ObjectRef] = Field(
        default_factory=list, description="task objects, in the order of the skill's object slots"
    )
    obstacles: list[ObjectRef] = Field(default_factory=list, description="objects to keep away from")

    def to_plan(self) -> TaskPlan:
        """The plan; raises ValueError when the reply is a refusal or has neither."""
        if self.refusal:
            raise ValueError(f"refused: {self.refusal}")
        if not self.skill:
            raise ValueError("the reply has neither a skill nor a refusal")
        return TaskPlan(skill=self.skill, targets=self.targets, obstacles=self.obstacles)


def _without_bounds(node):
    """The schema without length bounds: strict structured-output endpoints reject maxLength and friends;
    the bounds are checked on the reply instead (TaskPlan, ObjectRef)."""
    if isinstance(node, dict):
        return {k: _without_bounds(v) for k, v in node.items() if k not in ("maxLength", "minLength", "maxItems")}
    if isinstance(node, list):
        return [_without_bounds(v) for v in node]
    return node


def plan_json_schema(skill_names: Sequence[str] | None = None) -> dict:
    """JSON schema of a model's reply (`PlanReply`: a plan or a refusal) for structured output.

    Strict structured-output endpoints want every property required (nullable instead of
    optional) and no extra keys; with `skill_names` the skill becomes an enum (or null), so a
    constrained decoder cannot invent one.
    """
    schema = _without_bounds(copy.deepcopy(PlanReply.model_json_schema()))
    for definition in [schema, *schema.get("$defs", {}).values()]:
        # Class docstrings and titles only cost prompt tokens; the field descriptions stay.
        definition.pop("description", None)
        definition.pop("title", None)
        for prop in definition.get("properties", {}).values():
            prop.pop("title", None)
        if definition.get("type") == "object":
            definition["required"] = list(definition.get("properties", {}))
            definition["additionalProperties"] = False
            for prop in definition["properties"].values():
                prop.pop("default", None)
    if skill_names:
        schema["properties"]["skill"] = {
            "anyOf": [{"type": "string", "enum": list(skill_names)}, {"type": "null"}],
            "description": schema["properties"]["skill"]["description"],
        }
    return schema
