"""Scoring an instruction table under the one phrase convention (docs/language.md, issue 34).

Two table formats are read:
- {"cases": [{"instruction", "skill", "targets": ["red bowl", "pan"], "obstacles": [...], "refused"?: true,
  "objects"?: [...]}]}: phrases "position size colour noun";
- [{"instruction", "expected": {"skill", "targets": [{"name", "color", "size", "position"?}], "obstacles": [...]}
  or null (must be refused)}].

The convention: a target is compared by its slot. Where its noun is a registered synonym of its slot ("skillet"
in the pan slot, "flask" in the bottle slot) it is read as the slot word, on both sides, so a table written as
typed and a plan that reports the slot word agree; a noun the slot only accepts (the item slot's "stapler") is
compared as said. Objects compare as sets of words (position, size, colour and noun words), so "top drawer"
written as a name equals position "top" + name "drawer". What an object is made of, said before its noun ("glass
vase", "cast-iron skillet"), is no part of its name, on both sides (tables disagree: "the glass vase" is a vase).
Obstacles compare as a multiset: their order says nothing.
"""

from __future__ import annotations

import json
import re
import unicodedata
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from lano3dp.language import LanguageError
from lano3dp.language.mentions import MATERIALS
from lano3dp.language.offline import POSITION_WORDS
from lano3dp.vocabulary import COLOURS, SIZE_WORDS, canonical_attribute, singular

NEGATED = re.compile(r"\b(don'?t|do not|never|dont)\b", re.IGNORECASE)


@dataclass
class Case:
    instruction: str
    expected: tuple[str, list[dict], list[dict]] | None  # None: must be refused
    objects: list[str] | None = None


def _ref(value) -> dict:
    if isinstance(value, dict):
        return {k: value.get(k) for k in ("name", "color", "size", "position")}
    words = str(value).split()
    attributes = {"color": None, "size": None, "position": None}
    while len(words) > 1 and (words[0] in COLOURS or words[0] in SIZE_WORDS or words[0] in POSITION_WORDS):
        word = words.pop(0)
        key = "color" if word in COLOURS else "size" if word in SIZE_WORDS else "position"
        attributes[key] = attributes[key] or canonical_attribute(word)
    return {"name": " ".join(words), **attributes}


def load_cases(path: Path) -> list[Case]:
    data = json.loads(Path(path).read_text())
    rows = data["cases"] if isinstance(data, dict) else data
    cases = []
    for row in rows:
        if "expected" in row:
            expected = row["expected"]
            plan = None if expected is None else (
                expected["skill"], [_ref(t) for t in expected["targets"]], [_ref(o) for o in expected["obstacles"]]
            )
        elif row.get("refused"):
            plan = None
        else:
            plan = (row["skill"], [_ref(t) for t in row["targets"]], [_ref(o) for o in row["obstacles"]])
        cases.append(Case(row["instruction"], plan, row.get("objects")))
    return cases


def _words(ref: dict, slot=None) -> frozenset:
    name = ref["name"]
    if slot is not None and (name in slot.synonyms or singular(name) in slot.synonyms):
        name = slot.word  # the convention: a registered synonym is its slot's word, on both sides
    # a hyphen breaks words as a space does ("yo-yo" is read as "yo yo", as scene names are); accents are dropped
    # as the normaliser drops them ("pinata" for "pi\u00f1ata")
    name = "".join(c for c in unicodedata.normalize("NFKD", name) if not unicodedata.combining(c))
    words = name.replace("-", " ").split()
    while len(words) > 1 and words[0] in MATERIALS:
        words.pop(0)
    said = [ref.get("position"), ref.get("size"), ref.get("color"), " ".join(words)]
    return frozenset(canonical_attribute(w) for part in said if part for w in str(part).replace("-", " ").split())


def plan_key(plan: tuple[str, list[dict], list[dict]], registry) -> tuple:
    skill, targets, obstacles = plan
    slots = registry.get(skill).slots if skill in registry else ()
    target_words = [_words(t, slots[k] if k < len(slots) else None) for k, t in enumerate(targets)]
    return skill, target_words, Counter(_words(o) for o in obstacles)


@dataclass
class TableScore:
    total: int = 0
    exact: int = 0
    wrong: list[tuple[str, object]] = field(default_factory=list)
    dropped_obstacles: list[str] = field(default_factory=list)  # a named obstacle missing from the plan
    obstacle_as_target: list[str] = field(default_factory=list)
    negated_planned: list[str] = field(default_factory=list)
    refusals_expected: int = 0

    @property
    def rate(self) -> float:
        return self.exact / self.total if self.total else 0.0


def score_table(path: Path, decomposer) -> TableScore:
    """Exact plans and the safety counts of `decomposer` on the table at `path`."""
    score = TableScore()
    for case in load_cases(path):
        score.total += 1
        try:
            plan = decomposer.decompose(case.instruction, case.objects)
            got = (plan.skill, [t.model_dump() for t in plan.targets], [o.model_dump() for o in plan.obstacles])
        except LanguageError as error:
            got, plan = None, None
            reason = f"refused: {error}"
        expected = case.expected
        score.refusals_expected += expected is None
        if expected is None or got is None:
            ok = expected is None and got is None
            if expected is None and got is not None and NEGATED.search(case.instruction):
                score.negated_planned.append(case.instruction)
        else:
            registry = decomposer.registry
            want, have = plan_key(expected, registry), plan_key(got, registry)
            ok = want == have
            # dropped: a named obstacle the plan does not avoid; avoiding every one of its kind ("candle" for
            # "the red candle" beside "several candles") avoids it too
            if any(have[2][w] < n and not any(h and h < w for h in have[2]) for w, n in want[2].items()):
                score.dropped_obstacles.append(case.instruction)
            if set(want[2]) & set(have[1]):
                score.obstacle_as_target.append(case.instruction)
        score.exact += ok
        if not ok:
            score.wrong.append((case.instruction, plan.summary() if plan is not None else reason))
    return score
