"""Typos and everyday verbs: words the rules do not know, read as words they do, always with a warning.

A word is corrected only when all of these hold, so that a real word is never turned into another:
- it is not a word the rules or the object list know (`known`), nor a common English word listed here, nor
  (where a noun stands) any word of lemminflect's English lexicon, nor (where a verb stands) one it has as a verb;
- it stands where a verb or a noun stands (first word of a clause: a verb; after "the", "a", a colour, or
  after the first word of a compound: a noun), and is corrected only to a word of that kind;
- one candidate is strictly closest, at Damerau-Levenshtein distance 1 (a swap of two neighbouring letters
  counts 1: "pour" <- "puor"), or 2 for words of 9 letters or more;
- a changed letter (rather than a swapped, missing or extra one, or a letter typed twice: "brrom") only in nouns
  of 6 letters or more and verbs of 7 or more, since one changed letter in a shorter word is usually another
  word ("fish" / "dish", "vase" / "base", "clock" / "block", "change" / "charge"); 3-letter words only by a
  swap or a missing letter ("pna" -> "pan", "pur" -> "pour").
The matcher is rapidfuzz (a maintained C++ implementation), not a hand-written edit distance.

Everyday verbs that clearly mean a skill's verb ("pop the block in the drawer", "stick the phone on its base")
are read as that verb when the particle that makes their meaning is in the clause; each reading is a warning.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import NamedTuple

from rapidfuzz import process
from rapidfuzz.distance import DamerauLevenshtein

from lano3dp.language.mentions import word_classes

# Common English words a typo check must leave alone although they are one letter from a skill's word
# ("place" / "plate", "will" / "fill", "test" / "rest", "full" / "pull").
COMMON_WORDS = frozenset(
    """a about above after again against all also am an and any are as at away back be because been before being
    below between both but by can could did do does doing done down during each else even ever every few first
    for from full further get give go going gone good got had has have having he her here hers him his how i if
    in into is it its just keep kind last leave left let like little look lot made make many may me might mine
    more most much must my near need never new next no nor not now of off often ok okay on once only onto or
    other our out over own part pass past pick place plate please put quite rather really right same see set
    shall she should show side since slow slowly so some soon still stop such sure take tell than thank thanks
    that the their them then there these they thing think this those though through till to too top toward try
    turn under until up upon us use very want was way we well went were what when where which while who whom
    why will wish with within without would yet you your yours test best nest west vest rust must dust bust
    just cast last past fast mast vast most host post cost lost hand hands band land sand wand bill hill kill mill
    till will wall ball call fall hall tall fill full pull bull dull hull gull cull poll roll toll dock duck lock
    rock sock deck neck pack back rack sack tack hack jack lack crack track stack black slack snack bowl howl
    fowl cowl jowl growl prowl scowl owl soul foul full pour four sour tour your hour dour our power tower
    flower slower lower mower bower shower tip top tap tape type ripe pipe wipe lip hip dip rip sip zip ship
    chip skip slip drip grip trip strip whip stand hand brand grand gland land strand drop crop prop shop stop
    chop hop mop pop top cop dump jump bump lump pump rump sump hump stump tilt silt gilt hilt kilt wilt quilt
    built guilt spill still skill drill grill chill thrill sweep sleep sheep steep creep deep keep peep seep weep
    water later hater cater dater eater rater pattern open oven opened omen even seven eleven given
    close closed clone clothe clove glove cloth drawer drawn draws draw drew dress pan pen pin pun plan span
    can cane con cone cap cup cop cab cat cut cot pot pit pat put pet base vase case cast bass basin bison
    raisin plant slant scant chant grant giant plank plans planet bow row low tow sow mow cot car cat rag tab
    change invert""".split()
)
# Everyday verb -> (the lexicon verb it is read as, words that must follow in the clause for that reading).
_PUT_PARTICLES = frozenset({"in", "into", "inside", "on", "onto", "back"})
EVERYDAY_VERBS: dict[str, tuple[str, frozenset[str]]] = {
    **{
        word: ("put", _PUT_PARTICLES)
        for word in """pop stick chuck toss throw plonk plop bung stuff lay load hide get tidy relocate park deposit
        stow sit shove""".split()
    },
    "give": ("water", frozenset({"drink", "water"})),  # "give the plant a drink"
    "hydrate": ("water", frozenset()),  # no particle needed: the verb alone says it
}
_NOUN_SLOTS = frozenset(
    """the a an this that these those my your our their his her its some any another each both either
    red green blue yellow purple pink brown black white grey gray cyan magenta beige silver gold teal violet navy
    small little tiny large big huge medium tall short left right top bottom front back nearest other""".split()
)
_CLAUSE_STARTS = frozenset(
    """, ; . : ! ? and then please also now just you to i 'd kindly go ahead could would can will robot first
    next finally yo hey hi hello okay ok so must should shall""".split()
)
_NOUN_AFTER = frozenset("in into on onto to with from".split())
_TRIGGER_CLAUSE_END = frozenset(". ; : ! ? , and then but while".split())


_REVERSING_PREFIXES = frozenset({"re", "un", "de"})


def _reverses(word: str, other: str) -> bool:
    """ "recork" / "decork": the two differ by a prefix that reverses the verb, so one is no typo of the other."""
    return word[2:] == other[2:] and bool({word[:2], other[:2]} & _REVERSING_PREFIXES)


class Correction(NamedTuple):
    index: int
    said: str
    read_as: str


def _candidates(word: str, choices: Sequence[str]) -> list[tuple[str, int]]:
    limit = 2 if len(word) >= 9 else 1
    found = process.extract(word, choices, scorer=DamerauLevenshtein.distance, score_cutoff=limit, limit=None)
    best = min((distance for _, distance, _ in found), default=None)
    return [(choice, distance) for choice, distance, _ in found if distance == best]


def _swap_of(word: str, other: str) -> bool:
    return len(word) == len(other) and sorted(word) == sorted(other) and DamerauLevenshtein.distance(word, other) == 1


def _inserted(word: str, longer: str) -> bool:
    """`longer` is `word` with one letter added ("pur" -> "pour")."""
    return any(longer[:k] + longer[k + 1 :] == word for k in range(len(longer)))


def correct_word(word: str, choices: Sequence[str], substitution_from: int = 6) -> str | None:
    """The unique closest of `choices` under the rules above, or None. A changed letter (not a swap, a missing or
    an extra one) is accepted only in words of `substitution_from` letters or more: in shorter words it is as
    likely another word ("fish" / "dish", "vase" / "base", "clock" / "block")."""
    if not word.isalpha() or len(word) < 3:
        return None
    close = [
        (choice, distance)
        for choice, distance in _candidates(word, choices)
        if distance > 1 or len(word) >= substitution_from or not _substituted(word, choice)
    ]
    if len(close) != 1:
        return None
    ((choice, _),) = close
    if _reverses(word, choice):
        return None
    if len(word) == 3 and len(choice) < 4 and not _swap_of(word, choice):
        return None
    return choice


def _substituted(word: str, other: str) -> bool:
    """`other` is `word` with one letter changed (same length, not a swap of neighbours), other than a stutter:
    a letter typed twice in place of the next ("brrom" for "broom") is a typo, not another word."""
    if len(word) != len(other) or _swap_of(word, other):
        return False
    k = next(i for i, (a, b) in enumerate(zip(word, other, strict=True)) if a != b)
    return not (word[k] == word[k - 1 : k] or word[k] == word[k + 1 : k + 2])


def correct_typos(
    words: Sequence[str], is_known: Callable[[str], bool], verbs: Sequence[str], nouns: Sequence[str]
) -> tuple[list[str], list[Correction]]:
    """`words` (tokens) with typos of `verbs` and `nouns` corrected where they stand, and what was corrected.

    Args:
        words: tokens (lower case, punctuation as tokens).
        is_known: whether the caller reads a word (inflections included); such a word is never corrected.
        verbs / nouns: single-word candidates for verb and noun positions.
    """
    out = list(words)
    corrections: list[Correction] = []
    verb_set = set(verbs)
    for i, word in enumerate(words):
        if word in COMMON_WORDS or not word.isalpha() or word in EVERYDAY_VERBS or is_known(word):
            continue
        previous = out[i - 1] if i else ","  # as corrected: "opne drawr" -> "open", then "drawr" after a verb
        # a noun's place: after a determiner or an attribute, after the first noun of a compound ("the wine
        # botlte"), after a verb or a preposition in shorthand ("put blcok in drwer")
        compound = i >= 2 and out[i - 2] in _NOUN_SLOTS and previous.isalpha()
        english = word_classes(word)  # empty for a typo or a word English lacks
        if previous in _NOUN_SLOTS or compound or previous in verb_set or previous in _NOUN_AFTER:
            # a real word is no typo where a noun stands ("left ajar" is no "left jar")
            choice = None if english else correct_word(word, nouns, substitution_from=6)
        elif previous in _CLAUSE_STARTS:
            # a real word that can be a verb is no typo there; "poor the bowl" is one. A word English lacks
            # ("sweap") is another word by no reading, so a changed letter is a typo in a short verb too
            choice = None if "VERB" in english else correct_word(word, verbs, substitution_from=7 if english else 4)
            if choice is None and len(word) > 3 and word[-1] == word[-2] and word[:-1] in verb_set:
                choice = word[:-1]  # "putt the block in": a last letter typed twice, though "putt" is a word
        else:
            choice = None
        if choice is not None:
            out[i] = choice
            corrections.append(Correction(i, word, choice))
    return out, corrections


def everyday_verbs(words: Sequence[str], lexicon: Iterable[str]) -> tuple[list[str], list[Correction]]:
    """ "pop the block in the drawer" -> "put the block in the drawer": an everyday verb the lexicon lacks is read
    as a lexicon verb when its particle follows in the same clause; without one it is left as said."""
    lexicon = set(lexicon)
    out = list(words)
    corrections: list[Correction] = []
    for i, word in enumerate(words):
        reading = EVERYDAY_VERBS.get(word)
        previous = words[i - 1] if i else ","
        if reading is None or previous not in _CLAUSE_STARTS or reading[0] not in lexicon:
            continue
        verb, particles = reading
        if word == "pop" and "cork" in words[i + 1 : i + 3]:
            continue  # "pop the cork on the bottle" opens it: the idiom, not a placing
        if not particles:
            out[i] = verb
            corrections.append(Correction(i, word, verb))
            continue
        for k in range(i + 1, min(len(words), i + 10)):
            if words[k] in _TRIGGER_CLAUSE_END:
                break
            if words[k] in particles:
                out[i] = verb
                corrections.append(Correction(i, f"{word} ... {words[k]}", f"{verb} ... {words[k]}"))
                break
    return out, corrections


def suggest(word: str, choices: Sequence[str], cutoff: float = 70.0) -> str | None:
    """The closest of `choices` to an unknown `word` for a refusal's "did you mean", or None."""
    found = process.extractOne(word, choices, score_cutoff=cutoff)
    if found and _reverses(word, found[0]):
        return None  # never "recork: did you mean decork?"
    return found[0] if found else None
