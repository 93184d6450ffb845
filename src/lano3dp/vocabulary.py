"""The words language and perception share: colours, sizes, object nouns, and which scene objects a phrase means.

The offline parser reads "the small red bowl" with these words, the skill registry checks a plan's
objects against the scene with `resolve_phrase`, and the simulator's oracle segmenter masks the
object that same function picks; one module keeps the three from disagreeing about what a phrase
means. Pure Python with no lano3dp imports, so it sits in the bottom layer (tests/test_layers.py).
"""

from __future__ import annotations

import functools
import re
import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

COLOURS = frozenset(
    "red green blue yellow orange purple pink brown black white grey gray cyan magenta "
    "beige silver gold golden teal violet navy".split()
)
# Size words to one canonical word each, so "big bowl" finds an object whose size is "large".
SIZE_WORDS = {
    "small": "small", "little": "small", "tiny": "small", "mini": "small", "wee": "small", "teeny": "small",
    "large": "large", "big": "large", "huge": "large", "giant": "large",
    "medium": "medium", "mid": "medium", "middle": "medium",
    "tall": "tall", "short": "short",
    # comparatives and superlatives pick the same object among two or more ("the larger of the two bowls")
    "larger": "large", "largest": "large", "bigger": "large", "biggest": "large", "smaller": "small",
    "smallest": "small", "tinier": "small", "tiniest": "small", "taller": "tall", "tallest": "tall",
    "shorter": "short", "shortest": "short",
}  # fmt: skip
_COLOUR_ALIASES = {"gray": "grey", "golden": "gold"}
# Nouns of things found on a table, beyond the skills' own words. Language counts each one said as an object
# mention (which a plan must act on or avoid, with or without "the" before it), and the spelling corrector
# never "corrects" one into a skill's word ("vase" is not a typo of "base", nor "fish" of "dish").
OBJECT_NOUNS = frozenset(
    """mug cup teacup glass tumbler vase lamp kettle teapot jar can tin box carton crate case book notebook pen
    pencil marker plate saucer tray platter knife fork spoon spatula ladle whisk scissors tongs candle candlestick
    toaster blender mixer jug pitcher carafe decanter thermos canister container tub bucket pail basket bag pouch
    wallet purse key keys remote controller mouse keyboard laptop tablet monitor screen cable cord wire plug clock
    watch radio speaker headphones camera glasses ruler stapler tape folder paper napkin towel cloth rag sponge
    soap dispenser shaker grinder mill board tongs egg apple banana lemon lime pear peach fruit bread sandwich
    cookie cake toy ball cube block doll figurine statue ornament sculpture photo picture frame cactus succulent
    fan heater cushion pillow hat shoe umbrella helmet glove bin trashcan cylinder cone sphere pyramid brick
    battery lighter matches coaster bell hammer screwdriver wrench drill pliers nail screw bolt
    obstacle obstacles pot pan bowl dish bottle flask drawer microwave oven phone base dock charger plant flower
    broom brush dustpan sprinkler tumbler goblet chalice beaker vial tube toothbrush comb mirror ashtray""".split()
)
_STOPWORDS = frozenset("the a an this that these those some my our your its of one".split())
_TOKEN = re.compile(r"[a-z0-9]+")


# Kept as they are: plural-only nouns, and singular nouns that end in "s" ("thermos" is no plural of "thermo").
_PLURAL_ONLY = frozenset(
    "scissors tongs pliers tweezers shears binoculars headphones thermos canvas lens atlas".split()
)


@functools.lru_cache(maxsize=8192)
def singular(word: str) -> str:
    """English singular of an object noun ("bowls" -> "bowl", "knives" -> "knife", "batteries" -> "battery").

    Irregular plurals come from lemminflect's lexicon (a suffix rule makes "knive" and "batterie"); a word the
    lexicon lacks ("pipettes") loses its plural ending by rule. Among a word's noun lemmas an object noun wins
    ("glasses" -> "glass", "bases" -> "base")."""
    if word in _PLURAL_ONLY:
        return word
    by_rule = word
    if len(word) > 4 and word.endswith(("sses", "xes", "ches", "shes")):
        by_rule = word[:-2]
    elif len(word) > 3 and word.endswith("s") and not word.endswith(("ss", "us", "is")):
        by_rule = word[:-1]
    lemmas = _noun_lemmas(word) if word.isalpha() else ()
    if not lemmas:
        return by_rule
    if by_rule.endswith("se") and by_rule[:-1] in lemmas:
        by_rule = by_rule[:-1]  # "lenses" -> "lens": the lexicon also lists a "lense"
    return next((w for w in lemmas if w in OBJECT_NOUNS), by_rule if by_rule in lemmas else lemmas[0])


_LEXICON_LOADED = threading.Event()
_LEXICON_LOCK = threading.Lock()


def english_lexicon():
    """lemminflect with its lexicons loaded; imported on first use (~0.3 CPU-s), not when lano3dp is imported.

    lemminflect loads a lexicon lazily on its first lookup, without a lock: the threads of a batched evaluation,
    each reading its instruction at once, loaded it once per thread (16 loads at batch 16), hence the lock here."""
    import lemminflect

    if not _LEXICON_LOADED.is_set():
        with _LEXICON_LOCK:
            if not _LEXICON_LOADED.is_set():
                lemminflect.getAllLemmas("was")
                lemminflect.getInflection("be", "VBN")
                _LEXICON_LOADED.set()
    return lemminflect


def _noun_lemmas(word: str) -> tuple[str, ...]:
    return tuple(english_lexicon().getAllLemmas(word).get("NOUN", ()))


def canonical_attribute(word: str) -> str:
    word = word.lower()
    return SIZE_WORDS.get(word, _COLOUR_ALIASES.get(word, word))


def tokens(text: str) -> list[str]:
    """Lower-case word tokens; underscores and hyphens split words; articles are dropped."""
    return [t for t in _TOKEN.findall(text.lower().replace("_", " ")) if t not in _STOPWORDS]


@dataclass(frozen=True)
class SceneObject:
    """One object in words: its name, kind noun (as tokens) and attribute words (colour, size, ...)."""

    name: str
    kind: tuple[str, ...]
    attributes: frozenset[str] = field(default_factory=frozenset)

    @classmethod
    def from_frame_entry(cls, name: str, attributes: Mapping[str, str] | None) -> SceneObject:
        attributes = dict(attributes or {})
        name_tokens = [t for t in tokens(name) if not t.isdigit()]
        kind_text = attributes.get("kind") or (name_tokens[-1] if name_tokens else name)
        kind = tuple(singular(t) for t in tokens(str(kind_text)))
        # "role" (target / distractor / obstacle) is bookkeeping, not something a person says.
        words = {canonical_attribute(str(v)) for k, v in attributes.items() if k not in ("kind", "role") and v}
        # Names like "red_bowl" carry their attributes when the simulator gives none.
        words |= {canonical_attribute(t) for t in name_tokens if t in COLOURS or t in SIZE_WORDS}
        return cls(name, kind, frozenset(words))


def _contains(sequence: Sequence[str], sub: Sequence[str]) -> int:
    """Index of the first occurrence of `sub` in `sequence`, or -1."""
    n = len(sub)
    for i in range(len(sequence) - n + 1):
        if tuple(sequence[i : i + n]) == tuple(sub):
            return i
    return -1


def resolve_phrase(phrase: str, objects: Sequence[SceneObject]) -> list[str]:
    """Names of the objects a phrase can mean (empty if none, several if ambiguous).

    An exact object name wins outright. Otherwise an object matches when its kind noun
    appears in the phrase (the longest matching kind wins, so "watering can" beats "can")
    and every colour or size word left in the phrase is one of the object's attributes.
    Other words ("ceramic", "over there") are ignored.
    """
    phrase_tokens = tokens(phrase)
    joined = " ".join(phrase_tokens)
    for obj in objects:
        if joined and joined == " ".join(tokens(obj.name)):
            return [obj.name]
    words = [singular(t) for t in phrase_tokens]
    scene_attributes = set().union(*(o.attributes for o in objects)) if objects else set()
    best_len, matches = 0, []
    for obj in objects:
        start = _contains(words, obj.kind) if obj.kind else -1
        if start < 0:
            continue
        rest = [canonical_attribute(w) for i, w in enumerate(phrase_tokens) if not start <= i < start + len(obj.kind)]
        descriptive = [w for w in rest if w in COLOURS or w in SIZE_WORDS.values() or w in scene_attributes]
        if any(w not in obj.attributes for w in descriptive):
            continue
        if len(obj.kind) > best_len:
            best_len, matches = len(obj.kind), [obj.name]
        elif len(obj.kind) == best_len:
            matches.append(obj.name)
    return matches
