"""Episode videos: MP4 (ffmpeg via imageio) or GIF, chosen by the file suffix. A bottom-layer utility, so
evaluation writes videos without importing the simulator."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np


def write_video(path: str | Path, frames: Sequence[np.ndarray], fps: float = 10.0) -> Path:
    """Write (H, W, 3) uint8 frames to `path` (.mp4 or .gif). Returns the path."""
    import imageio.v2 as imageio

    path = Path(path)
    if len(frames) == 0:
        raise ValueError(f"no frames to write to {path}")
    path.parent.mkdir(parents=True, exist_ok=True)
    frames = [np.asarray(f, dtype=np.uint8) for f in frames]
    suffix = path.suffix.lower()
    if suffix == ".gif":
        imageio.mimsave(path, frames, duration=1000.0 / fps, loop=0)
    elif suffix in (".mp4", ".m4v", ".mov"):
        # macro_block_size=1: keep odd/small sizes such as 128x128 without rescaling.
        imageio.mimsave(path, frames, fps=fps, macro_block_size=1)
    else:
        raise ValueError(f"unsupported video suffix {suffix!r} for {path}; use .mp4 or .gif")
    return path
