"""Cross-check of a model's plan against the instruction it came from.

A plan that fits the schema and the registry can still be wrong: a model may drop an obstacle
the user named, invent one, or swap a target and an obstacle. The offline parser's reading of
the same instruction is the reference: what it is sure of (obstacles, target attributes) the
model's plan must contain, and every object the plan names must be said in the instruction.
Problems are errors (the reply is refused and sent back). Beyond the reference, three checks do not depend
on the rules' reading at all (issue 34):
- the skill must be one the instruction's own verbs ask for ("put" asks for put_item_in_drawer or
  bottle_in_drawer, never for bowl_pour); an instruction with no such verb supports no skill;
- every object the instruction names (`mentions.object_mentions`) must be a target or an obstacle of the plan;
- an instruction the rules refuse for a reason a model cannot remove (a negated command, two tasks, a
  contradiction) is refused whatever the model planned.
A different skill among those the verbs ask for is only a warning.
"""

from __future__ import annotations

from typing import NamedTuple

from lano3dp.language.exceptions import (
    ContradictionError,
    InputRejectedError,
    LanguageError,
    NegatedCommandError,
    SeveralTasksError,
)
from lano3dp.language.mentions import is_obstacle, unaccounted
from lano3dp.language.offline import POSITION_WORDS, OfflineDecomposer, lemmas, tokenize
from lano3dp.language.plan import ObjectRef, TaskPlan
from lano3dp.language.registry import SceneObjects, scene_vocabulary
from lano3dp.vocabulary import canonical_attribute, resolve_phrase, singular


class CrossCheck(NamedTuple):
    """errors: reasons to refuse the plan; warnings: what the caller should be told."""

    errors: list[str]
    warnings: list[str]


def cross_check(
    plan: TaskPlan, instruction: str, rules: OfflineDecomposer, scene_objects: SceneObjects | None = None
) -> CrossCheck:
    """Compare a model's `plan` (before scene grounding) with what `instruction` says. With the scene, a
    model may name an object by its scene name ("distractor_mug_2") and add attributes the scene gives it."""
    errors: list[str] = []
    warnings: list[str] = []
    said = {form for word in tokenize(instruction) for form in lemmas(word)}
    said |= {singular(w) for w in said} | {canonical_attribute(w) for w in said}
    said |= {POSITION_WORDS[w] for w in said if w in POSITION_WORDS}
    try:
        reading = rules.decompose(instruction)
    except (NegatedCommandError, SeveralTasksError, ContradictionError, InputRejectedError) as refusal:
        return CrossCheck([f"the instruction cannot be planned: {refusal.reason}"], [])
    except LanguageError:
        reading = None
    parse = rules.parse(instruction)
    expected_obstacles = reading.obstacles if reading is not None else parse.obstacles
    skill = rules.registry.get(plan.skill) if plan.skill in rules.registry else None
    asked = rules.skills_asked_for(parse)
    if plan.skill not in asked:
        verbs = ", ".join(f"'{v}'" for v in dict.fromkeys(parse.verbs))
        errors.append(
            f"the instruction's verbs ({verbs}) ask for {', '.join(sorted(asked))}, not {plan.skill}"
            if asked
            else f"the instruction has no verb that asks for {plan.skill} (or any skill)"
        )
    for mention in unaccounted(plan, parse.mentions, skill, rules.registry):
        if reading is None or not is_obstacle(mention, reading):
            errors.append(f"the instruction names '{mention.phrase}', which the plan neither acts on nor avoids")

    objects = scene_vocabulary(scene_objects) if scene_objects is not None else []

    def in_scene(ref: ObjectRef) -> list:
        return [o for o in objects if o.name in resolve_phrase(ref.phrase, objects)] if objects else []

    def heads(ref: ObjectRef) -> set[str]:
        return {singular(ref.name.split()[-1])} | {o.kind[-1] for o in in_scene(ref) if o.kind}

    def _same(a: ObjectRef, b: ObjectRef) -> bool:
        """Same object as far as words (and the scene) tell: a shared head noun, no attribute that differs."""
        if not heads(a) & heads(b):
            return False
        return all(None in (getattr(a, k), getattr(b, k)) or getattr(a, k) == getattr(b, k) for k in ("color", "size"))

    def mentioned(ref: ObjectRef) -> bool:
        if all(w in said for w in ref.name.split()):
            return True
        return any(o.kind and all(w in said for w in o.kind) for o in in_scene(ref))

    for obstacle in plan.obstacles:
        if not mentioned(obstacle):
            errors.append(f"the plan avoids '{obstacle.phrase}', which the instruction does not mention")
        elif reading is not None and not any(_same(obstacle, o) for o in expected_obstacles):
            if any(_same(obstacle, t) for t in reading.targets):
                errors.append(f"'{obstacle.phrase}' is a task object in the instruction, not an obstacle")
    for expected in expected_obstacles:
        if not any(_same(expected, o) for o in plan.obstacles):
            errors.append(f"the instruction says to avoid '{expected.phrase}' but the plan has no such obstacle")
    for k, target in enumerate(plan.targets):
        slot = skill.slots[k] if skill is not None and k < len(skill.slots) else None
        implied = slot is not None and target.name == slot.word
        if not implied and not mentioned(target) and not (slot and any(w in said for w in slot.synonyms)):
            errors.append(f"the plan's target '{target.phrase}' is not mentioned in the instruction")
        if any(_same(target, o) for o in expected_obstacles) and not implied:
            errors.append(f"'{target.phrase}' is an obstacle in the instruction, not a task object")
        for attribute in ("color", "size", "position"):
            value = getattr(target, attribute)
            if value is None or value in said or value == "other":
                continue
            if not any(value in o.attributes for o in in_scene(target)):  # true of the scene object: no invention
                errors.append(f"the plan gives '{target.name}' the {attribute} '{value}', not said in the instruction")
    if reading is not None and reading.skill == plan.skill:
        for slot, ours, theirs in zip(skill.slots, reading.targets, plan.targets, strict=False):
            renamed = ours.name != theirs.name and not (slot.matches(ours.name) and slot.matches(theirs.name))
            lost = any(
                getattr(ours, a) and getattr(ours, a) != getattr(theirs, a) for a in ("color", "size", "position")
            )
            if renamed or lost:
                errors.append(f"the instruction says '{ours.phrase}', the plan '{theirs.phrase}'")
    elif reading is not None:
        warnings.append(f"the rules read '{reading.summary()}' here; the model chose '{plan.summary()}'")
    return CrossCheck(errors, warnings)
