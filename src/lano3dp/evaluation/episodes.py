"""EpisodeRunner: one process's policy, env and runner, running episodes of an evaluation by seed.

The env is the built-in `TabletopEnv` by default, or a user's own simulator or robot from `EvalConfig.env`, both
built by `env_factory.make_env`. Targets are named by the phrases the scene uses (e.g. "blue bowl" among
look-alikes) and obstacles, by default, are the objects the scene marks as obstacles.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from lano3dp import env_factory
from lano3dp.evaluation.bundle import PolicyBundle, carried_slot_word
from lano3dp.evaluation.config import EvalConfig
from lano3dp.guidance.settings import GuidanceSettings
from lano3dp.runtime import PolicyRunner, rollout, scene_obstacles
from lano3dp.video import write_video


def evaluation_task(config: EvalConfig, bundle: PolicyBundle) -> str:
    """The task evaluated: the config's, else the one the checkpoint was trained on."""
    task = config.task or bundle.task
    if task is None:
        raise ValueError("no task given and the checkpoint does not say which task it was trained on; pass --task")
    return task


class EpisodeRunner:
    """Loads the policy and builds the env once, then runs episodes by seed (in this process or a worker).

    Args:
        config: the evaluation.
        guidance: the resolved guidance settings (`GuidanceChoice.resolve` with the checkpoint's tuning).
        bundle: the loaded checkpoint (loaded here when not given).
        policy: what the runner drives instead of the bundle's policy (`batched.PolicyHandle`).
    """

    def __init__(self, config: EvalConfig, guidance: GuidanceSettings, bundle: PolicyBundle | None = None, *,
                 policy=None):
        self.config = config
        self.bundle = bundle = bundle or PolicyBundle.load(config.checkpoint, task=config.task)
        self.task = evaluation_task(config, bundle)
        bundle.check_task(self.task, config.env)
        image_size = config.perception.image_size or bundle.observation.image_size or 128
        needs_rgb = bundle.policy.config.observation.needs_rgb or bool(config.video_dir)
        self.env = env_factory.make_env(config.env, task=self.task, seed=config.seed, variation=config.variation,
                                        image_size=image_size, render_rgb=needs_rgb, max_steps=config.max_steps)
        # the simulator truncates at its own limit; a user's env may not, so its max_steps attribute bounds it
        self.max_steps = config.max_steps if config.env is None else (config.max_steps
                                                                      or getattr(self.env, "max_steps", None))
        self.runner = PolicyRunner(policy or bundle.policy, bundle.observer(config.perception), guidance,
                                   n_action_steps=config.n_action_steps,
                                   step_limit=getattr(self.env, "max_ee_step", None), seed=config.seed)
        self.carried = carried_slot_word(self.task)

    def _on_reset(self, runner: PolicyRunner, frame, info) -> None:
        slots = tuple(runner.policy_config.object_names)
        phrases = info.get("target_phrases") or {}
        targets = [phrases.get(slot, slot) for slot in slots] if slots else None
        obstacles = list(self.config.obstacles) if self.config.obstacles is not None else scene_obstacles(frame)
        held = phrases.get(self.carried, self.carried) if self.carried else None
        runner.set_objects(targets if runner.policy_config.observation.object_slots else None, obstacles, held)

    def run(self, seed: int, video_path: str | None = None, rerun_path: str | None = None) -> dict[str, Any]:
        """One episode: its record (`EpisodeResult.to_dict` with the EE path), with its video written."""
        frames: list[np.ndarray] = []
        on_frame = (lambda frame, info: frames.append(frame.rgb.copy())) if video_path else None
        recording = None
        if rerun_path:
            from lano3dp.recording import record_episode

            recording, on_frame = record_episode(rerun_path, self.runner, on_frame)
        try:
            result = rollout(self.env, self.runner, seed=seed, on_reset=self._on_reset, on_frame=on_frame,
                             max_steps=self.max_steps, success_at=self.config.success_at)
            if recording is not None:
                recording.log_path(result.ee_path)
        finally:
            if recording is not None:
                recording.close()
        record = result.to_dict(include_path=True)
        record["success_reported"] = self.env.reports_success  # False: the env never said; success is unmeasured
        if video_path and frames:
            write_video(video_path, frames)
            record["video"] = video_path
        if rerun_path:
            record["rerun"] = str(Path(rerun_path))
        return record

    def close(self) -> None:
        self.env.close()
