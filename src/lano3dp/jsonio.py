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

from lano3dp.errors import CorruptFileError, StorageError, describe_os_error


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


def discard(path: str | Path) -> None:
    """Remove a temporary file on a failure path, never raising: the error being reported is the one that
    matters (on a read-only file system even removing a file that is not there fails)."""
    try:
        os.unlink(path)
    except OSError:
        pass


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write `text` through a temporary file and a rename, so a kill leaves the old file or the new, never half.

    What was written is read back before the rename; a failure (a full disk, a read-only folder) removes the
    temporary file, leaves any old file as it was, and raises StorageError naming `path` and the cause.
    """
    path = Path(path)
    temporary = path.with_name(path.name + ".tmp")
    data = text.encode()
    try:
        with open(temporary, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())  # a full disk may only say so here
        if temporary.read_bytes() != data:
            raise OSError(f"{len(data)} bytes written but {temporary.stat().st_size} read back")
        os.replace(temporary, path)
    except OSError as error:
        discard(temporary)
        raise StorageError(path, describe_os_error(error)) from error
    except BaseException:
        discard(temporary)
        raise
    return path


def write_json(path: str | Path, data: Any) -> Path:
    """Write `data` as indented JSON atomically, creating the folder (see `to_jsonable` for what converts)."""
    path = Path(path)
    text = json.dumps(to_jsonable(data), indent=2) + "\n"  # converted before anything touches the disk
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise StorageError(path, describe_os_error(error)) from error
    return write_text_atomic(path, text)


def read_json(path: str | Path) -> Any:
    """The JSON in `path`; a file that is not JSON (empty, cut short by a full disk, edited) is a CorruptFileError
    naming it, so the message says which file rather than only "Expecting value: line 1 column 1"."""
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as error:  # JSONDecodeError is a ValueError
        reason = "the file is empty" if not path.stat().st_size else f"not valid JSON ({error})"
        raise CorruptFileError(path, reason) from None
