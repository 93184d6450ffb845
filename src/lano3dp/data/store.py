"""Episode store in zarr, in Diffusion Policy's layout.

    <root>/data/<key>          episodes concatenated on axis 0
    <root>/meta/episode_ends   int64, exclusive end index of each episode
    <root> attributes          skill, object_names, camera, control_hz, versions, ...

Appending is crash-safe: zarr's local store writes every chunk atomically (temp file +
rename), and `meta/episode_ends` is written last, so it is the commit point. Rows past
the last episode end (an append cut short), and an end entry whose value was never
written, are invisible to readers and are overwritten by the next append.
"""

from __future__ import annotations

import platform
import re
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np
import zarr

from lano3dp.errors import CorruptFileError, Lano3dpError
from lano3dp.jsonio import to_jsonable

FORMAT_NAME = "lano3dp-episodes"
FORMAT_VERSION = 1
# Aim for chunks of about this many bytes along the time axis: large enough for fast
# reads, small enough that an append rewrites little.
_TARGET_CHUNK_BYTES = 2 << 20
_UNCOMMITTED_END = 0  # fill value of meta/episode_ends
ZARR_NEEDED = (3, 0, 8)  # the store uses zarr 3's API (create_array, async store listing); pyproject's lower bound


class DatasetSchemaError(Lano3dpError, ValueError):
    """An episode does not match the store's keys, shapes or dtypes."""


class ZarrVersionError(Lano3dpError, RuntimeError):
    """The installed zarr cannot write or read an episode store."""


def check_zarr_version(path) -> None:
    """Refuse, before a file is touched, to write or read a store with a zarr older than the store needs (zarr 2
    would fail half-way, leaving a store that then reads as damaged)."""
    installed = tuple(int(part) for part in re.findall(r"\d+", zarr.__version__)[:3])
    if installed < ZARR_NEEDED:
        needed = ".".join(map(str, ZARR_NEEDED))
        raise ZarrVersionError(f"{path}: episode stores need zarr >= {needed}, but zarr {zarr.__version__} is "
                               f"installed; pip install 'zarr>={needed}'")


def library_versions() -> dict[str, str]:
    import importlib.metadata as md

    versions = {"python": platform.python_version()}
    for package in ("lano3dp", "numpy", "zarr", "mujoco", "torch"):
        try:
            versions[package] = md.version(package)
        except md.PackageNotFoundError:
            pass
    return versions


class EpisodeStore:
    """A zarr store of episodes. Open with `create`, `open` or `open_or_create`."""

    def __init__(self, root: zarr.Group, path: Path):
        self._root = root
        self.path = path
        ends = np.asarray(root["meta/episode_ends"][:], dtype=np.int64)
        # Growing meta/episode_ends writes its new shape before its new value, so an append killed in
        # between leaves one trailing fill value (0). No episode ends at 0: that entry was never committed.
        if len(ends) and ends[-1] == _UNCOMMITTED_END:
            ends = ends[:-1]
        self._episode_ends = ends

    # ---- construction -------------------------------------------------------------------
    @classmethod
    def create(cls, path, attrs: Mapping | None = None, overwrite: bool = False) -> EpisodeStore:
        path = Path(path)
        check_zarr_version(path)
        if path.exists() and not overwrite:
            raise FileExistsError(f"{path} already exists; open it, or pass overwrite=True")
        root = zarr.open_group(str(path), mode="w")
        root.create_group("data")
        meta = root.create_group("meta")
        meta.create_array("episode_ends", shape=(0,), chunks=(4096,), dtype="int64", fill_value=_UNCOMMITTED_END)
        root.attrs.update(
            to_jsonable(
                {"format": FORMAT_NAME, "format_version": FORMAT_VERSION, "versions": library_versions()}
                | dict(attrs or {})
            )
        )
        return cls(root, path)

    @classmethod
    def open(cls, path, mode: str = "r") -> EpisodeStore:
        """Open an existing store; mode "r" (read-only) or "r+" (append)."""
        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"dataset {path} does not exist")
        check_zarr_version(path)
        try:
            root = zarr.open_group(str(path), mode=mode)
            if root.attrs.get("format") != FORMAT_NAME:
                raise CorruptFileError(path, f"not a {FORMAT_NAME} store (format={root.attrs.get('format')!r})")
            store = cls(root, path)
            store._validate()
        except CorruptFileError:
            raise
        except Exception as error:  # zarr raises many types for damaged metadata or chunks
            raise CorruptFileError(path, f"unreadable dataset ({type(error).__name__}: {error})") from error
        return store

    @classmethod
    def open_or_create(cls, path, attrs: Mapping | None = None) -> EpisodeStore:
        """Open for appending if `path` exists (checking `attrs` agree on skill and objects), else create."""
        path = Path(path)
        if not path.exists():
            return cls.create(path, attrs)
        store = cls.open(path, mode="r+")
        for key in ("skill", "object_names"):
            if attrs and key in attrs and key in store.attrs and store.attrs[key] != to_jsonable(attrs[key]):
                raise DatasetSchemaError(
                    f"{path} holds {key}={store.attrs[key]!r}, but {to_jsonable(attrs[key])!r} was asked for"
                )
        return store

    def _validate(self) -> None:
        """Refuse a store whose arrays do not hold every committed step (zarr would read fill values)."""
        ends = self._episode_ends
        if len(ends) and (np.any(np.diff(ends) <= 0) or ends[0] <= 0):
            raise CorruptFileError(self.path, "meta/episode_ends is not strictly increasing")
        for key in self.keys:
            array = self._root["data"][key]
            if array.shape[0] < self.n_steps:
                episode = self.episode_of_row(array.shape[0])
                raise CorruptFileError(
                    self.path, f"data/{key} has {array.shape[0]} rows, but meta/episode_ends says episode {episode} "
                    f"ends at row {int(ends[episode])} ({self.n_steps} rows in all): episodes {episode}.. are "
                    "incomplete")
            self._check_chunks(key, array)

    def _check_chunks(self, key: str, array) -> None:
        """Every chunk holding committed rows must be stored: a missing one would read as zeros."""
        import itertools

        from zarr.core.sync import sync

        async def stored(prefix: str) -> set[str]:
            return {name async for name in array.store.list_prefix(prefix)}

        rows = array.chunks[0]
        grid = [range(-(-self.n_steps // rows)), *(range(-(-n // c)) for n, c in
                                                   zip(array.shape[1:], array.chunks[1:], strict=True))]
        present = sync(stored(array.path + "/"))
        for coords in itertools.product(*grid):
            if f"{array.path}/{array.metadata.encode_chunk_key(coords)}" not in present:
                first = coords[0] * rows
                raise CorruptFileError(
                    self.path, f"data/{key} is missing chunk {'/'.join(map(str, coords))} (rows {first}-"
                    f"{min(first + rows, self.n_steps) - 1}, episode {self.episode_of_row(first)}); restore the "
                    "dataset or re-collect it")

    def episode_of_row(self, row: int) -> int:
        """Index of the episode that holds buffer row `row` (n_episodes - 1 for rows past the end)."""
        return int(min(np.searchsorted(self._episode_ends, row, side="right"), max(self.n_episodes - 1, 0)))

    # ---- properties ---------------------------------------------------------------------
    @property
    def attrs(self) -> dict:
        return dict(self._root.attrs)

    def update_attrs(self, **attrs) -> None:
        self._root.attrs.update(to_jsonable(attrs))

    @property
    def keys(self) -> list[str]:
        return sorted(name for name, _ in self._root["data"].arrays())

    @property
    def episode_ends(self) -> np.ndarray:
        return self._episode_ends.copy()

    @property
    def n_episodes(self) -> int:
        return len(self._episode_ends)

    @property
    def n_steps(self) -> int:
        return int(self._episode_ends[-1]) if len(self._episode_ends) else 0

    def episode_lengths(self) -> np.ndarray:
        return np.diff(np.concatenate([[0], self._episode_ends]))

    # ---- writing ------------------------------------------------------------------------
    def append_episode(self, episode: Mapping[str, np.ndarray]) -> int:
        """Append one episode; every array has the same length T >= 1 on axis 0. Returns its index."""
        if not episode:
            raise DatasetSchemaError("an episode needs at least one array")
        lengths = {key: len(value) for key, value in episode.items()}
        length = next(iter(lengths.values()))
        if length == 0 or any(n != length for n in lengths.values()):
            raise DatasetSchemaError(f"episode arrays must share a non-zero length on axis 0, got {lengths}")
        existing = set(self.keys)
        if existing and existing != set(episode):
            raise DatasetSchemaError(
                f"episode keys {sorted(episode)} differ from the store's {sorted(existing)}"
            )
        start = self.n_steps
        # Store every chunk, even one equal to the fill value, so that a missing chunk file always means damage.
        with zarr.config.set({"array.write_empty_chunks": True}):
            self._write_rows(episode, existing, start, length)
        ends = self._root["meta/episode_ends"]
        ends.resize((self.n_episodes + 1,))
        ends[self.n_episodes] = start + length  # the commit point
        self._episode_ends = np.append(self._episode_ends, start + length)
        return self.n_episodes - 1

    def _write_rows(self, episode: Mapping[str, np.ndarray], existing: set[str], start: int, length: int) -> None:
        data = self._root["data"]
        for key, value in episode.items():
            value = np.asarray(value)
            if key not in existing:
                row_bytes = max(1, value[0].nbytes)
                chunk_rows = int(np.clip(_TARGET_CHUNK_BYTES // row_bytes, 1, 4096))
                data.create_array(key, shape=(0, *value.shape[1:]), chunks=(chunk_rows, *value.shape[1:]),
                                  dtype=value.dtype)
            array = data[key]
            if array.shape[1:] != value.shape[1:]:
                raise DatasetSchemaError(f"'{key}' has per-step shape {value.shape[1:]}, store has {array.shape[1:]}")
            if not np.can_cast(value.dtype, array.dtype, casting="same_kind"):
                raise DatasetSchemaError(f"'{key}' has dtype {value.dtype}, store has {array.dtype}")
            # Drops rows left by an append that was cut short, then writes after the last episode.
            array.resize((start + length, *array.shape[1:]))
            array[start:] = value

    # ---- reading ------------------------------------------------------------------------
    def episode_slice(self, index: int) -> slice:
        if not -self.n_episodes <= index < self.n_episodes:
            raise IndexError(f"episode {index} out of range: {self.path} has {self.n_episodes} episodes")
        index %= self.n_episodes
        start = 0 if index == 0 else int(self._episode_ends[index - 1])
        return slice(start, int(self._episode_ends[index]))

    def get_episode(self, index: int, keys: Iterable[str] | None = None) -> dict[str, np.ndarray]:
        window = self.episode_slice(index)
        return {key: self._read(key, window) for key in (keys or self.keys)}

    def load(self, keys: Iterable[str] | None = None) -> dict[str, np.ndarray]:
        """Every committed step of `keys` (default all) as in-memory arrays."""
        return {key: self._read(key, slice(0, self.n_steps)) for key in (keys or self.keys)}

    def _read(self, key: str, window: slice) -> np.ndarray:
        if key not in self._root["data"]:
            raise KeyError(f"{self.path} has no data/{key}; it has {self.keys}")
        try:
            return np.asarray(self._root["data"][key][window])
        except Exception as error:
            raise CorruptFileError(self.path, f"data/{key} is unreadable ({type(error).__name__}: {error})") from error

    def __repr__(self) -> str:
        return f"EpisodeStore({str(self.path)!r}, episodes={self.n_episodes}, steps={self.n_steps}, keys={self.keys})"
