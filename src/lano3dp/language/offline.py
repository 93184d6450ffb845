"""Offline instruction decomposer: rules over a verb lexicon and noun phrases, no model needed.

How an instruction is read (each step is a small function below; docs/language.md says it for users):
0. Normalise and bound the text (`normalize`), tokenise, read typos and everyday verbs (`spelling`, each with a
   warning), find every object mention (`mentions`); move post-nominal positions in front ("the bowl on the
   left" -> "the left bowl"), resolve "one"-anaphora ("a red one" -> "a red bowl"), and take negated task
   clauses ("don't open the drawer") out of the task.
1. Find obstacle declarations: cues ("avoid", "without touching", "keep clear of", "watch out
   for", "but not", ...) govern the words up to the next clause; predicates ("X is in the way",
   "there is an X on the path", "X counts as an obstacle", "X must not be touched") govern the
   noun phrase they are said of. Either is a list of noun phrases split on "and", "or" and commas.
   A pronoun there ("avoid it", "the other one") is resolved after the skill is known, never to a
   target; words that name no object are a warning, a reference to nothing is a refusal.
2. In the rest, find verbs from the registry's lexicon (phrasal verbs too, with the particle
   anywhere in the clause: "pull the drawer out") and object nouns: registry slot words and
   synonyms (longest first, so "frying pan" beats "pan"), scene object kinds, and any head noun
   after a determiner ("the stapler"). Colour, size and position words in front become attributes.
3. Score each skill: 2 for a lexicon verb (+0.5 for a phrasal one), 1 per slot filled by a synonym, 0.5 per wildcard
   fill, -1 per registry object noun the skill has no place for; the best skill wins (ties
   and scores under 2 are errors, not guesses).
4. Map nouns onto the winning skill's slots in slot order; a slot nobody mentioned gets its
   own word ("water the plant" -> watering can, plant), since the policy needs that object.
   An obstacle that is one of the targets is a contradiction, refused ("put the bottle away without touching
   the bottle"), unless the cue asks for care ("pour the bowl, don't spill the bowl": a warning).
5. Refuse two tasks (clause verbs with no skill in common) and an instruction whose only task is negated or has
   no verb a skill is asked for with (never planned from its nouns alone; a verbless placement "block -> drawer"
   is read as "put", with a warning).
6. The safety invariant (`mentions.enforce_mentions`): every object named is a target or an obstacle.
7. With a scene, ground it (`grounding.ground_plan`): a target is never replaced by another object.

An optional `PhraseMatcher` (sentence embeddings) maps verbs and nouns the lexicon lacks onto
the registry and the scene; only the verb phrase is embedded, since whole-sentence embeddings
are dominated by the object nouns.
"""

from __future__ import annotations

import functools
import itertools
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

from lano3dp.language import spelling
from lano3dp.language.exceptions import (
    ContradictionError,
    InstructionNotUnderstoodError,
    NegatedCommandError,
    SeveralTasksError,
    UncertainObstacleError,
    UnknownVerbError,
)
from lano3dp.language.grounding import ground_plan
from lano3dp.language.mentions import (
    AFTER_STAND_VERB,
    CONTAINERS_OF,
    DESCRIBING,
    MATERIALS,
    NOT_OBJECTS,
    NUMBER_WORDS,
    PEOPLE,
    PROPERTY_WORDS,
    SUBJECT_VERBS,
    SWEEP_VERBS,
    UNITS,
    Mention,
    by_first_word,
    enforce_mentions,
    is_adjective,
    modal_can,
    named_in_passing,
    names_another,
    object_mentions,
    past_verb_form,
    permitted_spans,
    possessive,
    predicate_noun,
    same_participle,
    verb_lemmas,
    word_classes,
)
from lano3dp.language.normalize import normalize_instruction
from lano3dp.language.plan import MAX_NAME_CHARS, MAX_OBSTACLES, ObjectRef, TaskPlan
from lano3dp.language.registry import (
    SceneObjects,
    SkillRegistry,
    SkillSpec,
    Slot,
    default_registry,
    scene_vocabulary,
)
from lano3dp.vocabulary import COLOURS, OBJECT_NOUNS, SIZE_WORDS, canonical_attribute, singular

_WORD = re.compile(r"[a-z]+(?:'[a-z]+)?|[.,;:!?]")
_SENTENCE_END = frozenset(".;:!?")
_CLITICS = ("'s", "'re", "'m", "'ve", "'ll", "'d")  # "they're" -> they 're: the pronoun stays a pronoun
DETERMINERS = frozenset(
    """the a an this that these those its my your our their his her some any another both either each every
    all two three four five six seven eight nine ten few several many numerous various whichever""".split()
)
# Position words, kept as said; like colours they narrow which instance is meant ("the top drawer").
POSITION_WORDS = {
    w: w
    for w in """top upper uppermost topmost bottom lower lowest bottommost left leftmost right rightmost front
    frontmost back rear rearmost nearest closest farthest furthest centre center middle first second third
    last other""".split()
}
_MODIFIERS = COLOURS | SIZE_WORDS.keys() | POSITION_WORDS.keys()
# Words that end a noun phrase: prepositions, conjunctions, adverbs of place, pronouns.
_BOUNDARY = frozenset(
    """in into on onto over under from to with without of at by near next beside behind inside out up down
    off away back for using toward towards across through around while and or but then so that which who
    please again too there here it them is are be was were can could would will should must shall might if when
    before 's
    after until as not don't do does very now just also still nearby close somewhere past 're 'm 've 'll 'd can't
    cannot won't mustn't shouldn't""".split()
)
# Nouns that never name an object to look at.
_NON_OBJECTS = frozenset(
    """left right side top bottom middle front back edge corner table counter way time contents content
    water liquid soup stuff one ones area spot place workspace dirt dust crumb crumbs trash mess debris
    cork lid door what thing everything something nothing anything robot okay ok sure bit path route deal problem
    idea chance mistake distance space house home whatever things""".split()
) | UNITS
# Said where an object could be, naming none: "obstacles: none", "be a dear", "..., won't you?"
_TAGS = frozenset("none dear won't wouldn't isn't aren't".split())
_NON_OBJECTS = _NON_OBJECTS | _TAGS
_COLLISION_VERBS = frozenset(
    """touch hit bump knock disturb topple collide crash brush graze nudge move tip spill strike smash break
    jostle upset rattle scrape scratch damage push shove bang clip snag contact run go come splash soak drench
    wet scatter displace dislodge budge shift crush squash dent ruin wreck""".split()
)
# Places to set an object down that no skill puts things on.
_SURFACES = frozenset("table counter countertop worktop workbench floor ground side desk shelf surface".split())
_WISHES = (("i", "want"), ("i", "'d", "like"), ("i", "would", "like"), ("i", "need"))  # before a wanted placement
_PLACEMENT_MODALS = frozenset("needs need has have to should must can will ought".split())
_ROBOT_PARTS = frozenset("gripper grippers hand hands arm arms finger fingers elbow wrist claw".split())
_OWN_BODY = frozenset("your the its my yourself robot".split()) | _ROBOT_PARTS
_PHRASE_ENDS = frozenset(", and or from to near next beside away inside".split())
# What may follow a plural noun that heads a compound with a known object word ("toy cars all over the place").
_AFTER_PLURAL_HEAD = _PHRASE_ENDS | frozenset("all around everywhere nearby are must have on in by".split())
# Adjectives that place an object relative to others, never part of its name.
_RELATIONAL_ADJECTIVES = frozenset("neighbouring neighboring adjacent nearby".split())
_PERSONAL_PRONOUNS = frozenset("i you we he she they me him us myself yourself ourselves itself themselves".split())
# Words after an object word that are not the head of a compound with it ("water the plant today").
_NOT_HEADS = frozenset(
    "today tonight tomorrow again first too also instead yet still already soon later quick fast asap pronto".split()
)
_PARTICLES = frozenset("over into against with on off near to close next too by past around of".split())
_PRONOUNS = {
    ("it",): "it", ("that",): "it", ("this",): "it", ("that", "one"): "it", ("this", "one"): "it",
    ("them",): "them", ("those",): "them", ("these",): "them", ("they",): "them", ("both",): "them",
    ("the", "other"): "other", ("the", "other", "one"): "other", ("the", "others"): "other",
    ("the", "other", "ones"): "other", ("other",): "other", ("others",): "other", ("the", "rest"): "other",
}  # fmt: skip
_LIST_SEPARATORS = frozenset({"and", "or", ",", "nor", "plus"})
_CLAUSE_ENDS = frozenset({"then", "while", "but", "before", "after", "when", "so", "once", "until", "because"})
_DONE = frozenset("done finished over through complete completed ready".split())
_POLITE = frozenset(
    "please could would can will you robot okay ok now i need want to like kindly go ahead hey hi hello um uh yo"
    .split()
)
# Hesitations and chat shorthand: no word of the task ("don't hit the lamp lol" names a lamp)
_FILLERS = frozenset("um umm uh uhm er erm hmm lol lmao rofl thx ty pls plz rn btw tbh idk omg".split())
_COUNT_MARK = re.compile(r"\b\d+\s?x\b|\bx\s?\d+\b", re.IGNORECASE)
_CHAT_WORDS = {"n": "and", "u": "you", "ur": "your", "r": "are", "thru": "through", "da": "the", "teh": "the",
               "abt": "about", "tho": "though", "cn": "can", "bc": "because", "cuz": "because", "coz": "because"}
_COPULAS = frozenset("is are 's 're 'm was were be been being sits sit stands stand lies lie".split())
_PLURAL_COPULAS = frozenset("are 're were sit stand lie".split())
_WARNINGS = frozenset("careful caution warning attention heads".split())
_STANCE = frozenset("sitting standing lying placed located resting positioned kept".split())
_MEASURE = re.compile(r"\b\d+(?:[.,]\d+)?\s*(?:" + "|".join(sorted(map(re.escape, UNITS), key=len, reverse=True))
                      + r")\b", re.IGNORECASE)
_LIST_NUMBER = re.compile(r"(?:^|(?<=\s))\(?\d{1,2}[.)](?=\s)")
_STANCE_VERBS = frozenset("hang hangs sit sits lie lies rest rests lean leans".split())
_STANCE_PLACES = frozenset("over above on in near next beside behind under below by from against across".split())
# Words before a noun that make it a landmark ("the drawer under the microwave"), not a task object.
_LOCATIVES = frozenset("next near beside behind under below beneath above by besides opposite of close past".split())
# After "right", these make it an adverb of place or time, not the verb of bottle_upright.
_RIGHT_AS_ADVERB_BEFORE = _LOCATIVES | frozenset("there here now away in on at into onto in front after up".split())
# Verbs any manipulation can be said with; a skill that owns none of the others was not asked for.
_GENERIC_VERBS = frozenset("put place set move take get bring transfer drop rest return raise fill".split())
# Negation of a task verb: "don't / never VERB", "do not / try not to VERB" (issue 34: a negated command is refused).
# Verbs of abstaining are negators too ("refrain from putting", "skip opening", "no need to sweep", "you needn't
# open", "hold off on pouring"): each only when a task verb follows, so "skip the red block" is no negation.
_NEGATORS = frozenset(
    """don't dont didn't didnt doesn't doesnt won't wont wouldn't wouldnt never cannot can't cant shouldn't shouldnt
    mustn't mustnt needn't neednt refrain skip stop quit cease abstain forget""".split()
)
_ABSTAIN_VERBS = frozenset("refrain skip stop quit cease abstain forget".split())
# "I'd rather not open ...", "I'd prefer you did not open ..."
# ... and advice against it: "it's best not to open ...", "it would be wiser not to pour ..."
_NOT_AFTER = frozenset(
    "do does did please must should try better need rather would will could can shall best wiser wise safer safest"
    " smarter advisable idea prudent".split()
)
_NEGATION_FILLER = frozenset(
    "you ever even please try to go and just accidentally dare want need wish from on with bother bothering about mind"
    " necessary needed required"
    .split()
)
_NEGATING_BEFORE = {"no": "need", "off": "hold"}  # "no need to ...", "hold off on ...": the word and the one before
_DESTINATIONS = frozenset("in into inside onto on".split())
# Cue words that ask for care with an object rather than distance from it: said of a target they are no
# contradiction ("pour the bowl, don't spill it"); "avoid" or "don't touch" said of a target is one.
_CARE_WORDS = frozenset(
    """spill drop break damage scratch smash crack dent tip topple upset knock tilt shake crush fragile delicate
    hot breakable sharp precious valuable wobbly unstable expensive careful caution gently mind fall roll wobble
    tumble shatter""".split()
)
_NEGATIONS = frozenset("not never no without don't dont".split())  # in a cue, before what not to do
_PARTS = frozenset("handle rim edge spout lid neck knob cap side corner top bottom".split())  # of the object said
# Verbs that say an object may fall ("the bowl might tip"): said of it, it is an obstacle as "fragile" makes it.
_UNSTEADY_VERBS = frozenset("tip topple fall wobble tumble break shatter crack roll".split())
_DEGREE = frozenset("very quite really extremely super so too rather a bit".split())
# What may stand between a clause break and its verb ("and then carefully pour").
_CLAUSE_OPENERS = frozenset(
    "please now then also just carefully gently slowly first next finally go ahead and to you before after once when"
    .split()
)
_TASK_BREAKS = frozenset(". ; : ! ? , and then also plus afterwards".split())
_SEQUENCE_OPENERS = frozenset({("after", "that"), ("after", "this"), ("after", "which"), ("once", "done")})
# Between a passive's subject and "be": "is to", "should", "must not", "needs to", "shall", ...
_PASSIVE_MODALS = frozenset(
    "is are to should must shall needs need has have ought will would can could not never also please".split()
)
_STATE_WORDS = frozenset("open shut closed upright".split())
_PERMITTING = frozenset(
    (w, "to") for w in "allowed permitted ok okay fine alright free".split()
)  # "it is allowed to move the box": before a contact verb, a permission
_NEAR_WORDS = frozenset("to of front top in on adjacent right just".split())  # "right next to it", "on top of it"
_NARRATORS = frozenset("i he she they we someone somebody".split())  # subjects of what was done, never "you"
# A state asked for with "ensure ... is": the skill's verb that makes it ("ensure the bottle is upright").
_ENSURED_STATES = {"open": ("open",), "shut": ("shut",), "upright": ("stand", "upright")}
_KEEPING = frozenset("leave left leaving leaves keep kept keeping keeps found find".split())
_WANTING = frozenset("need needs want wants get have like".split())  # "I need the bottle standing up"
_STATES_AFTER = frozenset("wet dry hot cold open closed shut empty full dirty clean broken cracked upright".split())
_CLAUSE_CLOSE = frozenset(", . ; ! ? and but so".split())
_UNNEEDED = frozenset("necessary needed required".split())  # "... won't be necessary"
_NOT_NEEDED = frozenset("not isn't won't wont no never".split())
_MODALS_AFTER_SUBJECT = frozenset("could would can will might may should".split())
_RISK_MODALS = _MODALS_AFTER_SUBJECT - {"should"}  # "the bowl might tip" says what may happen
_WANTING_DONE = frozenset("need needs want wants like".split())  # "I'd like the drawer opened"
_CAUSATIVES = frozenset("get have".split())  # "get the plant watered": the object, then what is done
_DISCOURSE = frozenset("actually anyway though however well instead rather sorry oops little one".split())
_REMAIN_VERBS = frozenset("stay stays stayed staying remain remains remained".split())
_STATE_ADVERBS = frozenset("all already still now just not almost nearly half wide".split())
# Words between a subject and its predicate ("the mug and the cup are all in the way").
_SUBJECT_SKIPS = frozenset(
    "also still currently right now just all both each looks seems look seem to remain remains stay stays".split()
)  # "the green block is to remain untouched"
_COMPOUND_MODIFIERS = frozenset("water table counter trash soup door lid coffee tea wine house home".split())
_DETACHABLE = frozenset("lid cap cork cover case stopper".split())  # parts that come off: objects of their own
_MAX_COMPOUND = 3  # words of an object's name: "small red coffee mug" has two, "watering can" two
_QUANTIFIED = frozenset("any all each every either none both neither".split())  # "any of them"

# Obstacle cues as token patterns; "<ing>" is any -ing word, "<hit>" a collision verb, "<det>" a determiner.
_CUES: tuple[tuple[str, ...], ...] = (
    ("avoid",), ("avoiding",), ("avoids",), ("around",), ("dodge",), ("dodging",),
    ("without", "<ing>"), ("no", "<ing>"), ("careful", "not", "to", "<hit>"), ("careful", "of"),
    ("careful", "with"), ("careful", "around"), ("careful", "near"), ("careful", "for"), ("watch", "out", "for"),
    ("look", "out", "for"), ("beware", "of"), ("mind",), ("clear", "of"), ("away", "from"),
    ("distance", "from"), ("far", "from"), ("nowhere", "near"), ("not", "to", "<hit>"), ("don't", "<hit>"),
    ("dont", "<hit>"), ("not", "<hit>"), ("never", "<hit>"), ("but", "not"), ("and", "not"),
    ("not", "near"), ("not", "close", "to"), ("not", "<det>"), ("watch", "<det>"),
    ("skip", "<det>"),  # "skip the red block and put the blue one in ...": left alone, so avoided
    ("not", "on", "<det>"), ("not", "in", "<det>"), ("not", "into", "<det>"), ("not", "onto", "<det>"),
    ("not", "inside", "<det>"),  # "on the white base, not on the black one": the other place is avoided
    ("don't", "get"), ("dont", "get"), ("not", "get"), ("never", "get"),  # "don't get it wet"
    ("keep", "off"), ("stay", "off"), ("keeping", "off"), ("staying", "off"),
)  # fmt: skip
# Checked at every token: only the cues that start with the token's word (every cue starts with a word, not a class).
_CUES_BY_FIRST = by_first_word(_CUES)
_CONTRASTS = frozenset({("not", "<det>"), ("but", "not"), ("and", "not")}) | {
    c for c in _CUES if c[0] == "not" and c[-1] == "<det>"}
# Predicates said of the noun phrase before them ("the mug is in the way").
_WAY_MARKERS: tuple[tuple[str, ...], ...] = (
    ("in", "the", "way"), ("in", "my", "way"), ("in", "your", "way"), ("in", "its", "way"),
    ("in", "the", "path"), ("on", "the", "path"), ("in", "the", "robot", "'s", "way"), ("on", "the", "route"),
    ("blocking",), ("blocks",), ("obstructing",), ("obstructs",), ("untouched",),
    ("must", "not", "be", "<hit>"), ("mustn't", "be", "<hit>"), ("should", "not", "be", "<hit>"),
    ("shouldn't", "be", "<hit>"), ("not", "to", "be", "<hit>"), ("can't", "be", "<hit>"), ("cannot", "be", "<hit>"),
)  # fmt: skip
_OBSTACLE_NOUNS = frozenset("obstacle obstacles obstruction obstructions hazard hazards".split())
# Words between a subject and "obstacle" ("the lamp counts as an obstacle", "treat the lamp as one").
_PREDICATE_FILLER = frozenset(
    "a an as one the is are 's be was were counts count acts act serves serve considered treated regarded also "
    "both all just like another".split()
)
# Words a subject noun phrase never reaches back over.
_SUBJECT_STOPS = (
    _SENTENCE_END | _CLAUSE_ENDS | _COPULAS | frozenset(
        """there treat consider regard mark note remember know see notice think careful that with in into on onto
        from to at by near next beside behind under over inside through toward towards for if""".split()
    )
)  # fmt: skip


def tokenize(text: str) -> list[str]:
    """Lower-case words and punctuation; "bowl's" -> bowl 's, "there's" -> there 's (the noun stays a noun)."""
    words = []
    text = re.sub(r"\s[-–—]+\s|[–—]", " , ", text)  # a dash between words breaks the clause like a comma
    text = re.sub(r"\b(left|right)-hand(ed)?\b", r"\1", text.lower().replace("’", "'"))  # "the left-hand drawer"
    text = re.sub(r"\b([a-z]+s)'(?= [a-z])", r"\1's", text)  # "the kids' toys": a plural owner, as "the kid's toys"
    text = re.sub(r"\b(there|here)s\b", r"\1's", text)  # "theres a mug": typed without the apostrophe
    text = re.sub(r"\bits (fine|ok|okay|alright|allowed|been|not|just|gonna|always|still|too|so)\b", r"it's \1",
                  text)  # "its fine if you bump it", "its been open all day": typed without the apostrophe
    text = re.sub(r"\bthats (fine|ok|okay|alright|allowed|not|good|great)\b", r"that's \1", text)
    for word in _WORD.findall(text):
        ending = next((e for e in _CLITICS if word.endswith(e) and len(word) > len(e)), None)
        words.extend([word[: -len(ending)], ending] if ending else [word])
    return words


@functools.lru_cache(maxsize=8192)
def lemmas(word: str) -> frozenset[str]:
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
    return frozenset(forms)


def _matches(pattern: str, word: str) -> bool:
    if pattern == "<ing>":
        return word.endswith("ing") and len(word) > 4
    if pattern == "<hit>":
        return bool(lemmas(word) & _COLLISION_VERBS)
    if pattern == "<det>":
        return word in DETERMINERS
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
    index: int = 0  # token index, to resolve "avoid it" to the object named before
    end: int = 0  # token index after its words (its words: index to end)
    position: str | None = None
    in_task: bool = True  # said in a sentence with a lexicon verb, not in "there are two bowls."
    declared: bool = False  # the subject of "there's a bowl ..." or "the bowl is ...": said to be there, not acted on
    landmark: bool = False  # after "next to", "under", ...: where something is, not what to act on
    destination: bool = False  # after "into" / "onto": where the carried object goes
    source: bool = False  # after "from", "out of", "off": where something is taken from
    compound: str | None = None  # nouns typed before a known one that name its kind: "mixing" in "mixing bowl"
    permitted: bool = False  # the user lets it be touched ("the stapler can be moved"): a target only as a last resort

    def ref(self, name: str | None = None) -> ObjectRef:
        """The object as said (its compound too: "cat toy"), or named `name`."""
        said = f"{self.compound} {self.name}" if self.compound else self.name
        said = " ".join(said.split()[-_MAX_COMPOUND:])  # "put bowl bowl bowl ...": no name is a run of words
        return ObjectRef(name=name or said, color=self.color, size=self.size, position=self.position)


@dataclass(frozen=True)
class _Reference:
    """A pronoun in an obstacle declaration ("avoid it", "the other one"), resolved once the skill is known."""

    index: int
    kind: str  # "it" (one object), "them" (all), "other" (the one that is not the target)
    text: str  # the declaration as said, for messages


@dataclass
class Parse:
    """Intermediate reading of an instruction (exposed for debugging and tests)."""

    tokens: list[str]
    verbs: list[str] = field(default_factory=list)
    verb_phrase: str = ""
    nouns: list[_Noun] = field(default_factory=list)
    obstacles: list[ObjectRef] = field(default_factory=list)
    scores: dict[str, float] = field(default_factory=dict)
    references: list[_Reference] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    declared: list[tuple[int, ObjectRef]] = field(default_factory=list)  # (token index, obstacle) as declared
    cue_of: dict[ObjectRef, str] = field(default_factory=dict)  # obstacle -> the cue that declared it
    mentions: list[Mention] = field(default_factory=list)  # every object named (mentions.object_mentions)
    negated: list[str] = field(default_factory=list)  # negated task clauses ("don't open the drawer")
    negated_verbs: list[tuple[str, str]] = field(default_factory=list)  # (lexicon verb, the word after its object)
    verb_at: list[tuple[int, str]] = field(default_factory=list)  # (token index, verb) of task verbs


class OfflineDecomposer:
    """Rule-based instruction -> TaskPlan.

    Args:
        registry: the skills to choose from (default: `default_registry()`, the simulator's tasks).
        matcher: optional `PhraseMatcher` for verbs and nouns outside the lexicon.
        match_threshold: minimum cosine similarity for a matcher hit.
    """

    def __init__(
        self,
        registry: SkillRegistry | None = None,
        matcher: PhraseMatcher | None = None,
        match_threshold: float = 0.6,
    ):
        self.registry = _with_shared_synonyms(registry or default_registry())
        self.matcher = matcher
        self.match_threshold = match_threshold
        all_verbs = dict.fromkeys(v for s in self.registry for v in s.verbs)
        self._verbs = {verb: [s.name for s in self.registry if verb in s.verbs] for verb in all_verbs}
        self._single_verbs = {v for v in self._verbs if " " not in v}
        self._phrasal = [tuple(v.split()) for v in self._verbs if " " in v]
        self._vocabulary = sorted(
            {w for s in self.registry for slot in s.slots for w in slot.synonyms}, key=lambda w: -len(w.split())
        )
        # Every word the rules read, so the spelling corrector leaves it alone.
        self._known_words = (
            DETERMINERS | POSITION_WORDS.keys() | _MODIFIERS | _BOUNDARY | _NON_OBJECTS | _COLLISION_VERBS
            | _PARTICLES | _POLITE | _COPULAS | _WARNINGS | _STANCE | _LOCATIVES | _GENERIC_VERBS | _OBSTACLE_NOUNS
            | _PREDICATE_FILLER | PROPERTY_WORDS | _CARE_WORDS | OBJECT_NOUNS | _NEGATORS
            | {w for cue in (*_CUES, *_WAY_MARKERS) for w in cue} | {w for v in self._verbs for w in v.split()}
            | {w for entry in self._vocabulary for w in entry.split()}
        )  # fmt: skip
        self._object_words = OBJECT_NOUNS | {w for entry in self._vocabulary for w in entry.split()}

    # ---- public API -------------------------------------------------------------------------

    def decompose(self, instruction: str, scene_objects: SceneObjects | None = None) -> TaskPlan:
        """Plan for `instruction`; with `scene_objects` (names like "red_bowl", or a name -> attributes
        mapping such as `frame.instance_attributes`), objects are checked against (and synonyms mapped
        onto) the scene. What the parser was unsure of is in `plan.warnings`.

        Raises:
            InstructionNotUnderstoodError: no skill, or two equally likely skills.
            UncertainObstacleError: an obstacle declaration refers to nothing ("avoid it" with nothing
                named before).
            UnknownObjectError / SlotMismatchError: the plan does not fit the scene or the skill.
        """
        parse = self.parse(instruction, scene_objects)
        _refuse_question(instruction, parse)
        _refuse_cancelled(instruction, parse.tokens)
        self._check_one_task(instruction, parse)
        skill = self._choose_skill(instruction, parse)
        taken_back = [
            v for v, said_of in parse.negated_verbs if skill.name in self._verbs.get(v, ())
            and (said_of in ("it", "that", "this", "them") or any(_exact(slot, said_of) for slot in skill.slots))
        ]  # not "open the drawer but don't open the bottle"
        if taken_back:  # "open the bottle -- actually no, don't open it": asked for and taken back
            raise NegatedCommandError(
                instruction, f"it asks for {skill.name} and also not to '{taken_back[0]}'; say which is meant")
        self._check_fit(instruction, skill, parse)
        self._resolve_references(instruction, skill, parse)
        targets, target_nouns = self._fill_slots(skill, parse.nouns)
        _check_pronoun_object(instruction, skill, parse, target_nouns)
        _check_outcome(instruction, skill, parse.tokens, target_nouns)
        # the word each target was named with, where it is one of its slot's words (not "the stapler")
        typed = {k: noun.name for k, noun in target_nouns.items() if _exact(skill.slots[k], noun.name)}
        obstacles = self._drop_targets(instruction, skill, targets, parse, typed)
        _check_obstacle_count(instruction, obstacles)
        plan = TaskPlan(skill=skill.name, targets=targets, obstacles=obstacles, warnings=parse.warnings)
        # a mention among a target's own words is that target ("the remote control", "the rubber duck")
        target_words = {i for noun in target_nouns.values() for i in range(noun.index, max(noun.end, noun.index + 1))}
        mentions = [m for m in parse.mentions if m.index not in target_words]
        plan = enforce_mentions(plan, mentions, skill, self.registry, typed)
        _check_obstacle_count(instruction, plan.obstacles)
        if scene_objects is not None:
            plan = self.ground(plan, scene_objects)
        return self.registry.validate(plan, scene_objects)

    def ground(self, plan: TaskPlan, scene_objects: SceneObjects) -> TaskPlan:
        """`plan` with targets and obstacles renamed to the scene's object kinds where a registered slot synonym
        says they mean the same ("skillet" -> the scene's "pan"); never one object for another
        (`lano3dp.language.grounding.ground_plan`).

        Raises:
            UnknownSkillError: the plan's skill is not registered.
            TargetNotInSceneError: a target the scene does not hold.
            UnknownObjectError: an obstacle matches nothing in the scene.
        """
        skill = self.registry.get(plan.skill)
        if len(plan.targets) != len(skill.slots):
            return plan  # validation reports the count mismatch with the slot words
        grounded = ground_plan(plan, scene_objects, self.registry, matcher=self.matcher,
                               match_threshold=self.match_threshold)
        return grounded.plan.model_copy(update={"warnings": [*grounded.plan.warnings, *grounded.notes]})

    def skills_asked_for(self, parse: Parse) -> set[str]:
        """Skills the task verbs of `parse` ask for (with the embedding matcher, also its reading of the verb)."""
        skills = {name for verb in parse.verbs for name in self._verbs[verb]}
        if not skills and self.matcher is not None and parse.verb_phrase:
            skills = self._matcher_skills(parse.verb_phrase)
        return skills

    def parse(self, instruction: str, scene_objects: SceneObjects | None = None) -> Parse:
        """The intermediate reading of `instruction` (normalised first: `normalize.normalize_instruction`).

        Raises:
            InputRejectedError: the text is refused before it is read (too long, mixed scripts, ...).
        """
        normalized = normalize_instruction(instruction)
        text = _COUNT_MARK.sub(" ", normalized.text)  # "1x block", "mug x2": a count, not an "x block"
        # "the 2 litre jug", "8 cm to the right": a measure says how much, never what (the tokens drop its digits,
        # and a unit left alone names a kind: "the pint glass", "the foot pump")
        text = _MEASURE.sub(" ", text)
        text = _LIST_NUMBER.sub(" ; ", text)  # "1) close the microwave 2) stand the bottle": numbered steps
        text = re.sub(r"\b(lay|laying|lays|put|putting) a finger on\b", lambda m: "touching" if m.group(1).endswith(
            "ing") else "touch", text, flags=re.IGNORECASE)  # an idiom of touching
        text = re.sub(r"\s*(?:->|=>|-->|→)\s*", " into ", text)  # "block -> drawer": shorthand for "into"
        text = re.sub(r"\bon (?:its|their) feet\b", "upright", text, flags=re.IGNORECASE)  # "back on its feet"
        # "the bottle that's / thats on the left": a relative clause saying where, as "that is" says it
        text = re.sub(r"\b(that|which)(?:'s|s) (?=(?:on|in|at|by|near|next|behind|beside|under|closest|nearest)\b)",
                      r"\1 is ", text, flags=re.IGNORECASE)
        tokens = tokenize(text)
        words = [_CHAT_WORDS.get(w, w) for w in _without_disfluencies(tokens)]
        scene_kinds = [" ".join(o.kind) for o in scene_vocabulary(scene_objects)] if scene_objects else []
        vocabulary = sorted(set(self._vocabulary) | set(scene_kinds), key=lambda w: -len(w.split()))
        # a capitalised word inside a sentence is a name ("Sam, wait"), never a typo of a verb or an object
        names = {w.lower() for w in re.findall(r"(?<![.!?;:]\s)(?<!^)(?<=\s)[A-Z][a-z]+\b", text)}
        words, read_as = self._read_words(words, vocabulary, names)
        words = _colour_phrases(_quantities(_partitives(_self_repairs(words, self._is_task_verb))))
        words = self._passive_requests(_polite_requests(_own_body(words)))
        words = _front_positions(_declared_placements(_contact_cues(words)))
        words, shorthand = self._shorthand_placements(words, vocabulary)
        read_as += shorthand
        words = _appositives(_colour_lists(words))
        words = self._resolve_one_anaphora(words, vocabulary)  # first: "leave the green one" names a green bowl
        unresolved = next((i for i, w in enumerate(words) if w in ("one", "ones") and i >= 2 and words[i - 1] in (
            COLOURS | SIZE_WORDS.keys()) and words[i - 2] in DETERMINERS), None)
        if unresolved is not None:  # "put the pink one on the base": never any phone for the pink one
            raise InstructionNotUnderstoodError(
                instruction, f"'{' '.join(words[unresolved - 2 : unresolved + 1])}' refers to no object named before "
                "it; name the object")
        mentions = object_mentions(words, [*self._vocabulary, *scene_kinds], self._single_verbs)
        parse = Parse(tokens=list(words), warnings=[*normalized.warnings, *read_as], mentions=mentions)
        self._mask_negated(words, parse)
        task_mask = [True] * len(words)
        spans = [(start, end, start, end, cue) for start, end, cue in self._obstacle_spans(words)]
        spans += self._predicate_spans(words)
        for start, end, mask_start, mask_stop, cue in sorted(spans):
            self._read_declaration(words, start, end, cue, parse)
            for i in range(mask_start, mask_stop):
                task_mask[i] = False
        task = [w if keep else "," for w, keep in zip(words, task_mask, strict=True)]
        verb_positions = self._find_verbs(task, parse)
        parse.nouns = self._find_nouns(task, verb_positions, vocabulary)
        sentence = _running_count(words, _SENTENCE_END)  # sentence index of each token
        with_verb = {sentence[i] for i in verb_positions}
        previous_noun = None
        for noun in parse.nouns:
            noun.in_task = not with_verb or sentence[noun.index] in with_verb
            k = noun.index - 1
            while k >= 0 and (task[k] in DETERMINERS or task[k] in _MODIFIERS) and not _nearest_to(task, k):
                k -= 1
            locative = k >= 0 and task[k] in _LOCATIVES | {"to"} and (task[k] != "to" or task[k - 1] in _LOCATIVES)
            noun.landmark = locative or (k >= 0 and _nearest_to(task, k))
            noun.destination = k >= 0 and task[k] in ("into", "onto")
            noun.source = k >= 0 and (task[k] in ("from", "off") or (task[k] == "of" and task[k - 1 : k] == ["out"]))
            existential = task[k] == "theres" if k >= 0 else False
            existential = existential or (k >= 1 and task[k] in _COPULAS and task[k - 1] == "there")
            noun.declared = existential or (noun.end < len(task) and task[noun.end] in _COPULAS | _STANCE_VERBS)
            # "the red watering can leaks, use the blue one": a clause that only says how a thing is
            said_how = noun.end < len(task) and task[noun.end] in SUBJECT_VERBS
            noun.declared = noun.declared or (said_how and (task[noun.end + 1 : noun.end + 2] or ["."])[0] in (
                _CLAUSE_CLOSE))
            if k >= 0 and task[k] in ("and", "or") and previous_noun is not None and previous_noun.landmark:
                noun.landmark = True  # "past the mug and the jar": both are landmarks
            if not noun.declared and (_in_existential_list(task, noun.index, verb_positions) or _in_subject_list(
                task, noun.end, verb_positions
            )):  # "there's dolls, teddy bears and toy cars", "the cacti and the trays are ...": said to be there
                noun.declared = True
            # "the stapler can be moved, put the eraser in ...": an object the user lets be touched fills a slot last
            noun.permitted = any(m.permitted and noun.index <= m.index < max(noun.end, noun.index + 1)
                                 for m in mentions)
            previous_noun = noun
        parse.obstacles = list(dict.fromkeys(parse.obstacles))
        return parse

    def _shorthand_placements(self, words: list[str], vocabulary: Sequence[str]) -> tuple[list[str], list[str]]:
        """ "Block into drawer.", "Carabiner to drawer": read as "put X into Y", with a warning. Only where no word
        of the instruction is a lexicon verb and the place is a known object."""
        out, warnings, start = list(words), [], 0
        places = {w for entry in vocabulary for w in entry.split()} | OBJECT_NOUNS
        if any(lemmas(w) & self._single_verbs for w in out):
            return out, warnings  # a verb somewhere ("Mixing bowl -> frying pan. Pour.") says what to do
        while start < len(out):
            end = next((k for k in range(start, len(out)) if out[k] in _SENTENCE_END), len(out))
            wish = next((len(w) for w in _WISHES if tuple(out[start : start + len(w)]) == w), 0)
            start += wish  # "i want the phone on the charger": the wish asks for the placement
            sentence = out[start:end]
            p = next((k for k, w in enumerate(sentence) if w in ("into", "onto", "to", "in", "on")), None)
            if p is not None and 0 < p <= 4:
                head = [w for w in sentence[:p] if w not in DETERMINERS and w not in _MODIFIERS]
                rest = [w for w in sentence[p + 1 :] if w not in DETERMINERS and w not in _MODIFIERS]
                # the first word names a thing, never a verb the rules lack ("smash the bowl into the pan",
                # "stack the block on the block" stay unknown verbs)
                before = [w for w in sentence[:p] if w not in _POLITE]
                known_thing = bool(head) and singular(head[0]) in places
                # an unknown word, a noun alone ("carabiner into drawer"); before "the" it is a verb ("blorp the ...")
                thing = known_thing or (len(head) == 1 and word_classes(head[0]) <= {"NOUN"})
                thing = thing and not any(w in DETERMINERS for w in before[1:])
                # after a wish the place ends the clause: not "i want the vase in the drawer to stay"
                after_place = itertools.dropwhile(
                    lambda w: w in DETERMINERS or w in _MODIFIERS or singular(w) in places, sentence[p + 1 :])
                settled = not wish or all(w in _POLITE for w in itertools.takewhile(
                    lambda w: w not in _CLAUSE_CLOSE, after_place))
                if thing and settled and all(w.isalpha() for w in head) and rest and singular(rest[0]) in places:
                    said = " ".join(sentence)
                    out.insert(start, "put")
                    warnings.append(f"read '{said}' as 'put {said}'")
                    end += 1
            start = end + 1
        return out, warnings

    def _passive_requests(self, words: list[str]) -> list[str]:
        """ "the bowl is to be poured into the pan", "the phone should be placed on its base", "it is requested that
        the plant be watered" -> "pour the bowl into the pan", ...: a task verb in the passive after a modal asks
        for the task; with "not" it is a negated command ("the drawer must not be opened" -> "don't open the
        drawer"). A collision verb stays as said ("the glass must not be touched" declares an obstacle)."""
        out = list(words)
        i = len(out) - 1
        while i > 1:
            i -= 1
            ensured = out[i] in ("is", "are") and any(w in ("ensure", "sure") for w in out[max(0, i - 8) : i])
            if out[i] != "be" and not ensured:  # "ensure that the phone is placed on its base" asks for it too
                continue
            j = i + 1
            while j < len(out) and out[j].endswith("ly"):
                j += 1  # "be carefully placed"
            if j >= len(out):
                continue
            task_verbs = (lemmas(out[j]) | verb_lemmas(out[j])) & (self._single_verbs | {"avoid"}) - _COLLISION_VERBS
            state = _ENSURED_STATES.get(out[j]) if ensured else None  # "ensure the drawer is open"
            if state is not None and state[0] in self._single_verbs:
                task_verbs = {state[0]}
            elif not task_verbs or (out[j] in self._single_verbs and not same_participle(out[j])):
                continue  # not a participle of a task verb ("be careful", "be open"); "be put", "be set" are
            subject_end = i
            while subject_end > 0 and out[subject_end - 1] in _PASSIVE_MODALS:
                subject_end -= 1
            start = subject_end
            while start > 0 and out[start - 1] not in _SENTENCE_END | {",", "so", "and", "then"}:
                start -= 1
            while start >= 2 and out[start - 1] in ("and", "or", ",") and out[start] in DETERMINERS:
                previous = start - 1  # "both flasks and every test tube are to be avoided": the whole list
                while previous > 0 and out[previous - 1] not in _SENTENCE_END | {",", "so", "and", "or", "then"}:
                    previous -= 1
                segment = out[previous : start - 1]
                if out[previous] not in DETERMINERS or any(
                    w in _COPULAS | _PASSIVE_MODALS | {"be"} or lemmas(w) & self._single_verbs for w in segment
                ):
                    break  # a clause of its own: "the drawer is to be opened and the microwave ..."
                start = previous
            while start < subject_end and (out[start] in _CLAUSE_OPENERS or out[start] in ("after", "which")):
                start += 1  # "..., after which the drawer is to be opened"
            clause = out[start:subject_end]
            # "it is requested that the plant be watered": the subject follows "that"
            subject_at = start + len(clause) - clause[::-1].index("that") if "that" in clause else start
            if ensured and subject_at == start and {"ensure", "sure"} & set(clause):
                # "ensure the microwave is closed", "make sure the drawer is open"
                subject_at = start + max(k for k, w in enumerate(clause) if w in ("ensure", "sure")) + 1
            if subject_at >= subject_end or out[subject_at] not in DETERMINERS:
                continue
            coordinated = ensured and start > 0 and out[start - 1] == "and"  # "ensure X is open and Y is shut"
            if subject_end == i and subject_at == start and not coordinated:
                continue  # no modal and no "that": "the drawer be opened" is no request
            modals = out[subject_end:i]
            if {"can", "could", "may", "might"} & set(modals) and not {"please", "to"} & set(modals):
                continue  # "the stapler can be moved": what is allowed, not a request (was: the stapler put away)
            negated = "not" in modals or "never" in modals
            out[start : j + 1] = [*(["don't"] if negated else []), sorted(task_verbs)[0], *out[subject_at:subject_end],
                                  *(state[1:] if state else ())]
            i = start + 1  # what is left of the sentence before it
        return out

    def _read_words(
        self, words: list[str], vocabulary: Sequence[str], names: frozenset[str] | set[str] = frozenset()
    ) -> tuple[list[str], list[str]]:
        """Everyday verbs ("pop ... in") and typos of the rules' verbs and nouns, read as the words they mean;
        one warning per word read otherwise (`spelling`). `names`: words written as names, left alone."""
        joined = {entry.replace(" ", ""): entry.split() for entry in vocabulary if " " in entry}
        joined = {w: parts for w, parts in joined.items() if w not in vocabulary and w not in self._known_words}
        if joined.keys() & set(words):  # "the wateringcan": a known two-word name typed as one word
            words = [part for w in words for part in joined.get(w, [w])]
        verbs = sorted(self._single_verbs | {v[0] for v in self._phrasal} | spelling.EVERYDAY_VERBS.keys())
        nouns = sorted({w for entry in vocabulary for w in entry.split()} | OBJECT_NOUNS)
        known = self._known_words | set(nouns) | set(names)

        def is_known(word: str) -> bool:
            return word in known or bool(lemmas(word) & known) or singular(word) in known

        # Never read an unknown word as one that names no object ("avoid the duss" as "the dust"): the object
        # said would be dropped; unread, it stays a named object and is avoided.
        objects = [w for w in nouns if w not in _NON_OBJECTS]
        words, typos = spelling.correct_typos(words, is_known, verbs, objects)
        words, everyday = spelling.everyday_verbs(words, self._verbs)  # after typos: "deposti ... in"
        warnings = [f"read '{c.said}' as '{c.read_as}' (a typo?)" for c in typos]
        warnings += [f"read '{c.said}' as '{c.read_as}'" for c in everyday]
        return words, warnings

    def _mask_negated(self, words: list[str], parse: Parse) -> None:
        """ "don't open the drawer", "never pour ...", "do not put ...": a negated task clause is no task. Its
        words become clause breaks (its objects stay mentions, so they are avoided). A negated collision verb
        ("don't move the mug") is an obstacle cue instead, unless it says where to ("don't move it into ...")."""
        self._mask_unneeded(words, parse)
        for i, word in enumerate(words):
            if word in _ABSTAIN_VERBS and i and words[i - 1] in _NEGATORS | {"not"}:
                continue  # "don't forget to close it", "never stop ...": two negations ask for the task
            if word in ("don't", "dont") and i and words[i - 1] == "why" and words[i + 1 : i + 2] == ["you"]:
                continue  # "why don't you open the drawer" suggests the task
            negates = (
                word in _NEGATORS
                or word == "not" and i and words[i - 1] in _NOT_AFTER
                or word == "no" and words[i + 1 : i + 2] == [_NEGATING_BEFORE["no"]]
                or word == "off" and i and words[i - 1] == _NEGATING_BEFORE["off"]
                or word in ("isn't", "not") and words[i + 1 : i + 2] != [] and words[i + 1] in _UNNEEDED
                # "please no open the drawer", "you not water the plant": a bare "no" or "not" before a task
                # verb's base form (not a state after a copula: "it is not open")
                or word in ("no", "not") and i + 1 < len(words) and self._is_task_verb(words[i + 1]) and (
                    not i or words[i - 1] not in _COPULAS) and not past_verb_form(words[i + 1]) and not words[
                    i + 1].endswith("ing")
            )
            if not negates:
                continue
            j = i + 1
            while j < len(words) and words[j] in _NEGATION_FILLER:
                j += 1
            if j < len(words) and words[j] == ",":  # "do not, under any circumstances, stand the bottle up"
                j = next((k + 1 for k in range(j + 1, min(len(words), j + 7)) if words[k] == ","), j)
            if j >= len(words):
                continue
            if _WANTING & set(words[i + 1 : j]) and not self._is_task_verb(words[j]):
                wanted = self._wanted_verb(words, j)  # "I don't want the bottle put in the drawer"
                if wanted == j and words[j] in DETERMINERS and self._rejected_object(words, j):
                    words[i:j] = [","] * (j - i - 1) + ["not"]  # "I don't want the red block, ...": not that one
                    continue
                j = wanted
            forms = lemmas(words[j])
            if not (forms & self._single_verbs or any(v[0] in forms for v in self._phrasal)):
                continue
            end = j + 1
            while end < len(words) and words[end] != "," and not self._clause_ends(words, end):
                end += 1
            if forms & _COLLISION_VERBS and not _DESTINATIONS & set(words[j:end]):
                if not any(t in self._single_verbs for t in forms - _COLLISION_VERBS):
                    parse.negated.append(" ".join(words[i:end]))  # also a cue; refused if nothing else is asked
                    continue
            start = i - 1 if i and words[i - 1] in ("do", "try", "hold") else i
            parse.negated.append(" ".join(words[start:end]))
            k = j + 1
            while k < end and (words[k] in DETERMINERS or words[k] in _MODIFIERS or words[k] in _PARTICLES):
                k += 1
            said_of = singular(words[k]) if k < end else "it"  # "don't open it", "don't open the bottle"
            parse.negated_verbs.extend((verb, said_of) for verb in sorted(forms & self._single_verbs))
            for k in range(start, end):
                words[k] = ","

    def _mask_unneeded(self, words: list[str], parse: Parse) -> None:
        """ "sweeping the dirt won't be necessary", "opening the drawer isn't needed": a task said to be
        unneeded is a negated command."""
        for i, word in enumerate(words):
            if not (word.endswith("ing") and self._is_task_verb(word)) or i and words[i - 1] not in _TASK_BREAKS:
                continue
            end = i + 1
            while end < len(words) and words[end] not in _SENTENCE_END and words[end - 1] not in _UNNEEDED:
                end += 1
            said = words[i:end]
            if said[-1] in _UNNEEDED and _NOT_NEEDED & set(said):
                parse.negated.append(" ".join(said))
                words[i:end] = [","] * (end - i)

    def _is_task_verb(self, word: str) -> bool:
        forms = lemmas(word)
        return bool(forms & self._single_verbs) or any(v[0] in forms for v in self._phrasal)

    def _wanted_verb(self, words: list[str], j: int) -> int:
        """After "want" at j - 1: the task verb that follows its object ("want the bottle put ...", "want the
        drawer opened"), or `j` if there is none within a short noun phrase."""
        k = j
        while k < len(words) and k - j < 5 and (words[k] in DETERMINERS or words[k] in _MODIFIERS or (
            words[k].isalpha() and not self._is_task_verb(words[k]) and words[k] not in _BOUNDARY
        )):
            k += 1
        return k if k < len(words) and k > j and self._is_task_verb(words[k]) else j

    @staticmethod
    def _rejected_object(words: list[str], j: int) -> bool:
        """ "(I don't want) the red block, put the blue one ...": a noun phrase alone in its clause."""
        k = j + 1
        while k < len(words) and k - j < 5 and words[k].isalpha() and words[k] not in _BOUNDARY and (
            words[k] in _MODIFIERS or words[k] in COLOURS or not word_classes(words[k])
            or "NOUN" in word_classes(words[k])
        ):
            k += 1
        return k > j + 1 and (k == len(words) or words[k] in _SENTENCE_END or words[k] == ",")

    def _check_one_task(self, instruction: str, parse: Parse) -> None:
        """Refuse two tasks in one instruction: task verbs that start clauses ("open the drawer and put the block
        in it", "..., then close the microwave") and have no skill in common. A clause of only generic verbs
        ("take the bowl and pour it") counts only when it says where to ("put it in the drawer")."""
        tokens = parse.tokens
        repeat = _task_repeated_on(tokens, self._object_words)
        if repeat is not None:
            raise SeveralTasksError(instruction, f"'{repeat}' asks for the task again on another object; a plan "
                                                 "runs one skill on its objects, so give them one at a time")
        clause_of = _running_count(tokens, _TASK_BREAKS)
        clauses: dict[int, list[tuple[int, str]]] = {}
        for position, verb in parse.verb_at:
            k = position - 1
            while k >= 0 and tokens[k] not in _TASK_BREAKS and (
                tokens[k] in _CLAUSE_OPENERS or tuple(tokens[k - 1 : k + 1]) in _SEQUENCE_OPENERS
            ):
                k -= 2 if tuple(tokens[k - 1 : k + 1]) in _SEQUENCE_OPENERS else 1
            # "once that's done open ...", "when you're finished close ...": a clause of time ends before the verb
            after_done = k >= 0 and tokens[k] in _DONE and bool(_CLAUSE_ENDS & set(tokens[max(0, k - 5) : k]))
            if k >= 0 and tokens[k] not in _TASK_BREAKS and tokens[k] not in _POLITE and not after_done and not (
                _after_wanted_object(tokens, position)
            ):
                continue  # not a clause's verb ("the drawer is open", "a glass of water")
            clauses.setdefault(clause_of[position], []).append((position, verb))
        counted: list[tuple[str, set[str]]] = []
        permitted = permitted_spans(tokens)
        for clause, verbs in sorted(clauses.items()):
            # the verbs that share the clause with this one: "set the bottle upright" is one phrasal verb
            same = [v for p, v in parse.verb_at if clause_of[p] == clause]
            chosen = [v for v in same if " " in v] or same
            skills = {name for v in chosen for name in self._verbs[v]}
            position = verbs[0][0]
            stop = position + 1
            while stop < len(tokens) and tokens[stop] not in _TASK_BREAKS:
                stop += 1
            if all(v.split()[0] in _GENERIC_VERBS for v in chosen) and not _DESTINATIONS & set(tokens[position:stop]):
                continue
            said = tokens[position:stop]
            said = said[: said.index("if")] if "if" in said else said
            particles = {p for v in chosen for p in v.split()[1:]}
            if position in permitted and lemmas(tokens[position]) & _COLLISION_VERBS and not particles & set(said):
                continue  # "push them aside if you need to": leave to touch, not a task ("push it shut" is one)
            counted.append((chosen[0], skills))
        said_with_verb = {clause_of[p] for p, _ in parse.verb_at}
        clause_words: dict[int, list[str]] = {}  # grouped once: a clause per punctuation mark made the scan quadratic
        for token, clause in zip(tokens, clause_of, strict=True):
            if token not in _TASK_BREAKS:
                clause_words.setdefault(clause, []).append(token)
        for clause in sorted(set(clause_of) - said_with_verb):
            words = clause_words.get(clause, [])
            k = next((j for j, w in enumerate(words) if w in ("into", "onto")), None)
            things = [w for w in words[:k] if w not in DETERMINERS and w not in _MODIFIERS] if k else []
            if counted and things and all(singular(w) in self._object_words for w in things) and any(
                singular(w) in self._object_words or "NOUN" in word_classes(w) for w in words[k + 1 :]
            ):  # "1) stand bottle upright 2) bottle into drawer": a placement said with no verb is a task too
                raise SeveralTasksError(instruction, f"'{' '.join(words)}' asks for a placement beside another task; a "
                                                     "plan runs one skill, so give them one at a time")
        alternative = next((k for k, w in enumerate(tokens) if w in ("otherwise", "else")), None)
        if alternative is not None:  # "if the drawer is closed open it, otherwise close the microwave"
            before = {n for p, v in parse.verb_at if p < alternative for n in self._verbs[v]}
            after = {n for p, v in parse.verb_at if p > alternative for n in self._verbs[v]}
            if before and after and before.isdisjoint(after):
                raise SeveralTasksError(instruction, f"it asks for one task or, '{tokens[alternative]}', another; a "
                                                     "plan runs one skill, so say which to do")
        for k, (verb, skills) in enumerate(counted):
            for other, other_skills in counted[k + 1 :]:
                if skills.isdisjoint(other_skills):
                    raise SeveralTasksError(
                        instruction,
                        f"it asks for two tasks ('{verb}': {', '.join(sorted(skills))}; '{other}': "
                        f"{', '.join(sorted(other_skills))}); a plan runs one skill, so give them one at a time",
                    )

    # ---- step 0: positions and "one" ----------------------------------------------------------

    def _resolve_one_anaphora(self, words: list[str], vocabulary: Sequence[str]) -> list[str]:
        """ "two bowls, a red one and a blue one" -> "... a red bowl and a blue bowl": a modifier + "one"
        takes the noun last said with that modifier, else the noun last said."""
        words = list(words)
        if "one" not in words and "ones" not in words:
            return words
        said = self._mentions(words, vocabulary)  # once: (index, noun, modifiers), not once per "one"
        for i, word in enumerate(words):
            if word not in ("one", "ones") or not i or words[i - 1] not in _MODIFIERS or words[i - 1] == "other":
                continue
            if i < 2 or words[i - 2] in (",", "!", "?", "."):
                continue  # "mind the metronome, little one, ...": a name for the robot, not "the little metronome"
            earlier = [(noun, modifiers) for k, noun, modifiers in said if k < i - 1]
            if not earlier:
                continue
            modifier = words[i - 1]
            group = COLOURS if modifier in COLOURS else SIZE_WORDS.keys() if modifier in SIZE_WORDS else POSITION_WORDS
            same = [noun for noun, modifiers in earlier if modifier in modifiers]
            # "the red block ... the blue one"
            alike = [noun for noun, modifiers in earlier if modifiers.intersection(group)]
            described = [noun for noun, modifiers in earlier if modifiers]  # "the left block ... the small one"
            words[i] = (same or alike or described or [earlier[-1][0]])[-1]
            said = sorted([*said, (i, words[i], {modifier})])
        return words

    def _mentions(self, words: Sequence[str], vocabulary: Sequence[str]) -> list[tuple[int, str, set[str]]]:
        """(index, noun, modifiers said before it) for each object noun in `words`, in order."""
        words = list(words)
        out, i = [], 0
        not_nouns = _BOUNDARY | _NON_OBJECTS | DETERMINERS | _MODIFIERS | self._single_verbs
        while i < len(words):
            match = self._vocabulary_match(words, i, vocabulary)
            length = len(match.split()) if match else 1
            if match is not None and words[i] in self._single_verbs and (not i or words[i - 1] in _TASK_BREAKS) and (
                words[i + 1 : i + 2] and words[i + 1] in DETERMINERS
            ):
                match = None  # "Dock the pink one on the base": a verb before its object, not a dock
            if match is None:
                previous = words[i - 1] if i else ""
                word = words[i]
                after_determiner = previous in DETERMINERS or previous in _MODIFIERS
                if not (after_determiner and word.isalpha() and word not in not_nouns):
                    i += 1
                    continue
                match = singular(word)
            modifiers, j = set(), i - 1
            while j >= 0 and words[j] in _MODIFIERS:
                modifiers.add(words[j])
                j -= 1
            out.append((i, match, modifiers))
            i += length
        return out

    # ---- step 1: obstacles ------------------------------------------------------------------

    def _obstacle_spans(self, words: list[str]) -> list[tuple[int, int, str]]:
        """(start, end, cue) token spans governed by obstacle cues."""
        spans, i = [], 0
        while i < len(words):
            cue = next((c for c in _CUES_BY_FIRST.get(words[i], ()) if self._cue_at(words, i, c)), None)
            if cue is not None and cue[0] == "mind" and i and words[i - 1] in ("don't", "dont", "not"):
                cue = None  # "I don't mind if you brush the boxes": a permission (`mentions`), not a caution
            if cue == ("around",) and _around_says_where(words, i):
                cue = None
            if cue is None:
                i += 1
                continue
            cue_words = words[i : i + len(cue)]
            start = i + len(cue)
            if cue[-1] == "<det>":
                start -= 1  # the determiner belongs to the noun phrase ("not the mug")
                cue_words = cue_words[:-1]
            while start < len(words) and (
                words[start] in _PARTICLES or words[start] in (":", "=", "anywhere", "somewhere")
                or (words[start].endswith("ing") and _matches("<hit>", words[start]))
            ):
                start += 1  # "avoid knocking over the mug": the mug, not a "knocking mug"; "avoid: mug"
            end = start
            contrast = cue in _CONTRASTS  # "the red block, not the mug, into the drawer": one noun phrase
            while end < len(words) and not self._clause_ends(words, end):
                if contrast and end > start and (words[end] == "," or words[end] in _DESTINATIONS | {"to"}):
                    break
                end += 1
            if ("<hit>" in cue or cue == ("no", "<ing>")) and not any(w.isalpha() for w in words[start:end]):
                # "the cup do not touch", "the bottle never touching", "phones no touching": the object said
                # before the cue
                before = i
                while before > 0 and words[before - 1] not in _SENTENCE_END | {",", "but", "and"}:
                    before -= 1
                if before < i and (any(w in DETERMINERS for w in words[before:i]) or singular(words[i - 1]) in (
                    OBJECT_NOUNS
                )) and not any(self._is_task_verb(w) for w in words[before:i]):
                    spans.append((before, i, " ".join(cue_words)))
                    for j in range(i, start):
                        words[j] = ","
                    i = max(end, start)
                    continue
            spans.append((start, end, " ".join(cue_words)))
            for j in range(i, start):
                words[j] = ","  # the cue words are not task words
            i = end
        return spans

    @staticmethod
    def _cue_at(words: list[str], i: int, cue: tuple[str, ...]) -> bool:
        if i + len(cue) > len(words):
            return False
        for k, pattern in enumerate(cue):
            word = words[i + k]
            if pattern != word and (pattern[0] != "<" or not _matches(pattern, word)):
                return False
        return True

    def _clause_ends(self, words: list[str], i: int) -> bool:
        word = words[i]
        if word in _SENTENCE_END or word in _CLAUSE_ENDS:
            return True
        if any(self._cue_at(words, i, c) for c in _CUES_BY_FIRST.get(word, ()) if c[-1] != "<det>"):
            return True
        previous = words[i - 1] if i else ","
        # ", which is next to it", ", it is right in front": a new clause about the object, not more objects
        if previous == "," and (word in ("which", "who") or words[i + 1 : i + 2] and words[i + 1] in _COPULAS):
            return True
        if previous == "," and (word.endswith("ing") and lemmas(word) & _COLLISION_VERBS or _subject_of_verb(words, i)):
            return True  # ", touching it is fine", ", the remote doesn't matter": a clause, not one more object
        # A lexicon verb right after "and" or a comma (and "just", "now", "please") starts the next clause ("avoid
        # the mug and pour ...", "don't touch the mug, just put ...").
        k = i - 1
        while k > 0 and words[k] in _CLAUSE_OPENERS | _POLITE and words[k] not in ("and", "to", "you"):
            k -= 1
        previous = words[k] if k >= 0 else ","
        return previous in ("and", ",") and bool(lemmas(word) & self._single_verbs)

    def _predicate_spans(self, words: list[str]) -> list[tuple[int, int, int, int, str]]:
        """(start, end, mask_start, mask_stop, predicate): obstacles declared by what is said of them,
        the noun phrase words[start:end]; words[mask_start:mask_stop] are not task words."""
        spans = []
        for i in range(len(words)):
            marker = next((m for m in _WAY_MARKERS if self._cue_at(words, i, m)), None)
            if marker in (("blocks",), ("obstructs",)) and not (
                words[i + 1 : i + 2] and (words[i + 1] in DETERMINERS or words[i + 1] in ("it", "them", "access"))
            ):
                marker = None  # "the toy blocks are fragile": a plural noun, not the verb ("the mug blocks the way")
            if marker is not None:
                stop = i + len(marker)
                if marker[0] in ("blocking", "blocks", "obstructing", "obstructs"):
                    # "blocking the way" (not "blocking the drawer": that drawer is still a task word)
                    if words[stop : stop + 2] in (["the", "way"], ["the", "path"], ["my", "way"]):
                        stop += 2
                start, end = self._subject_before(words, i)
                if start < end:
                    spans.append((start, end, start, stop, " ".join(words[start:stop])))
            elif words[i] in _OBSTACLE_NOUNS and self._obstacle_predicate(words, i):
                spans.append(self._obstacle_predicate(words, i))
            elif words[i] == "around" and i >= 2 and (words[i - 1] in _COPULAS or words[i - 1] in (
                "all", "just", "right") and words[i - 2] in _COPULAS):
                # "the toy sheep are all around it": they stand around it, so they are in the way
                start, end = self._subject_before(words, i - (words[i - 1] not in _COPULAS))
                if start < end:
                    spans.append((start, end, start, i, " ".join(words[start : i + 1])))
            elif words[i] == "between":
                # "there is a mug between the bowl and the pan", "the mug sits between them": on the path
                start, end = self._subject_before(words, i)
                there = start >= 2 and words[start - 1] in _COPULAS and words[start - 2] == "there"
                if start < end and (words[i - 1] in _COPULAS or there):
                    spans.append((start, end, start, i, " ".join(words[start : i + 1])))
            elif words[i] in _WARNINGS and words[i + 1 : i + 2] and words[i + 1] in {",", ":", "!", "-"}:
                # "careful, the can is right beside the pan": what a warning is about is an obstacle
                k = i + 2
                while k < len(words) and (words[k] not in _COPULAS and words[k] not in _SUBJECT_STOPS or (
                    _noun_before_copula(words, k)
                )):
                    k += 1
                said = words[i + 2 : k]
                if (
                    said
                    and k < len(words)
                    and words[k] in _COPULAS
                    and not any(self._is_verb(words, m) for m in range(i + 2, k))
                ):
                    spans.append((i + 2, k, i + 2, k, " ".join(words[i:k])))
            elif self._unsteady_at(words, i):
                # "the bowl might tip", "the vase could fall over", "the lamp wobbles": what may fall is an obstacle
                k = i - (words[i - 1] in _RISK_MODALS)
                start, end = self._subject_before(words, k)
                if start < end and words[start:end] not in (["it"], ["they"], ["this"], ["that"]):  # "it": the mention
                    spans.append((start, end, start, i + 1, " ".join(words[start : i + 1])))
            elif words[i] in PROPERTY_WORDS and self._said_of(words, i):
                # "the glass is fragile", "the kettle is very hot": the object it is said of is an obstacle
                k = i
                while k > 0 and words[k - 1] in _DEGREE:
                    k -= 1
                start, end = self._subject_before(words, k)
                if start < end:
                    spans.append((start, end, start, i + 1, " ".join(words[start : i + 1])))
            elif (words[i] == "alone" or words[i] == "be" and (i + 1 == len(words) or words[i + 1] in _CLAUSE_CLOSE)
                  ) and "leave" in words[max(0, i - 8) : i]:  # "leave the vase alone", "leave the others be"
                leave = max(k for k in range(max(0, i - 8), i) if words[k] == "leave")
                spans.append((leave + 1, i, leave, i + 1, " ".join(words[leave : i + 1])))
        return spans

    @staticmethod
    def _unsteady_at(words: list[str], i: int) -> bool:
        """words[i] says its subject may fall, used without an object: after a modal ("might tip", "could fall
        over") or as the subject's own verb ("wobbles", "tips easily"); not "tip the bowl over"."""
        if i == 0 or not lemmas(words[i]) & _UNSTEADY_VERBS:
            return False
        following = words[i + 1] if i + 1 < len(words) else "."
        intransitive = following in _CLAUSE_CLOSE or following in ("over", "off", "down", "easily", "too", "if")
        third_person = words[i].endswith("s") and words[i - 1].isalpha() and words[i - 1] not in DETERMINERS
        return intransitive and (words[i - 1] in _RISK_MODALS or third_person)

    @staticmethod
    def _said_of(words: list[str], i: int) -> bool:
        """Whether the adjective words[i] is predicated ("is fragile", "are very hot"), not attributive."""
        k = i - 1
        while k >= 0 and words[k] in _DEGREE:
            k -= 1
        return k >= 0 and (words[k] in _COPULAS or words[k] in ("looks", "seems", "look", "seem", "all", "both"))

    def _obstacle_predicate(self, words: list[str], i: int) -> tuple[int, int, int, int, str] | None:
        """ "the lamp counts as an obstacle", "treat the lamp as an obstacle", "obstacles: the mug and the
        glass", "the obstacle is the lamp"; None for a plain noun ("avoid the obstacle")."""
        j = i - 1
        while j >= 0 and words[j] in _PREDICATE_FILLER:
            j -= 1
        said_of = {w for w in words[j + 1 : i]} & {"as", "is", "are", "'s", "counts", "count", "acts", "act"}
        if said_of - {"is", "are", "'s"} or (said_of and words[j + 1 : i][-1:] not in (["the"],)):
            start, end = self._subject_before(words, j + 1, plural=words[i].endswith("s"))
            if start < end:
                return start, end, start, i + 1, " ".join(words[start : i + 1])
        k = i + 1
        while k < len(words) and words[k] in (":", ",", "is", "are", "'s", "include", "includes"):
            k += 1
        # "the obstacle is the lamp", "obstacles: a mug"; not "the obstacle is next to the pan" (a place)
        if k > i + 1 and k < len(words) and (words[k] not in _BOUNDARY or words[k] in DETERMINERS):
            end = k
            while end < len(words) and not self._clause_ends(words, end) and words[end] not in _COPULAS:
                end += 1
            return k, end, i, end, " ".join(words[i:end])
        if i and words[i - 1] in DETERMINERS:
            return i, i + 1, i, i + 1, " ".join(words[i - 1 : i + 1])  # the simulator's "obstacle" itself
        return None

    def _subject_before(self, words: list[str], i: int, plural: bool = False) -> tuple[int, int]:
        """The noun phrase (or list, after a plural verb) that ends before words[i], skipping a copula."""
        j = i
        while j > 0 and words[j - 1] in _COPULAS | _STANCE | _DEGREE | _SUBJECT_SKIPS:
            if _noun_before_copula(words, j - 1):
                break
            plural |= words[j - 1] in _PLURAL_COPULAS
            j -= 1
        end = start = j
        while start > 0 and words[start - 1] not in _SUBJECT_STOPS and not self._is_verb(words, start - 1):
            if start < end and words[start] in DETERMINERS and words[start - 1] not in _LIST_SEPARATORS:
                break  # "open the drawer the lamp counts as ...": a noun phrase starts at its determiner
            if words[start - 1] in _LIST_SEPARATORS:
                k = start - 1
                while k > 0 and words[k - 1] not in _SUBJECT_STOPS and words[k - 1] not in _LIST_SEPARATORS:
                    k -= 1
                if any(self._is_verb(words, m) for m in range(k, start - 1)):
                    break  # "open the drawer, the mug and the glass are in the way": a clause, not a list item
                if not plural:
                    # "there's a mug, a can and a ball in the way": the list follows "there is"
                    k = start - 1
                    while k > 0 and words[k - 1] not in _SUBJECT_STOPS:
                        k -= 1
                    plural = k >= 2 and words[k - 1] in _COPULAS and words[k - 2] == "there"
                if not plural:
                    break
            start -= 1
        if start > 0 and words[start - 1] in _PLURAL_COPULAS:
            plural = True  # "there are a mug and a glass in the way"
        while start < end and words[start] in _LIST_SEPARATORS:
            start += 1
        pronoun = end - start == 1 and words[start] in ("it", "them")
        places = _LOCATIVES | {"to", "of"} if pronoun else (_LOCATIVES | {"on", "in", "at"}) - {"of"}
        if (pronoun or words[end - 1] in _SURFACES) and start >= 3 and words[start - 1] in places:
            # "the petri dishes beside it are fragile", "every tin on the shelf is fragile": not the landmark
            k = start - 1
            while k > 0 and words[k] in _LOCATIVES | _NEAR_WORDS:
                k -= 1
            first = k
            while first > 0 and words[first] not in DETERMINERS and words[first - 1] not in _SUBJECT_STOPS and (
                not self._is_verb(words, first - 1)
            ):
                first -= 1
            if first < k and words[first] in DETERMINERS:
                start, end = first, k + 1
        if start >= 2 and words[start - 1] == "'s" and end > start and words[end - 1] in NOT_OBJECTS:
            owner = start - 1  # "the kettle's handle is hot": the kettle is the object, its handle a part of it
            while owner > 0 and words[owner - 1] not in _SUBJECT_STOPS and not self._is_verb(words, owner - 1):
                owner -= 1
                if words[owner] in DETERMINERS:
                    break
            start = owner
        return start, end

    def _is_verb(self, words: list[str], i: int) -> bool:
        """A lexicon verb, not a noun after a determiner ("the base")."""
        previous = words[i - 1] if i else ","
        return bool(lemmas(words[i]) & self._single_verbs) and previous not in DETERMINERS | _MODIFIERS

    def _read_declaration(self, words: list[str], start: int, end: int, cue: str, parse: Parse) -> None:
        """Obstacles (or pending references) from an obstacle declaration's noun phrase list."""
        chunk: list[str] = []
        chunk_start = start
        for k, word in enumerate([*words[start:end], ","]):
            if word in _LIST_SEPARATORS or word in _SENTENCE_END:
                self._read_chunk(chunk, chunk_start, cue, parse)
                chunk, chunk_start = [], start + k + 1
            else:
                chunk.append(word)

    def _read_chunk(self, chunk: list[str], index: int, cue: str, parse: Parse) -> None:
        if chunk and chunk[0] in _QUANTIFIED and "of" in chunk[1:4]:
            rest = chunk[1 : chunk.index("of", 1)]
            if all(w in ("one", "single", "last", "single one") or w in NUMBER_WORDS for w in rest):
                chunk = chunk[chunk.index("of", 1) + 1 :]  # "any of them", "every one of them", "all of the cups"
        content = tuple(w for w in chunk if w not in _POLITE or w in ("it", "one"))
        bare = tuple(w for w in content if w not in ("very", "just", "also", "either", "any"))
        while len(bare) > 1 and bare[-1] in ("over", "off", "down", "up", "away", "around"):
            bare = bare[:-1]  # "don't knock it over"
        if len(bare) > 1 and bare[0] in ("it", "they", "them") and bare[1] not in ("and", "or"):
            bare = bare[:1]  # "the kettle, it just boiled", "none of them can be knocked": a clause about them
        said = bare
        if not bare and content in (("any",), ("either",)):
            bare = ("them",)  # "there are cards and chess pieces about, so don't knock any": any of them
            said = content
        if bare in _PRONOUNS:
            parse.references.append(_Reference(index, _PRONOUNS[bare], f"{cue} {' '.join(said)}".strip()))
            return
        ref = self._chunk_to_ref(chunk)
        if ref is not None:
            parse.obstacles.append(ref)
            parse.declared.append((index, ref))
            parse.cue_of.setdefault(ref, cue)
            return
        said = [
            w for w in chunk
            if w not in DETERMINERS | _PARTICLES | _POLITE | _CLAUSE_OPENERS | _DISCOURSE | _TAGS and w.isalpha()
        ]
        if said:
            parse.warnings.append(
                f"'{cue} {' '.join(chunk)}' names no object the robot can see; no obstacle was added for it"
            )

    @staticmethod
    def _chunk_to_ref(chunk: Sequence[str]) -> ObjectRef | None:
        """'the small red coffee mug next to it' -> ObjectRef(name='coffee mug', color='red', size='small')."""
        color = size = position = None
        nouns: list[str] = []
        previous = ""
        vague = False  # "the thing next to the pan": a head that names no object ends the phrase too
        for k, word in enumerate(chunk):
            after_determiner = previous in DETERMINERS or previous in COLOURS or previous in SIZE_WORDS
            after_modifier = after_determiner or previous in POSITION_WORDS
            previous = word
            following = chunk[k + 1] if k + 1 < len(chunk) else ","
            if word == "can" and (nouns or after_modifier) and following not in ("be", "you", "i", "we", "not", "now"):
                nouns.append(word)  # "the tin can", "the soda can", "the left can": a noun after a noun or a modifier
                continue
            if word in _COMPOUND_MODIFIERS and not nouns and following.isalpha() and following not in _BOUNDARY and (
                following not in _NON_OBJECTS or following in UNITS and len(following) > 3
            ):
                nouns.append(word)  # "the water bottle", "the table lamp", "the water meter"
                continue
            last = k + 1 == len(chunk) or not following.isalpha()  # the phrase's last word
            if word == "stand" and nouns and singular(nouns[-1]) == nouns[-1]:
                nouns.append(word)  # "the soldering iron stand": a holder after a singular noun
                continue
            if nouns and chunk[k - 1] == nouns[-1] and (last or following in _BOUNDARY) and (
                word in UNITS and len(word) > 3 or word in POSITION_WORDS and nouns[-1].endswith("ing")
            ):
                nouns.append(word)  # "the light meter", "a spinning top": the head of a compound, no unit or side
                continue
            after = chunk[k + 2] if k + 2 < len(chunk) else ","
            if nouns and word.endswith("ing") and following.isalpha() and following not in _BOUNDARY and (
                "NOUN" in word_classes(following) and (after in _BOUNDARY or not after.isalpha())
            ):
                nouns.append(word)  # "the lens cleaning kit": a gerund naming the kind of the noun after it
                continue
            if nouns and word in ("table", "counter", "door", "side") and following.isalpha() and (
                following not in _BOUNDARY | _NON_OBJECTS
            ) and ("NOUN" in word_classes(following) or following in OBJECT_NOUNS):
                nouns.append(word)  # "the coffee table book", "the side door key": inside a compound
                continue
            if nouns and (word in _STANCE or word in SUBJECT_VERBS or word.endswith("ing") and len(word) > 4):
                break  # "the phone case lying next to it", "the vase stays put": a verb ends the noun phrase
            if nouns and singular(nouns[-1]) in PEOPLE and past_verb_form(word):
                break  # "my son spent all morning on it": what the person did
            if nouns and word in _DETACHABLE:
                nouns.append(word)  # "the pan lid": a lid is an object of its own, not the pan
                continue
            if nouns and word.isalpha() and word_classes(word) == {"ADV"}:
                break  # "mind the lamp though": an adverb ends the noun phrase
            if nouns and (word in _STATES_AFTER or word in ("half", "partly", "almost")):
                break  # "don't get the books wet", "the jigsaw puzzle half done": a state said of the object
            if nouns and word.endswith("ed") and word_classes(word) and "NOUN" not in word_classes(word):
                break  # "the wine glasses lined up behind it": a participle after the noun
            if word == "'s" and nouns and " ".join(nouns) not in OBJECT_NOUNS and possessive(chunk, k) and (
                singular(following) not in _NON_OBJECTS
            ):
                nouns, color, size = [], None, None  # "grandad's cake stand": the owner is no object, the stand is
                continue
            # A function word straight after "the" is a noun after all ("the can").
            if word in _BOUNDARY and not after_determiner:
                if nouns or vague:
                    break
                continue
            if word in DETERMINERS:
                if nouns:
                    break  # "the teacup its my favourite": a second determiner starts another phrase
                continue
            if word == "single" and not nouns and chunk[k - 1 : k] and chunk[k - 1] in ("every", "each", "any", "a"):
                continue  # "every single bottle" is every bottle, "don't touch a single bottle" none of them
            if word in _PERSONAL_PRONOUNS or word.isdigit():
                break  # "I want that you put ...": "that" is a conjunction, "you" no object; "the abacus 12 cm ..."
            if not nouns and word in _RELATIONAL_ADJECTIVES:
                continue  # "the neighbouring vase" is a vase
            if not nouns and not after_determiner and len(word) > 5 and word.endswith("ly"):
                continue  # "especially the vase", "particularly the lamp": an adverb before the phrase
            if (word in UNITS and k and chunk[k - 1] in NUMBER_WORDS or word in NUMBER_WORDS) and not nouns:
                continue  # "the two litre jug", "the dozen eggs": a measure or a count before the noun
            if word in UNITS and not nouns and following.isalpha() and following not in _BOUNDARY:
                nouns.append(word)  # "the pint glass", "the foot pump": a unit with no number names a kind
                continue
            if not nouns and (word in PROPERTY_WORDS or word in DESCRIBING and word not in _MODIFIERS and (
                "NOUN" not in word_classes(word)  # not "the rubber duck", "the paper towel"
            )) and following.isalpha() and following not in _BOUNDARY:
                continue  # "the hot water bottle": how it is, before its name ("water" then starts the name)
            if word in POSITION_WORDS and not nouns and (word != "middle" or after_determiner):
                position = POSITION_WORDS[word]
            elif word in COLOURS:
                color = canonical_attribute(word)
            elif word in SIZE_WORDS:
                size = canonical_attribute(word)
            elif word not in _NON_OBJECTS and not vague:
                nouns.append(word)
            elif word not in POSITION_WORDS:
                vague = True  # "anything else": nothing after a vague head is its noun
        while len(nouns) > 1 and (nouns[0] in DESCRIBING or is_adjective(nouns[0])) and (
            "NOUN" not in word_classes(nouns[0]) or nouns[0] in MATERIALS and " ".join(nouns) not in OBJECT_NOUNS
        ):
            nouns.pop(0)  # "the hot red pan", "the porcelain teapot"; not "the rubber duck", "the remote control"
        while len(nouns) > 1 and nouns[0].endswith("ing") and singular(nouns[-1]) in PEOPLE:
            nouns.pop(0)  # "the sleeping cat": what it does; a "sleeping bag" is a kind of bag
        nouns = nouns[-_MAX_COMPOUND:]  # "the a b c d e f": no object's name is a run of words
        if not nouns or len(" ".join(nouns)) > MAX_NAME_CHARS:
            return None
        if nouns == [nouns[0]] and nouns[0] not in OBJECT_NOUNS and (
            word_classes(nouns[0]) and "NOUN" not in word_classes(nouns[0]) and is_adjective(nouns[0])
            or nouns[0] in _STATES_AFTER
        ):
            return None  # "don't get distracted", "must not get wet": a state alone names no object
        nouns[-1] = singular(nouns[-1])
        return ObjectRef(name=" ".join(nouns), color=color, size=size, position=position)

    # ---- step 2: verbs and nouns ------------------------------------------------------------

    def _find_verbs(self, task: list[str], parse: Parse) -> set[int]:
        positions = set()
        for i, word in enumerate(task):
            hits = lemmas(word) & self._single_verbs
            heads = {v for v in self._phrasal if v[0] in lemmas(word)}
            if not hits and not heads:
                continue
            wanted_done = i >= 2 and task[i - 1].isalpha() and "NOUN" in word_classes(task[i - 1]) and any(
                _asks_done(task, k) for k in range(max(0, i - 6), i - 1))  # "I want the drawer opened"
            if past_verb_form(word) and not wanted_done:
                continue  # "you stood the bottle up yesterday", "I spilled soil": what happened, not a request
            if _may_happen(task, i):
                continue  # "the cat bowl's water could spill": what may happen, not a request
            keeping = [k for k in range(max(0, i - 5), i - 1) if task[k] in _KEEPING and not (
                task[k] == "left" and k and task[k - 1] in DETERMINERS)  # "on the left, open ..." is a side
                and not _CLAUSE_CLOSE & set(task[k + 1 : i])]  # "keep away from it and open the drawer": two clauses
            if word in _STATE_WORDS and i >= 2 and keeping and task[i - 1] not in _PERSONAL_PRONOUNS:
                continue  # "I left the drawer open", "keep the bottle upright": how it is, not a request
            wanted = any(w in _WANTING for w in task[max(0, i - 6) : i])
            after_noun = i and task[i - 1].isalpha() and "NOUN" in word_classes(task[i - 1])
            after_noun = after_noun and task[i - 1] not in _POLITE and not lemmas(task[i - 1]) & self._single_verbs
            if word.endswith("ing") and after_noun and not wanted:
                continue  # "the wine bottle standing at the back" says which bottle; not "I need the bottle standing"
            # A lexicon word right after a determiner or adjective is a noun ("the water", "the base"); after a
            # copula it is a state ("the drawer is open"); "close to" / "close by" is a place, not the verb.
            previous = task[i - 1] if i else ","
            if word == "put" and previous in _REMAIN_VERBS:
                continue  # "the vase stays put": it is to remain where it is, not a request to put something
            if tuple(task[i - 2 : i]) in _SEQUENCE_OPENERS:
                previous = ","  # "after that open it": "that" is no determiner there
            if previous in ("first", "second", "third", "last", "next") and (i < 2 or task[i - 2] in _TASK_BREAKS):
                previous = ","  # "first stand the bottle up": an adverb opening the clause, not "the first drawer"
            if previous in DETERMINERS | _MODIFIERS or previous in _COPULAS:
                continue  # "the base", "the small brush": a noun after a determiner or an attribute
            following = task[i + 1] if i + 1 < len(task) else ","
            if positions and after_noun and i >= 2 and task[i - 2] in DETERMINERS and "NOUN" in word_classes(word) and (
                following not in DETERMINERS
            ):
                continue  # "put the spark plug in the drawer": after the task's verb, a noun's second word
            unlisted = previous.isalpha() and not word_classes(previous) and previous not in _POLITE  # "mic"
            if (after_noun or unlisted) and i >= 2 and task[i - 2] in DETERMINERS and "NOUN" in word_classes(word) and (
                singular(previous) == previous) and (
                following in _COPULAS or following in _LOCATIVES or following in _CLAUSE_CLOSE
            ):  # (after a plural it is the subject's verb: "doesn't matter if the pens move")
                continue  # "a blister pack near the drawer", "the ice pack is cold": a compound's head noun
            k = i - 1
            while k > 0 and (task[k].endswith("ly") or task[k] in _STATE_ADVERBS):
                k -= 1
            if k < i - 1 and task[k] in _COPULAS:
                continue  # "it's fully charged", "the drawer is already open": a state, not a request
            if word == "close" and (following in ("to", "by", "beside", "behind", "next") or previous in _DEGREE and (
                following not in DETERMINERS)):
                continue  # "close to the mug", "so close": a place; not "..., so close the microwave"
            if word == "right" and following in _RIGHT_AS_ADVERB_BEFORE:
                continue  # "a vase right next to the drawer", "right there": an adverb, not "right the bottle"
            permission = tuple(task[max(0, i - 2) : i]) in _PERMITTING or previous in ("may", "can")
            if permission and lemmas(word) & _COLLISION_VERBS & _GENERIC_VERBS and not _DESTINATIONS & set(
                task[i + 1 : next((k for k in range(i + 1, len(task)) if task[k] in _CLAUSE_CLOSE), len(task))]
            ):
                continue  # "it is allowed to move the box", "you may push the mug": contact permitted, no task
            if same_participle(word) and (singular(previous) in PEOPLE or previous in _NARRATORS):
                continue  # "my son put a cup there", "I set it down": what someone did, not a request
            if word == "stand" and after_noun and singular(previous) == previous and following not in (
                AFTER_STAND_VERB
            ) and any(w in DETERMINERS for w in task[max(0, i - 4) : i - 1]):
                continue  # "a soldering iron stand on the left": a holder named after what it holds
            place = task[i + 2] if following in ("right", "just", "directly") and i + 2 < len(task) else following
            unknown_before = previous.isalpha() and not word_classes(previous)  # "the dreamcatcher hangs ..."
            if word in _STANCE_VERBS and (after_noun or unknown_before) and place in _STANCE_PLACES and any(
                w in DETERMINERS for w in task[max(0, i - 4) : i - 1]
            ):
                continue  # "two model aircraft hang over the drawer": where things are, not a request
            if hits:
                parse.verbs.append(sorted(hits)[0])
                parse.verb_at.append((i, sorted(hits)[0]))
                positions.add(i)
            for verb in sorted(heads):
                particle = self._particle_after(task, i, verb[1:])
                if particle is not None:
                    parse.verbs.append(" ".join(verb))
                    parse.verb_at.append((i, " ".join(verb)))
                    positions.update({i, particle})
        content = [w for w in task if w not in _POLITE and w not in _SENTENCE_END and w != ","]
        head = []
        for word in content:
            if word in DETERMINERS or word in COLOURS or word in SIZE_WORDS:
                break
            head.append(word)
        parse.verb_phrase = " ".join(head[:3])
        return positions

    @staticmethod
    def _particle_after(task: list[str], i: int, particle: tuple[str, ...]) -> int | None:
        """Index of a phrasal verb's particle within its clause: "pull out the drawer", "pull the drawer out"."""
        for k in range(i + 1, min(len(task), i + 8)):
            if task[k] in _SENTENCE_END or task[k] in _CLAUSE_ENDS or task[k] == ",":
                return None
            if tuple(task[k : k + len(particle)]) == particle:
                return k
        return None

    def _find_nouns(self, task: list[str], verb_positions: set[int], vocabulary: Sequence[str]) -> list[_Noun]:
        nouns: list[_Noun] = []
        used = set(verb_positions)
        i = 0
        while i < len(task):
            match = None if i in used else self._vocabulary_match(task, i, vocabulary)
            if match is None:
                i += 1
                continue
            end = i + len(match.split())
            if task[end : end + 1] == ["can"] and not match.endswith("can") and not modal_can(task, end):
                match, end = f"{match} can", end + 1  # "the tin can": a can, whatever the word before it names
            if self._modifies_next_noun(task, end, verb_positions):
                i += 1  # "the toy car" is a car: read below as a noun of its own, never as the slot's "toy"
                continue
            compound = self._compound_before(task, i, verb_positions, used)
            start = i - len(compound.split()) if compound else i  # its words begin with the compound's
            color, size, position = self._modifiers(task, start)
            noun = _Noun(match, color, size, known=True, index=start, end=end, position=position, compound=compound)
            if nouns and nouns[-1].known and nouns[-1].end == i and i - 1 not in verb_positions:
                # two object words in a row are one object, named by the last ("the toy block", "the phone
                # charger"); the first says its kind and carries what was said before it ("the red toy block")
                first = nouns.pop()
                noun.compound = " ".join(filter(None, (first.compound, " ".join(task[first.index : first.end]))))
                noun.index, noun.color, noun.size, noun.position = first.index, first.color, first.size, first.position
            nouns.append(noun)
            used.update(range(i, end))
            i = end
        # Unknown head nouns after a determiner ("the stapler"), or right after the verb ("put teapots in the
        # drawer"), fill wildcard slots.
        for i, word in enumerate(task):
            after_verb = i in verb_positions and i + 1 < len(task) and task[i + 1] not in DETERMINERS | _MODIFIERS
            if word not in DETERMINERS and not after_verb:
                continue
            chunk = []
            for j in range(i + 1, len(task)):
                # "a can", "the can": a function word straight after an article is the noun
                noun_after_article = j == i + 1 and word in ("a", "an", "the") and task[j] == "can"
                # "the soda can", "the jerry can can tip over": a can after the words naming its kind
                noun_after_article = noun_after_article or task[j] == "can" and bool(chunk) and not modal_can(task, j)
                if task[j] in _SENTENCE_END or task[j] == "," or j in verb_positions:
                    break
                if task[j] in _BOUNDARY and not noun_after_article:
                    break
                chunk.append(j)
            if chunk and not used & set(chunk):
                ref = self._chunk_to_ref([*([] if after_verb else [word]), *(task[j] for j in chunk)])
                if ref is not None:
                    name = self._matcher_noun(ref.name, vocabulary) or ref.name
                    nouns.append(
                        _Noun(name, ref.color, ref.size, known=name != ref.name, index=chunk[0], end=chunk[-1] + 1,
                              position=ref.position)
                    )
                    used.update(chunk)
        return sorted(nouns, key=lambda n: n.index)

    def _compound_before(self, task: list[str], i: int, verb_positions: set[int], used: set[int]) -> str | None:
        """The nouns typed right before the known object word at `i` that make a compound with it ("the mixing
        bowl", "the fruit bowl"): up to two words no rule reads, or nouns such as "water" or "fruit"; not
        adjectives ("the empty bowl"), between a determiner, a colour/size/position or the verb and the object."""
        start = i
        while start > 0 and i - start < 2:
            word = task[start - 1]
            if start - 1 in used or start - 1 in verb_positions or not word.isalpha() or word.endswith("ly"):
                break
            if is_adjective(word) or (word in self._known_words and word not in _COMPOUND_MODIFIERS | OBJECT_NOUNS):
                break
            start -= 1
        opens_phrase = start == 0 or task[start - 1] in DETERMINERS or task[start - 1] in _MODIFIERS or (
            start - 1 in verb_positions
        )
        return " ".join(task[start:i]) if start < i and opens_phrase else None

    def _modifies_next_noun(self, task: list[str], end: int, verb_positions: set[int]) -> bool:
        """Whether the word at `end`, right after a known object word, is the head of their compound: a word the
        rules do not know (or a table object that is no skill's), ending the noun phrase ("toy car in ...")."""
        if end >= len(task) or end in verb_positions:
            return False
        head = task[end]
        if head in NOT_OBJECTS or head in _NOT_HEADS or head.endswith("ly"):
            return False  # "the drawer handle", "the plant today", "the toy quickly"
        after = task[end + 1] if end + 1 < len(task) else "."
        if head.endswith("s") and head not in SUBJECT_VERBS and singular(head) != head and (
            "NOUN" in word_classes(singular(head)) and after in _AFTER_PLURAL_HEAD
        ):
            return True  # "toy cars all over the place", "the tape measures have to stay": a plural noun head
        if head.endswith(("s", "ed", "ing")) and head not in OBJECT_NOUNS:
            return False  # "the drawer ends up open", "the block stays": a verb after its subject
        classes = word_classes(head) if head.isalpha() else frozenset()
        if classes and "NOUN" not in classes:
            return False  # "open the bottle together": an adverb, no noun the bottle word could be part of
        unknown = head not in self._known_words
        table_object = head in OBJECT_NOUNS and head not in self._vocabulary and head not in _NON_OBJECTS
        if not head.isalpha() or not (unknown or table_object):
            return False
        after = task[end + 1] if end + 1 < len(task) else "."
        # what may end such a phrase; not a particle ("the bottle fell over", "the drawer ends up open")
        return after in _SENTENCE_END or after in _DESTINATIONS | _PHRASE_ENDS or after in _COPULAS

    @staticmethod
    def _vocabulary_match(task: list[str], i: int, vocabulary: Sequence[str]) -> str | None:
        multi, single = _vocabulary_index(tuple(vocabulary))
        for entry in multi.get(task[i], ()):
            parts = entry.split()
            window = task[i : i + len(parts)]
            if len(window) == len(parts) and window[:-1] == parts[:-1] and parts[-1] in lemmas(window[-1]):
                return entry
        return next((entry for entry in single if entry in lemmas(task[i])), None)

    @staticmethod
    def _modifiers(task: list[str], i: int) -> tuple[str | None, str | None, str | None]:
        color = size = position = None
        j = i - 1
        while j >= 0 and task[j] in _MODIFIERS:
            if task[j] in POSITION_WORDS:
                opens = (not j or task[j - 1] in _SENTENCE_END or task[j - 1] == ",") and task[j] not in (
                    "left", "right")
                if j and (task[j - 1] in DETERMINERS or task[j - 1] in _MODIFIERS) or opens:
                    # "the top drawer", "bottom drawer is jammed"; not "right the bottle", "left it open"
                    position = position or POSITION_WORDS[task[j]]
            elif task[j] in COLOURS:
                color = color or canonical_attribute(task[j])
            else:
                size = size or canonical_attribute(task[j])
            j -= 1
        return color, size, position

    def _matcher_noun(self, noun: str, vocabulary: Sequence[str]) -> str | None:
        if self.matcher is None or noun in _NON_OBJECTS:
            return None
        index, similarity = self.matcher.best_match(noun, list(vocabulary))
        return vocabulary[index] if similarity >= self.match_threshold else None

    # ---- step 3: skill ----------------------------------------------------------------------

    def _choose_skill(self, instruction: str, parse: Parse) -> SkillSpec:
        verb_skills = {name for verb in parse.verbs for name in self._verbs[verb]}
        phrasal_skills = {name for verb in parse.verbs if " " in verb for name in self._verbs[verb]}
        if not verb_skills and self.matcher is not None and parse.verb_phrase:
            verb_skills = self._matcher_skills(parse.verb_phrase)
        if not verb_skills:
            self._refuse_without_verb(instruction, parse)
        evidence: dict[str, float] = {}
        direct = self._direct_object(parse)
        for skill in self.registry:
            score = 2.0 if skill.name in verb_skills else 0.0
            score += 0.5 if skill.name in phrasal_skills else 0.0  # "pull out" says more than "pull"
            assigned, unplaced = self._assign(skill, parse.nouns)
            # an object only said to be there ("there's a toy on the right") is weaker evidence than the task's own
            score += sum((0.5 if wildcard else 1.0) * self._weight(noun, parse) for noun, wildcard in
                         assigned.values())
            score -= sum(self._weight(noun, parse) for noun in unplaced
                         if noun.known and not self._same_object(skill, noun, assigned))
            evidence[skill.name] = score
            if direct is not None and all(noun is not direct for noun, _ in assigned.values()):
                score -= 2.0  # "put the sponge in the drawer next to the bottle": the verb's own object has no place
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

    def _refuse_without_verb(self, instruction: str, parse: Parse) -> None:
        """No task verb: a negated command, or a verb no skill is asked for with (never planned from nouns)."""
        if parse.negated:
            raise NegatedCommandError(
                instruction, f"'{parse.negated[0]}' asks the robot not to do something, and nothing else is asked"
            )
        word = parse.verb_phrase.split()[0] if parse.verb_phrase else None
        examples = ", ".join(dict.fromkeys(s.verbs[0] for s in self.registry))
        if word is None:
            raise UnknownVerbError(
                instruction,
                f"no skill fits: it has no verb that asks for a task (skills are asked for with: {examples})",
            )
        if lemmas(word) & self._single_verbs:  # "I put the block in the drawer": told, not asked
            raise UnknownVerbError(
                instruction, f"no task is asked for: '{word}' here says what happened or how things are, not what "
                f"to do; ask for it as a command (skills are asked for with: {examples})")
        guess = spelling.suggest(word, sorted(self._single_verbs))
        hint = f"; did you mean '{guess}'?" if guess else ""
        raise UnknownVerbError(
            instruction,
            f"no skill fits: '{word}' is not a verb any skill is asked for with{hint} (skills are asked for with: "
            f"{examples})",
        )

    def _check_fit(self, instruction: str, skill: SkillSpec, parse: Parse) -> None:
        """Refuse a reading that would silently drop or swap an object the user asked to act on: "pour the
        plant into the pan" is not bowl_pour(bowl, pan), nor "sweep the bowl into the pan", nor "pour the pan
        into the bowl", nor "put the microwave in the drawer"."""
        assigned, free = self._assign(skill, parse.nouns)
        slots = f"{skill.name} ({', '.join(skill.slot_words)})"
        for noun in free:
            if noun.known and noun.in_task and not (
                noun.landmark or noun.declared or noun.permitted
            ) and not self._same_object(
                skill, noun, assigned
            ):  # an object said to be there is avoided (`mentions`), not refused: "there's a bowl by the drawer"
                raise InstructionNotUnderstoodError(instruction, f"'{noun.name}' has no place in {slots}")
        specific = [v for v in parse.verbs if v.split()[0] not in _GENERIC_VERBS]
        if specific and not any(skill.name in self._verbs[v] for v in parse.verbs):
            raise InstructionNotUnderstoodError(
                instruction,
                f"'{specific[0]}' is not how {skill.name} is asked for; known skills: {', '.join(self.registry.names)}",
            )
        fixtures = {
            w
            for s in self.registry
            for slot in s.slots
            if not slot.carried and not slot.accepts_any
            for w in slot.synonyms
        }
        for noun, wildcard in assigned.values():
            # a compound names another thing of its own ("the phone charger" is carried, "the charger" is a base)
            if wildcard and singular(noun.name) in PEOPLE:
                raise InstructionNotUnderstoodError(instruction, f"'{noun.name}' is a person or an animal; "
                                                    f"{skill.name} moves objects only")
            if wildcard and noun.name in fixtures and (not noun.compound or f"{noun.compound} {noun.name}" in fixtures):
                raise InstructionNotUnderstoodError(instruction, f"'{noun.name}' cannot be carried by {skill.name}")
        carried = skill.carried_slot
        for k, (noun, _) in assigned.items():
            if carried is not None and k != carried and noun.source:
                raise InstructionNotUnderstoodError(
                    instruction,
                    f"it asks to take something out of or off the {noun.name}, but {skill.name} puts the "
                    f"{skill.slots[carried].word} there",
                )
        held = assigned[carried][0] if carried is not None and carried in assigned else None
        # "put the cork back in the wine bottle": the object said after "in" / "on" is where something goes
        placed_in = held is not None and _placed_in_or_on(parse.tokens, held.index)
        if held is not None and (held.destination or placed_in):
            others = [n for k, (n, _) in assigned.items() if k != carried]
            if not any(n.destination for n in others) and (others or placed_in):
                where = ", ".join(n.name for n in others) or skill.slots[-1].word
                into = "into" if held.destination else "in or on"
                raise InstructionNotUnderstoodError(
                    instruction,
                    f"it asks to move things {into} the {held.name}, but {skill.name} carries the "
                    f"{skill.slots[carried].word} to the {where}",
                )

    def _matcher_skills(self, verb_phrase: str) -> set[str]:
        verbs = list(self._verbs)
        index, similarity = self.matcher.best_match(verb_phrase, verbs)
        return set(self._verbs[verbs[index]]) if similarity >= self.match_threshold else set()

    @staticmethod
    def _assign(skill: SkillSpec, nouns: list[_Noun]) -> tuple[dict[int, tuple[_Noun, bool]], list[_Noun]]:
        """Slot index -> (noun, filled as wildcard); and the nouns left over."""
        assigned: dict[int, tuple[_Noun, bool]] = {}
        # "there are two bowls. pour the red one ...", "if there are two drawers, open the top drawer": what is
        # said to be there fills a slot last
        free = sorted(nouns, key=lambda n: (n.permitted, not n.in_task, n.declared))
        for k, slot in enumerate(skill.slots):
            # A landmark ("past the block", "next to the drawer") fills a slot only when nothing else can: for the
            # item slot, any other noun said as the object can ("move the teapot past the block").
            plain = [n for n in free if not n.landmark]
            landmarks = [] if slot.accepts_any else [n for n in free if n.landmark]
            noun = next((n for n in plain if _exact(slot, n.name)), None) or next(
                (n for n in [*plain, *landmarks] if slot.matches(n.name)), None
            )
            if noun is not None:
                assigned[k] = (noun, False)
                free.remove(noun)
        for k, slot in enumerate(skill.slots):
            if k in assigned or not slot.accepts_any:
                continue
            # The object of the verb, not a landmark, a destination or a source ("put the block next to the vase
            # in the drawer"), and not an object the registry knows for another slot.
            unplaced = [n for n in free if not any(s.matches(n.name) for s in skill.slots)]
            plain = [n for n in unplaced if not (n.landmark or n.destination or n.source)]
            noun = next(iter(plain or unplaced), None)
            if noun is None:
                noun = next((n for n in free if slot.matches(n.name)), None)  # only a landmark names it
                if noun is not None:
                    assigned[k] = (noun, False)
                    free.remove(noun)
                    continue
                noun = next(iter(free), None)
            if noun is not None:
                assigned[k] = (noun, True)
                free.remove(noun)
        return assigned, free

    @staticmethod
    def _direct_object(parse: Parse) -> _Noun | None:
        """In "put X in/on Y": X, the object the placing verb acts on (None for any other shape of request)."""
        if not parse.verb_at:
            return None
        position = parse.verb_at[0][0]
        if any(v.split()[0] not in _GENERIC_VERBS or not set(v.split()[1:]) <= _DESTINATIONS
               for p, v in parse.verb_at if p == position):
            return None  # only "put X in/on Y": "take the cap off", "brush against" say no placement
        k = position + 1
        while k < len(parse.tokens) and (parse.tokens[k] in DETERMINERS or parse.tokens[k] in _MODIFIERS):
            k += 1
        noun = next((n for n in parse.nouns if n.index == k), None)
        placed = noun is not None and noun.end < len(parse.tokens) and parse.tokens[noun.end] in _DESTINATIONS
        return noun if placed else None

    @staticmethod
    def _weight(noun: _Noun, parse: Parse) -> float:
        """How much a noun says about the skill: half for one only said to be somewhere ("there's a toy on the
        right", "the pill organiser sits on top of it")."""
        tokens = parse.tokens
        located = any(w in SUBJECT_VERBS or w in _STANCE for w in tokens[noun.index : noun.end + 1])
        k = noun.index - 1
        while k >= 0 and (tokens[k] in DETERMINERS or tokens[k] in _MODIFIERS or is_adjective(tokens[k])):
            k -= 1
        there = k >= 0 and (tokens[k] == "theres" or tokens[k] in _COPULAS and tokens[k - 1 : k] == ["there"])
        said_to_be = noun.end < len(tokens) and tokens[noun.end] in _COPULAS - {"'s"}  # "the fan is right by it"
        return 1.0 if noun.in_task and not located and not there and not said_to_be else 0.5

    @staticmethod
    def _same_object(skill: SkillSpec, noun: _Noun, assigned: dict[int, tuple[_Noun, bool]]) -> bool:
        """A leftover noun that names an already filled slot again ("the bottle of wine")."""
        return any(skill.slots[k].matches(noun.name) for k in assigned)

    def _resolve_references(self, instruction: str, skill: SkillSpec, parse: Parse) -> None:
        """ "there's a vase nearby, avoid it": a pronoun in an obstacle declaration means an object named
        before it that is not a target. Several candidates: all are avoided and a warning says so; only
        targets: no obstacle, a warning; nothing at all: a refusal, since the obstacle cannot be dropped."""
        avoided_at: list[int] = []  # where the objects earlier references resolved to were named
        for reference in parse.references:
            assigned, free = self._assign(skill, parse.nouns)
            targets = [noun for noun, _ in assigned.values()]
            before = sorted((n for n in free if n.index < reference.index), key=lambda n: n.index)
            # "the vase was my grandmother's, so be careful with it": the owner is no object to avoid
            before = [n for n in before if not (
                not n.known and parse.tokens[n.end : n.end + 1] == ["'s"] and possessive(parse.tokens, n.end)
                and parse.tokens[n.end + 1 : n.end + 2] in ([], *([w] for w in _SENTENCE_END), [","], ["and"]))]
            before = [n for n in before if not predicate_noun(parse.tokens, n.index - 1)]  # "... was a gift"
            # "sweep the sand into the dustpan, ... don't knock them": what is swept is dirt, never meant
            before = [n for n in before if not _swept(parse.tokens, n.index)]
            # "my glasses are on the table, don't break them", "it got water yesterday, don't get it wet", "it
            # belongs to my neighbour", "my kids left a ball ...": no object a pronoun means
            before = [n for n in before if n.name not in _SURFACES and n.name not in NOT_OBJECTS
                      and not named_in_passing(n.name, parse.tokens, n.index, n.index + len(n.name.split()))]
            others = [n for n in before if not any(_same_thing(skill, n, t) for t in targets)]
            # "water the plant, keep the can away from it": the unsaid watering can, named by its head, is the tool
            unsaid = [ObjectRef(name=slot.word) for k, slot in enumerate(skill.slots) if k not in assigned]
            others = [n for n in others if not any(_short_for(n.ref(), ref) for ref in unsaid)]
            if reference.kind == "other":
                others = self._other_one(skill, reference, before, others, targets, parse)
            declared_before = [k for k, _ in parse.declared if k < reference.index]
            declared_before += [k for k in avoided_at if k < reference.index]  # "..., don't touch that one" again
            if not others and declared_before:
                k, last = max(((k, ref) for k, ref in parse.declared if k < reference.index), key=lambda d: d[0],
                              default=(-1, None))
                target = next((t for t in targets if last is not None and k > max(avoided_at, default=-1) and (
                    last.name == t.ref().name or _short_for(last, t.ref())) and all(
                    getattr(last, a) in (None, getattr(t.ref(), a)) for a in ("color", "size", "position"))), None)
                if target is not None and not _is_care(reference.text):
                    raise ContradictionError(  # "pour the bowl into the pan, mind the pan, don't touch it"
                        instruction, f"'{reference.text}' means {target.ref().phrase}, which {skill.name} acts on; "
                        "say which object to keep away from")
                continue  # "the plate is in the way, so go around it": an obstacle already
            if not others:
                # "there's dolls, teddy bears and toy cars about, go around them": objects only the mention finder
                # reads (no determiner, words no rule knows); never one of the targets
                named = [m for m in parse.mentions if m.index < reference.index and not m.permitted and not any(
                    m.name in (t.name, t.ref().name) or _short_for(m, t.ref()) for t in targets)]
                if named:
                    if reference.kind == "it" and len(named) > 1:
                        parse.warnings.append(f"'{reference.text}' may mean {' or '.join(m.phrase for m in named)}; "
                                              "avoiding all of them")
                    parse.obstacles.extend(m.ref() for m in named)
                    continue
            if not others:
                named = [t for t in sorted(targets, key=lambda t: t.index) if t.index < reference.index]
                if named and not _is_care(reference.text):
                    raise ContradictionError(
                        instruction,
                        f"'{reference.text}' can only mean what {skill.name} acts on "
                        f"({', '.join(t.ref().phrase for t in named)}); say which object to keep away from",
                    )
                if named:
                    parse.warnings.append(
                        f"'{reference.text}' can only mean a target ({', '.join(t.ref().phrase for t in named)}); "
                        f"a target is never made an obstacle"
                    )
                    continue
                raise UncertainObstacleError(
                    instruction, f"'{reference.text}' refers to no object named before it; name the obstacle"
                )
            chosen = others
            if reference.kind == "it" and len(others) > 1:
                parse.warnings.append(
                    f"'{reference.text}' may mean {' or '.join(n.ref().phrase for n in others)}; avoiding all of them"
                )
            avoided = [(noun.end - 1, _fuller_name(noun.ref(), noun.end - 1, parse.mentions)) for noun in chosen]
            if reference.kind == "them":
                # "there are coffee tins and some paint brushes nearby, keep off them": every object of the
                # sentence before it, also those only the mention reader finds (no determiner, a word no rule knows)
                sentence = _running_count(parse.tokens, frozenset(".!?"))  # "there are X and Y; avoid them"
                avoided += [(m.index, m.ref()) for m in parse.mentions if m.index < reference.index and (
                    sentence[m.index] == sentence[reference.index]) and not m.permitted and not any(
                    n.index <= m.index < n.end for n in chosen) and not any(
                    m.name in (t.name, t.ref().name) or _short_for(m, t.ref()) for t in targets)
                    and m.ref() not in parse.obstacles]
            for noun in chosen:
                if noun in parse.nouns:
                    parse.nouns.remove(noun)
                avoided_at.append(noun.index)
            parse.obstacles.extend(ref for _, ref in sorted(avoided, key=lambda a: a[0]))

    @staticmethod
    def _other_one(skill, reference, before, others, targets, parse) -> list[_Noun]:
        """ "the other one": an object of a target's kind that is not the target (named before, or implied)."""
        named_before = [t for t in targets if t.index < reference.index] or targets
        if not named_before:
            return others
        same_kind = [n for n in others if any(n.name == t.name for t in named_before)]
        if same_kind:
            return same_kind
        contrasted = [t for t in named_before if t.color or t.size or t.position] or named_before
        target = max(contrasted, key=lambda t: t.index)
        if len({t.name for t in named_before}) > 1 and not (target.color or target.size or target.position):
            parse.warnings.append(f"'{reference.text}' read as the other {target.name}")
        return [_Noun(target.name, None, None, known=True, index=reference.index, position="other")]

    # ---- step 4: slots and scene ------------------------------------------------------------

    def _fill_slots(self, skill: SkillSpec, nouns: list[_Noun]) -> tuple[list[ObjectRef], dict[int, _Noun]]:
        """The targets in slot order (a slot nothing fills takes its word), and the noun that filled each slot."""
        assigned, _ = self._assign(skill, nouns)
        targets = []
        for k, slot in enumerate(skill.slots):
            if k not in assigned:
                targets.append(ObjectRef(name=slot.word))
                continue
            noun, wildcard = assigned[k]
            if noun.compound:  # a kind of the slot's object, named as typed ("mixing bowl"); grounded by its head
                targets.append(noun.ref())
                continue
            keep_own_name = wildcard or (slot.accepts_any and not _exact(slot, noun.name))
            targets.append(noun.ref(None if keep_own_name else slot.word))
        return targets, {k: noun for k, (noun, _) in assigned.items()}

    @staticmethod
    def _drop_targets(
        instruction: str, skill: SkillSpec, targets: list[ObjectRef], parse: Parse, typed: Mapping[int, str]
    ) -> list[ObjectRef]:
        """Obstacles without those that are a target. Care said of a target ("pour the bowl into the pan, don't
        spill the bowl", "the bowl is hot") is kept as a warning; distance from it ("without touching the
        bottle", "avoid the bowl") is a contradiction, refused. `typed` (slot index -> the word the target was
        named with): another word of the slot names another object (`mentions.names_another`)."""
        kept = []
        for obstacle in parse.obstacles:
            same = [
                t
                for k, (slot, t) in enumerate(zip(skill.slots, targets, strict=True))
                if (
                    _exact(slot, obstacle.name) and slot.matches(t.name)
                    and not names_another(obstacle.name, slot.word, typed.get(k))
                    or obstacle.name == t.name
                )
                and obstacle.position != "other"
                and all(getattr(obstacle, a) in (None, getattr(t, a)) for a in ("color", "size", "position"))
            ]
            if not same:
                kept.append(obstacle)
                continue
            cue = parse.cue_of.get(obstacle, "")
            if "between" in cue.split():
                continue  # "the dustpan sits between the dog bed and the stand": where the target is, no caution
            # care for every object of the target's kind ("mind all the blocks") is care for the target too
            every = any(ref == obstacle and parse.tokens[k : k + 1] in (["all"], ["every"], ["each"], ["any"])
                        for k, ref in parse.declared)
            # "mind the pan" keeps away from it as "mind the mug" does; "mind the pan's handle" asks for care
            part = any(ref == obstacle and _PARTS & set(parse.tokens[k : k + 6]) for k, ref in parse.declared)
            minded = cue.split()[:1] == ["mind"] and not part
            if not _is_care(cue) or every or minded:
                raise ContradictionError(
                    instruction,
                    f"'{same[0].phrase}' is the object {skill.name} acts on, and '{cue or 'avoid'}' says to keep "
                    f"away from it; say which it is",
                )
            parse.warnings.append(
                f"'{obstacle.phrase}' is said to be handled with care ('{cue}') and is the target {same[0].phrase} of "
                f"{skill.name}; it is not made an obstacle"
            )
        return kept


def _short_for(said: Mention | ObjectRef, target: ObjectRef) -> bool:
    """ "the can" said after "the watering can": a target's compound name said by its head alone (no attribute
    that differs) is the target."""
    words, theirs = said.name.split(), target.name.split()
    return set(words) < set(theirs) and words[-1] == theirs[-1] and all(
        getattr(said, a) in (None, getattr(target, a)) for a in ("color", "size", "position"))


def _fuller_name(ref: ObjectRef, head: int, mentions: Sequence[Mention]) -> ObjectRef:
    """`ref` named as the mention reader names the noun phrase whose head is at `head` (or the word after it), where
    that name holds `ref`'s and is longer ("there are flower pots about, don't touch them": the flower pots, not any
    pot; "the jerry can can tip over, go around it": the jerry can)."""
    mention = next((m for m in mentions if m.index == head), None) or next(
        (m for m in mentions if m.index == head + 1 and m.name.startswith(ref.name + " ")), None)
    if mention is None or not (mention.name.endswith(" " + ref.name) or mention.name.startswith(ref.name + " ")):
        return ref
    return ObjectRef(name=mention.name, color=ref.color, size=ref.size, position=ref.position)


def _is_care(cue: str) -> bool:
    """After a negation only what is not to be done counts: "careful not to knock" asks for care, "careful not to
    touch" for distance, as "don't touch" does."""
    words = cue.split()
    negation = next((k for k, word in enumerate(words) if word in _NEGATIONS), None)
    return any(lemmas(word) & _CARE_WORDS for word in words[negation + 1 if negation is not None else 0 :])


_QUESTION_WORDS = frozenset("is are was were do does did where what why when who which how has have am".split())
_WH_WORDS = frozenset("where what why when who which how".split())
_AUXILIARIES = frozenset("did do does is are was were has have had can could will would should".split())
_REQUEST_FRAMES = frozenset("could would can will please mind may shall kindly".split())
_YES_NO_AUXILIARIES = frozenset("is are was were does did has have".split())


_CANCEL_WORDS = frozenset("cancel cancelled canceled cancelling aborted abort".split())  # not "scrap paper"
_CANCEL_PHRASES: tuple[tuple[str, ...], ...] = (
    ("do", "not", "execute"), ("don't", "execute"), ("not", "execute"), ("do", "not", "run", "it"),
    ("don't", "run", "it"), ("don't", "run", "this"),
    ("must", "not", "do"), ("mustn't", "do"), ("do", "not", "do"), ("don't", "do", "it"), ("don't", "do", "this"),
    ("don't", "do", "that"), ("never", "do", "it"), ("never", "do", "this"), ("never", "do", "that"),
    ("should", "not", "do"), ("shouldn't", "do"),
)  # fmt: skip


def _refuse_cancelled(instruction: str, tokens: Sequence[str]) -> None:
    """ "cmd: water plant; status=cancelled", "put the phone on the base, this you must not do": the task is
    called off as a whole."""
    for i, word in enumerate(tokens):
        phrase = next((p for p in _CANCEL_PHRASES if tuple(tokens[i : i + len(p)]) == p), None)
        if word in _CANCEL_WORDS or phrase:
            said = " ".join(phrase) if phrase else word
            raise NegatedCommandError(instruction, f"'{said}' calls the task off; nothing is asked")


def _refuse_question(instruction: str, parse: Parse) -> None:
    """ "is the drawer open?", "where did you put the phone?": a question asks for an answer, not a task. A
    request put as a question ("could you put the block in the drawer?") is a task."""
    tokens = parse.tokens
    for position, _ in parse.verb_at[:1]:
        start = max((k + 1 for k in range(position) if tokens[k] in _SENTENCE_END), default=0)
        end = next((k for k in range(position, len(tokens)) if tokens[k] in _SENTENCE_END), len(tokens))
        asked = end < len(tokens) and tokens[end] == "?" and tokens[start] in _QUESTION_WORDS
        # "where did you put the broom", typed without its "?": a wh-word and an auxiliary ask all the same
        asked = asked or tokens[start] in _WH_WORDS and tokens[start + 1 : start + 2] in [[a] for a in _AUXILIARIES]
        # "is the drawer open", "did the bottle fall over": an auxiliary before a noun phrase asks; not "is it
        # possible to ...", "are you able to ...", which request
        asked = asked or tokens[start] in _YES_NO_AUXILIARIES and tokens[start + 1 : start + 2] in [
            [d] for d in DETERMINERS]
        sentence = tokens[start : end + 1]
        if end < len(tokens) and tokens[end] == "?":
            # "if I asked you to open the bottle, how would you do it?": a wh-question after a clause
            asked = asked or any(
                w in _WH_WORDS - {"which", "who"} and sentence[k + 1 : k + 2] in [[a] for a in _AUXILIARIES]
                for k, w in enumerate(sentence)
            )
            # "drawer open or closed?": no request frame, no verb that opens the sentence
            request = any(w in _REQUEST_FRAMES for w in sentence)
            opens = sentence[:1] and (lemmas(sentence[0]) & {v for _, v in parse.verb_at} or sentence[0] in _POLITE)
            asked = asked or (not request and not opens and "or" in sentence)
        if asked:
            raise InstructionNotUnderstoodError(instruction, "it is a question, not a task; say what to do")


def _check_outcome(instruction: str, skill: SkillSpec, tokens: Sequence[str], filled: Mapping[int, _Noun]) -> None:
    """Refuse a request for an outcome the skill does not produce: "slide the drawer shut" is no open_drawer, and
    "lay the bottle on its side" or "put the phone on the table" is no placement in the drawer or on the base (the
    skill's destination, not named, would be taken instead)."""
    for i in range(len(tokens) - 2):
        lying = tokens[i] in ("on", "onto") and tokens[i + 1] in ("its", "their", "the") and tokens[i + 2] == "side"
        state = i and (tokens[i - 1] in _COPULAS or tokens[i - 1] in ("lying", "fell", "fallen") or past_verb_form(
            tokens[i - 1]))  # "it's lying on its side", "it fell on its side": how it is now
        if lying and not state and (i + 3 >= len(tokens) or tokens[i + 3] != "of"):  # not "on the side of the table"
            raise InstructionNotUnderstoodError(
                instruction, f"'{' '.join(tokens[i : i + 3])}' asks for an object to end up lying down, which "
                             f"{skill.name} does not do; no skill fits")
    for noun in filled.values():
        result = tokens[noun.end] if noun.end < len(tokens) else ""
        opposite = {"shut": "open", "closed": "open", "open": "close"}.get(result)
        before = noun.index - 1
        while before > 0 and tokens[before] not in _KEEPING and (
            tokens[before] in DETERMINERS or tokens[before] in _MODIFIERS
        ):
            before -= 1  # "left" is a side as well
        if before >= 0 and (tokens[before] in _KEEPING or past_verb_form(tokens[before])):
            continue  # "somebody left the microwave open": how it is now, not the outcome asked for
        if opposite and skill.name.startswith(opposite):
            raise InstructionNotUnderstoodError(
                instruction, f"'{noun.name} {result}' asks for the {noun.name} to end up {result}, which "
                             f"{skill.name} does not do; no skill fits")
    destinations = [k for k, slot in enumerate(skill.slots) if not slot.carried and k not in filled]
    carried_named = any(slot.carried and k in filled for k, slot in enumerate(skill.slots))
    if not destinations or not carried_named:
        return  # "sweep the crumbs on the table": the place is where the dirt is, not where a named object goes
    for i, word in enumerate(tokens):
        if word not in _DESTINATIONS:
            continue
        k = i + 1
        while k < len(tokens) and (tokens[k] in DETERMINERS or tokens[k] in ("'s", "own")):
            k += 1
        after_carried = any(slot.carried and k_ in filled and filled[k_].end in (i, i - 1) and (
            filled[k_].end == i or tokens[i - 1] in ("back", "down")) for k_, slot in enumerate(skill.slots))
        # "put the block on the plate": a place said right after the carried object that is no slot of the skill
        # is where the user wants it, so the skill's own destination (the drawer) would be the wrong place
        # nothing is put "on" or "onto" a drawer: there any noun is another place ("slide the mobile onto the stand")
        on_not_in = word in ("on", "onto") and all(skill.slots[d].word == "drawer" for d in destinations)
        other_place = after_carried and k < len(tokens) and tokens[k].isalpha() and tokens[k] not in NOT_OBJECTS and (
            word_classes(tokens[k]) == {"NOUN"} or singular(tokens[k]) in OBJECT_NOUNS  # not "the stand"
            or on_not_in and "NOUN" in word_classes(tokens[k])
        ) and not any(slot.matches(singular(tokens[k])) for slot in skill.slots)
        other_place = other_place and not {"its", "their"} & set(tokens[i + 1 : k])  # "on its stand": its own base
        if k < len(tokens) and (tokens[k] in _SURFACES or other_place):
            said = " ".join(tokens[i : k + 1])
            raise InstructionNotUnderstoodError(
                instruction, f"'{said}' is not where {skill.name} puts things (the "
                             f"{', '.join(skill.slots[d].word for d in destinations)}); no skill fits")


def _check_pronoun_object(instruction: str, skill: SkillSpec, parse: Parse, filled: Mapping[int, _Noun]) -> None:
    """ "the blue container, pour it in the pan": "it" is the object named before, which no slot of the skill
    took; the slot's own word ("bowl") would stand for it, so any bowl would be poured. Refused, naming it."""
    if len(filled) == len(skill.slots):
        return
    obstacles = set(parse.obstacles)
    objects = {m.index for m in parse.mentions}  # not "I spilled some flour, can you sweep it ...": dirt
    for position, verb in parse.verb_at:
        pronoun = parse.tokens[position + 1] if position + 1 < len(parse.tokens) else ""
        if pronoun not in ("it", "them"):
            continue
        named = [n for n in parse.nouns if n.index < position and n not in filled.values() and n.in_task and not (
            n.landmark or n.declared or n.permitted or n.ref() in obstacles) and objects & set(range(n.index, n.end))]
        if named:
            raise InstructionNotUnderstoodError(
                instruction, f"'{verb.split()[0]} {pronoun}' means the {named[-1].ref().phrase}, which {skill.name} "
                f"({', '.join(skill.slot_words)}) cannot act on; name the object it is for")


def _check_obstacle_count(instruction: str, obstacles: Sequence[ObjectRef]) -> None:
    count = len(set(obstacles))
    if count > MAX_OBSTACLES:
        raise InstructionNotUnderstoodError(
            instruction, f"it names {count} objects to keep away from; at most {MAX_OBSTACLES} are accepted"
        )


def _with_shared_synonyms(registry: SkillRegistry) -> SkillRegistry:
    """The registry with each slot's synonyms shared by every slot of the same word: a "flask" is a bottle in
    open_wine_bottle too, since bottle_in_drawer says so ("open the flask")."""
    shared: dict[str, tuple[str, ...]] = {}
    for skill in registry:
        for slot in skill.slots:
            shared[slot.word] = tuple(dict.fromkeys([*shared.get(slot.word, ()), *slot.synonyms]))
    return SkillRegistry(
        skill.model_copy(
            update={"slots": tuple(slot.model_copy(update={"synonyms": shared[slot.word]}) for slot in skill.slots)}
        )
        for skill in registry
    )  # fmt: skip


def _noun_before_copula(words: Sequence[str], k: int) -> bool:
    """ "the cake stand is wobbly": "stand" or "sit" right before "is" names the thing, it is no copula."""
    return words[k] in ("stand", "sit") and words[k + 1 : k + 2] in (["is"], ["'s"], ["was"])


def _may_happen(tokens: Sequence[str], i: int) -> bool:
    """ "the water could spill", "the vase might break": a modal after a noun (its subject) says what may
    happen; "could you ...", "you could ..." ask."""
    return i >= 2 and tokens[i - 1] in _MODALS_AFTER_SUBJECT and tokens[i - 2].isalpha() and (
        tokens[i - 2] not in _POLITE and "NOUN" in word_classes(tokens[i - 2])
        or tokens[i - 2] in ("it", "they", "which", "and"))  # "the glass is full and could spill"


def _task_repeated_on(tokens: Sequence[str], object_words: set[str]) -> str | None:
    """ "put the red block in the drawer and then the blue one", "..., then the green one too": a noun phrase
    alone after "and then" / "then", or with "too" / "as well", repeats the task on another object. The words
    said, or None. `object_words`: nouns the lexicon may not class as nouns ("pan")."""
    for i, word in enumerate(tokens):
        opener = word == "then" and i > 0 and tokens[i - 1] in ("and", ",")
        if not opener and not (word == "and" and tokens[i + 1 : i + 2] in (["also"], ["the"], ["a"])):
            continue
        k = i + 1 + (tokens[i + 1 : i + 2] == ["also"])
        if tokens[k : k + 1] not in (["the"], ["a"], ["an"], ["that"], ["this"]):
            continue
        end = k + 1
        while end < len(tokens) and tokens[end].isalpha() and (tokens[end] in _MODIFIERS or tokens[end] in COLOURS or (
            "NOUN" in word_classes(tokens[end]) or singular(tokens[end]) in object_words or tokens[end] == "one"
        )) and tokens[end] not in _BOUNDARY:
            end += 1
        rest = tokens[end:]
        too = rest[:1] == ["too"] or rest[:2] == ["as", "well"]
        rest = rest[1 if rest[:1] == ["too"] else 2 if too else 0 :]
        alone = not rest or rest[0] in _SENTENCE_END
        if end > k + 1 and alone and (opener or too):
            return " ".join(tokens[i - opener : end])
    return None


def _after_wanted_object(tokens: Sequence[str], position: int) -> bool:
    """ "I want the drawer opened (and the block put in it)": a verb after the object of "want", or after a noun
    phrase joined to it, is a task of its own."""
    k = position - 1
    if k < 0 or not (tokens[k].isalpha() and "NOUN" in word_classes(tokens[k])):
        return False
    while k >= 0 and tokens[k] not in _TASK_BREAKS and not _asks_done(tokens, k) and (
        tokens[k] in DETERMINERS or tokens[k] in _MODIFIERS or tokens[k] in COLOURS
        or tokens[k].isalpha() and "NOUN" in word_classes(tokens[k])
    ):
        k -= 1
    wanted_before = any(_asks_done(tokens, j) for j in range(position))
    return k >= 0 and wanted_before and (_asks_done(tokens, k) or tokens[k] in ("and", ","))


def _asks_done(tokens: Sequence[str], k: int) -> bool:
    """ "I want (the drawer opened)", "(could you) get / have (the plant watered)": the word before an object asks
    for what is done to it. After "I", a causative tells how it is ("I have the drawer opened")."""
    return tokens[k] in _WANTING_DONE or tokens[k] in _CAUSATIVES and not (k and tokens[k - 1] in _NARRATORS)


def _running_count(words: Sequence[str], marks) -> list[int]:
    """For each token, how many of `marks` come before it (the sentence or clause it is in)."""
    counts, seen = [], 0
    for word in words:
        counts.append(seen)
        seen += word in marks
    return counts


@functools.lru_cache(maxsize=64)
def _vocabulary_index(vocabulary: tuple[str, ...]) -> tuple[dict[str, list[str]], list[str]]:
    """Multi-word entries by their first word (longest first), and the single words in `vocabulary` order: a
    lookup per token instead of a scan of the vocabulary (bounded time on a 1,000-character instruction)."""
    multi: dict[str, list[str]] = {}
    for entry in sorted((e for e in vocabulary if " " in e), key=lambda e: -len(e.split())):
        multi.setdefault(entry.split()[0], []).append(entry)
    return multi, [e for e in vocabulary if " " not in e]


def _exact(slot: Slot, noun: str) -> bool:
    return noun in slot.synonyms or singular(noun) in slot.synonyms


def _same_thing(skill: SkillSpec, noun: _Noun, target: _Noun) -> bool:
    """Whether a mention is (or may be) the target again: the same kind, no attribute that tells them apart."""
    same_kind = noun.name == target.name or any(s.matches(noun.name) and s.matches(target.name) for s in skill.slots)
    same_kind = same_kind or _short_for(noun.ref(), target.ref())  # "the can" after "the watering can"
    if not same_kind or noun.position == "other":
        return False
    return all(
        getattr(noun, a) is None or getattr(target, a) is None or getattr(noun, a) == getattr(target, a)
        for a in ("color", "size", "position")
    )


_POST_POSITIONS = {
    ("on", "the", "left"): "left", ("on", "the", "right"): "right", ("to", "the", "left"): "left",
    ("to", "the", "right"): "right", ("on", "your", "left"): "left", ("on", "your", "right"): "right",
    ("to", "your", "left"): "left", ("to", "your", "right"): "right", ("at", "the", "top"): "top",
    ("at", "the", "bottom"): "bottom", ("on", "top"): "top", ("at", "the", "back"): "back",
    ("at", "the", "front"): "front", ("in", "front"): "front", ("in", "the", "back"): "back",
    ("at", "the", "rear"): "rear", ("in", "the", "rear"): "rear",
    ("in", "the", "front"): "front", ("on", "the", "bottom"): "bottom", ("in", "the", "middle"): "middle",
    ("in", "the", "centre"): "centre", ("in", "the", "center"): "center", ("nearest",): "nearest",
    ("closest",): "closest", ("farthest",): "farthest", ("furthest",): "furthest",
    ("on", "the", "middle"): "middle", ("at", "the", "middle"): "middle",
    **{(at, "the", side, "side"): side for at in ("on", "at", "to") for side in ("left", "right")},
}  # fmt: skip


def _polite_requests(words: list[str]) -> list[str]:
    """ "would you mind opening the bottle" asks for the task: "mind" there is politeness, not the obstacle cue of
    "mind the mug", and the gerund is the verb."""
    out = list(words)
    for i in range(1, len(out) - 1):
        if out[i] == "mind" and out[i - 1] == "you" and out[i + 1].endswith("ing"):
            out[i] = "please"
        if out[i - 1] == "let" and out[i] in ("'s", "us") and (i < 2 or out[i - 2] in _TASK_BREAKS):
            out[i - 1 : i + 1] = [",", "please"]  # "let's open the bottle" asks for it
        if out[i - 1] == "you" and out[i] in ("are", "'re") and out[i + 1].endswith("ing") and (
            i < 2 or out[i - 2] in _TASK_BREAKS or out[i - 2] in _POLITE
        ):
            out[i - 1 : i + 1] = [",", "please"]  # "you are opening the drawer now please": a request
        if out[i - 1] == "come" and out[i] == "on" and (i < 2 or out[i - 2] in _TASK_BREAKS):
            out[i - 1 : i + 1] = [",", "please"]  # "come on, ...": encouragement, not a verb of moving
    return out


def _colour_phrases(words: list[str]) -> list[str]:
    """ "the phone of grey colour", "a cup in red colour" -> "the grey phone", "a red cup"; "the red and the blue
    bottles" -> "the red bottle and the blue bottles": a colour whose noun is said only with the next one."""
    out = list(words)
    for i in range(len(out) - 5, -1, -1):
        if out[i] in ("the", "a") and out[i + 1] in COLOURS and out[i + 2] in ("and", "or") and (
            out[i + 3] == "the" and out[i + 4] in COLOURS and out[i + 5].isalpha()
        ) and out[i + 5] not in _BOUNDARY | _MODIFIERS:
            out[i + 2 : i + 2] = [singular(out[i + 5])]
    i = 1
    while i + 2 < len(out):
        k = i + 1 + (out[i + 1] in ("a", "the"))
        if out[i] in ("of", "in") and k + 1 < len(out) and out[k] in COLOURS and out[k + 1] in ("colour", "color"):
            noun = i - 1
            if out[noun].isalpha() and out[noun] not in _BOUNDARY:
                out[noun : k + 2] = [out[k], out[noun]]
                continue
        i += 1
    return out


_COUNTS = frozenset("two three four five several both".split())


_RELATIVE_SUPERLATIVES = frozenset({("nearest",), ("closest",), ("farthest",), ("furthest",)})


def _subject_of_verb(words: Sequence[str], i: int) -> bool:
    """A determiner-led noun phrase at `i` followed by an auxiliary, a copula or a negation: a clause's subject."""
    if words[i] not in DETERMINERS:
        return False
    k = i + 1
    while k < len(words) and k - i < 5 and words[k].isalpha() and words[k] not in _BOUNDARY:
        k += 1
    after = words[k] if k < len(words) else "."
    return after in _COPULAS or after in _AUXILIARIES or after.endswith("n't") or after in _NEGATORS


def _nearest_to(task: Sequence[str], k: int) -> bool:
    """ "the bottle nearest (to) the microwave": a superlative of place before a determiner relates to a
    landmark."""
    superlative = (task[k],) in _RELATIVE_SUPERLATIVES or task[k] == "to" and k > 0 and (
        task[k - 1],) in _RELATIVE_SUPERLATIVES
    return superlative and task[k + 1 : k + 2] in [[d] for d in DETERMINERS]


def _partitives(words: list[str]) -> list[str]:
    """ "the leftmost of the three blocks", "the larger of the two bowls" -> "the leftmost block", "the larger
    bowl": the attribute picks one of the objects named after "of"."""
    out = list(words)
    i = 1
    while i + 3 < len(out):
        picks = out[i] in _MODIFIERS and out[i - 1] in ("the", "a") and out[i + 1] == "of" and out[i + 2] == "the"
        picks = picks and (i < 2 or out[i - 2] not in _BOUNDARY)  # not a place: "to the right of the pan"
        k = i + 3 + (out[i + 3] in _COUNTS)
        if picks and k < len(out) and out[k].isalpha() and out[k] not in _BOUNDARY:
            out[i + 1 : k + 1] = [singular(out[k])]
        i += 1
    return out


# Nouns that count or gather what follows "of": "a couple of pipettes" names pipettes, not a couple.
_INSIDE_OR_ON = frozenset("in into inside on onto".split())
_QUANTITY_NOUNS = frozenset(
    """couple pair lot lots loads load bunch bunches pile piles stack stacks heap heaps handful number dozen dozens
    plenty row rows set group collection bundle cluster coil coils splash dash""".split()
)


def _in_existential_list(words: Sequence[str], i: int, verb_positions: set[int]) -> bool:
    """Whether the noun at `i` is in the list a "there is / there are" opened, no verb nor sentence end between."""
    k = i - 1
    while k >= 1 and k not in verb_positions and words[k] not in _SENTENCE_END:
        if words[k - 1] == "there" and words[k] in (*_COPULAS, "'s", "'re"):
            return True
        if words[k] == "theres":
            return True
        if words[k] not in _LIST_SEPARATORS and words[k] in _BOUNDARY and words[k] not in DETERMINERS:
            return False  # "there's a mug by the drawer, open it": a landmark or a new clause
        k -= 1
    return False


def _swept(words: Sequence[str], i: int) -> bool:
    """The noun at `i` is what a sweep verb acts on ("sweep the sand into ..."): dirt, no object."""
    k = i - 1
    while k >= 0 and (words[k] in DETERMINERS or words[k] in _MODIFIERS):
        k -= 1
    return k >= 0 and bool(lemmas(words[k]) & SWEEP_VERBS)


def _in_subject_list(words: Sequence[str], end: int, verb_positions: set[int]) -> bool:
    """Whether the noun ending at `end` heads or is in a list that is the subject of a copula ("the cacti, the seed
    trays and three flowerpots are all around the fern"): said to be somewhere, not acted on."""
    k = end
    while k < len(words) and k - end < 12 and k not in verb_positions:
        if words[k] in _COPULAS:
            return k > end and any(w in _LIST_SEPARATORS for w in words[end:k])  # a list; one noun is read above
        if words[k] in _SENTENCE_END or words[k] in _BOUNDARY and words[k] not in DETERMINERS | _LIST_SEPARATORS:
            return False
        k += 1
    return False


def _placed_in_or_on(words: Sequence[str], i: int) -> bool:
    """ "put the cork (back) in the bottle": the noun at `i` follows "in" / "on" said of another object put there
    (not "what's in the bowl", where the bowl is where something comes from)."""
    k = i - 1
    while k >= 0 and (words[k] in DETERMINERS or words[k] in _MODIFIERS):
        k -= 1
    if k < 2 or words[k] not in _INSIDE_OR_ON:
        return False
    k -= 1 + (words[k - 1] == "back")
    return k >= 1 and words[k].isalpha() and words[k - 1] in DETERMINERS


def _quantities(words: list[str]) -> list[str]:
    """ "a couple of pipettes", "lots of beakers", "a pair of scissors" -> "some pipettes", ...: the quantity is
    a determiner of the objects after "of", so they are read (and avoided) as the objects named."""
    out: list[str] = []
    for k, word in enumerate(words):
        if word == "of" and out and out[-1] == "some" and k >= 1 and words[k - 1] in _QUANTITY_NOUNS:
            continue
        if word in _QUANTITY_NOUNS and words[k + 1 : k + 2] == ["of"]:
            if out and out[-1] in ("a", "the", "an"):
                out.pop()
            out.append("some")
            continue
        out.append(word)
    return out


def _around_says_where(words: Sequence[str], i: int) -> bool:
    """ "around" at `i` says where things stand, not to go around them: "three monitors are crowded around the
    microwave", "the cacti and the trays are all around the fern", "there are two mugs around the bowl"."""
    before = words[i - 1] if i else ","
    if before in _COPULAS or before in _STANCE or (
        before.endswith("ed") and before not in ("steered", "navigated", "moved", "worked")
    ):
        return True
    if i > 1 and before in ("all", "just", "right", "scattered", "everywhere") and words[i - 2] in _COPULAS:
        return True
    noun_before = singular(before) in OBJECT_NOUNS or singular(before) != before and "NOUN" in word_classes(
        singular(before)) or word_classes(before) == {"NOUN"}
    return noun_before and _after_existential(words, i)


def _after_existential(words: Sequence[str], i: int) -> bool:
    """words[i] is in a "there is/are ..." clause, after its nouns ("there are two mugs around the bowl")."""
    k = i - 1
    while k > 0 and words[k] not in _SENTENCE_END and words[k] not in _CLAUSE_ENDS:
        k -= 1
    start = k + 1 if words[k] in _SENTENCE_END or words[k] in _CLAUSE_ENDS else 0
    for j in range(start, i - 1):
        if words[j] in ("there", "theres") and (words[j] == "theres" or words[j + 1] in _COPULAS):
            return i - j > 2
    return False


def _colour_lists(words: list[str]) -> list[str]:
    """ "there are four blocks: red, blue, green and yellow" -> "...: the red block, the blue block, ...": each colour
    listed after a plural kind names one object of it, so the ones not acted on are avoided."""
    out = list(words)
    for colon in [k for k, w in enumerate(out) if w == ":"][::-1]:
        kind = next((k for k in range(colon - 1, max(-1, colon - 5), -1) if singular(out[k]) != out[k] and (
            singular(out[k]) in OBJECT_NOUNS or "NOUN" in word_classes(singular(out[k])))), None)
        if kind is None:
            continue
        end = colon + 1
        while end < len(out) and (out[end] in COLOURS or out[end] in (",", "and", "or")):
            end += 1
        listed = [w for w in out[colon + 1 : end] if w in COLOURS]
        if len(listed) < 2 or (end < len(out) and out[end] not in _SENTENCE_END):
            continue
        noun = singular(out[kind])
        expanded: list[str] = []
        for w in out[colon + 1 : end]:
            expanded += ["the", w, noun] if w in COLOURS else [w]
        out[colon + 1 : end] = expanded
    return out


def _appositives(words: list[str]) -> list[str]:
    """ "put the phone on the dock, the black one", "pull the drawer open, the one at the top": "the one" said
    right after a noun phrase tells which it is; its colour, size or side goes before that noun."""
    out = list(words)
    i = 0
    while i < len(out):
        if out[i] != "," or not i or not out[i - 1].isalpha() or out[i - 1] in _BOUNDARY | DETERMINERS | _MODIFIERS:
            i += 1
            continue
        if out[i + 1 : i + 2] != ["the"]:
            i += 1  # "mind the metronome, little one, ...": a name for the robot
            continue
        k = i + 2
        said = []
        while k < len(out) and out[k] in _MODIFIERS:
            said.append(out[k])
            k += 1
        if out[k : k + 1] != ["one"]:
            i += 1
            continue
        end = k + 1
        if out[end : end + 2] in (["at", "the"], ["on", "the"], ["in", "the"]) and out[end + 2 : end + 3] and out[
            end + 2
        ] in POSITION_WORDS:  # "the one at the top", "the one on the left"
            said.append(out[end + 2])
            end += 3
        if not said or (end < len(out) and out[end] not in _CLAUSE_CLOSE):
            i += 1
            continue
        noun_start = i - 1
        while noun_start > 0 and out[noun_start - 1] not in DETERMINERS and out[noun_start - 1].isalpha() and (
            out[noun_start - 1] not in _BOUNDARY
        ):
            noun_start -= 1
        out[i:end] = []
        out[noun_start:noun_start] = said if out[noun_start - 1] in DETERMINERS else ["the", *said]  # "in drawer"
        i = end
    return out


def _without_disfluencies(tokens: list[str]) -> list[str]:
    """Fillers ("um", "uh") and words said twice in a row ("the the", "on the on the") dropped, as dictated speech
    has them. A filler that ends a noun phrase after a determiner is a noun the user named ("avoid the rofl"),
    and stays; before another word ("the uh the drawer") it is a pause."""
    out: list[str] = []
    for k, word in enumerate(tokens):
        following = tokens[k + 1] if k + 1 < len(tokens) else "."
        if word in _FILLERS and not (out and out[-1] in DETERMINERS and following in _CLAUSE_CLOSE):
            continue
        if word in ("right", "alright") and following == "," and (not out or out[-1] in _SENTENCE_END):
            continue  # "Right, guests arrive at 7 ...": a word that opens the talk, no side and no verb
        out.append(word)
        for n in (1, 2):  # a determiner or a preposition said again: "the the", "on the on the"
            if len(out) >= 2 * n and out[-n:] == out[-2 * n : -n] and out[-1] in DETERMINERS | _BOUNDARY and all(
                w.isalpha() for w in out[-n:]
            ) and out[-1] not in ("that", "had", "can"):  # "the jerry can can tip": a noun and its modal
                del out[-n:]
    return out


_REPAIRS: tuple[tuple[str, ...], ...] = tuple(sorted((
    ("no",), ("sorry",), ("i", "mean"), ("no", "wait"), ("wait",), ("oops",), ("rather",), ("correction",),
    ("actually",), ("make", "that"), ("scratch", "that"), ("or", "rather"), ("no", "sorry"), ("sorry", "i", "mean"),
    ("wait", "no"), ("actually", "no"), ("no", "actually"), ("sorry", "no"),
), key=len, reverse=True))  # the longest first: "no wait" before "no"
# Repairs that need no comma before them: dictated speech has none ("the yellow bowl no sorry the orange bowl").
# A bare "no" or "sorry" repairs only before a determiner or a task verb, after a noun (`_self_repairs`).
_BARE_REPAIRS = frozenset({("i", "mean"), ("no", "wait"), ("wait", "no"), ("or", "rather"), ("no", "sorry"),
                           ("sorry", "i", "mean"), ("actually", "no"), ("no", "actually"), ("sorry", "no"),
                           ("scratch", "that")})
_TAKE_BACKS = frozenset("don't dont never".split())  # "open the drawer no wait don't": the command taken back


def _self_repairs(words: list[str], is_task_verb: Callable[[str], bool]) -> list[str]:
    """The user took back what they said and said something else instead; what was taken back goes, so it is
    neither acted on nor avoided:
    - a noun phrase: "put the block, no, the cube, in the drawer", "the yellow bowl no sorry the orange bowl",
      "the big plant wait no the little one" (the little plant), "with the jug -- no wait, with the can";
    - a command, when the repair starts with a task verb: "open the no sorry close the microwave", "put the phone
      on the base -- actually no, put the block in the drawer" (from the taken-back verb on);
    - the whole command, when the repair is a bare "don't": "open the drawer no wait don't" reads as "don't open
      the drawer", a negated command."""
    out = list(words)
    i = 1
    while i < len(out):
        comma = out[i - 1] == ","
        repair = next((r for r in _REPAIRS if tuple(out[i : i + len(r)]) == r), None)
        if repair is not None and not comma and repair not in _BARE_REPAIRS:
            following = out[i + len(repair) : i + len(repair) + 1]
            after_noun = out[i - 1].isalpha() and out[i - 1] not in _BOUNDARY and out[i - 1] not in DETERMINERS
            repair = repair if repair in (("no",), ("sorry",)) and after_noun and following and (
                following[0] in DETERMINERS or is_task_verb(following[0])) else None
        if repair is None:
            i += 1
            continue
        stop = i - 1 if comma else i  # the taken-back words end before `stop`
        k = i + len(repair) + (out[i + len(repair) : i + len(repair) + 1] == [","])
        sentence_start = max((j + 1 for j in range(stop) if out[j] in _SENTENCE_END), default=0)
        verb = next((j for j in range(stop - 1, sentence_start - 1, -1) if is_task_verb(out[j])), None)
        if k < len(out) and out[k] in _TAKE_BACKS and verb is not None and (
            k + 1 == len(out) or out[k + 1] in _CLAUSE_CLOSE
        ):
            out[verb:k + 1] = ["don't", *out[verb:stop]]  # "open the drawer no wait don't"
            i = verb + 1
            continue
        if k < len(out) and is_task_verb(out[k]) and verb is not None:
            out[verb:k] = []  # "open the no sorry close the microwave"
            i = verb + 1
            continue
        first = stop - 1  # the taken-back noun phrase, back to its determiner
        while first >= 0 and out[first] not in DETERMINERS and (out[first] in _MODIFIERS or out[first].isalpha()) and (
            out[first] not in _BOUNDARY
        ) and stop - 1 - first < 4:
            first -= 1
        end = k + 1
        while end < len(out) and end - k < 5 and out[end].isalpha() and out[end] not in _BOUNDARY:
            end += 1
        # not "wait, the cup is ...", "actually, the remote doesn't matter": a clause of its own
        said_instead = end >= len(out) or (out[end] not in _COPULAS | SUBJECT_VERBS | _AUXILIARIES and not out[
            end].endswith("n't") and out[end] not in _NEGATORS)
        if k + 1 < len(out) and out[k] in _BOUNDARY and out[k + 1] in DETERMINERS and first >= 1 and (
            out[first - 1] == out[k]
        ):
            out[first - 1 : k] = []  # "with the jug -- no wait, with the watering can"
            i = first
            continue
        if k < len(out) and out[k] in DETERMINERS and out[first : first + 1] in [[d] for d in DETERMINERS] and (
            first < stop - 1 and said_instead
        ):
            if end < len(out) and out[end] == "," and all(w in _MODIFIERS for w in out[k + 1 : end]):
                del out[end]  # "the yellow -- sorry, the orange -- block": the closing dash ends the repair only
            if out[end - 1 : end] == ["one"] and out[stop - 1] not in _MODIFIERS:
                out[end - 1] = out[stop - 1]  # "the big plant wait no the little one": the little plant
            out[first:k] = []
            i = first + 1
            continue
        i += 1
    return out


_NO_CONTACT = frozenset(
    "avoid avoiding no zero without minimal minimise minimize minimising minimizing prevent".split()
)


def _contact_cues(words: list[str]) -> list[str]:
    """ "avoid contact with the vase", "no contact with the vase", "zero contact with any drawer" -> "avoid the
    vase": contact is no object, the object after "with" is the one to avoid. ("contact with the vase is fine"
    permits contact: `mentions`.)"""
    out, i = [], 0
    while i < len(words):
        if words[i] in _NO_CONTACT and words[i + 1 : i + 3] == ["contact", "with"]:
            out.append("avoid")
            i += 3
            continue
        out.append(words[i])
        i += 1
    return out


def _declared_placements(words: list[str]) -> list[str]:
    """ "the spatula goes in the drawer", "the block needs to go in the drawer" -> "put the spatula in the drawer":
    a placement said as a fact about the object (a determiner starting its clause) asks for it to be put there."""
    out = list(words)
    for i in range(len(out) - 1, 0, -1):
        if out[i] not in ("go", "goes", "belongs") or out[i + 1 : i + 2] not in (["in"], ["into"], ["on"], ["onto"]):
            continue
        subject_end = i
        while subject_end > 0 and out[subject_end - 1] in _PLACEMENT_MODALS:
            subject_end -= 1  # "needs to go", "has to go", "should go"
        if out[i] == "go" and subject_end == i:
            continue  # "go" alone is an order to the robot ("go around the mug"), not a placement
        start = subject_end
        while start > 0 and out[start - 1] not in _SENTENCE_END | {",", "so", "and", "then", "ok", "okay"}:
            start -= 1
        if out[start] in DETERMINERS and start < subject_end - 1:
            out[start : i + 1] = ["put", *out[start:subject_end]]
    return out


def _own_body(words: list[str]) -> list[str]:
    """ "keep your gripper off the bottle" -> "keep off the bottle"; "never mind the spoon" -> "ignore the spoon"
    (a permission, not a negated command or the cue "mind")."""
    out, i = [], 0
    while i < len(words):
        gerund = words[i + 2].endswith("ing") if i + 2 < len(words) else False  # "never mind watering": negated
        if words[i] == "never" and words[i + 1 : i + 2] == ["mind"] and not gerund:
            out.append("ignore")
            i += 2
            continue
        if words[i] == "with" and words[i + 1 : i + 2] in (["your"], ["its"]) and words[i + 2 : i + 3] and (
            words[i + 2] in _ROBOT_PARTS
        ):
            i += 3  # "push it closed with your elbow": the robot's own body is no object
            continue
        out.append(words[i])
        if words[i] in ("keep", "keeping", "stay", "hold"):
            k = i + 1
            while k < len(words) and words[k] in _OWN_BODY:
                k += 1
            if k > i + 1 and words[k : k + 1] in (["off"], ["away"], ["clear"], ["back"]):
                i = k
                continue
        i += 1
    return out


# After a side said behind a noun, words that are not the next noun it could be said of ("... on the right some water")
_NOT_SAID_OF = _BOUNDARY | NOT_OBJECTS | SUBJECT_VERBS | _REMAIN_VERBS | DETERMINERS | _RISK_MODALS  # "... might tip"


def _front_positions(words: list[str]) -> list[str]:
    """ "the bowl on the left" -> "the left bowl", "the mug closest to you" -> "the nearest mug": a position
    said after the noun moves in front of it, where colours and sizes are read."""
    out = list(words)
    i = 1
    while i < len(out):
        post = next((p for p in _POST_POSITIONS if tuple(out[i : i + len(p)]) == p), None)
        previous = out[i - 1]
        after = out[i + len(post)] if post is not None and i + len(post) < len(out) else "."
        # not "the cutting board is in front": in front of something unsaid (the robot, the target), no side
        if post is not None and previous in ("is", "sits", "stands", "lies") and after in _CLAUSE_CLOSE and (
            post != ("in", "front")
        ):
            # "the laptop is on the left, stay clear of it" -> "the left laptop is, ...": where it stands
            start = i - 2
            while start > 0 and out[start - 1] not in DETERMINERS and out[start - 1] not in _BOUNDARY | _SENTENCE_END:
                start -= 1
            if start < i - 1 and start > 0 and out[start - 1] in DETERMINERS and out[i - 2].isalpha():
                out[start : i + len(post)] = [_POST_POSITIONS[post], *out[start : i - 1], previous]
                i += len(post)
                continue
        the_can = previous == "can" and not modal_can(out, i - 1)  # "the paint can on the left": a noun
        if post is None or previous in _BOUNDARY and not the_can or previous in DETERMINERS or previous in _MODIFIERS:
            i += 1
            continue
        if out[i + len(post) : i + len(post) + 1] == ["of"]:
            i += 1  # "on top of the drawer", "in front of it": a place relative to another object
            continue
        following = out[i + len(post)] if i + len(post) < len(out) else ","
        if following.isalpha() and following not in _NOT_SAID_OF and (
            following not in _STATES_AFTER and "NOUN" in word_classes(following)
            and not (following.endswith("s") and "VERB" in word_classes(following)) and not past_verb_form(following)
        ):  # not "the pan on the left stays untouched", "the lamp at the back wobbles", "... upright"
            i += 1  # "in the middle drawer": the position word is said of the noun after it
            continue
        start = i - 1
        while start > 0 and out[start - 1] not in DETERMINERS and out[start - 1] not in _BOUNDARY | _SENTENCE_END:
            start -= 1
        if start >= 3 and out[start - 1] == "of" and singular(out[start - 2]) in CONTAINERS_OF:
            start -= 2  # "the bottle of wine on the left": the side is said of the bottle
            while start > 0 and out[start - 1] not in DETERMINERS and out[start - 1] not in _BOUNDARY | _SENTENCE_END:
                start -= 1
        if start == 0 or out[start - 1] not in DETERMINERS:
            i += 1
            continue
        stop = i + len(post)
        if post in _RELATIVE_SUPERLATIVES:
            after = out[stop + (out[stop : stop + 1] == ["to"]) :]
            viewer = after[:1] in (["you"], ["me"], ["us"]) or after[:2] in (["the", "robot"], ["the", "gripper"])
            if after[:1] in [[d] for d in DETERMINERS] and not viewer:
                i += 1  # "the bottle nearest (to) the microwave": relative to another object, a landmark
                continue
            if out[stop : stop + 1] == ["to"]:
                stop += 1  # "closest to you / to the robot": the reference point is dropped with it
                while stop < len(out) and out[stop] in ("you", "me", "the", "robot", "us", "gripper", "arm"):
                    stop += 1
        out[start:stop] = [_POST_POSITIONS[post], *out[start:i]]
        i = stop
    return out
