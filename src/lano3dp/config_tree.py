"""Nested, typed settings as plain data: read from dicts, written to JSON, changed by dotted paths.

A settings tree is a frozen dataclass whose fields are values or other such dataclasses (EvalConfig, its
`guidance` section and theirs). One tree is written once and read by everything: the command line derives
`--set guidance.sampler.rho=0.02` and `--config eval.yaml` from the field paths (as LeRobot derives its CLI from
its config dataclasses), results save the tree, and a saved tree is read back by the same code.

    from_dict(GuidanceSettings, {"sampler": {"rho": 0.02}})      # the defaults of every other field
    override(settings, "sampler.rho", 0.02)                      # a copy with one field changed
    to_dict(settings)                                            # JSON types: lists, not tuples

Validation is pydantic's (types, nested dicts into dataclasses, unknown keys refused), and each dataclass's own
`__post_init__` checks run as it is built; every failure is one `SettingsError` line naming the field path.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, TypeVar

from lano3dp.errors import Lano3dpError

T = TypeVar("T")


class SettingsError(Lano3dpError, ValueError):
    """A setting that does not exist, has the wrong type or value, or cannot work with another one."""


def _adapter(cls):
    from pydantic import TypeAdapter  # imported here: the command line's --help reads defaults without it

    adapter = _ADAPTERS.get(cls)
    if adapter is None:
        adapter = _ADAPTERS[cls] = TypeAdapter(cls)
    return adapter


_ADAPTERS: dict[type, Any] = {}


def from_dict(cls: type[T], data: Mapping[str, Any], *, where: str = "") -> T:
    """`cls` built from a (nested) dict; fields left out take their defaults. `where` prefixes the field paths
    in errors (e.g. "guidance")."""
    from pydantic import ValidationError

    try:
        return _adapter(cls).validate_python(dict(data))
    except ValidationError as error:
        problem = error.errors()[0]
        path = ".".join(str(part) for part in (where, *problem["loc"]) if part != "")
        message = problem["msg"].removeprefix("Value error, ")
        if problem["type"] == "unexpected_keyword_argument":
            message = f"no such setting (settings here: {', '.join(_field_names(cls, problem['loc'][:-1]))})"
        if message.startswith(f"{path}"):  # a nested settings class named the path already
            raise SettingsError(message) from None
        raise SettingsError(f"{path or cls.__name__}: {message}") from None
    except (TypeError, ValueError) as error:  # a __post_init__ check that pydantic passes through
        raise SettingsError(f"{where or cls.__name__}: {error}") from None


def _field_names(cls, loc) -> list[str]:
    for part in loc:
        field = next((f for f in dataclasses.fields(cls) if f.name == part), None)
        if field is None or not dataclasses.is_dataclass(field.default_factory if field.default_factory
                                                          is not dataclasses.MISSING else field.default):
            return []
        cls = type(field.default_factory() if field.default_factory is not dataclasses.MISSING else field.default)
    return [f.name for f in dataclasses.fields(cls)]


def to_dict(settings) -> dict[str, Any]:
    """The tree in JSON types (tuples become lists), every field written."""
    return _jsonable(dataclasses.asdict(settings))


def _jsonable(value):
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    return value


def override(settings: T, path: str, value: Any, *, where: str = "") -> T:
    """A copy of `settings` with the field at dotted `path` set to `value` (a dict-valued field takes keys
    below it too: "execution.options.repair.steps"), validated as a whole."""
    return overrides(settings, {path: value}, where=where)


def overrides(settings: T, changes: Mapping[str, Any], *, where: str = "") -> T:
    """`override` for several paths at once (applied in order, validated once at the end)."""
    data = dataclasses.asdict(settings)
    for path, value in changes.items():
        keys = path.split(".")
        node, field, free = data, settings, False  # free: below a dict-valued field, where any key may go
        for depth, key in enumerate(keys):
            if not free and key not in node:
                raise SettingsError(f"{_join(where, '.'.join(keys[:depth + 1]))}: no such setting "
                                    f"(here: {', '.join(sorted(node))})")
            if depth == len(keys) - 1:
                node[key] = value
                break
            if not free:
                field = getattr(field, key) if dataclasses.is_dataclass(field) else field[key]
                free = isinstance(field, Mapping)
            child = node.setdefault(key, {}) if free else node[key]
            if not isinstance(child, dict):
                raise SettingsError(f"{_join(where, '.'.join(keys[:depth + 1]))} is a setting, not a section; "
                                    f"set it as {_join(where, '.'.join(keys[:depth + 1]))}=VALUE")
            node = child
    return from_dict(type(settings), data, where=where)


def _join(where: str, path: str) -> str:
    return f"{where}.{path}" if where else path


def parse_assignment(text: str) -> tuple[str, Any]:
    """'guidance.sampler.rho=0.02' -> ("guidance.sampler.rho", 0.02): the value is read as YAML (numbers,
    true/false, null, [lists]); a value that is not valid YAML is kept as text."""
    import yaml

    path, sep, raw = text.partition("=")
    path = path.strip()
    if not sep or not path or any(not part for part in path.split(".")):
        raise SettingsError(f"--set {text!r}: write it as section.field=value, e.g. guidance.sampler.rho=0.02")
    try:
        value = yaml.safe_load(raw) if raw.strip() else None
    except yaml.YAMLError:
        value = raw
    return path, value
