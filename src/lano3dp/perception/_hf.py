"""Shared helpers for the transformers backends: local-only loading and image conversion."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lano3dp.perception.exceptions import MissingWeightsError

_HINT = (
    "point it at a local folder holding config.json and the weights (save_pretrained output, or a hub "
    "snapshot copied onto this machine); weights are never downloaded at run time"
)


def check_weights_dir(path: str | Path, what: str) -> Path:
    """`path` as a Path if it looks like a saved transformers model, else MissingWeightsError naming it."""
    path = Path(path).expanduser()
    if not path.is_dir():
        raise MissingWeightsError(path, what, _HINT)
    if not (path / "config.json").is_file():
        raise MissingWeightsError(path, what, "the folder has no config.json; " + _HINT)
    return path


def load_local(cls, path: Path, what: str, **kwargs):
    """`cls.from_pretrained(path)` without touching the network; load failures name the folder."""
    try:
        return cls.from_pretrained(str(path), local_files_only=True, **kwargs)
    except (OSError, ValueError) as error:
        raise MissingWeightsError(path, what, f"it could not be loaded ({error})") from error


def to_pil(rgb: np.ndarray):
    from PIL import Image

    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise ValueError(f"expected an (H, W, 3) uint8 image, got {rgb.shape} {rgb.dtype}")
    return Image.fromarray(rgb)


def clip_box(box, height: int, width: int) -> np.ndarray:
    """(4,) xyxy clipped to the image, float32."""
    box = np.asarray(box, dtype=np.float32).copy()
    box[[0, 2]] = np.clip(box[[0, 2]], 0, width)
    box[[1, 3]] = np.clip(box[[1, 3]], 0, height)
    return box
