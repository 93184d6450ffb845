"""Errors specific to guided sampling and checked execution."""

from lano3dp.errors import EmptyCloudError, Lano3dpError

__all__ = ["CollisionError", "EmptyCloudError", "GuidanceError"]


class GuidanceError(Lano3dpError, ValueError):
    """Guidance cannot be applied as configured (bad cost shape, non-finite gradient...)."""


class CollisionError(Lano3dpError, RuntimeError):
    """No collision-free action chunk was found; the chunk must not be executed."""
