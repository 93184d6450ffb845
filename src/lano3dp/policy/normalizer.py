"""Min-max normalisation to [-1, 1], Diffusion Policy's "limits" mode.

Statistics are per dimension of the last axis: per action / state component, and per xyz for point
clouds (all slots and points share one xyz range, so the relative layout of objects is preserved).
They live in registered buffers, so they travel inside model.safetensors and follow `.to(device)`.
`unnormalize` is plain tensor arithmetic, hence differentiable: guidance back-propagates a metric
cost through it to the normalised trajectory.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import torch
from torch import nn

# Every key is in metres or unit-scale quantities (rotation components, gripper opening), so one floor
# serves all. Diffusion Policy only special-cases exactly constant dimensions (range < 1e-4); a nearly
# constant one, like the roll/pitch components of a yaw-only demonstration (range ~5e-4), then gets a
# scale of thousands, and the 1 cm of tilt a closed-loop hand picks up becomes an input of +-40 that
# the policy never saw: measured here, it turned smooth chunks into 10 cm jumps per step.
MIN_SPAN = 0.05


class NormalizerNotFittedError(RuntimeError):
    """The normaliser was used before `fit` / `set_stats`."""


class LinearNormalizer(nn.Module):
    """Per-key affine map x -> x * scale + offset taking [min, max] to [-1, 1] (spans below MIN_SPAN widened).

    Args:
        dims: key -> size of the last axis (e.g. {"action": 10, "state": 11, "object_clouds": 3}).
    """

    def __init__(self, dims: Mapping[str, int]):
        super().__init__()
        self.keys = tuple(dims)
        for key, dim in dims.items():
            for name in ("min", "max", "scale", "offset"):
                self.register_buffer(self._buffer(key, name), torch.zeros(dim))
        self.register_buffer("fitted", torch.zeros((), dtype=torch.bool))

    @staticmethod
    def _buffer(key: str, name: str) -> str:
        return f"{key}__{name}"

    def _get(self, key: str, name: str) -> torch.Tensor:
        if key not in self.keys:
            raise KeyError(f"normaliser has no statistics for {key!r}; it has {list(self.keys)}")
        return getattr(self, self._buffer(key, name))

    def set_stats(self, stats: Mapping[str, Mapping[str, np.ndarray | torch.Tensor]]) -> None:
        """Set statistics {key: {"min": (D,), "max": (D,)}} for every key of this normaliser."""
        missing = [key for key in self.keys if key not in stats]
        if missing:
            raise KeyError(f"normaliser statistics missing for {missing}")
        for key in self.keys:
            low = torch.as_tensor(np.asarray(stats[key]["min"], dtype=np.float32))
            high = torch.as_tensor(np.asarray(stats[key]["max"], dtype=np.float32))
            expected = self._get(key, "min").shape
            if low.shape != expected or high.shape != expected:
                raise ValueError(f"{key}: statistics of shape {tuple(low.shape)}/{tuple(high.shape)}, "
                                 f"expected {tuple(expected)}")
            if not (torch.isfinite(low).all() and torch.isfinite(high).all()) or bool((high < low).any()):
                raise ValueError(f"{key}: statistics must be finite with max >= min")
            # [min, max] -> [-1, 1]; a span below MIN_SPAN is widened about its midpoint instead.
            scale = 2.0 / (high - low).clamp_min(MIN_SPAN)
            offset = -scale * (low + high) / 2.0
            for name, value in (("min", low), ("max", high), ("scale", scale), ("offset", offset)):
                self._get(key, name).copy_(value)
        self.fitted.fill_(True)

    def fit(self, data: Mapping[str, np.ndarray]) -> None:
        """Fit on raw arrays {key: (..., D)}; every row of every key counts."""
        stats = {}
        for key in self.keys:
            if key not in data:
                raise KeyError(f"no data to fit the normaliser for {key!r}")
            rows = np.asarray(data[key], dtype=np.float64).reshape(-1, self._get(key, "min").shape[0])
            if len(rows) == 0:
                raise ValueError(f"no rows to fit the normaliser for {key!r}")
            stats[key] = {"min": rows.min(axis=0), "max": rows.max(axis=0)}
        self.set_stats(stats)

    def stats(self) -> dict[str, dict[str, np.ndarray]]:
        """{key: {"min": (D,), "max": (D,)}} as numpy arrays."""
        return {key: {name: self._get(key, name).detach().cpu().numpy().copy() for name in ("min", "max")}
                for key in self.keys}

    def scale(self, key: str) -> np.ndarray:
        """(D,) the map's slope per dimension (1 / unit): d normalised / d raw."""
        self._check()
        return self._get(key, "scale").detach().cpu().numpy().copy()

    def _check(self) -> None:
        if not bool(self.fitted):
            raise NormalizerNotFittedError("the policy's normaliser has no statistics yet; call "
                                           "set_normalizer(stats) or fit_normalizer(dataset) first")

    def normalize(self, key: str, x: torch.Tensor) -> torch.Tensor:
        """(..., D) raw -> (..., D) in [-1, 1] over the fitted range."""
        self._check()
        return x * self._get(key, "scale") + self._get(key, "offset")

    def unnormalize(self, key: str, x: torch.Tensor) -> torch.Tensor:
        """(..., D) normalised -> (..., D) raw units; differentiable in x."""
        self._check()
        return (x - self._get(key, "offset")) / self._get(key, "scale")
