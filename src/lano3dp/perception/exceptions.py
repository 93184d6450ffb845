"""Errors raised by perception: each names the object (or file) so a caller can act on it."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from lano3dp.errors import EmptyCloudError, Lano3dpError


class PerceptionError(Lano3dpError):
    """Base class of perception errors."""


class ObjectNotFoundError(PerceptionError, LookupError):
    """A named object is not visible in the frame."""

    def __init__(self, phrase: str, visible: Sequence[str] = ()):
        self.phrase = phrase
        self.visible = tuple(visible)
        seen = ", ".join(self.visible) if self.visible else "nothing"
        super().__init__(f"object '{phrase}' was not found in the frame; visible: {seen}")


class AmbiguousObjectError(PerceptionError, LookupError):
    """A phrase matches several objects and no rule picks one."""

    def __init__(self, phrase: str, candidates: Sequence[str]):
        self.phrase = phrase
        self.candidates = tuple(candidates)
        super().__init__(
            f"object '{phrase}' is ambiguous: it matches {', '.join(self.candidates)}; "
            "name a colour or size, or use the exact object name"
        )


class TooFewPointsError(PerceptionError, EmptyCloudError):
    """An object's mask has too few pixels with valid depth (inside the crop box) to make a cloud."""

    def __init__(self, name: str, count: int, minimum: int):
        self.name = name
        self.count = int(count)
        self.minimum = int(minimum)
        super().__init__(
            f"object '{name}' has {self.count} valid depth points, fewer than the {self.minimum} required "
            "(occluded, outside the crop box, or depth holes?)"
        )


class MissingWeightsError(PerceptionError, FileNotFoundError):
    """A model weights directory is missing or incomplete. Weights are never fetched from the hub."""

    def __init__(self, path: str | Path, what: str = "model weights", hint: str = ""):
        self.path = str(path)
        message = f"{what} not found at '{self.path}'"
        if hint:
            message += f": {hint}"
        super().__init__(message)
