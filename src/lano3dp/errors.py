"""Errors shared across layers. Each package adds its own specific subclasses."""

from __future__ import annotations

import os


class Lano3dpError(Exception):
    """Base class of every error this library raises on purpose."""


class EmptyCloudError(Lano3dpError, ValueError):
    """A point cloud has no (or too few) points where some were required."""


class CorruptFileError(Lano3dpError, OSError):
    """A dataset or checkpoint file is truncated, unreadable or inconsistent."""

    def __init__(self, path, reason: str):
        self.path, self.reason = str(path), reason
        super().__init__(f"{self.path}: {reason}")

    def __str__(self) -> str:  # OSError's own str() would show "[Errno ...]" forms for some argument counts
        return f"{self.path}: {self.reason}"

    def __reduce__(self):  # an evaluation worker's error crosses the process boundary as itself
        return type(self), (self.path, self.reason)


class IncompatibleFormatError(Lano3dpError, ValueError):
    """A file was written in a format version this lano3dp cannot read (usually by a newer release)."""

    def __init__(self, path, found: int, supported: int):
        self.path, self.found, self.supported = str(path), found, supported
        super().__init__(f"{self.path}: written in format version {found}; this lano3dp reads versions up to "
                         f"{supported} (upgrade lano3dp to load it)")

    def __reduce__(self):
        return type(self), (self.path, self.found, self.supported)


class StorageError(Lano3dpError, OSError):
    """A file could not be written whole (a full disk, a read-only folder, a tool that failed), or what was
    written did not read back; nothing of it is left under its name.

    Attributes:
        path: the file that was being written.
        cause: what went wrong, one line ("No space left on device").
    """

    def __init__(self, path, cause: str):
        self.path, self.cause = str(path), cause
        super().__init__(f"cannot write {self.path}: {cause}")

    def __str__(self) -> str:
        return f"cannot write {self.path}: {self.cause}"

    def __reduce__(self):
        return type(self), (self.path, self.cause)


def describe_os_error(error: BaseException) -> str:
    """The cause of a failed write on one line: "No space left on device" for an OSError with an errno, else
    the error's own text (a library's message), always naming its type when it has no text."""
    if isinstance(error, OSError) and error.errno is not None:
        return error.strerror or os.strerror(error.errno)
    text = " ".join(part.strip() for part in str(error).splitlines() if part.strip())
    return text or type(error).__name__
