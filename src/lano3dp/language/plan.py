"""TaskPlan: what an instruction decomposes into (skill, ordered targets, obstacles)."""

from __future__ import annotations

import copy
from collections.abc import Sequence

from pydantic import BaseModel, ConfigDict, Field, field_validator


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
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    name: str = Field(min_length=1, description="kind noun of the object, e.g. 'bowl' or 'watering can'")
    color: str | None = Field(default=None, description="colour word, e.g. 'red', or null")
    size: str | None = Field(default=None, description="size word, e.g. 'small' or 'large', or null")

    @field_validator("name", "color", "size", mode="before")
    @classmethod
    def _normalise(cls, value):
        return _clean(value) if isinstance(value, str) else value

    @property
    def phrase(self) -> str:
        """'size colour name', e.g. 'small red bowl': what the segmenter is asked for."""
        return " ".join(w for w in (self.size, self.color, self.name) if w)

    def __str__(self) -> str:
        return self.phrase


class TaskPlan(BaseModel):
    """A decomposed instruction.

    Attributes:
        skill: registry name of the policy to run.
        targets: objects the policy observes, in the order of the skill's slots.
        obstacles: objects to avoid; they become guidance costs, never policy inputs.
    """

    model_config = ConfigDict(extra="forbid")

    skill: str = Field(min_length=1, description="name of the skill to run, from the skill list")
    targets: list[ObjectRef] = Field(description="task objects, in the order of the skill's object slots")
    obstacles: list[ObjectRef] = Field(default_factory=list, description="objects to keep away from")

    @property
    def target_phrases(self) -> list[str]:
        return [t.phrase for t in self.targets]

    @property
    def obstacle_phrases(self) -> list[str]:
        return [o.phrase for o in self.obstacles]

    def summary(self) -> str:
        avoid = f"; avoid {', '.join(self.obstacle_phrases)}" if self.obstacles else ""
        return f"{self.skill}({', '.join(self.target_phrases)}){avoid}"


def plan_json_schema(skill_names: Sequence[str] | None = None) -> dict:
    """JSON schema of TaskPlan for an LLM's structured output.

    Strict structured-output endpoints want every property required (nullable instead of
    optional) and no extra keys; with `skill_names` the skill becomes an enum, so a
    constrained decoder cannot invent one.
    """
    schema = copy.deepcopy(TaskPlan.model_json_schema())
    for definition in [schema, *schema.get("$defs", {}).values()]:
        if definition.get("type") == "object":
            definition["required"] = list(definition.get("properties", {}))
            definition["additionalProperties"] = False
            for prop in definition["properties"].values():
                prop.pop("default", None)
    if skill_names:
        schema["properties"]["skill"]["enum"] = list(skill_names)
    return schema
