"""Windowed samples for diffusion-policy training, as Diffusion Policy's SequenceSampler.

A sample is a window of `horizon` steps. Windows may start up to n_obs_steps - 1 steps
before an episode and end up to n_action_steps - 1 steps after it; the missing steps
repeat the episode's first or last frame (edge padding), so every state of an episode,
including the first, is a training observation.

With a time stride S the window's consecutive steps are S recorded steps apart (a policy for an env
recorded at 80 Hz with S = 4 sees and plans at 20 Hz); windows still start at every recorded step, and the
padding reaches S x (n_obs_steps - 1) recorded steps before an episode and S x (n_action_steps - 1) after it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from lano3dp.data.store import EpisodeStore
from lano3dp.errors import Lano3dpError


class NonFiniteDataError(Lano3dpError, ValueError):
    """A dataset holds NaN or infinite values where a policy would learn from them."""


def split_episodes(n_episodes: int, val_ratio: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Split episode indices into (train, val). At least one episode each when val_ratio > 0 and n >= 2."""
    if not 0.0 <= val_ratio < 1.0:
        raise ValueError(f"val_ratio must be in [0, 1), got {val_ratio}")
    order = np.random.default_rng(seed).permutation(n_episodes)
    n_val = int(round(n_episodes * val_ratio))
    if val_ratio > 0 and n_episodes >= 2:
        n_val = min(max(n_val, 1), n_episodes - 1)
    return np.sort(order[n_val:]), np.sort(order[:n_val])


def check_finite(store: EpisodeStore, data: dict[str, np.ndarray], episodes: Sequence[int]) -> None:
    """Refuse NaN/inf in the selected episodes, naming key, episode and step (a NaN would train silently)."""
    ends = store.episode_ends
    for key, values in data.items():
        if not np.issubdtype(values.dtype, np.floating):
            continue
        for episode in episodes:
            start = 0 if episode == 0 else int(ends[episode - 1])
            bad = ~np.isfinite(values[start:int(ends[episode])].reshape(int(ends[episode]) - start, -1)).all(axis=1)
            if bad.any():
                step = int(np.argmax(bad))
                raise NonFiniteDataError(f"{store.path}: data/{key} holds NaN or inf in episode {int(episode)} "
                                         f"(step {step}, {int(bad.sum())} step(s) in all); re-collect the dataset "
                                         "or leave that episode out")


def window_indices(episode_ends: np.ndarray, episodes: Sequence[int], horizon: int, pad_before: int,
                   pad_after: int, stride: int = 1) -> np.ndarray:
    """(M, 4) int64 rows of (buffer_start, buffer_end, sample_start, sample_end) for every window.

    buffer_start:buffer_end are the recorded rows the window spans, cut to its episode; sample_start and
    sample_end say where they lie in the uncut span, counted in recorded steps from the window's first step.
    Window step i is recorded row clip(buffer_start - sample_start + i * stride, buffer_start, buffer_end - 1)
    (`window_rows`). pad_before and pad_after count window steps; with stride 1 these are Diffusion Policy's
    SequenceSampler indices.
    """
    if stride < 1:
        raise ValueError(f"stride must be >= 1, got {stride}")
    span = (horizon - 1) * stride + 1  # recorded steps from a window's first step to its last, inclusive
    rows = []
    for episode in episodes:
        start = 0 if episode == 0 else int(episode_ends[episode - 1])
        end = int(episode_ends[episode])
        length = end - start
        for offset in range(-pad_before * stride, length - span + pad_after * stride + 1):
            buffer_start = max(offset, 0) + start
            buffer_end = min(offset + span, length) + start
            sample_start = buffer_start - (offset + start)
            rows.append((buffer_start, buffer_end, sample_start, sample_start + buffer_end - buffer_start))
    return np.asarray(rows, dtype=np.int64).reshape(-1, 4)


def window_rows(row: np.ndarray, length: int, stride: int = 1) -> np.ndarray:
    """The recorded rows of a window's first `length` steps: edge padding repeats the episode's first or last row."""
    buffer_start, buffer_end, sample_start, _ = (int(v) for v in row)
    return np.clip(buffer_start - sample_start + np.arange(length) * stride, buffer_start, buffer_end - 1)


class SequenceDataset:
    """Map-style dataset of training windows from an EpisodeStore, held in memory.

    Each item is {"obs": {key: (n_obs_steps, ...)}, "action": (horizon, action_dim)}, numpy
    arrays (a torch DataLoader's default collate makes them tensors).
    """

    def __init__(self, store: EpisodeStore | str, obs_keys: Sequence[str], action_key: str = "action",
                 n_obs_steps: int = 2, horizon: int = 16, n_action_steps: int = 8,
                 episodes: Sequence[int] | None = None, time_stride: int = 1):
        if time_stride < 1:
            raise ValueError(f"time_stride must be >= 1, got {time_stride}")
        if not 1 <= n_obs_steps <= horizon or not 1 <= n_action_steps <= horizon:
            raise ValueError(f"need 1 <= n_obs_steps, n_action_steps <= horizon; got {n_obs_steps}, "
                             f"{n_action_steps}, {horizon}")
        store = store if isinstance(store, EpisodeStore) else EpisodeStore.open(store)
        if store.n_episodes == 0:
            raise ValueError(f"{store.path} has no episodes")
        self.store = store
        self.obs_keys = list(obs_keys)
        self.action_key = action_key
        self.n_obs_steps, self.horizon, self.n_action_steps = n_obs_steps, horizon, n_action_steps
        self.time_stride = int(time_stride)
        self.episodes = np.arange(store.n_episodes) if episodes is None else np.asarray(episodes, dtype=np.int64)
        self.data = store.load([*self.obs_keys, action_key])
        check_finite(store, self.data, self.episodes)
        self.indices = window_indices(store.episode_ends, self.episodes, horizon,
                                      pad_before=n_obs_steps - 1, pad_after=n_action_steps - 1,
                                      stride=self.time_stride)

    def __len__(self) -> int:
        return len(self.indices)

    def _window(self, key: str, row: np.ndarray, length: int) -> np.ndarray:
        buffer_start, buffer_end, sample_start, sample_end = row
        if self.time_stride == 1 and sample_start == 0 and sample_end == self.horizon:
            return self.data[key][buffer_start:buffer_start + length]
        # Edge padding: repeat the first frame before the episode, the last after it.
        return self.data[key][window_rows(row, length, self.time_stride)]

    def __getitem__(self, index: int) -> dict:
        row = self.indices[index]
        obs = {key: self._window(key, row, self.n_obs_steps) for key in self.obs_keys}
        return {"obs": obs, "action": self._window(self.action_key, row, self.horizon)}

    def all_actions(self) -> np.ndarray:
        """Every action row of the selected episodes, for fitting the normaliser."""
        return self._rows(self.action_key)

    def all_obs(self, key: str) -> np.ndarray:
        return self._rows(key)

    def episode_arrays(self, key: str) -> list[np.ndarray]:
        """The selected episodes' rows of `key`, one array per episode."""
        ends = self.store.episode_ends
        return [self.data[key][(0 if e == 0 else ends[e - 1]):ends[e]] for e in self.episodes]

    def _rows(self, key: str) -> np.ndarray:
        return np.concatenate(self.episode_arrays(key), axis=0)
