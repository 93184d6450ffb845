"""JSON for results, dataset attributes and training states: one conversion of numpy/torch values, one atomic write.

Bottom layer: imports neither numpy nor torch, which it meets only through their `tolist`.
"""

from __future__ import annotations

import enum
import json
import math
import os
from pathlib import Path
from typing import Any


def to_jsonable(value: Any, *, finite: bool = True) -> Any:
    """`value` as plain JSON types: dict keys as strings, tuples and sets as lists, numpy arrays and scalars and
    torch tensors through their `tolist`, paths as strings, enums as their values.

    finite: write NaN and infinities as null (strict JSON, which results files promise); False keeps them, for
    states read back only by Python (a scheduler's `inf` must survive the round trip).
    """
    if isinstance(value, dict):
        return {str(key): to_jsonable(item, finite=finite) for key, item in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [to_jsonable(item, finite=finite) for item in value]
    if isinstance(value, enum.Enum):
        return to_jsonable(value.value, finite=finite)
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, str | bool | int) or value is None:
        return value
    if isinstance(value, float):
        return None if finite and not math.isfinite(value) else value
    if hasattr(value, "tolist"):  # numpy arrays and scalars, torch tensors
        return to_jsonable(value.tolist(), finite=finite)
    raise TypeError(f"cannot write a {type(value).__name__} as JSON")


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write `text` through a temporary file and a rename, so a kill leaves the old file or the new, never half."""
    path = Path(path)
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text(text)
    os.replace(temporary, path)
    return path


def write_json(path: str | Path, data: Any) -> Path:
    """Write `data` as indented JSON atomically, creating the folder (see `to_jsonable` for what converts)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_text_atomic(path, json.dumps(to_jsonable(data), indent=2) + "\n")
