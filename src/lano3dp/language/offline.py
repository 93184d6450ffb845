"""Offline instruction decomposer: rules over a verb lexicon and noun phrases, no model needed.

How an instruction is read (each step is a small function below):
1. Tokenise; find obstacle cues ("avoid", "without touching", "keep clear of", "watch out
   for", "X in the way", ...). Everything a cue governs, up to the next clause, is a list of
   obstacle noun phrases split on "and", "or" and commas.
2. In the rest, find verbs from the registry's lexicon and object nouns: registry slot words
   and synonyms (longest first, so "frying pan" beats "pan"), scene object kinds, and any head
   noun after a determiner ("the stapler"). Colour and size words in front become attributes.
3. Score each skill: 2 for a lexicon verb, 1 per slot filled by a synonym, 0.5 per wildcard
   fill, -1 per registry object noun the skill has no place for; the best skill wins (ties
   and scores under 2 are errors, not guesses).
4. Map nouns onto the winning skill's slots in slot order; a slot nobody mentioned gets its
   own word ("water the plant" -> watering can, plant), since the policy needs that object.

An optional `PhraseMatcher` (sentence embeddings) maps verbs and nouns the lexicon lacks onto
the registry and the scene; only the verb phrase is embedded, since whole-sentence embeddings
are dominated by the object nouns.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

from lano3dp.language.exceptions import InstructionNotUnderstoodError, UnknownObjectError
from lano3dp.language.plan import ObjectRef, TaskPlan
from lano3dp.language.registry import (
    SceneObjects,
    SkillRegistry,
    SkillSpec,
    Slot,
    default_registry,
    scene_vocabulary,
)
from lano3dp.perception.sim_oracle import COLOURS, SIZE_WORDS, canonical_attribute, resolve_phrase, singular

_WORD = re.compile(r"[a-z]+(?:'[a-z]+)?|[.,;:!?]")
_SENTENCE_END = frozenset(".;:!?")
DETERMINERS = frozenset(
    """the a an this that these those its my your our their his her some any another other both either each
    all two three four few several""".split()
)
# Words that end a noun phrase: prepositions, conjunctions, adverbs of place, pronouns.
_BOUNDARY = frozenset(
    """in into on onto over under from to with without of at by near next beside behind inside out up down
    off away back for using toward towards across through around while and or but then so that which who
    please again too there here it them is are be was were can could would will should if when before 's
    after until as not don't do does very now just also still nearby close somewhere""".split()
)
# Nouns that never name an object to look at.
_NON_OBJECTS = frozenset(
    """left right side top bottom middle front back edge corner table counter way time contents content
    water liquid soup stuff one ones area spot place workspace dirt dust crumb crumbs trash mess debris
    cork lid door what thing everything something nothing robot okay ok sure bit""".split()
)
_COLLISION_VERBS = frozenset(
    "touch hit bump knock disturb topple collide crash brush graze nudge move tip spill".split()
)
_PARTICLES = frozenset("over into against with on off".split())
_PRONOUN_PHRASES = (["it"], ["them"], ["that"], ["that", "one"], ["those"], ["this"], ["this", "one"])
_LIST_SEPARATORS = frozenset({"and", "or", ",", "nor", "plus"})
_CLAUSE_ENDS = frozenset({"then", "while", "but", "before", "after", "when", "so", "once", "until", "because"})
_POLITE = frozenset("please could would can will you robot okay ok now i need want to like kindly go ahead".split())

# Obstacle cues as token patterns; "<ing>" is any -ing word, "<hit>" a collision verb.
_CUES: tuple[tuple[str, ...], ...] = (
    ("avoid",), ("avoiding",), ("avoids",), ("around",), ("dodge",), ("dodging",),
    ("without", "<ing>"), ("careful", "not", "to", "<hit>"), ("careful", "of"), ("careful", "with"),
    ("careful", "around"), ("careful", "near"), ("watch", "out", "for"), ("look", "out", "for"),
    ("beware", "of"), ("mind",), ("clear", "of"), ("away", "from"), ("not", "to", "<hit>"),
    ("don't", "<hit>"), ("dont", "<hit>"), ("not", "<hit>"), ("never", "<hit>"),
)  # fmt: skip


def lemmas(word: str) -> set[str]:
    """Candidate base forms of an inflected verb or noun ("putting" -> put, "stored" -> store)."""
    forms = {word}
    if word.endswith("ing") and len(word) > 5:
        stem = word[:-3]
        forms |= {stem, stem + "e"}
        if len(stem) > 2 and stem[-1] == stem[-2]:
            forms.add(stem[:-1])
    if word.endswith("ed") and len(word) > 4:
        stem = word[:-2]
        forms |= {stem, stem + "e", word[:-1]}
        if len(stem) > 2 and stem[-1] == stem[-2]:
            forms.add(stem[:-1])
    if word.endswith("s") and len(word) > 3:
        forms |= {word[:-1], singular(word)}
    return forms


def _matches(pattern: str, word: str) -> bool:
    if pattern == "<ing>":
        return word.endswith("ing") and len(word) > 4
    if pattern == "<hit>":
        return bool(lemmas(word) & _COLLISION_VERBS)
    return pattern == word


class PhraseMatcher(Protocol):
    """The optional embedding matcher (`lano3dp.language.embeddings.MiniLMMatcher`)."""

    def best_match(self, query: str, candidates: Sequence[str]) -> tuple[int, float]:
        """Index of the candidate closest in meaning to `query`, and the cosine similarity."""
        ...


@dataclass
class _Noun:
    name: str
    color: str | None
    size: str | None
    known: bool  # a registry or scene word, not just a head noun after a determiner
    position: int = 0  # token index, to resolve "avoid it" to the object named before

    def ref(self, name: str | None = None) -> ObjectRef:
        return ObjectRef(name=name or self.name, color=self.color, size=self.size)


@dataclass
class Parse:
    """Intermediate reading of an instruction (exposed for debugging and tests)."""

    tokens: list[str]
    verbs: list[str] = field(default_factory=list)
    verb_phrase: str = ""
    nouns: list[_Noun] = field(default_factory=list)
    obstacles: list[ObjectRef] = field(default_factory=list)
    scores: dict[str, float] = field(default_factory=dict)
    pronoun_obstacles: list[int] = field(default_factory=list)  # token index of "avoid it"-style cues


class OfflineDecomposer:
    """Rule-based instruction -> TaskPlan.

    Args:
        registry: the skills to choose from (default: the simulator's tasks).
        matcher: optional `PhraseMatcher` for verbs and nouns outside the lexicon.
        match_threshold: minimum cosine similarity for a matcher hit.
    """

    def __init__(
        self,
        registry: SkillRegistry | None = None,
        matcher: PhraseMatcher | None = None,
        match_threshold: float = 0.6,
    ):
        self.registry = registry or default_registry()
        self.matcher = matcher
        self.match_threshold = match_threshold
        all_verbs = dict.fromkeys(v for s in self.registry for v in s.verbs)
        self._verbs = {verb: [s.name for s in self.registry if verb in s.verbs] for verb in all_verbs}
        self._vocabulary = sorted(
            {w for s in self.registry for slot in s.slots for w in slot.synonyms}, key=lambda w: -len(w.split())
        )

    # ---- public API -------------------------------------------------------------------------

    def decompose(self, instruction: str, scene_objects: SceneObjects | None = None) -> TaskPlan:
        """Plan for `instruction`; with `scene_objects` (names like "red_bowl", or a name -> attributes
        mapping such as `frame.instance_attributes`), objects are checked against (and synonyms mapped
        onto) the scene.

        Raises:
            InstructionNotUnderstoodError: no skill, or two equally likely skills.
            UnknownObjectError / SlotMismatchError: the plan does not fit the scene or the skill.
        """
        parse = self.parse(instruction, scene_objects)
        skill = self._choose_skill(instruction, parse)
        self._resolve_pronoun_obstacles(skill, parse)
        plan = TaskPlan(skill=skill.name, targets=self._fill_slots(skill, parse.nouns), obstacles=parse.obstacles)
        if scene_objects is not None:
            plan = self._ground_in_scene(plan, skill, scene_objects)
        return self.registry.validate(plan, scene_objects)

    def ground(self, plan: TaskPlan, scene_objects: SceneObjects) -> TaskPlan:
        """`plan` with targets and obstacles renamed to the scene's object kinds where a slot synonym
        (or the embedding matcher) says they mean the same ("skillet" -> the scene's "pan").

        Raises:
            UnknownSkillError: the plan's skill is not registered.
            UnknownObjectError: an object matches nothing in the scene.
        """
        skill = self.registry.get(plan.skill)
        if len(plan.targets) != len(skill.slots):
            return plan  # validation reports the count mismatch with the slot words
        return self._ground_in_scene(plan, skill, scene_objects)

    def parse(self, instruction: str, scene_objects: SceneObjects | None = None) -> Parse:
        words = []
        for word in _WORD.findall(instruction.lower().replace("’", "'")):
            # "bowl's" -> bowl 's, "there's" -> there 's: the noun stays a noun.
            words.extend([word[:-2], "'s"] if word.endswith("'s") and len(word) > 2 else [word])
        parse = Parse(tokens=words)
        task_mask = [True] * len(words)
        for start, end in self._obstacle_spans(words):
            if [w for w in words[start:end] if w not in _SENTENCE_END and w != ","] in _PRONOUN_PHRASES:
                parse.pronoun_obstacles.append(start)
            parse.obstacles.extend(self._noun_phrase_list(words[start:end]))
            for i in range(start, end):
                task_mask[i] = False
        for start, end, stop in self._in_the_way_spans(words):
            parse.obstacles.extend(self._noun_phrase_list(words[start:end]))
            for i in range(start, stop):
                task_mask[i] = False
        task = [w if keep else "," for w, keep in zip(words, task_mask, strict=True)]
        verb_positions = self._find_verbs(task, parse)
        scene_kinds = [" ".join(o.kind) for o in scene_vocabulary(scene_objects)] if scene_objects else []
        parse.nouns = self._find_nouns(task, verb_positions, scene_kinds)
        parse.obstacles = list(dict.fromkeys(parse.obstacles))
        return parse

    # ---- step 1: obstacles ------------------------------------------------------------------

    def _obstacle_spans(self, words: list[str]) -> list[tuple[int, int]]:
        """(start, end) token spans governed by obstacle cues."""
        spans, i = [], 0
        while i < len(words):
            cue = next((c for c in _CUES if self._cue_at(words, i, c)), None)
            if cue is None:
                i += 1
                continue
            start = i + len(cue)
            while start < len(words) and words[start] in _PARTICLES:
                start += 1
            end = start
            while end < len(words) and not self._clause_ends(words, end):
                end += 1
            spans.append((start, end))
            for j in range(i, start):
                words[j] = ","  # the cue words are not task words
            i = end
        return spans

    @staticmethod
    def _cue_at(words: list[str], i: int, cue: tuple[str, ...]) -> bool:
        return i + len(cue) <= len(words) and all(_matches(p, words[i + k]) for k, p in enumerate(cue))

    def _clause_ends(self, words: list[str], i: int) -> bool:
        word = words[i]
        if word in _SENTENCE_END or word in _CLAUSE_ENDS:
            return True
        if any(self._cue_at(words, i, c) for c in _CUES):
            return True
        # A lexicon verb right after "and" or a comma starts the next clause ("avoid the mug and pour ...").
        previous = words[i - 1] if i else ","
        return previous in ("and", ",") and bool(lemmas(word) & self._verbs.keys())

    @staticmethod
    def _in_the_way_spans(words: list[str]) -> list[tuple[int, int, int]]:
        """(start, end, stop): the noun phrase words[start:end] before "in the way" ("there is a mug in
        the way", "the mug is in the way"); words[start:stop] are not task words."""
        spans = []
        copulas = {"is", "are", "'s", "was", "were", "sits", "stands"}
        stops = _SENTENCE_END | _CLAUSE_ENDS | copulas | {","}
        for i in range(len(words) - 2):
            if words[i : i + 3] == ["in", "the", "way"]:
                end = i - 1 if i and words[i - 1] in copulas else i
                start = end
                while start > 0 and words[start - 1] not in stops:
                    start -= 1
                spans.append((start, end, i + 3))
        return spans

    def _noun_phrase_list(self, words: Sequence[str]) -> list[ObjectRef]:
        """Obstacle phrases from "the blue glass or the kettle, the can and the green box"."""
        refs, chunk = [], []
        for word in [*words, ","]:
            if word in _LIST_SEPARATORS or word in _SENTENCE_END:
                ref = self._chunk_to_ref(chunk)
                if ref is not None:
                    refs.append(ref)
                chunk = []
            else:
                chunk.append(word)
        return refs

    @staticmethod
    def _chunk_to_ref(chunk: Sequence[str]) -> ObjectRef | None:
        """'the small red coffee mug next to it' -> ObjectRef(name='coffee mug', color='red', size='small')."""
        color = size = None
        nouns: list[str] = []
        previous = ""
        for word in chunk:
            after_determiner = previous in DETERMINERS or previous in COLOURS or previous in SIZE_WORDS
            previous = word
            # A function word straight after "the" is a noun after all ("the can").
            if word in _BOUNDARY and not after_determiner:
                if nouns:
                    break
                continue
            if word in DETERMINERS:
                continue
            if word in COLOURS:
                color = canonical_attribute(word)
            elif word in SIZE_WORDS:
                size = canonical_attribute(word)
            elif word not in _NON_OBJECTS:
                nouns.append(word)
        if not nouns:
            return None
        nouns[-1] = singular(nouns[-1])
        return ObjectRef(name=" ".join(nouns), color=color, size=size)

    # ---- step 2: verbs and nouns ------------------------------------------------------------

    def _find_verbs(self, task: list[str], parse: Parse) -> set[int]:
        positions = set()
        for i, word in enumerate(task):
            hits = lemmas(word) & self._verbs.keys()
            if hits:
                # A lexicon word right after a determiner or adjective is a noun ("the water", "the base").
                previous = task[i - 1] if i else ","
                if previous in DETERMINERS or previous in COLOURS:
                    continue
                parse.verbs.append(sorted(hits)[0])
                positions.add(i)
        content = [w for w in task if w not in _POLITE and w not in _SENTENCE_END and w != ","]
        head = []
        for word in content:
            if word in DETERMINERS or word in COLOURS or word in SIZE_WORDS:
                break
            head.append(word)
        parse.verb_phrase = " ".join(head[:3])
        return positions

    def _find_nouns(self, task: list[str], verb_positions: set[int], scene_kinds: Sequence[str]) -> list[_Noun]:
        vocabulary = sorted(set(self._vocabulary) | set(scene_kinds), key=lambda w: -len(w.split()))
        nouns: list[_Noun] = []
        used = set(verb_positions)
        i = 0
        while i < len(task):
            match = None if i in used else self._vocabulary_match(task, i, vocabulary)
            if match is None:
                i += 1
                continue
            end = i + len(match.split())
            color, size = self._modifiers(task, i)
            nouns.append(_Noun(match, color, size, known=True, position=i))
            used.update(range(i, end))
            i = end
        # Unknown head nouns after a determiner ("the stapler") fill wildcard slots.
        for i, word in enumerate(task):
            if word not in DETERMINERS:
                continue
            chunk = []
            for j in range(i + 1, len(task)):
                if task[j] in _BOUNDARY or task[j] in _SENTENCE_END or task[j] == "," or j in verb_positions:
                    break
                chunk.append(j)
            if chunk and not used & set(chunk):
                ref = self._chunk_to_ref([task[j] for j in chunk])
                if ref is not None:
                    name = self._matcher_noun(ref.name, vocabulary) or ref.name
                    nouns.append(_Noun(name, ref.color, ref.size, known=name != ref.name, position=chunk[0]))
                    used.update(chunk)
        return sorted(nouns, key=lambda n: n.position)

    @staticmethod
    def _vocabulary_match(task: list[str], i: int, vocabulary: Sequence[str]) -> str | None:
        for entry in vocabulary:
            parts = entry.split()
            window = task[i : i + len(parts)]
            if len(window) == len(parts) and window[:-1] == parts[:-1] and parts[-1] in lemmas(window[-1]):
                return entry
        return None

    @staticmethod
    def _modifiers(task: list[str], i: int) -> tuple[str | None, str | None]:
        color = size = None
        j = i - 1
        while j >= 0 and (task[j] in COLOURS or task[j] in SIZE_WORDS):
            if task[j] in COLOURS:
                color = color or canonical_attribute(task[j])
            else:
                size = size or canonical_attribute(task[j])
            j -= 1
        return color, size

    def _matcher_noun(self, noun: str, vocabulary: Sequence[str]) -> str | None:
        if self.matcher is None or noun in _NON_OBJECTS:
            return None
        index, similarity = self.matcher.best_match(noun, list(vocabulary))
        return vocabulary[index] if similarity >= self.match_threshold else None

    # ---- step 3: skill ----------------------------------------------------------------------

    def _choose_skill(self, instruction: str, parse: Parse) -> SkillSpec:
        verb_skills = {name for verb in parse.verbs for name in self._verbs[verb]}
        if not verb_skills and self.matcher is not None and parse.verb_phrase:
            verb_skills = self._matcher_skills(parse.verb_phrase)
        evidence: dict[str, float] = {}
        for skill in self.registry:
            score = 2.0 if skill.name in verb_skills else 0.0
            assigned, unplaced = self._assign(skill, parse.nouns)
            score += sum(0.5 if wildcard else 1.0 for _, wildcard in assigned.values())
            score -= sum(1 for noun in unplaced if noun.known and not self._same_object(skill, noun, assigned))
            evidence[skill.name] = score
            # Ties go to the reading that leaves fewer objects implied ("set the bottle upright" needs no drawer).
            parse.scores[skill.name] = score - 0.25 * (len(skill.slots) - len(assigned))
        ranked = sorted(self.registry, key=lambda s: -parse.scores[s.name])
        best = ranked[0]
        if evidence[best.name] < 2.0:
            mentioned = ", ".join(n.name for n in parse.nouns) or "no known object"
            raise InstructionNotUnderstoodError(
                instruction,
                f"no skill fits (verbs: {', '.join(parse.verbs) or 'none'}; objects: {mentioned}); "
                f"known skills: {', '.join(self.registry.names)}",
            )
        if len(ranked) > 1 and parse.scores[ranked[1].name] == parse.scores[best.name]:
            raise InstructionNotUnderstoodError(
                instruction, f"it fits '{best.name}' and '{ranked[1].name}' equally; name the objects"
            )
        return best

    def _matcher_skills(self, verb_phrase: str) -> set[str]:
        verbs = list(self._verbs)
        index, similarity = self.matcher.best_match(verb_phrase, verbs)
        return set(self._verbs[verbs[index]]) if similarity >= self.match_threshold else set()

    @staticmethod
    def _assign(skill: SkillSpec, nouns: list[_Noun]) -> tuple[dict[int, tuple[_Noun, bool]], list[_Noun]]:
        """Slot index -> (noun, filled as wildcard); and the nouns left over."""
        assigned: dict[int, tuple[_Noun, bool]] = {}
        free = list(nouns)
        for k, slot in enumerate(skill.slots):
            noun = next((n for n in free if _exact(slot, n.name)), None) or next(
                (n for n in free if slot.matches(n.name)), None
            )
            if noun is not None:
                assigned[k] = (noun, False)
                free.remove(noun)
        for k, slot in enumerate(skill.slots):
            if k in assigned or not slot.accepts_any:
                continue
            noun = next((n for n in free if not any(s.matches(n.name) for s in skill.slots)), None)
            if noun is None:
                noun = next(iter(free), None)
            if noun is not None:
                assigned[k] = (noun, True)
                free.remove(noun)
        return assigned, free

    @staticmethod
    def _same_object(skill: SkillSpec, noun: _Noun, assigned: dict[int, tuple[_Noun, bool]]) -> bool:
        """A leftover noun that names an already filled slot again ("the bottle of wine")."""
        return any(skill.slots[k].matches(noun.name) for k in assigned)

    def _resolve_pronoun_obstacles(self, skill: SkillSpec, parse: Parse) -> None:
        """ "there's a vase nearby, avoid it": the object named last before the cue, if no slot took it."""
        for cue in parse.pronoun_obstacles:
            _, free = self._assign(skill, parse.nouns)
            before = [n for n in free if n.position < cue]
            if before:
                parse.nouns.remove(before[-1])
                parse.obstacles.append(before[-1].ref())

    # ---- step 4: slots and scene ------------------------------------------------------------

    def _fill_slots(self, skill: SkillSpec, nouns: list[_Noun]) -> list[ObjectRef]:
        assigned, _ = self._assign(skill, nouns)
        targets = []
        for k, slot in enumerate(skill.slots):
            if k not in assigned:
                targets.append(ObjectRef(name=slot.word))
                continue
            noun, wildcard = assigned[k]
            keep_own_name = wildcard or (slot.accepts_any and not _exact(slot, noun.name))
            targets.append(noun.ref(None if keep_own_name else slot.word))
        return targets

    def _ground_in_scene(self, plan: TaskPlan, skill: SkillSpec, scene_objects: SceneObjects) -> TaskPlan:
        """Rename targets and obstacles to scene kinds where the words differ but mean the same."""
        objects = scene_vocabulary(scene_objects)
        kinds = list(dict.fromkeys(" ".join(o.kind) for o in objects))

        def ground(ref: ObjectRef, slot: Slot | None, role: str) -> ObjectRef:
            if resolve_phrase(ref.phrase, objects):
                return ref
            options = [k for k in kinds if slot is not None and slot.matches(k)]
            if not options and self.matcher is not None:
                index, similarity = self.matcher.best_match(ref.name, kinds)
                options = [kinds[index]] if similarity >= self.match_threshold else []
            for kind in options:
                candidate = ref.model_copy(update={"name": kind})
                if resolve_phrase(candidate.phrase, objects):
                    return candidate
            raise UnknownObjectError(ref.phrase, [o.name for o in objects], role)

        targets = [ground(t, slot, "target") for t, slot in zip(plan.targets, skill.slots, strict=True)]
        obstacles = [ground(o, None, "obstacle") for o in plan.obstacles]
        return plan.model_copy(update={"targets": targets, "obstacles": obstacles})


def _exact(slot: Slot, noun: str) -> bool:
    return noun in slot.synonyms or singular(noun) in slot.synonyms
