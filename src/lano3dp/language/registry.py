"""Skill registry: which policies exist, the verbs that call them and the objects they observe.

A skill's `slots` are the object words its policy was trained on, in the order of the
`object_clouds` axis (`attrs["object_names"]` of its dataset). A plan's targets must fill
them in that order; `validate` enforces it so a decomposer (rules or LLM) cannot hand a
policy its objects swapped.

The built-in skills are not written here: each simulator task declares its own (`lano3dp.sim.tasks`), and
`default_registry` returns what sim installed with `set_default_skills`, since language never imports sim.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from lano3dp.language.exceptions import LanguageError, SlotMismatchError, UnknownObjectError, UnknownSkillError
from lano3dp.language.plan import TaskPlan
from lano3dp.vocabulary import COLOURS, SIZE_WORDS, SceneObject, resolve_phrase, singular


def _normalise_words(words: Iterable[str]) -> tuple[str, ...]:
    return tuple(dict.fromkeys(" ".join(w.lower().replace("_", " ").split()) for w in words))


class Slot(BaseModel):
    """One object a skill's policy observes.

    Attributes:
        word: the object word the policy was trained on (the dataset's object name).
        synonyms: other nouns that mean the same object ("skillet" for "pan"); include `word`.
        accepts_any: the slot takes any graspable object (e.g. "put an item in the drawer"); a noun
            that is no registered synonym still fills it and is kept as said.
        carried: the gripper carries this object through the skill (the bowl that is poured, not the
            drawer that is pulled), so obstacles must keep clear of its extent too (Q* of the guidance).
    """

    model_config = ConfigDict(frozen=True)

    word: str
    synonyms: tuple[str, ...] = ()
    accepts_any: bool = False
    carried: bool = False

    @field_validator("synonyms", mode="after")
    @classmethod
    def _with_word(cls, synonyms, info):
        return _normalise_words([info.data.get("word", ""), *synonyms])

    def matches(self, noun: str) -> bool:
        """Whether `noun` (possibly a compound like "frying pan") names this slot's object."""
        noun = " ".join(noun.lower().split())
        if noun in self.synonyms:
            return True
        head = singular(noun.split()[-1]) if noun else ""
        return head in self.synonyms or singular(noun) in self.synonyms


class SkillSpec(BaseModel):
    """A trained (or trainable) policy and how language refers to it.

    Attributes:
        name: registry key, also the simulator task name.
        description: one sentence, shown to the LLM.
        verbs: verb lemmas that ask for this skill, and phrasal verbs as "verb particle" ("pull out",
            "set upright"); the particle may come after the object ("pull the drawer out").
        slots: the ordered objects the policy observes.
        checkpoint: optional path to the trained policy folder.
    """

    model_config = ConfigDict(frozen=True)

    name: str
    description: str
    verbs: tuple[str, ...]
    slots: tuple[Slot, ...] = Field(min_length=1)
    checkpoint: Path | None = None

    @model_validator(mode="after")
    def _one_carried_slot(self):
        carried = [slot.word for slot in self.slots if slot.carried]
        if len(carried) > 1:
            raise ValueError(f"skill {self.name!r}: one gripper carries at most one object, got {carried}")
        return self

    @property
    def slot_words(self) -> tuple[str, ...]:
        return tuple(slot.word for slot in self.slots)

    @property
    def carried_slot(self) -> int | None:
        """Index of the slot whose object the gripper carries, or None (a pushed door, a pulled drawer)."""
        return next((k for k, slot in enumerate(self.slots) if slot.carried), None)


class SkillRegistry:
    """Skills by name, in a fixed order (the order ties are broken in)."""

    def __init__(self, skills: Iterable[SkillSpec]):
        self._skills: dict[str, SkillSpec] = {}
        for skill in skills:
            if skill.name in self._skills:
                raise ValueError(f"skill '{skill.name}' is registered twice")
            self._skills[skill.name] = skill

    def __iter__(self):
        return iter(self._skills.values())

    def __len__(self) -> int:
        return len(self._skills)

    def __contains__(self, name: str) -> bool:
        return name in self._skills

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self._skills)

    def get(self, name: str) -> SkillSpec:
        try:
            return self._skills[name]
        except KeyError:
            raise UnknownSkillError(name, self.names) from None

    def with_checkpoint(self, name: str, path: str | Path) -> SkillRegistry:
        """A copy where skill `name` points at a trained policy folder."""
        skill = self.get(name).model_copy(update={"checkpoint": Path(path)})
        return SkillRegistry(skill if s.name == name else s for s in self)

    def validate(self, plan: TaskPlan, scene_objects: SceneObjects | None = None) -> TaskPlan:
        """Check `plan` against the registry (and the scene, if given); returns it unchanged.

        Raises:
            UnknownSkillError: the skill is not registered.
            SlotMismatchError: wrong number of targets, or a target that names another slot's
                object (targets out of slot order).
            UnknownObjectError: with `scene_objects` (names such as "red_bowl", or a name -> attributes
                mapping such as `frame.instance_attributes`), a target or obstacle that matches none of them.
        """
        skill = self.get(plan.skill)
        got = plan.target_phrases
        if len(plan.targets) != len(skill.slots):
            raise SlotMismatchError(skill.name, skill.slot_words, got)
        for slot, target in zip(skill.slots, plan.targets, strict=True):
            if not slot.matches(target.name) and any(s.matches(target.name) for s in skill.slots if s is not slot):
                raise SlotMismatchError(skill.name, skill.slot_words, got)
        if scene_objects is not None:
            objects = scene_vocabulary(scene_objects)
            names = [o.name for o in objects]
            for role, refs in (("target", plan.targets), ("obstacle", plan.obstacles)):
                for ref in refs:
                    if not resolve_phrase(ref.phrase, objects):
                        raise UnknownObjectError(ref.phrase, names, role)
        return plan

    def to_json(self) -> str:
        return json.dumps([s.model_dump(mode="json") for s in self], indent=2)

    @classmethod
    def from_json(cls, text: str) -> SkillRegistry:
        return cls(SkillSpec.model_validate(entry) for entry in json.loads(text))

    @classmethod
    def load(cls, path: str | Path) -> SkillRegistry:
        """A registry JSON file; one that is not one (not JSON, a skill that does not validate) is a
        CorruptFileError naming the file."""
        from lano3dp.errors import CorruptFileError

        text = Path(path).read_text()
        try:
            return cls.from_json(text)
        except (ValueError, TypeError) as error:  # JSONDecodeError and pydantic's ValidationError are ValueErrors
            if not text.strip():
                what = "the file is empty"
            elif callable(getattr(error, "errors", None)):  # pydantic: the first problem, not a page of them
                problems = error.errors()
                first = problems[0]
                what = f"{'.'.join(map(str, first['loc'])) or 'entry'}: {first['msg']}" + \
                    (f" (and {len(problems) - 1} more)" if len(problems) > 1 else "")
            else:
                what = f"{type(error).__name__}: {error}"
            raise CorruptFileError(path, f"not a skill registry ({what})") from None


# What a caller may pass as "the scene": object names ("red_bowl", "pan"), a name -> attributes
# mapping (`RGBDFrame.instance_attributes`: {"item0": {"kind": "item", "color": "red"}}), or SceneObjects.
SceneObjects = Sequence[str] | Mapping[str, Mapping[str, str]] | Sequence[SceneObject]


def scene_vocabulary(scene_objects: SceneObjects) -> list[SceneObject]:
    """Scene objects from names, a name -> attributes mapping, or ready `SceneObject`s. Names alone
    carry only what they spell ("red_bowl": a red bowl); the mapping also knows "item0" is a red item."""
    if isinstance(scene_objects, Mapping):
        return [SceneObject.from_frame_entry(str(n), a) for n, a in scene_objects.items()]
    return [o if isinstance(o, SceneObject) else SceneObject.from_frame_entry(str(o), None) for o in scene_objects]


def describe_scene(scene_objects: SceneObjects) -> list[str]:
    """One line per object for prompts and messages: "item0 (red item)"."""
    out = []
    for obj in scene_vocabulary(scene_objects):
        ordered = sorted(obj.attributes, key=lambda w: (w not in SIZE_WORDS.values(), w not in COLOURS, w))
        words = " ".join([*ordered, *obj.kind])
        out.append(f"{obj.name} ({words})" if words and words != obj.name.replace("_", " ") else obj.name)
    return out


# The built-in skills are the simulator's tasks, and sim sits above language, so sim hands them down: importing
# lano3dp.sim.tasks installs its task-derived registry here. Language never imports sim (tests/test_layers.py).
_default_skills: Callable[[], SkillRegistry] | None = None


def set_default_skills(source: Callable[[], SkillRegistry]) -> None:
    """Make `source()` the registry `default_registry` returns (the simulator's tasks install theirs)."""
    global _default_skills
    _default_skills = source


def default_registry() -> SkillRegistry:
    """The default skills: the simulator's tasks (`lano3dp.sim.tasks.skill_registry`), once that package is imported.

    Raises:
        LanguageError: nothing installed them (only language was imported): import `lano3dp.sim.tasks`, use
            `lano3dp.OfflineDecomposer` (which does), or pass a `SkillRegistry` (`SkillRegistry.load(path)`).
    """
    if _default_skills is None:
        raise LanguageError(
            "no default skills: they are the simulator's tasks, installed when lano3dp.sim.tasks is imported; "
            "import it (or use lano3dp.OfflineDecomposer / LLMDecomposer, which do), or pass a SkillRegistry"
        )
    return _default_skills()
