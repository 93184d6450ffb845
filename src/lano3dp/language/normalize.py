"""What an instruction is before any rule reads it: bounded, normalised, in one script.

Every decomposer (the rules, an LLM, the cross-check) reads the text `normalize_instruction` returns, so an
invisible character, a look-alike letter or a terminal escape cannot make "bl\u200bock" a different word
from "block", and a megabyte of text is refused before a regular expression runs over it.

Steps, in order (each a function below):
1. Length: more than `MAX_INSTRUCTION_CHARS` characters is refused at once (checked again after NFKC, which
   can expand a character to several).
2. ANSI escape sequences (colours, cursor moves pasted from a terminal) are removed.
3. Unicode NFKC: full-width letters, ligatures ("ﬁ") and compatibility forms become plain letters.
4. Bidirectional overrides and isolates (U+202A-U+202E, U+2066-U+2069) are refused: they make a line display in
   another order than it is read, so removing them would leave a text the user never saw. Other format
   characters (zero-width space and joiners, soft hyphen, bidi marks, BOM) and control characters are removed
   (tab and newline become spaces).
5. Scripts: a word mixing scripts (a Cyrillic "о" inside "blоck") is refused; so is a word in another script
   altogether, since the rules read English and would otherwise skip it (and an object named in it).
6. Accents are dropped from Latin letters ("café" -> "cafe"), since the rules' words are ASCII.
"""

from __future__ import annotations

import re
import unicodedata
from typing import NamedTuple

from lano3dp.language.exceptions import InputRejectedError

MAX_INSTRUCTION_CHARS = 1000

# CSI (ESC [ ... final byte), OSC (ESC ] ... BEL or ST), and two-character escapes; also the 8-bit CSI.
_ANSI = re.compile(r"\x1b\[[0-?]*[ -/]*[@-~]|\x1b\][^\x07\x1b]*(?:\x07|\x1b\\)?|\x1b[@-Z\\-_]|\x9b[0-?]*[ -/]*[@-~]")
_BIDI_EMBEDDINGS = frozenset("\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069")
_LETTERS = re.compile(r"[^\W\d_]+")


class NormalizedInstruction(NamedTuple):
    """text: what the rules read; warnings: what was removed or changed, for the user."""

    text: str
    warnings: list[str]


def check_length(instruction: str) -> None:
    """Raise `InputRejectedError` for an instruction over `MAX_INSTRUCTION_CHARS`; O(1), before any parsing."""
    if len(instruction) > MAX_INSTRUCTION_CHARS:
        raise InputRejectedError(
            instruction,
            f"it is {len(instruction):,} characters long; at most {MAX_INSTRUCTION_CHARS:,} are accepted "
            "(say one task in a sentence or two)",
        )


def normalize_instruction(instruction: str) -> NormalizedInstruction:
    """The instruction as the rules read it, and warnings for what was removed.

    Raises:
        InputRejectedError: too long, a bidirectional override, or a word in a mixed or non-Latin script.
    """
    if not isinstance(instruction, str):
        raise InputRejectedError(repr(instruction), f"an instruction is text, got {type(instruction).__name__}")
    check_length(instruction)
    warnings: list[str] = []
    text, escapes = _ANSI.subn(" ", instruction)
    if escapes:
        warnings.append(f"removed {escapes} terminal escape sequence(s) from the instruction")
    text = unicodedata.normalize("NFKC", text)
    check_length(text)
    overrides = sorted({f"U+{ord(c):04X}" for c in text if c in _BIDI_EMBEDDINGS})
    if overrides:
        raise InputRejectedError(
            instruction,
            f"it contains bidirectional control characters ({', '.join(overrides)}) that change the order it is "
            "shown in; retype it without them",
        )
    text, removed = _without_invisible(text)
    if removed:
        names = ", ".join(f"U+{ord(c):04X} {unicodedata.name(c, 'control')}" for c in sorted(set(removed)))
        warnings.append(f"removed {len(removed)} invisible or control character(s) from the instruction ({names})")
    _check_scripts(instruction, text)
    text = "".join(c for c in unicodedata.normalize("NFKD", text) if not unicodedata.combining(c))
    return NormalizedInstruction(" ".join(text.split()), warnings)


def _without_invisible(text: str) -> tuple[str, list[str]]:
    kept, removed = [], []
    for char in text:
        category = unicodedata.category(char)
        if char in "\t\n\r\v\f":
            kept.append(" ")
        elif category in ("Cc", "Cf", "Co", "Cs", "Cn") or char == "\u00ad":
            removed.append(char)  # zero-width space/joiners, soft hyphen, bidi marks, BOM, controls, unassigned
        else:
            kept.append(char)
    return "".join(kept), removed


def _script(char: str) -> str:
    """The script of a letter by its Unicode name ("LATIN SMALL LETTER A" -> "LATIN"): no library needed for
    the one distinction that matters here, Latin or not."""
    return unicodedata.name(char, "UNKNOWN").split()[0]


def _check_scripts(instruction: str, text: str) -> None:
    for word in _LETTERS.findall(text):
        scripts = sorted({_script(c) for c in word})
        if len(scripts) > 1:
            raise InputRejectedError(
                instruction,
                f"the word '{word}' mixes {' and '.join(s.title() for s in scripts)} letters (a look-alike "
                "letter?); retype it in Latin letters",
            )
        if scripts != ["LATIN"]:
            raise InputRejectedError(
                instruction, f"'{word}' is not written in Latin letters; instructions are read in English"
            )
