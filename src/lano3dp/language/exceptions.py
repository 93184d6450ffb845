"""Errors of the language layer: each says which skill, slot or object is wrong and what is known."""

from __future__ import annotations

from collections.abc import Sequence

from lano3dp.errors import Lano3dpError


class LanguageError(Lano3dpError):
    """Base class of language errors."""


class PlanValidationError(LanguageError, ValueError):
    """A TaskPlan does not fit the skill registry or the scene."""


class UnknownSkillError(PlanValidationError):
    def __init__(self, skill: str, known: Sequence[str]):
        self.skill = skill
        self.known = tuple(known)
        super().__init__(f"unknown skill '{skill}'; the registry has: {', '.join(self.known)}")


class SlotMismatchError(PlanValidationError):
    def __init__(self, skill: str, slots: Sequence[str], got: Sequence[str]):
        self.skill = skill
        self.slots = tuple(slots)
        self.got = tuple(got)
        super().__init__(
            f"skill '{skill}' takes {len(self.slots)} target(s) in the order ({', '.join(self.slots)}), "
            f"got {len(self.got)}: ({', '.join(self.got)})"
        )


class UnknownObjectError(PlanValidationError):
    def __init__(self, phrase: str, scene: Sequence[str], role: str = "object"):
        self.phrase = phrase
        self.scene = tuple(scene)
        super().__init__(f"{role} '{phrase}' is not in the scene; the scene has: {', '.join(self.scene) or 'nothing'}")


class InstructionNotUnderstoodError(LanguageError, ValueError):
    """The offline parser found no skill (or no unique skill) for an instruction."""

    def __init__(self, instruction: str, reason: str):
        self.instruction = instruction
        super().__init__(f"cannot plan '{instruction}': {reason}")


class UncertainObstacleError(InstructionNotUnderstoodError):
    """Words after an avoidance cue (or an "is in the way" predicate) name no object the parser can
    point at, e.g. "avoid it" with nothing named before: refusing beats planning without the obstacle."""
