"""Named plug-in registries (obstacle shapes, observation types): one implementation of their shared rules.

A name is a word without spaces. Registering a name again with an object of the same class replaces it (a module
imported twice); another class needs `replace=True`, so a plug-in cannot silently take over a built-in. Built-in
entries cannot be removed, as configs and checkpoints default to them. Spawned worker processes start with the
built-ins alone, so a user's entry travels to them pickled (`worker_payload`).
"""

from __future__ import annotations

import pickle
from collections.abc import Callable, Iterator
from typing import Generic, TypeVar

T = TypeVar("T")


class Registry(Generic[T]):
    """Args:
        kind: what an entry is called in messages ("obstacle shape").
        not_found: the error class for an unknown name (it names the registered ones).
        methods: what an entry must have callable; a missing one is a TypeError naming `base`.
        base: the class to subclass for the defaults, as a user would import it.
        check: further validation of an entry (raise TypeError), e.g. a required attribute.
        hint: appended to the unknown-name message (how to make a user's entry known).
        field: the config field the name is given in, if users know the entry by it ("obs_type").
    """

    def __init__(self, kind: str, not_found: type[Exception], methods: tuple[str, ...], base: str, *,
                 check: Callable[[str, T], None] | None = None, hint: str = "", field: str | None = None):
        self.kind, self.not_found, self.methods, self.base = kind, not_found, methods, base
        self.check, self.hint, self.field = check, hint, field
        self._entries: dict[str, T] = {}
        self.builtin: tuple[str, ...] = ()

    def register(self, name: str, entry, *, replace: bool = False) -> T:
        if not isinstance(name, str) or not name or any(c.isspace() for c in name):
            raise ValueError(f"an {self.kind} name is a non-empty word without spaces, got {name!r}")
        if isinstance(entry, type):
            entry = entry()
        missing = [method for method in self.methods if not callable(getattr(entry, method, None))]
        if missing:
            raise TypeError(f"{self.kind} {name!r} lacks {', '.join(missing)}; subclass {self.base} for the defaults")
        if self.check is not None:
            self.check(name, entry)
        previous = self._entries.get(name)
        if previous is not None and type(previous) is not type(entry) and not replace:
            raise ValueError(f"{self.kind} {name!r} is already registered ({type(previous).__name__}); "
                             "pass replace=True to replace it")
        self._entries[name] = entry
        return entry

    def mark_builtin(self) -> tuple[str, ...]:
        """Everything registered so far is built in."""
        self.builtin = tuple(self._entries)
        return self.builtin

    def unregister(self, name: str) -> None:
        if name in self.builtin:
            raise ValueError(f"the built-in {self.kind} {name!r} cannot be removed")
        self.get(name)
        del self._entries[name]

    def names(self) -> tuple[str, ...]:
        """Registered names, built-in ones first, then in the order they were registered."""
        return tuple(self._entries)

    def get(self, name: str) -> T:
        entry = self._entries.get(name)
        if entry is None:
            raise self.not_found(f"unknown {self.field or self.kind} {name!r}; "
                                 f"registered: {', '.join(self.names())}{self.hint}")
        return entry

    def __iter__(self) -> Iterator[T]:
        return iter(list(self._entries.values()))

    def worker_payload(self, name: str) -> dict[str, bytes]:
        """{name: pickled entry} for a user's entry, {} for a built-in one. Pickled here and unpickled in the
        worker, so one that cannot be unpickled is reported per episode instead of killing the pool."""
        if name in self.builtin:
            return {}
        try:
            return {name: pickle.dumps(self.get(name))}
        except (pickle.PicklingError, AttributeError, TypeError) as error:
            raise ValueError(f"{self.kind} {name!r} cannot be sent to worker processes ({error}); define its class "
                             "at the top level of an importable module, or evaluate with workers=1") from None
