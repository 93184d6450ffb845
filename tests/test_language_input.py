"""Issue 34, item 4: what the rules read is normalised and bounded, and typos are read with a warning."""

import re
import time

import pytest

from lano3dp import OfflineDecomposer
from lano3dp.language import InputRejectedError, UnknownVerbError
from lano3dp.language.normalize import MAX_INSTRUCTION_CHARS, normalize_instruction


@pytest.fixture(scope="module")
def decomposer():
    return OfflineDecomposer()


def reading(decomposer, instruction):
    plan = decomposer.decompose(instruction)
    return plan.summary(), plan.warnings


INVISIBLE = [
    ("put the bl\u200bock in the drawer", "U+200B ZERO WIDTH SPACE"),
    ("put the bl\u00adock in the drawer", "U+00AD SOFT HYPHEN"),
    ("put the blo\u200dck in the drawer", "U+200D ZERO WIDTH JOINER"),
    ("put the \ufeffblock in the drawer", "U+FEFF ZERO WIDTH NO-BREAK SPACE"),
    ("put the blo\u200eck in the drawer", "U+200E LEFT-TO-RIGHT MARK"),
    ("put the blo\x07ck in the drawer", "U+0007 control"),
]


@pytest.mark.parametrize(("instruction", "removed"), INVISIBLE)
def test_invisible_and_control_characters_are_removed_with_a_warning(decomposer, instruction, removed):
    summary, warnings = reading(decomposer, instruction)
    assert summary == "put_item_in_drawer(block, drawer)"
    assert warnings == [f"removed 1 invisible or control character(s) from the instruction ({removed})"]


def test_terminal_escapes_are_removed_and_full_width_letters_read_as_letters(decomposer):
    assert reading(decomposer, "put the \x1b[31mblock\x1b[0m in the drawer") == (
        "put_item_in_drawer(block, drawer)", ["removed 2 terminal escape sequence(s) from the instruction"],
    )  # fmt: skip
    assert reading(decomposer, "ｐｕｔ the ｂｌｏｃｋ in the drawer") == ("put_item_in_drawer(block, drawer)", [])
    assert reading(decomposer, "put the block in the drawer, avoid the café mug") == (
        "put_item_in_drawer(block, drawer); avoid cafe mug", [],
    )  # fmt: skip


REFUSED = [
    ("put the bl\u043eck in the drawer", "the word 'blоck' mixes Cyrillic and Latin letters (a look-alike letter?)"),
    ("put the block in the drawer, avoid the \u03bcug", "the word 'μug' mixes Greek and Latin letters"),
    ("put the block in the drawer, avoid the кружка", "'кружка' is not written in Latin letters"),
    ("put the \u202ekcolb\u202c in the drawer", "bidirectional control characters (U+202C, U+202E)"),
]


@pytest.mark.parametrize(("instruction", "reason"), REFUSED)
def test_look_alike_letters_other_scripts_and_bidi_overrides_are_refused(decomposer, instruction, reason):
    with pytest.raises(InputRejectedError, match=re.escape(reason)):
        decomposer.decompose(instruction)


def test_a_megabyte_instruction_is_refused_at_once_before_parsing(decomposer):
    huge = "put the block in the drawer and avoid the mug " * 23_000  # ~1 MB
    start = time.thread_time()  # CPU time: a busy machine does not fail it
    with pytest.raises(InputRejectedError) as refused:
        decomposer.decompose(huge)
    assert time.thread_time() - start < 0.05
    assert f"at most {MAX_INSTRUCTION_CHARS:,} are accepted" in str(refused.value)
    assert len(str(refused.value)) < 300  # the message quotes the start of it, not a megabyte
    assert normalize_instruction("a" * MAX_INSTRUCTION_CHARS).text == "a" * MAX_INSTRUCTION_CHARS


ADVERSARIAL = {
    "repeated task": "put the block in the drawer and avoid the mug ",
    "articles": "the ",
    "conjunctions": "and ",
    "cue list": "avoid the mug, ",
    "single letters": "a b c d e ",
    "pronouns": "avoid it ",
    "predicates": "the mug is in the way ",
    "unknown nouns": "the zorb, ",
    "modifiers": "the big red left small blue ",
    "negations": "don't open the drawer ",
    "properties": "the glass is very fragile ",
    "there is": "there's a mug, ",
    "typos": "blcok ",
    "one-anaphora": "a red one ",
    "positions": "the bowl on the left ",
    "between": "a mug is between the bowl and the pan ",
    "punctuation": ".,;:!? ",
    "one long word": "x",
}


def test_no_instruction_within_the_cap_takes_the_parser_more_than_about_100_ms(decomposer):
    """Each pattern repeated to the 1,000-character cap (the shapes that made rules quadratic before). The parser's
    CPU time (its thread's), best of three, so that a busy machine does not fail it: a wall-clock bound read 163 ms
    for 101 ms of CPU beside two trainings. Measured 1-27 ms of CPU, punctuation the slowest (101 ms before the
    scans over every clause, permission phrase and obstacle cue became lookups)."""
    times = {}
    for name, unit in ADVERSARIAL.items():
        text = (unit * (MAX_INSTRUCTION_CHARS // len(unit) + 1))[:MAX_INSTRUCTION_CHARS]
        best = float("inf")
        for _ in range(3):
            start = time.thread_time()
            try:
                decomposer.decompose(text)
            except ValueError:  # refusals are answers too
                pass
            best = min(best, time.thread_time() - start)
        times[name] = best
    assert max(times.values()) < 0.15, times


TYPOS = [
    ("put the blcok in the drawer", "put_item_in_drawer(block, drawer)", "read 'blcok' as 'block' (a typo?)"),
    ("pur the bowl into the pan", "bowl_pour(bowl, pan)", "read 'pur' as 'pour' (a typo?)"),
    ("pour the bowl into the pna", "bowl_pour(bowl, pan)", "read 'pna' as 'pan' (a typo?)"),
    ("put the bottle in the drawre", "bottle_in_drawer(bottle, drawer)", "read 'drawre' as 'drawer' (a typo?)"),
    ("opne the drawer", "open_drawer(drawer)", "read 'opne' as 'open' (a typo?)"),
    ("water the plant, avoid the vsae", "water_plants(watering can, plant); avoid vase",
     "read 'vsae' as 'vase' (a typo?)"),
    ("close the mircowave", "close_microwave(microwave)", "read 'mircowave' as 'microwave' (a typo?)"),
    # the head of a compound stands where a noun stands
    ("put the water bottel in the drawer", "bottle_in_drawer(water bottle, drawer)",
     "read 'bottel' as 'bottle' (a typo?)"),
    # shorthand: a noun after a verb or a preposition, a verb after a modal
    ("Put blcok in drawer.", "put_item_in_drawer(block, drawer)", "read 'blcok' as 'block' (a typo?)"),
    ("The drawer you must opne, please", "open_drawer(drawer)", "read 'opne' as 'open' (a typo?)"),
    # a verb no English dictionary has: a changed letter is a typo in a short word too (the blind table 14)
    ("sweap the dirt into the dustpan", "sweep_to_dustpan(broom, dustpan)", "read 'sweap' as 'sweep' (a typo?)"),
    # a last letter typed twice, though "putt" is a word (three blind tables wrote it)
    ("putt the block in the drawer", "put_item_in_drawer(block, drawer)", "read 'putt' as 'put' (a typo?)"),
]


@pytest.mark.parametrize("instruction", [
    "Water the plant, Sam, wait, with the watering can",  # a name, not "slam"
    "Close the microwave, its door was left ajar",  # a word of English, not "a jar"
])
def test_names_and_real_words_are_never_read_as_typos(decomposer, instruction):
    assert not any("a typo?" in w for w in decomposer.decompose(instruction).warnings)


@pytest.mark.parametrize(("instruction", "summary", "warning"), TYPOS)
def test_typos_of_known_words_are_corrected_and_the_correction_is_shown(decomposer, instruction, summary, warning):
    assert reading(decomposer, instruction) == (summary, [warning])


def test_real_words_are_never_corrected_into_a_skills_word(decomposer):
    # "vase" is one letter from "base", "fish" from "dish", "fan" from "pan", "plate" from "place", "clock" from
    # "block": all real objects (a changed letter in a short word is not read as a typo).
    assert reading(decomposer, "put the phone on the base, avoid the vase") == (
        "phone_on_base(phone, base); avoid vase", [],
    )  # fmt: skip
    plan = decomposer.decompose("pour the bowl into the pan, mind the fan, the fish and the clock")
    assert (plan.obstacle_phrases, [w for w in plan.warnings if "typo" in w]) == (["fan", "fish", "clock"], [])
    assert decomposer.decompose("put the plate in the drawer").target_phrases == ["plate", "drawer"]


EVERYDAY = [
    ("pop the block in the drawer", "put_item_in_drawer(block, drawer)", "read 'pop ... in' as 'put ... in'"),
    ("stick the phone on its base", "phone_on_base(phone, base)", "read 'stick ... on' as 'put ... on'"),
    ("chuck the block into the drawer", "put_item_in_drawer(block, drawer)", "read 'chuck ... into' as 'put ... into'"),
    ("park the phone on the dock", "phone_on_base(phone, base)", "read 'park ... on' as 'put ... on'"),
    ("give the plant a drink", "water_plants(watering can, plant)", "read 'give ... drink' as 'water ... drink'"),
    ("shut the microwave", "close_microwave(microwave)", None),
]


@pytest.mark.parametrize(("instruction", "summary", "warning"), EVERYDAY)
def test_everyday_verbs_that_clearly_mean_a_skill_are_read_as_it_with_a_warning(
    decomposer, instruction, summary, warning
):
    assert reading(decomposer, instruction) == (summary, [warning] if warning else [])


def test_an_everyday_verb_without_its_meaning_is_refused_with_a_suggestion(decomposer):
    with pytest.raises(UnknownVerbError, match="'smash' is not a verb any skill is asked for with; did you mean"):
        decomposer.decompose("smash the bowl into the pan")
    with pytest.raises(UnknownVerbError, match="'grab' is not a verb any skill is asked for with"):
        decomposer.decompose("grab the mug")


def test_every_obstacle_cue_starts_with_a_word_so_the_lookup_by_first_word_finds_it():
    """The parser checks at each token only the cues that start with its word; a cue starting with a class such as
    <ing> would never be found there."""
    from lano3dp.language import offline

    assert all(not cue[0].startswith("<") for cue in offline._CUES)
    assert sum(len(cues) for cues in offline._CUES_BY_FIRST.values()) == len(offline._CUES)
