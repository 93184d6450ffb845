"""Expert videos of the built-in tasks (the writer itself is `lano3dp.video`)."""

from __future__ import annotations

from pathlib import Path

from lano3dp.video import write_video  # re-exported: the expert videos and their tests use it from here


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
