"""Errors shared across layers. Each package adds its own specific subclasses."""


class Lano3dpError(Exception):
    """Base class of every error this library raises on purpose."""


class EmptyCloudError(Lano3dpError, ValueError):
    """A point cloud has no (or too few) points where some were required."""


class CorruptFileError(Lano3dpError, OSError):
    """A dataset or checkpoint file is truncated, unreadable or inconsistent."""

    def __init__(self, path, reason: str):
        self.path = str(path)
        super().__init__(f"{self.path}: {reason}")


class IncompatibleFormatError(Lano3dpError, ValueError):
    """A file was written in a format version this lano3dp cannot read (usually by a newer release)."""

    def __init__(self, path, found: int, supported: int):
        self.path, self.found, self.supported = str(path), found, supported
        super().__init__(f"{self.path}: written in format version {found}; this lano3dp reads versions up to "
                         f"{supported} (upgrade lano3dp to load it)")
