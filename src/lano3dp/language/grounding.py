"""Grounding: a plan's phrases -> the objects a scene holds, never one object for another.

A target is found in the scene by its own words ("red bowl" -> the red bowl), or through a registered synonym of
its slot when the user said one ("dish" for the bowl slot finds the scene's bowl, "skillet" its frying pan): the
user's word and the scene's kind are then the same object by the registry's word. Anything else, such as a noun
the item slot accepts as said ("teapot") that the scene lacks, is an error naming the phrase and listing what
the scene holds; it is never replaced by the scene's object of that slot (the block), nor by a look-alike an
embedding matcher proposes. The user may map a phrase to a scene object explicitly (`mapping`).

Obstacles are grounded the same way. In the simulator's demo scenes the obstacle is a grey cylinder that stands
in for whatever the user named ("keep clear of the mug"); with `obstacle_stand_ins` a named obstacle the scene
lacks is replaced by the scene's obstacle objects (role "obstacle"), and a note says so. That never applies to a
target.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import NamedTuple

from lano3dp.language.exceptions import TargetNotInSceneError, UnknownObjectError
from lano3dp.language.plan import ObjectRef, TaskPlan
from lano3dp.language.registry import SceneObjects, SkillRegistry, Slot, describe_scene, scene_vocabulary
from lano3dp.vocabulary import SceneObject, resolve_phrase, singular, tokens


class GroundedPlan(NamedTuple):
    """plan: the plan with phrases renamed to the scene's words where a registered synonym (or the user's
    mapping) says they mean the same; obstacles: the phrases to segment as obstacles (stand-in object names
    where the scene's obstacle stands in); notes: what the user should be told (a mapping, a stand-in)."""

    plan: TaskPlan
    obstacles: list[str]
    notes: list[str]


def _exact(slot: Slot, noun: str) -> bool:
    return noun in slot.synonyms or singular(noun) in slot.synonyms


def _scene_roles(scene_objects: SceneObjects) -> dict[str, str]:
    if isinstance(scene_objects, Mapping):
        return {str(name): str((attributes or {}).get("role", "")) for name, attributes in scene_objects.items()}
    return {}


def ground_plan(
    plan: TaskPlan,
    scene_objects: SceneObjects,
    registry: SkillRegistry,
    *,
    mapping: Mapping[str, str] | None = None,
    obstacle_stand_ins: bool = False,
    matcher=None,
    match_threshold: float = 0.6,
) -> GroundedPlan:
    """Ground `plan` in `scene_objects` (names, a name -> attributes mapping such as
    `frame.instance_attributes`, or `SceneObject`s).

    Args:
        mapping: the user's explicit phrase -> scene object (name or kind) mapping, e.g. {"teapot": "block"}.
        obstacle_stand_ins: a named obstacle the scene lacks is replaced by the scene's objects of role
            "obstacle" (the simulator's demo scenes), with a note; without them it is an error.
        matcher: optional embedding matcher (`PhraseMatcher`) for obstacles only: a target is never matched
            by similarity.

    Raises:
        TargetNotInSceneError: a target the scene does not hold (by its words or a registered synonym).
        UnknownObjectError: an obstacle the scene does not hold and no stand-in is allowed or present.
    """
    objects = scene_vocabulary(scene_objects)
    described = describe_scene(scene_objects)
    kinds = list(dict.fromkeys(" ".join(o.kind) for o in objects if o.kind))
    mapping = {" ".join(k.lower().split()): v for k, v in (mapping or {}).items()}
    skill = registry.get(plan.skill) if plan.skill in registry else None
    notes: list[str] = []

    def mapped(ref: ObjectRef) -> ObjectRef | None:
        for key in (ref.phrase, ref.name):
            if key in mapping:
                target = mapping[key]
                if not resolve_phrase(target, objects):
                    raise UnknownObjectError(target, described, f"mapping of '{key}' to")
                notes.append(f"'{ref.phrase}' is mapped to the scene's '{target}', as asked")
                return ObjectRef(name=target)
        return None

    targets, target_objects = [], set()
    for k, target in enumerate(plan.targets):
        slot = skill.slots[k] if skill is not None and k < len(skill.slots) else None
        found = mapped(target) or _by_words_or_synonym(target, slot, objects, kinds)
        if found is None:
            raise TargetNotInSceneError(target.phrase, described)
        targets.append(found)
        target_objects.update(resolve_phrase(found.phrase, objects))

    obstacles, segment = [], []
    roles = _scene_roles(scene_objects)
    stand_ins = sorted(name for name, role in roles.items() if role == "obstacle")
    missing = []
    for obstacle in plan.obstacles:
        found = mapped(obstacle) or _by_words_or_synonym(obstacle, None, objects, kinds)
        if found is not None and set(resolve_phrase(found.phrase, objects)) <= target_objects:
            # "pour the mixing bowl ..., careful of the fruit bowl" in a scene with one bowl: the object to avoid is
            # not the one acted on, so it is not in this scene
            notes.append(f"obstacle '{obstacle.phrase}' is not the target of the same kind; the scene holds no other")
            found = None
        if found is None and matcher is not None and kinds:
            index, similarity = matcher.best_match(obstacle.name, kinds)
            candidate = obstacle.model_copy(update={"name": kinds[index]})
            if similarity >= match_threshold and resolve_phrase(candidate.phrase, objects):
                notes.append(f"obstacle '{obstacle.phrase}' read as the scene's '{candidate.phrase}' (similar words)")
                found = candidate
        if found is not None:
            obstacles.append(found)
            segment.append(found.phrase)
        elif obstacle_stand_ins and stand_ins:
            obstacles.append(obstacle)
            missing.append(obstacle.phrase)
        else:
            raise UnknownObjectError(obstacle.phrase, described, "obstacle")
    if missing:
        extra = [name for name in stand_ins if name not in segment]
        notes.append(
            f"{', '.join(repr(m) for m in missing)} not in the simulated scene; avoiding its obstacle object(s) "
            f"{', '.join(stand_ins)} instead (the demo scenes' stand-in for a named obstacle)"
        )
        segment += extra
    grounded = plan.model_copy(update={"targets": targets, "obstacles": obstacles})
    return GroundedPlan(grounded, segment, notes)


def _by_head(ref: ObjectRef, objects: list[SceneObject]) -> list[str]:
    """The objects `ref` names, read by the last noun of its name: a compound names a kind of its last noun ("the
    phone charger" is a charger, not the phone; "the mixing bowl" is a bowl)."""
    head = singular(ref.name.split()[-1]) if ref.name.split() else ""
    by_name = {o.name: o for o in objects}
    return [name for name in resolve_phrase(ref.phrase, objects) if by_name[name].kind[-1:] == (head,)
            or " ".join(ref.phrase.split()) == " ".join(tokens(name))]


def _by_words_or_synonym(
    ref: ObjectRef, slot: Slot | None, objects: list[SceneObject], kinds: list[str]
) -> ObjectRef | None:
    """`ref` if the scene has it by its words (renamed to the object's kind where another word of a compound is a
    scene kind too: "phone charger" -> "charger"); else `ref` renamed to a scene kind that is a registered synonym of
    the same slot as `ref`'s own noun or its compound's last noun; else None."""
    found = _by_head(ref, objects)
    if found:
        if found == resolve_phrase(ref.phrase, objects):
            return ref
        kind = " ".join(next(o.kind for o in objects if o.name == found[0]))
        return ref.model_copy(update={"name": kind})
    head = singular(ref.name.split()[-1]) if ref.name.split() else ""
    if slot is None or not (_exact(slot, ref.name) or _exact(slot, head)):
        return None  # a noun the slot merely accepts ("teapot" in the item slot) is never swapped for another
    for kind in kinds:
        if _exact(slot, kind):
            candidate = ref.model_copy(update={"name": kind})
            if resolve_phrase(candidate.phrase, objects):
                return candidate
    return None
