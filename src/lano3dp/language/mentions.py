"""The safety invariant: every object an instruction names is acted on or avoided, whatever the parse says.

`object_mentions` finds the noun phrases of an instruction that name a physical thing, in any role (the object
to carry, a landmark "next to the mug", a warning "the vase is fragile", a list "X, Y and Z are in the way",
the object of a negated verb), with its own word lists and without the parser's reading of roles, so a parser
mistake cannot also hide the mistake. `enforce_mentions` then checks a plan from any source (the rules or an
LLM): a mention that is neither a target nor an obstacle becomes an obstacle, with a warning that says so,
unless the instruction explicitly permits contact with it ("you may touch the mug", "don't worry about the
mug", "ignore the mug"); an obstacle with permitted contact is dropped, with a warning.

What is a mention:
- any registry or scene object word, or a noun of `vocabulary.OBJECT_NOUNS`, with or without a determiner
  (but not used as a verb: "water the plant", "dock the phone");
- the head of a noun phrase after a determiner ("the stapler", "a zorb"), with its compound ("coffee mug",
  "water bottle", "tin can");
- not: support surfaces the robot works on (table, counter), parts of an object (lid, handle, door), contents
  and liquids (water, the bowl's contents), places (side, corner, way), the robot and the user, vague heads
  (thing, anything), and the contents after "a bottle of wine".
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

from lano3dp.language.plan import MAX_NAME_CHARS, ObjectRef, TaskPlan
from lano3dp.language.registry import SkillSpec
from lano3dp.vocabulary import COLOURS, OBJECT_NOUNS, SIZE_WORDS, canonical_attribute, english_lexicon, singular

_DETERMINERS = frozenset(
    """the a an this that these those my your our their his her its some any another both either each every
    all two three four five several few many""".split()
)
_POSITIONS = frozenset(
    """top upper bottom lower left leftmost right rightmost front back rear nearest closest farthest furthest
    centre center middle first second third last other""".split()
)
_MODIFIERS = COLOURS | SIZE_WORDS.keys() | _POSITIONS
# Nothing to act on or avoid: surfaces under everything, parts of objects, contents, places, people, vagueness,
# times ("all week"), "ok", the berth one gives ("give the kettle a wide berth"), and abstract nouns of everyday
# idioms ("it cost a fortune", "have a look", "take care").
NOT_OBJECTS = frozenset(
    """table counter countertop worktop floor surface desk workspace shelf lid handle door knob cap cork rim edge
    spout neck stem side corner top bottom front back inside outside middle centre center left right area spot
    place way path route direction time water liquid soup drink contents content stuff dirt dust crumb crumbs mess
    debris trash rubbish one ones thing things something anything everything nothing robot gripper arm hand
    yourself you me it them bit while moment second minute job task obstacle? way hour day night week weekend month
    year morning afternoon evening tonight today tomorrow yesterday okay ok alright berth contact itself
    themselves vicinity surroundings none dear kitchen room house home lab office fortune favour favor look try
    go shot chance idea problem mistake reason sense care attention hurry rush sec mo deal distance space
    step other others rest help lot bathroom garage studio workshop workbench classroom nursery bedroom hallway
    basement attic cellar lounge pantry cafe bakery shop store supermarket market restaurant canteen cafeteria picnic
    party meeting breakfast brunch lunch dinner supper wedding funeral birthday anniversary ceremony concert festival
    christening graduation celebration holiday shoot lake beach park airport station school church gym river sea
    city town village slope slopes till haha hahaha lol hehe lmao omg""".split()  # rooms, shops, places and
    # events name where and when ("in the garage: open the drawer", "we're closing the bakery soon", "for the
    # picnic", "we leave for the lake"); "thanks a lot"; laughter
) - {"obstacle?"}
# Units: "the grinder 8 cm to the right of the pan" names a grinder, "the 2 litre jug" a jug.
UNITS = frozenset(
    """cm mm centimetre centimetres centimeter centimeters millimetre millimetres metre metres meter meters inch
    inches foot feet litre litres liter liters ml millilitre millilitres milliliter milliliters gallon gallons
    pint pints oz ounce ounces kg kilo kilos gram grams""".split()
)
# Numbers said as words: counts, never objects ("the chess pieces, all sixteen of them").
NUMBER_WORDS = frozenset(
    """two three four five six seven eight nine ten eleven twelve thirteen fourteen fifteen sixteen seventeen eighteen
    nineteen twenty thirty forty fifty hundred dozen""".split()
)
NOT_OBJECTS = NOT_OBJECTS | UNITS | NUMBER_WORDS
# Words that end a noun phrase.
_BOUNDARY = frozenset(
    """in into on onto over under from to with without of at by near next beside behind inside out up down off
    away back for using toward towards across through around while and or but then so that which who please
    again too there here it them is are be was were can could would will should if when before after until as
    not don't dont do does very now just also still nearby close somewhere between against past beyond below
    above beneath underneath along than like i you we they he she me us sits sit stands stand lies lie rests
    looks look seems seem appears has have had holds contains 's must might may can't cannot won't mustn't
    shouldn't""".split()
)
# Object words that are also verbs or function words: without a determiner they are not read as objects.
_AMBIGUOUS_BARE = frozenset(
    """watch case matches base dock brush plant tape drill nail screw bolt mill board frame picture block tube fan
    can tin key mouse remote screen bell paper cloth mirror comb plug wire cable cord box pen tray glass glasses
    water charger station cradle item object toy pot bottle cup lamp brick marker ball flower""".split()
)
# Verbs said right after their subject: they end its noun phrase ("the sextant stays put", "the vase looks old").
SUBJECT_VERBS = frozenset(
    """looks seems appears contains holds has have had stays remains sits stands lies belongs needs goes got gets
    wobbles rattles leaks drips tips breaks spills falls sticks squeaks topples""".split()
)
# Phrases that permit contact with what follows them, up to the end of the clause.
_PERMISSIONS: tuple[tuple[str, ...], ...] = (
    ("may", "touch"), ("can", "touch"), ("may", "bump"), ("can", "bump"), ("may", "push"), ("can", "push"),
    ("may", "move"), ("can", "move"), ("ok", "to"), ("okay", "to"), ("fine", "to"), ("alright", "to"),
    ("free", "to"), ("don't", "worry", "about"), ("dont", "worry", "about"), ("do", "not", "worry", "about"),
    ("needn't", "worry", "about"), ("need", "not", "worry", "about"), ("no", "need", "to", "worry", "about"),
    ("no", "need", "to", "avoid"), ("ignore",), ("doesn't", "matter"), ("does", "not", "matter"),
    ("allowed", "to"), ("may", "knock"), ("can", "knock"), ("may", "brush"),
    ("can", "brush"), ("may", "nudge"), ("can", "nudge"), ("fine", "if"), ("ok", "if"), ("okay", "if"),
    ("alright", "if"), ("matter", "if"), ("no", "problem", "if"), ("not", "a", "problem", "if"),
    ("no", "worries", "if"), ("don't", "mind"), ("dont", "mind"), ("do", "not", "mind"),
    ("no", "need", "to", "be", "careful"), ("not", "a", "big", "deal", "if"), ("no", "big", "deal", "if"),
    ("not", "necessary", "to", "avoid"), ("isn't", "necessary", "to", "avoid"),
    ("don't", "care", "if"), ("dont", "care", "if"), ("do", "not", "care", "if"), ("don't", "care", "about"),
    ("dont", "care", "about"), ("not", "bothered", "if"), ("not", "bothered", "about"), ("not", "fussed", "if"),
    ("not", "fussed", "about"),
    # "go ahead and nudge the dishcloth"
    *(("go", "ahead", "and", verb) for verb in ("nudge", "bump", "touch", "move", "push", "knock", "brush")),
)  # fmt: skip
# Said after an object, permitting contact with it ("the mug can be moved", "the mug may be touched").
_PERMITTED_AFTER: tuple[tuple[str, ...], ...] = (
    ("don't", "matter"), ("dont", "matter"), ("do", "not", "matter"),
    *((modal, "be", done) for modal in ("can", "may") for done in ("touched", "moved", "pushed", "nudged", "bumped",
                                                                   "knocked", "brushed", "shifted", "hit")),
    # "the lamp you may touch", "the shoes you can push aside": the object said first
    *(("you", modal, verb) for modal in ("can", "may") for verb in ("touch", "move", "push", "bump", "nudge")),
    ("doesn't", "matter"), ("does", "not", "matter"),
    ("is", "fine"), ("is", "ok"), ("is", "okay"), ("is", "alright"), ("is", "allowed"), ("are", "fine"),
    ("is", "no", "problem"), ("'s", "no", "problem"), ("'s", "fine"), ("'s", "ok"), ("'s", "okay"),
    ("if", "you", "have", "to"),
    ("if", "you", "must"), ("if", "you", "need", "to"), ("if", "needed"), ("if", "necessary"), ("contact", "ok"),
    ("contact", "okay"), ("contact", "fine"), ("contact", "allowed"), ("is", "permitted"), ("are", "permitted"),
    ("is", "acceptable"), ("are", "acceptable"), ("is", "tolerated"), ("are", "allowed"),
    ("all", "you", "like"), ("all", "you", "want"), ("is", "no", "big", "deal"), ("'s", "no", "big", "deal"),
    ("is", "not", "a", "big", "deal"), ("'s", "not", "a", "big", "deal"),
    # "the bath mat can get bumped"
    *((modal, "get", done) for modal in ("can", "may") for done in ("touched", "bumped", "moved", "pushed",
                                                                    "knocked", "nudged", "brushed", "hit")),
)  # fmt: skip
_CLAUSE_END = frozenset(". ; : ! ? , but and then while".split())
_CLAUSE_START = frozenset(", ; . : ! ? and then please also now just to you i kindly first next".split())
_COMPOUND_MODIFIERS = frozenset("water wine coffee tea glass".split())  # "water bottle", "coffee mug"
_DETACHABLE = frozenset("lid cap cork cover case stopper".split())
# What holds or is a unit of something: "a bottle of wine" names the bottle (also where a side is said after it).
CONTAINERS_OF = frozenset(
    "bottle glass cup mug jar can bowl box bag bucket jug pitcher carafe flask pot pan tin".split()
    + "loaf slice bar roll sheet".split()  # "loaves of bread", "a bar of soap": the unit is the object
)


@dataclass(frozen=True)
class Mention:
    """An object named in an instruction.

    Attributes:
        name: the noun, with its compound ("coffee mug"), singular.
        color / size / position: attribute words said in front of it, canonical.
        index: token index of its head.
        permitted: the instruction explicitly permits contact with it.
        compound: the whole name said, where a known noun inside it was taken as the object ("mouse pad" named
            "mouse"); empty otherwise.
    """

    name: str
    color: str | None = None
    size: str | None = None
    position: str | None = None
    index: int = 0
    permitted: bool = False
    compound: str = ""

    @property
    def head(self) -> str:
        return self.name.split()[-1]

    def ref(self) -> ObjectRef:
        return ObjectRef(name=self.name, color=self.color, size=self.size, position=self.position)

    @property
    def phrase(self) -> str:
        return self.ref().phrase


def by_first_word(phrases: Iterable[tuple[str, ...]]) -> dict[str, tuple[tuple[str, ...], ...]]:
    """Phrases grouped by their first word, each group in the given order, so a word is matched against the few
    that can start there: a lookup per token, not a scan of every phrase (bounded time on 1,000 characters)."""
    grouped: dict[str, list[tuple[str, ...]]] = {}
    for phrase in phrases:
        grouped.setdefault(phrase[0], []).append(phrase)
    return {word: tuple(group) for word, group in grouped.items()}


@functools.lru_cache(maxsize=64)
def _object_words(extra: tuple[str, ...]) -> dict[str, tuple[tuple[str, ...], ...]]:
    """Known object words (tuples of tokens) by their first token, longest first."""
    words = {tuple(w.split()) for w in OBJECT_NOUNS} | {tuple(w.split()) for w in extra if w}
    return by_first_word(sorted(words, key=lambda w: -len(w)))


def _known_at(words: Sequence[str], i: int, known: dict[str, tuple[tuple[str, ...], ...]]) -> int:
    """Length of the longest known object word starting at words[i] (its last word may be plural), or 0."""
    word = words[i]
    for key in dict.fromkeys((word, singular(word))):
        for entry in known.get(key, ()):
            window = words[i : i + len(entry)]
            if len(window) == len(entry) and tuple(window[:-1]) == entry[:-1] and singular(window[-1]) == entry[-1]:
                return len(entry)
            if tuple(window) == entry:
                return len(entry)
    return 0


_AFTER_MODAL = frozenset("both all also still safely easily freely".split())
_ALLOWED_WORDS = frozenset("ok okay fine allowed acceptable permitted alright".split())
_CONTACT_VERBS = frozenset("touch bump brush nudg knock hitt push mov graz contact".split())  # stems before "-ing"


def _joins_subjects(words: Sequence[str], k: int) -> bool:
    """ "the spoon and the oven mitt can be touched": "and" at `k` joins two noun phrases of one subject (the
    phrase before it is a determiner and nouns, opening its clause)."""
    if words[k] != "and" or words[k + 1 : k + 2] == [] or words[k + 1] not in _DETERMINERS:
        return False
    start = k - 1
    while start >= 0 and words[start] not in _CLAUSE_END:
        start -= 1
    phrase = words[start + 1 : k]
    return len(phrase) >= 2 and phrase[0] in _DETERMINERS and all(
        w.isalpha() and (w in _MODIFIERS or not word_classes(w) or "NOUN" in word_classes(w)) for w in phrase[1:])


_PERMISSIONS_BY_FIRST = by_first_word(_PERMISSIONS)
_PERMITTED_AFTER_BY_FIRST = by_first_word(_PERMITTED_AFTER)


def permitted_spans(words: Sequence[str]) -> set[int]:
    """Indices of the tokens a permission covers ("you can nudge the mug", "the towel is fine")."""
    permitted: set[int] = set()
    for i in range(len(words)):
        for phrase in _PERMISSIONS_BY_FIRST.get(words[i], ()):
            if tuple(words[i : i + len(phrase)]) == phrase:
                k = i + len(phrase)
                # "feel free to move the lantern and the tent pegs": a list of objects goes on after "and"
                while k < len(words) and (words[k] not in _CLAUSE_END or words[k] in ("and", "or", ",") and (
                    words[k + 1 : k + 2] != [] and words[k + 1] in _DETERMINERS
                )):
                    permitted.add(k)
                    k += 1
        # "the spoon and the mitt can both be touched": a quantifier or adverb after the modal changes nothing
        skip = 1 if words[i] in ("can", "may") and words[i + 1 : i + 2] and words[i + 1] in _AFTER_MODAL else 0
        for phrase in _PERMITTED_AFTER_BY_FIRST.get(words[i], ()):
            if (words[i], *words[i + 1 + skip : i + len(phrase) + skip]) == phrase:
                k = i - 1 - (words[i - 1 : i] == [":"])  # "towel: contact ok"
                if words[k : k + 1] in (["that"], ["this"], ["it"]) and words[k - 1 : k] == [","]:
                    k -= 2  # "if you have to nudge the board, that's fine": the clause before it
                subject = []
                while k >= 0 and (words[k] not in _CLAUSE_END or _joins_subjects(words, k)):
                    subject.append(k)
                    k -= 1
                if not {"none", "neither", "nothing", "nobody"} & {words[m] for m in subject}:
                    permitted.update(subject)  # not "none of them can be knocked": no permission
        if words[i] in _ALLOWED_WORDS and (i + 1 == len(words) or words[i + 1] in _CLAUSE_END):
            k = i - 1  # "touching the box OK.": a clause about contact that ends in a permission
            while k >= 0 and words[k] not in _CLAUSE_END:
                k -= 1
            clause = range(k + 1, i)
            if any(words[m].endswith("ing") and words[m][:-3] in _CONTACT_VERBS for m in clause):
                permitted.update(clause)
    return permitted


def _permit_referents(words: Sequence[str], mentions: list[Mention], permitted: set[int]) -> list[Mention]:
    """ "the bin is unbreakable, don't worry about hitting it", "the sponge is soft, knock it if you have to": a
    permission said of "it" or "them" (and of no object) permits the object named last before it."""
    out = list(mentions)
    for k in sorted(permitted):
        if words[k] not in ("it", "them"):
            continue
        start, end = k, k
        while start - 1 in permitted:
            start -= 1
        while end + 1 in permitted:
            end += 1
        if any(start <= m.index <= end for m in out):
            continue  # the permission names its object itself
        before = [n for n, m in enumerate(out) if m.index < start]
        if before:
            out[before[-1]] = dataclasses.replace(out[before[-1]], permitted=True)
    return out


def object_mentions(
    words: Sequence[str], object_words: Iterable[str] = (), verbs: Iterable[str] = ()
) -> list[Mention]:
    """The objects `words` (tokens of a normalised instruction) name, in order.

    Args:
        words: lower-case tokens, punctuation as tokens ("'s" apart).
        object_words: the registry's slot words and synonyms and the scene's object kinds (multi-word allowed).
        verbs: lexicon verbs: after "the" they are nouns ("the base"), anywhere else not objects.
    """
    known = _object_words(tuple(sorted(set(object_words))))
    verbs = set(verbs)
    permitted = permitted_spans(words)
    mentions: list[Mention] = []
    i, n = 0, len(words)
    last_end = -1  # where the last noun phrase ended: "that" right there is a relative pronoun ("the bottle that fell")
    while i < n:
        word = words[i]
        if word == "that" and (i == last_end or _relative_verb(words, i + 1)):
            i += 1  # "the bottle that fell", "a vase on the right of it that wobbles"
            continue
        if word in SWEEP_VERBS and (words[i - 1] if i else ",") in _CLAUSE_START:
            i = _after_swept(words, i + 1, known, verbs)  # "sweep the sand ...": what is swept is no object
            continue
        if tuple(words[i - 2 : i]) in _OWNED_BY:
            j = i + (word in _ARTICLES)
            i = max(i + 1, _noun_run(words, j, known, verbs))  # "the dustpan belongs to my neighbour": no object
            continue
        if last_end == i - 1 and predicate_noun(words, i):
            i = _noun_run(words, i + 1, known, verbs)  # "that vase was a wedding present": the vase again
            continue
        if word == "left" and i and (singular(words[i - 1]) in PEOPLE or words[i - 1] in _SUBJECT_PRONOUNS):
            # "the kids left dominoes everywhere": what someone did, no side; what they left is named after it
            j = i + 1 + (words[i + 1 : i + 2] != [] and words[i + 1] in _DETERMINERS)
            end = _noun_run(words, j, known, verbs)
            found = _mention(words, i + 1, j, end, known, permitted) if end > j else None
            if found is not None:
                mentions.append(found)
                last_end = end
            i = max(end, i + 1)
            continue
        if word in _DETERMINERS or word in _MODIFIERS or possessive(words, i):
            j = i
            while j < n and (words[j] in _DETERMINERS or words[j] in _MODIFIERS or possessive(words, j)):
                j += 1
            if j > i and j < n and words[j] in verbs and all(w in _POSITIONS for w in words[i:j]):
                i = j  # "but first move the mug": an adverb of order before a verb, not "the first move"
                continue
            end = _noun_run(words, j, known, verbs)
            found = _mention(words, i, j, end, known, permitted)
            if found is not None and i and words[i - 1] in _SPILLED and found.head not in OBJECT_NOUNS:
                found = None  # "I spilled some flour, can you sweep it up": what was spilled is dirt, no object
            if found is not None and i and words[i - 1] in _POURING and words[end : end + 1] in (["from"], ["out"]):
                found = None  # "pour the batter from the bowl into the pan": what is poured is the contents
            if found is not None and i and words[i - 1] in ("during", "throughout", "since"):
                found = None  # "it fell over during the last run": an event, no object
            if found is not None and words[i] in ("my", "our") and (
                i >= 1 and words[i - 1] in ("find", "finding") or tuple(words[i - 2 : i]) in _LOOKING_FOR
            ):
                found = None  # "I need to find my passport", "I'm looking for my keys": not there to be avoided
            if found is not None and _person_who_did(found, words, end):
                found = None  # "my son made a mess": who did something earlier is no object on the table
            if found is not None and i and words[i - 1] == "with" and singular(found.head) in PEOPLE and (
                words[i] in ("my", "our", "his", "her", "their", "your")
            ):
                found = None  # "I'm heading out with my cousin": company, not a thing on the table
            if found is not None and not _possessor(words, j, end, known, verbs):
                mentions.append(found)
                last_end = end
            i = max(end, j, i + 1)
            continue
        if i == last_end and _verb_with_object(words, i):
            i += 1  # "the mug blocks the way": no "block" named
            continue
        length = _known_at(words, i, known)
        previous = words[i - 1] if i else ","
        if i and last_end == i - 1 and _coordinated_noun(words, i, length, verbs):
            end = _noun_run(words, i, known, verbs)  # "the batteries and tape measures": one determiner for both
            found = _mention(words, i, i, end, known, permitted)
            if found is not None:
                mentions.append(found)
                last_end = end
            i = max(end, i + 1)
            continue
        if not length and tuple(words[i - 2 : i]) in _EXISTENTIAL and word not in verbs:
            run_end = _noun_run(words, i, known, verbs)
            head = words[run_end - 1] if run_end > i else ""
            plural = _plural_noun(head) or _unlisted_plural(head) or (
                singular(head) != head and _known_at(words, run_end - 1, known))  # "there are tins"
            if run_end > i and plural and not any(
                _known_at(words, k, known) for k in range(i, run_end - 1)
            ):  # a known word before the head is read where it stands ("there are sharp knives")
                length = run_end - i  # "there are paintbrushes", "there are coffee tins": objects, known or not
        ambiguous = word in _AMBIGUOUS_BARE and not _bare_plural_noun(words, i) and not _bare_noun_said(words, i) and (
            i + 1 >= len(words) or not (_plural_noun(words[i + 1]) and words[i + 1] not in _BOUNDARY)
        )  # "remote controls", "tape measures": the first word of a compound before its plural head
        if length and not ambiguous and word not in NOT_OBJECTS and not (word in verbs and previous in _CLAUSE_START):
            end = _noun_run(words, i, known, verbs)
            found = _mention(words, i, i, end, known, permitted)
            if found is not None:
                mentions.append(found)
                last_end = end
            i = max(end, i + 1)
            continue
        i += 1
    return _permit_referents(words, mentions, permitted)


# What may follow a plural noun heading a compound with a known object word ("toy cars all over the place"); not
# what follows a verb after its subject ("the bottle stops rolling", "the drawer ends up open").
_AFTER_PLURAL_HEAD = frozenset(
    ". , ; : ! ? and or all around everywhere nearby are must have on in by near next beside away from to inside"
    .split()
)
_PARTICLES_AFTER_VERBS = frozenset("out up down over off away around for about".split())


_EXISTENTIAL = frozenset({("there", "are"), ("there", "'re"), ("there", "were")})


def _plural_noun(word: str) -> bool:
    return singular(word) != word and "NOUN" in word_classes(singular(word))


def _unlisted_plural(word: str) -> bool:
    """A plural of a noun the lexicon lacks ("bookends", "crucibles"): nouns are open-ended, verbs are not."""
    return word.isalpha() and singular(word) != word and not word_classes(word) and not word_classes(singular(word))


def _coordinated_noun(words: Sequence[str], i: int, known_length: int, verbs: set[str]) -> bool:
    """ "the batteries and tape measures", "dolls, teddy bears and toy cars": a noun joined to the noun phrase just
    before it, without a determiner of its own. Not a verb of a second clause ("and mind the lamp", "and watch
    the cup": an object follows it)."""
    word = words[i]
    following = words[i + 1] if i + 1 < len(words) else "."
    if not word.isalpha() or word in verbs or _not_object(word) or word in _BOUNDARY or word in _DETERMINERS:
        return False
    if words[i - 1] not in ("and", "or", ","):
        return False
    if words[i - 1] == ",":  # "dolls, teddy bears and toy cars": a comma joins nouns only in a list going on
        end = i + 1
        while end < len(words) and words[end] not in _CLAUSE_END:
            end += 1
        if end - i > 3 or words[end : end + 1] not in ([","], ["and"], ["or"]):
            return False
    if following in _DETERMINERS or following in _MODIFIERS or following in _PARTICLES_AFTER_VERBS or (
        following in ("it", "them", "him", "her", "you", "me", "us")
    ):
        return False  # "and watch out for the lamp", "and mind the mug": a verb with its object or particle
    classes = word_classes(word)
    if known_length or _plural_noun(word) or _unlisted_plural(word):
        return True  # a known object word, or a plural noun
    if following.isalpha() and following not in _BOUNDARY and (following in OBJECT_NOUNS or _plural_noun(following)):
        return True  # "salt shakers": a compound with an object noun after it
    if "VERB" in classes and "NOUN" not in classes:
        return False
    # a noun, or a word the lexicon lacks before a noun ("teddy bears")
    return "NOUN" in classes and "VERB" not in classes or not classes and following.isalpha() and bool(
        word_classes(following) & {"NOUN"})


# What a thing is made of describes it and is no part of its name ("the porcelain teapot" is a teapot). Not
# "paper" or "rubber": they also start compound names ("paper towel", "rubber duck").
MATERIALS = frozenset(
    """plastic wooden metal metallic ceramic steel cardboard porcelain silk leather cotton wool woollen woolen
    velvet linen wicker bamboo copper brass aluminium aluminum enamel suede satin nylon denim terracotta pewter
    bronze stainless glass foam cast iron""".split()
)  # "glass", "iron" name things alone ("the glass"); before a noun they say what it is made of
# What is said of an object to ask for care ("the glass is fragile"); before a noun no part of its name.
PROPERTY_WORDS = frozenset("fragile delicate breakable hot sharp precious valuable wobbly unstable expensive".split())
_PRONOUNS_BEFORE_IS = frozenset(
    "that it there here what who he she this where which whatever whoever something anything everything nothing"
    .split()
)
_ADJECTIVES = frozenset(
    """open closed shut empty full dirty clean old new broken cracked upright fallen lying standing tipped wet dry
    hot cold warm heavy light glass paper iron rubber fragile delicate shiny dull round square flat tall short big
    small little large huge tiny long narrow wide nice pretty ugly spare extra same different whole half favourite
    favorite usual neighbouring neighboring adjacent nearby safe good single""".split()
) | MATERIALS


# Adjectives that, said alone after an article, name a thing ("the iron", "a rubber", "a little light").
_ADJECTIVES_ALSO_THINGS = frozenset("iron light rubber safe".split())
_ARTICLES = frozenset("a an the this that my your our their his her".split())


@functools.cache
def word_classes(word: str) -> frozenset[str]:
    """The word classes an English lexicon gives `word` ("NOUN", "ADJ", "VERB", ...; empty if it lacks it).
    lemminflect's lexicon rather than a hand list: which words are nouns is open-ended ("kitchen", "cereal"),
    and suffixes mislead ("kitchen" ends like "wooden")."""
    return frozenset(english_lexicon().getAllLemmas(word))


DESCRIBING = _ADJECTIVES  # adjectives that describe an object and never start its name ("hot", "open")


def is_adjective(word: str) -> bool:
    """Whether a word before a noun describes it rather than naming another object ("open", "ceramic",
    "battered"); "water" in "water bottle", "kitchen" in "kitchen drawer" or an unknown noun in a compound names
    a kind, and is no adjective."""
    if word in _ADJECTIVES:
        return True
    if word in _COMPOUND_MODIFIERS or word in OBJECT_NOUNS:
        return False
    classes = word_classes(word)
    if "NOUN" in classes:
        return False  # a noun before a noun names a kind of it, also where it can be an adjective ("cereal")
    if "ADJ" in classes:
        return True
    if classes == {"VERB"}:
        # "battered", "chipped", and irregular participles ("lit", "burnt", "torn"); not "-ing": "frying pan"
        return word.endswith(("ed", "en")) or past_verb_form(word)
    # a word the lexicon lacks: by its suffix
    return len(word) > 4 and word.endswith(("ed", "ic", "ous", "ful", "less", "ive", "ish", "ble"))


def verb_lemmas(word: str) -> frozenset[str]:
    """Base forms of a verb form ("swept" -> sweep) from lemminflect's lexicon."""
    return frozenset(english_lexicon().getAllLemmas(word).get("VERB", ()))


@functools.cache
def past_verb_form(word: str) -> bool:
    """A past tense or participle other than its verb's base ("lit", "torn", "stood", "opened"; not "put",
    "set", "bed"). A request is in the base form; the passive is rewritten before."""
    lemminflect = english_lexicon()
    return any(word != lemma and word in (*lemminflect.getInflection(lemma, "VBN"), *lemminflect.getInflection(
        lemma, "VBD")) for lemma in verb_lemmas(word))  # "lit" is only a VBD there


def same_participle(verb: str) -> bool:
    """Whether the verb's past participle is its base form ("put", "set", "shut")."""
    return verb in english_lexicon().getInflection(verb, "VBN")


def _bare_plural_noun(words: Sequence[str], i: int) -> bool:
    """ "there are glasses everywhere": a plural needs no determiner to name objects. Not a verb with its subject
    before it or its object after it ("it matches the cup", "the broom brushes the dirt")."""
    word = words[i]
    if singular(word) == word:
        return False
    previous, following = (words[i - 1] if i else ","), (words[i + 1] if i + 1 < len(words) else ".")
    return previous not in _PRONOUNS_BEFORE_IS and following not in _DETERMINERS and following not in _MODIFIERS


_WHERE_AFTER_BARE = frozenset(
    """nearby near next beside behind by close on in at under below above left right is are 's , . ; : ! - and
    or""".split()
)


SWEEP_VERBS = frozenset("sweep brush".split())


def _after_swept(words: Sequence[str], j: int, known, verbs: set[str]) -> int:
    """Where the words after a sweeping verb end, past the material it sweeps ("the sand", "the coffee grounds"):
    a noun no object list holds. A known object or a noun of `OBJECT_NOUNS` ("sweep the mug ...") is left to be
    read as a mention."""
    k = j + (words[j : j + 1] == ["up"])
    start = k
    while k < len(words) and (words[k] in _DETERMINERS or words[k] in _MODIFIERS):
        k += 1
    end = _noun_run(words, k, known, verbs)
    nouns = words[k:end]
    material = nouns and all(_known_at(words, m, known) == 0 for m in range(k, end)) and singular(
        nouns[-1]) not in OBJECT_NOUNS
    return end if material else start


def _bare_noun_said(words: Sequence[str], i: int) -> bool:
    """ "lamp nearby, careful", "cup on the left": a word that is also a verb ("to lamp", "to cup") names an object
    in shorthand when it opens a clause and what follows says where it is or ends the clause; as a verb an object
    would follow ("cup the ball")."""
    previous, following = (words[i - 1] if i else ","), (words[i + 1] if i + 1 < len(words) else ".")
    return previous in _CLAUSE_END and following in _WHERE_AFTER_BARE


def predicate_noun(words: Sequence[str], i: int) -> bool:
    """ "(that vase) was a wedding present": an indefinite noun phrase at `i` after "is"/"was" says what the
    subject is, and names no other object. Not after "there", "it" or "that" ("there's a mug")."""
    return words[i] in ("a", "an") and i >= 2 and words[i - 1] in ("is", "was", "'s") and (
        words[i - 2].isalpha() and words[i - 2] not in _PRONOUNS_BEFORE_IS)


def possessive(words: Sequence[str], i: int) -> bool:
    """ "'s" after a noun ("the bowl's contents"); after "that", "it", "there" it is "is"."""
    has = words[i + 1 : i + 2] in (["been"], ["got"], ["gotten"])  # "the microwave's been left open"
    following = words[i + 1] if i + 1 < len(words) else "."
    classes = word_classes(following) if following.isalpha() else frozenset()
    # "dinner's almost ready", "the lamp's fragile": before an adverb or an adjective, "'s" is "is"
    state = following.endswith("ly") or ("NOUN" not in classes and bool(classes & {"ADJ", "ADV"}))
    return words[i] == "'s" and i > 0 and words[i - 1] not in _PRONOUNS_BEFORE_IS and not has and not state


def _noun_run(words: Sequence[str], j: int, known, verbs: set[str]) -> int:
    """End of the nouns from words[j]: known object words, and other nouns ("coffee mug", "tin can")."""
    end = j
    while end < len(words):
        word = words[end]
        more = _known_at(words, end, known)
        if word == "can" and modal_can(words, end):
            break  # "the mug can be moved", "the mitt can both be touched": a modal verb
        if word in _HOLDERS and end > j and (words[end + 1 : end + 2] in [*_SENTENCE_ENDS, [","], ["and"],
                                                                            *_BEFORE_A_MODAL]
                                             or word == "stand" and not _plural_noun(words[end - 1]) and (
                                                 end + 1 == len(words) or words[end + 1] not in AFTER_STAND_VERB)):
            # "the umbrella stand.", "the soldering iron stand on the left": a holder heads the compound, though
            # "stand" is also a verb (not after a plural: "the cups stand on the left")
            end += 1
            continue
        if end > j and singular(words[end - 1]) in PEOPLE and (_third_person_verb(word) or past_verb_form(word) or (
                singular(words[end - 1]) != words[end - 1] and "VERB" in word_classes(word))):
            break  # "before my mum visits", "my son spent all morning", "the visitors leave at six": a person's verb
        if word in ("half", "partly", "almost") and end > j and words[end + 1 : end + 2] and (
            past_verb_form(words[end + 1]) or words[end + 1] in ("done", "full", "empty", "open", "built")
        ):
            break  # "a jigsaw puzzle half done": how far along it is, no part of its name
        if word == "old" and end > j and words[end - 1] in ("year", "years", "month", "months"):
            return end + 1  # "my 2 year old keeps grabbing it": a child (its number was no word), no object
        if end > j and past_verb_form(word) and words[end + 1 : end + 2] in _FELL_PARTICLES:
            break  # "the bottle on the workbench fell over": the verb after its subject, not a "workbench fell"
        if end > j and _result_state(words, j, end):
            break  # "don't get the charts wet", "keep the rug dry": the state wanted, no part of the name
        if end > j and _verb_with_object(words, end):
            break  # "the mug blocks the way", "the cat knocks it": the verb after its subject, with its object
        if end > j and (word in ("avoid", "mind", "beware") or word in ("watch", "look") and words[end + 1 : end + 2]
                        == ["out"]):
            break  # "close the microwave watch out for the mug": a caution after an unpunctuated task
        if more:
            end += more
        elif word == "can" and end > j:
            end += 1  # "the tin can"
        elif (
            word.isalpha()
            and word not in _BOUNDARY
            and word not in _DETERMINERS
            and word not in _MODIFIERS
            and (word not in verbs or end == j or words[end + 1 : end + 2] in _BEFORE_A_MODAL + _SENTENCE_ENDS
                 or bool(_known_at(words, end + 1, known)))
            # a verb's word heads a compound before "is" or a full stop: "the chess set is", "the umbrella stand.";
            # before a known noun it names its kind: "the hot water bottle"
            and not (word.endswith("ly") and "ADJ" not in word_classes(word))  # not "wobbly", "curly": adjectives
            and not (end > j and (word.endswith("ing") or word.endswith("ed") and past_verb_form(word)
                                  or word in SUBJECT_VERBS))  # "the mug used ...", not "the dog bed"
            and not (end > j and word in _PLURAL_SUBJECT_VERBS and singular(words[end - 1]) != words[end - 1])
            and not (end > j and word_classes(word) and "NOUN" not in word_classes(word)
                     and words[end + 1 : end + 2] not in _BEFORE_A_MODAL)  # "the guests arrive"; "the wind chime can't"
            and end - j < 3
        ):
            end += 1
        else:
            break
    return end


_STATE_VERBS = frozenset("get gets getting got keep keeps keeping kept leave leaves leaving left make makes".split())


def _result_state(words: Sequence[str], j: int, end: int) -> bool:
    """The adjective at `end` closes a clause whose verb makes or keeps the noun phrase from `j` so ("get the charts
    wet", "leave the towel dry,"): the state, said after its object."""
    if "ADJ" not in word_classes(words[end]) or words[end + 1 : end + 2] not in [*_SENTENCE_ENDS, [","], ["?"]]:
        return False
    k = j - 1
    while k >= 0 and (words[k] in _DETERMINERS or words[k] in _MODIFIERS):
        k -= 1
    return k >= 0 and words[k] in _STATE_VERBS


_LOOKING_FOR = frozenset((verb, "for") for verb in "look looking search searching".split())
_SUBJECT_PRONOUNS = frozenset("i you he she we they someone somebody".split())
AFTER_STAND_VERB = frozenset("up upright it them back the a this that".split())  # "stand it upright": a verb
_OWNED_BY = frozenset({("belongs", "to"), ("belong", "to"), ("belonged", "to"), ("belonging", "to")})
# People, as the subject of what they did ("my roommate knocked it over"); a person said to be near is avoided.
PEOPLE = frozenset(
    """son daughter kid child children mom mum dad mother father brother sister wife husband partner roommate
    flatmate housemate neighbour neighbor friend boss colleague grandma grandpa grandmother grandfather aunt uncle
    cousin baby toddler guest visitor cleaner nanny teacher someone somebody everyone nobody parent grandparent
    family nana nan nanna granny gran grandad granddad grampa nephew niece boyfriend girlfriend fiance fiancee
    sibling cat dog puppy kitten pet farmer florist gardener vet doctor nurse plumber electrician builder courier
    driver postman landlord landlady customer client patient""".split()
)  # pets too: "the cat knocked it over"


def named_in_passing(name: str, words: Sequence[str], start: int, end: int) -> bool:
    """The noun phrase words[start:end] (naming `name`) names a person who did something ("my son made a
    mess") or an owner ("it belongs to my neighbour"): no object on the table."""
    owner = tuple(words[start - 2 : start]) in _OWNED_BY or (
        tuple(words[start - 3 : start - 1]) in _OWNED_BY and words[start - 1] in _ARTICLES)
    return owner or _person_who_did(Mention(name), words, end)


def _person_who_did(mention: Mention, words: Sequence[str], end: int) -> bool:
    """ "my son made a mess", "my roommate has left it open": a person who did something is named in passing."""
    following = words[end : end + 2]
    if following[:1] in _REPORTING and following[1:2] in _REPORTED:
        return True  # "the florist said it's thirsty", "the vet told us to ...": only a person reports
    if mention.head not in PEOPLE and singular(mention.head) not in PEOPLE:
        return False
    if following[:1] in (["are"], ["is"], ["'re"]) and following[1:] and following[1] in _ON_THEIR_WAY:
        return True  # "my parents are coming over for dinner": not here now
    if following[:1] in (["has"], ["had"], ["have"]):
        following = following[1:]
    plural = end > 0 and singular(words[end - 1]) != words[end - 1]  # (a mention's name is singular)
    if plural and following and following[0].isalpha() and following[0] not in _BOUNDARY and "VERB" in word_classes(
        following[0]):
        return True  # "the guests arrive at eight", "my kids play there": people doing something
    if following and following[0] not in _BOUNDARY and _third_person_verb(following[0]):
        return True  # "before my mum visits", "my son leaves it lying around": a person doing something
    if len(following) == 2 and following[1] in ("you", "it", "them", "me", "us") and following[0].isalpha() and (
        "VERB" in word_classes(following[0])
    ):
        return True  # "my partner set you up", "my son put it there": a verb with its object
    if following and following[0].isalpha() and same_participle(following[0]) and following[1:2] != ["to"]:
        return True  # "my son put a cup there": a verb whose past is its base
    return bool(following) and following[0].isalpha() and past_verb_form(following[0])


_FELL_PARTICLES = [[w] for w in "over off down out up away apart".split()]
_POURING = frozenset("pour tip empty transfer".split())
_ON_THEIR_WAY = frozenset("coming visiting arriving calling expecting".split())
_REPORTING = [[w] for w in "said says told tells reckons reckoned thinks thought mentioned suggested asked".split()]
# What follows a reporting verb when it reports ("the label says fragile" is an object's print, not a person).
_REPORTED = [[w] for w in "it it's its that to we i you they he she us me the this these those so".split()]
_BEFORE_A_MODAL = [[w] for w in "can can't cannot must mustn't should shouldn't is are won't will may".split()]
_SENTENCE_ENDS = [[], ["."], [";"], ["!"]]
_ROOMS = frozenset("""kitchen bathroom office garden lab house room garage studio workshop classroom nursery bedroom
    hallway basement attic cellar lounge pantry""".split())  # "the kitchen roll" is a roll's kind
_SPILLED = frozenset("spilled spilt spill spills dropped".split())
_HOLDERS = frozenset("stand rack holder tray mat stool basket bed".split())
# Verbs said right after a plural subject ("the drumsticks need to stay", "the cups look fragile").
_PLURAL_SUBJECT_VERBS = frozenset(
    "look seem appear contain hold stay remain sit stand lie belong need go wobble rattle leak tip break fall".split()
)


def _third_person_verb(word: str) -> bool:
    """ "wobbles", "visits", "blocks": a word that can be a verb said of one subject."""
    return word.endswith("s") and "VERB" in word_classes(word)


def _relative_verb(words: Sequence[str], i: int) -> bool:
    """words[i] is the verb of a relative clause with no object ("... that wobbles.", "that tips over")."""
    word = words[i] if i < len(words) else ""
    following = words[i + 1] if i + 1 < len(words) else "."
    return _third_person_verb(word) and (
        following in _CLAUSE_END or following in _PARTICLES_AFTER_VERBS or following.endswith("ly"))


def _verb_with_object(words: Sequence[str], i: int) -> bool:
    """words[i] is a verb of the third person with its object or particle after it ("blocks the way", "knocks
    it", "sticks out")."""
    word = words[i]
    return _third_person_verb(word) and words[i + 1 : i + 2] != [] and (
        words[i + 1] in _ARTICLES or words[i + 1] in ("it", "them", "its", "these", "those", "out", "up")
    )  # not "pieces all over"


_PLACE_PREPOSITIONS = frozenset("on in at by near beside behind under over next above below".split())


def modal_can(words: Sequence[str], i: int) -> bool:
    """ "can" at `i` is the modal verb ("the mug can be moved", "can both be touched"), not "the tin can"."""
    following = words[i + 1] if i + 1 < len(words) else "."
    if i and words[i - 1] == "can":
        return True  # the second of "the petrol can can leak"
    if following in _PLACE_PREPOSITIONS or following == "can":
        return False  # "the paint can on the right", "the can by the sink", "the jerry can can tip": a can
    if following in ("be", "you", "i", "we", "not", "now", "both", "all", "also", "still", "safely", "easily", "stay",
                     "go", "move", "get", "remain", "fall", "break", "tip", "stand", "sit", "touch"):
        return True
    classes = word_classes(following) if following.isalpha() else frozenset()
    base_verb = "VERB" in classes and not following.endswith("s")  # "can go", not "the paint can sits"
    return "NOUN" not in classes and (base_verb or "ADV" in classes)


def _mention(words, i: int, j: int, end: int, known, permitted: set[int]) -> Mention | None:
    """The mention of words[j:end] with the modifiers of words[i:j], or None if it names no object."""
    chunk = list(words[j:end])
    if _degree_before_state(words, i, j, end, known):
        return None
    if len(chunk) > 1 and chunk[-1] in ("one", "ones") and not _known_at(chunk, 0, known):
        return None  # "the laptop, it's my work one": a word that tells the object named before from others
    known_ends = [k + _known_at(chunk, k, known) for k in range(len(chunk)) if _known_at(chunk, k, known)]
    if known_ends:
        rest = chunk[max(known_ends) :]
        after = words[end] if end < len(words) else "."
        plural_head = len(rest) == 1 and singular(rest[0]) != rest[0] and "NOUN" in word_classes(singular(rest[0]))
        plural_head = plural_head and after in _AFTER_PLURAL_HEAD  # not "the drawer ends up open"
        # "the paper shredder is next to it": an agent noun (a thing that does something) heads the compound;
        # "the umbrella stand", "the mug rack": what holds a known thing is named by both, and is the holder
        noun_head = len(rest) == 1 and (rest[0].endswith(("er", "ers")) and "NOUN" in word_classes(
            singular(rest[0])) and "VERB" not in word_classes(rest[0]) and not _not_object(rest[0])
            or singular(rest[0]) in _HOLDERS)
        if not plural_head and not noun_head:  # "the toy cars", "the tape measures": the plural noun is the head
            chunk = chunk[: max(known_ends)]  # "the mug holder" -> mug: the known noun is the head
    while chunk and _not_object(chunk[-1]) and not _known_at(chunk, len(chunk) - 1, known):
        if len(chunk) > 1 and chunk[-1] in _DETACHABLE:
            break  # "the pan lid": a lid comes off, so it is an object of its own
        chunk.pop()  # "the drawer handle", "the bowl contents": a part or contents of the object named
    first = j  # the index in `words` of chunk[0]: the loop below drops words from the front
    # a measure: "the two litre jug", "a dozen eggs"; a unit after no number names a kind ("the pint glass"; a measure
    # in digits is gone before the words are read)
    while len(chunk) > 1 and _known_at(chunk, 0, known) != len(chunk) and (
        chunk[0] in NOT_OBJECTS - UNITS and chunk[0] not in _ROOMS and not known_ends or chunk[0] in NUMBER_WORDS
        or chunk[0] in UNITS and first > 0 and words[first - 1] in NUMBER_WORDS
        or is_adjective(chunk[0]) and (chunk[0] not in OBJECT_NOUNS or chunk[0] in MATERIALS)
        or chunk[0] in PROPERTY_WORDS  # "the sharp knives", though "sharp" is a noun too
    ):  # not "the paper shredder": a thing's name before a noun names its kind
        chunk.pop(0)  # "the open drawer", "the glass beaker", "the 2 litre jug": the object is the noun
        first += 1
    # ("the trash can", "the table lamp", "the cutting board": a noun before a known noun names its kind)
    # a lone adjective names nothing ("they're both hot"; "a good robot" once "robot" is dropped); a word no
    # lexicon has, alone after its article, is a name ("the babed")
    material = len(chunk) == 1 and (chunk[0] in _ADJECTIVES or bool(word_classes(chunk[0])) and is_adjective(
        chunk[0])) and not _known_at(chunk, 0, known)  # not "the glass"
    # "the iron is next to it", "a little light near the drawer": a thing, said with its article
    material = material and not (chunk == words[j:end] and chunk[0] in _ADJECTIVES_ALSO_THINGS and any(
        w in _ARTICLES for w in words[i:j]))
    if not chunk or (len(chunk) == 1 and _not_object(chunk[0])) or material:
        return None  # "the left side", "they're both hot": no object
    if _contents_after_of(words, j):
        return None
    if chunk in (["obstacle"], ["obstacles"]) and (
        words[j - 1 : j] != ["the"] or words[end : end + 1] in ([":"], [","], ["is"], ["are"], ["'s"], ["include"])
    ):
        return None  # "counts as an obstacle", "the obstacle is the lamp": a role, not the simulator's object
    color = size = position = None
    said = list(words[i:j])
    last_determiner = max((k for k, w in enumerate(said) if w in _DETERMINERS or w == "'s"), default=-1)
    for value in said[last_determiner + 1 :]:  # "right the bottle": a verb before "the" is no attribute
        if value in COLOURS:
            color = color or canonical_attribute(value)
        elif value in _POSITIONS:  # before sizes: "the middle drawer" is a place, as the parser reads it
            position = position or value
        elif value in SIZE_WORDS:
            size = size or canonical_attribute(value)
    chunk = chunk[-3:]
    chunk[-1] = singular(chunk[-1])
    if len(" ".join(chunk)) > MAX_NAME_CHARS:
        return None  # no object's name is that long; a plan could not carry it either
    typed = [*words[j : end - 1], singular(words[end - 1])]
    compound = " ".join(typed[-3:]) if typed[-1] != chunk[-1] else ""
    return Mention(" ".join(chunk), color, size, position, j + len(chunk) - 1, bool(set(range(j, end)) & permitted),
                   compound)


_DEGREE_NOUNS = frozenset("bit tad touch".split())
_COPULAS = frozenset("is are was were 's be been feels feel seems seem looks look gets get".split())


def _degree_before_state(words: Sequence[str], i: int, j: int, end: int, known) -> bool:
    """ "the drawer is a bit stiff", "it's a tad heavy", "the lid feels a little loose": a degree before an
    adjective says how something is, and names no object. Not "there's a little light" (an object there)."""
    chunk = words[j:end]
    if chunk[:1] and chunk[0] in _DEGREE_NOUNS and words[j - 1 : j] == ["a"]:
        state = chunk[1:] or words[end : end + 1]  # "a tad wobbly": the adverb-like adjective ended the run
        end += len(chunk) == 1
    elif tuple(words[max(i, j - 2) : j]) == ("a", "little") and words[j - 3 : j - 2] and (
        words[j - 3] in _COPULAS and words[j - 4 : j - 3] not in (["there"], ["here"])
    ):
        state = chunk
    else:
        return False
    return len(state) == 1 and not _known_at(state, 0, known) and "ADJ" in word_classes(state[0]) and (
        end == len(words) or words[end] in _CLAUSE_END or words[end] in _BOUNDARY)


def _possessor(words: Sequence[str], j: int, end: int, known, verbs: set[str]) -> bool:
    """ "my grandfather's sextant", "the cat's bowl": the owner is no object to avoid, the thing owned is. Not a
    known object word, nor the owner of a part ("the kettle's handle": the kettle is the object)."""
    if end >= len(words) or not possessive(words, end) or any(_known_at(words, k, known) for k in range(j, end)):
        return False
    if end + 1 >= len(words) or words[end + 1] in _CLAUSE_END:
        return True  # "the vase ... it was my mother's": the owner of what was named before
    k = end + 1
    while k < len(words) and (words[k] in _DETERMINERS or words[k] in _MODIFIERS):
        k += 1
    owned_end = _noun_run(words, k, known, verbs)
    return owned_end > k and not _not_object(words[owned_end - 1])


def _not_object(word: str) -> bool:
    return word in NOT_OBJECTS or singular(word) in NOT_OBJECTS  # "at all times"


def _contents_after_of(words: Sequence[str], i: int) -> bool:
    """ "a bottle of wine", "the glass of water": what a container holds is not another object."""
    return i >= 2 and words[i - 1] == "of" and singular(words[i - 2]) in CONTAINERS_OF


# ---- the invariant ------------------------------------------------------------------------------------------


def _compatible(mention: Mention, ref: ObjectRef) -> bool:
    """No attribute the mention has differs from the object's (a target "phone" is not the mention "grey
    phone")."""
    return all(getattr(mention, a) in (None, getattr(ref, a)) for a in ("color", "size"))


def _covered(mention: Mention, obstacle: ObjectRef) -> bool:
    """An obstacle said without an attribute ("that mug") covers the mention with it ("the white mug"): grounding
    avoids every object its phrase names. Never used for targets: one object is acted on, not all its kind."""
    return all(getattr(obstacle, a) is None or getattr(mention, a) in (None, getattr(obstacle, a))
               for a in ("color", "size"))


def _exact_synonyms(skill: SkillSpec | None, k: int, registry=None) -> set[str]:
    """The registered synonyms of slot k's object, in this skill and in every other skill with a slot of the same
    word ("wine bottle" is the bottle's name in open_wine_bottle, so also in bottle_in_drawer)."""
    if skill is None or k >= len(skill.slots):
        return set()
    word = skill.slots[k].word
    synonyms = set(skill.slots[k].synonyms)
    for other in registry or ():
        synonyms |= {w for slot in other.slots if slot.word == word for w in slot.synonyms}
    return synonyms


def is_target(
    mention: Mention, plan: TaskPlan, skill: SkillSpec | None, registry=None, typed: Mapping[int, str] | None = None
) -> bool:
    """The mention is (or may be) one of the plan's targets: the same noun or a registered synonym of the same
    slot, and no attribute that tells them apart. A compound ("water bottle") is not its head's target ("bottle").
    With `typed` (slot index -> the word the user named that target with), another specific synonym names another
    object ("water the plant, the cactus is prickly")."""
    for k, target in enumerate(plan.targets):
        synonyms = _exact_synonyms(skill, k, registry)
        same = mention.name == target.name or (
            target.name in synonyms and (mention.name in synonyms or singular(mention.name) in synonyms)
        ) or (" " in target.name and mention.name == target.name.split()[-1])  # "the can": the watering can
        if same and names_another(mention.name, target.name, (typed or {}).get(k)):
            continue
        if same and _compatible(mention, target) and mention.position in (None, target.position, "other"):
            if mention.position == "other" and target.position != "other":
                continue
            return True
    return False


def names_another(name: str, slot_word: str, typed_word: str | None) -> bool:
    """Whether a word of a target's slot names another object of that kind: a specific word other than the one the
    target was named with ("water the plant, the cactus is prickly"); the slot's own word may mean either."""
    said = {typed_word, slot_word} if typed_word is not None else set()
    said |= {w.split()[-1] for w in said if " " in w}  # "the can" after "the watering can" is that can
    return typed_word is not None and not {name, singular(name)} & said


def is_obstacle(mention: Mention, plan: TaskPlan) -> bool:
    """The mention is among the plan's obstacles: the same head, no compound word the obstacle lacks ("mug" is
    the obstacle "coffee mug"; "water bottle" is not the obstacle "bottle"), no attribute that differs."""
    words = set(mention.name.split())
    for obstacle in plan.obstacles:
        theirs = set(obstacle.name.split())
        same = mention.name == obstacle.name or (
            (mention.head == obstacle.name.split()[-1] and words <= theirs) or (theirs <= words and len(theirs) > 0
                                                                                 and mention.head not in OBJECT_NOUNS)
        ) or f" {mention.name} " in f" {obstacle.name} "  # "toy" read in "the toy car", "towel" in "paper towel roll"
        if same and _covered(mention, obstacle):
            return True
    return False


def enforce_mentions(
    plan: TaskPlan, mentions: Sequence[Mention], skill: SkillSpec | None, registry=None,
    typed: Mapping[int, str] | None = None,
) -> TaskPlan:
    """`plan` with every mention that is neither a target nor an obstacle added as an obstacle (and a warning),
    and obstacles the instruction permits contact with removed (and a warning). `typed`: see `is_target`."""
    obstacles = list(plan.obstacles)
    warnings = list(plan.warnings)
    for mention in mentions:
        if mention.permitted or is_target(mention, plan, skill, registry, typed):
            continue
        if is_obstacle(mention, plan.model_copy(update={"obstacles": obstacles})):
            continue
        obstacles.append(mention.ref())
        warnings.append(
            f"'{mention.phrase}' is named but is neither acted on nor said to be avoided; it is avoided"
        )
    permitted = [m for m in mentions if m.permitted and not is_target(m, plan, skill, registry)]
    kept = []
    for obstacle in obstacles:
        if any(_permits(m, obstacle, plan) for m in permitted):
            warnings.append(f"contact with '{obstacle.phrase}' is permitted by the instruction; it is not avoided")
        else:
            kept.append(obstacle)
    return plan.model_copy(update={"obstacles": kept, "warnings": warnings})


def _permits(mention: Mention, obstacle: ObjectRef, plan: TaskPlan) -> bool:
    """A permission lifts the obstacle it names. Said of a compound named by a known noun inside it, only that
    compound's: "bumping the mouse pad is fine" leaves "don't touch the mice"."""
    if mention.compound:
        theirs = obstacle.name.split()
        return theirs[-1] == mention.compound.split()[-1] and set(theirs) <= set(mention.compound.split())
    return is_obstacle(mention, plan.model_copy(update={"obstacles": [obstacle]}))


def unaccounted(
    plan: TaskPlan, mentions: Sequence[Mention], skill: SkillSpec | None, registry=None
) -> list[Mention]:
    """Mentions a plan neither acts on nor avoids (and contact with which is not permitted): what a model's
    plan may not drop."""
    return [
        m for m in mentions if not m.permitted and not is_target(m, plan, skill, registry) and not is_obstacle(m, plan)
    ]
