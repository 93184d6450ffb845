"""Episode videos: MP4 (ffmpeg via imageio) or GIF, chosen by the file suffix."""

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


def record_expert_video(task: str, path: str | Path, seed: int = 0, variation: str = "clean",
                        image_size: int = 256, camera: str = "front") -> dict:
    """Run the scripted expert for one episode and write its camera video. Returns a summary dict."""
    from lano3dp.sim.env import TabletopEnv

    env = TabletopEnv(task, variation=variation, camera=camera, image_size=image_size, render_rgb=True)
    try:
        obs, info = env.reset(seed=seed)
        frames = [obs["rgb"]]
        actions = env.expert_plan().actions()
        steps = 0
        for t in range(env.max_steps):
            obs, _, terminated, truncated, info = env.step(actions[min(t, len(actions) - 1)])
            frames.append(obs["rgb"])
            steps = t + 1
            if terminated or truncated:
                break
        write_video(path, frames, fps=env.control_hz)
        return {"path": str(path), "task": task, "seed": seed, "variation": info["variation"], "steps": steps,
                "success": bool(info["success"]), "instruction": info["instruction"]}
    finally:
        env.close()
