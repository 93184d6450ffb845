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


class TargetNotInSceneError(UnknownObjectError):
    """A target the scene does not hold: never replaced by another object of the scene (issue 34). The user may
    map it explicitly (`lano3dp.language.grounding.ground_plan(..., mapping={"teapot": "block"})`)."""

    def __init__(self, phrase: str, scene: Sequence[str]):
        self.phrase = phrase
        self.scene = tuple(scene)
        PlanValidationError.__init__(
            self,
            f"target '{phrase}' is not in the scene; the scene has: {', '.join(self.scene) or 'nothing'} "
            f"(nothing was done; name one of those, or map the phrase to one explicitly)",
        )


_QUOTED_CHARS = 80  # an instruction quoted in a message: a megabyte of it is no help to anyone


def quoted(instruction: str) -> str:
    """The instruction for a one-line message: at most `_QUOTED_CHARS` characters, no line breaks."""
    head = str(instruction)[: 2 * _QUOTED_CHARS]  # never split a megabyte to quote 80 characters
    text = " ".join(head.split())
    if len(text) <= _QUOTED_CHARS and len(head) == len(str(instruction)):
        return text
    return text[: _QUOTED_CHARS - 1] + "…"


class InstructionNotUnderstoodError(LanguageError, ValueError):
    """The offline parser found no skill (or no unique skill) for an instruction, or refused it.

    Attributes:
        instruction: the instruction as given.
        reason: what could not be accepted, one line.
    """

    def __init__(self, instruction: str, reason: str):
        self.instruction = instruction
        self.reason = reason
        super().__init__(f"cannot plan '{quoted(instruction)}': {reason}")


class InputRejectedError(InstructionNotUnderstoodError):
    """The text itself is refused before parsing: too long, a bidirectional override, a mixed-script word."""


class NegatedCommandError(InstructionNotUnderstoodError):
    """The only task asked for is negated ("don't open the drawer"): there is nothing to do."""


class SeveralTasksError(InstructionNotUnderstoodError):
    """Two tasks in one instruction ("open the drawer and put the block in it"); a plan runs one skill."""


class ContradictionError(InstructionNotUnderstoodError):
    """An object is both the one to act on and one to avoid ("put the bottle away without touching the bottle")."""


class UnknownVerbError(InstructionNotUnderstoodError):
    """The instruction asks for its task with a verb no skill is asked for with ("smash the bowl")."""


class UncertainObstacleError(InstructionNotUnderstoodError):
    """Words after an avoidance cue (or an "is in the way" predicate) name no object the parser can
    point at, e.g. "avoid it" with nothing named before: refusing beats planning without the obstacle."""
