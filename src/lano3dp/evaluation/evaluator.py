"""`evaluate`: closed-loop evaluation of a checkpoint, many episodes, to one results JSON.

    result = evaluate(EvalConfig(checkpoint="runs/bowl", task="bowl_pour", variation="obstacle",
                                 episodes=20, guidance=GuidanceChoice("tuned")))
    result["summary"]["success_rate"], result["summary"]["collision_rate"]
    result["summary"]["stage_rates"]   # e.g. {"reached_handle": 0.9, "grasped_handle": 0.6, ..., "opened": 0.4}

Each episode is a fresh scene from its seed (seed, seed + 1, ...; or the first scenes from seed on with room for
the variation's obstacles). Episodes run in `workers` processes and come back in seed order, so the JSON does not
depend on the number of workers; latencies measured with several workers include their contention. With
`config.out`, each finished episode is appended to the episode log beside it as it finishes, and an evaluation
killed part-way resumes from that log.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from lano3dp import provenance
from lano3dp.config_tree import to_dict
from lano3dp.evaluation.bundle import PolicyBundle
from lano3dp.evaluation.config import EvalConfig
from lano3dp.evaluation.episodes import evaluation_task
from lano3dp.evaluation.pool import Job, run_jobs
from lano3dp.evaluation.results import EpisodeLog, episode_log_path, results_file, summarize
from lano3dp.guidance.settings import GuidanceSettings
from lano3dp.jsonio import write_json

# EvalConfig fields that change how an evaluation runs or where it writes, never what an episode does
NOT_MEASURED = ("workers", "video_dir", "n_videos", "rerun_dir", "out", "guidance")

Progress = Callable[[int, int, dict], None]


def evaluation_identity(config: EvalConfig, guidance: GuidanceSettings, weights: str) -> dict[str, Any]:
    """What makes two evaluations give the same episodes: the config up to where it writes and how many
    processes run it, the guidance that runs (however it was named), the exact weights, and the behaviour
    version of the code (`provenance.BEHAVIOUR_VERSION`)."""
    measured = {name: value for name, value in config.to_dict().items() if name not in NOT_MEASURED}
    return {"config": measured, "guidance": to_dict(guidance), "weights": weights,
            "behaviour_version": provenance.BEHAVIOUR_VERSION}


def current_identity(config: EvalConfig) -> dict[str, Any]:
    """`evaluation_identity` of `config` as this code would run it, without loading the policy."""
    from lano3dp.evaluation.bundle import resolve_folder, weights_checksum
    from lano3dp.guidance.settings import load_guidance_tuning
    from lano3dp.policy.integrity import verify_checkpoint

    folder = resolve_folder(config.checkpoint, config.task)
    verify_checkpoint(folder)
    guidance = config.guidance.resolve(load_guidance_tuning(folder))
    return evaluation_identity(config, guidance, weights_checksum(folder))


def evaluation_seeds(config: EvalConfig, task: str) -> list[int]:
    """The episode seeds: seed, seed + 1, ...; with obstacle_scenes_only, the first seeds from seed on whose scene
    has room for the variation's obstacles."""
    if not config.obstacle_scenes_only:
        return [config.seed + i for i in range(config.episodes)]
    from lano3dp.sim.env import obstacle_scene_seeds

    return obstacle_scene_seeds(task, config.variation, config.seed, config.episodes)


def evaluate(config: EvalConfig, progress: Progress | None = None, command: str | None = None) -> dict[str, Any]:
    """Run every episode and return (and, with `config.out`, write) the results dict. The output is locked: a
    second evaluation writing the same file is refused.

    Args:
        progress: called after each finished episode with (done, total, record); resumed episodes first.
        command: the command line to record (default: this process's).
    """
    from lano3dp.locking import WriteLock, prepare_parent

    if config.out and Path(config.out).is_dir():
        raise IsADirectoryError(f"--out {config.out} is a folder; give the results JSON file to write")
    lock = None
    if config.out:
        prepare_parent(config.out)  # a bad --out fails here, before the first episode
        lock = WriteLock(config.out).acquire()
    try:
        return _evaluate(config, progress, command)
    finally:
        if lock is not None:
            lock.release()


def _evaluate(config: EvalConfig, progress: Progress | None, command: str | None) -> dict[str, Any]:
    started = time.perf_counter()
    bundle = PolicyBundle.load(config.checkpoint, task=config.task)
    guidance = config.guidance.resolve(bundle.tuning)
    task = evaluation_task(config, bundle)
    bundle.check_task(task, config.env)
    identity = evaluation_identity(config, guidance, bundle.weights)
    log = EpisodeLog(episode_log_path(config.out), identity) if config.out else None
    seeds = evaluation_seeds(config, task)
    records: dict[int, dict[str, Any]] = {i: r for i, r in (log.records if log else {}).items() if i < len(seeds)}
    resumed = len(records)
    jobs = [Job(index, seed,
                str(Path(config.video_dir) / f"episode_{seed}.mp4") if config.video_dir and index < config.n_videos
                else None,
                str(Path(config.rerun_dir) / f"episode_{seed}.rrd") if config.rerun_dir else None)
            for index, seed in enumerate(seeds) if index not in records]
    done = 0
    for index in sorted(records):
        done += 1
        if progress:
            progress(done, len(seeds), records[index])

    def finished(index: int, record: dict[str, Any]) -> None:
        nonlocal done
        records[index] = log.append(index, record) if log else record
        done += 1
        if progress:
            progress(done, len(seeds), records[index])

    workers = run_jobs(config, guidance, jobs, finished, bundle=bundle)
    episodes = [records[index] for index in sorted(records)]
    summary = summarize(episodes)
    notes = ["the environment reports no info['success']: success is not measured"] \
        if summary["success_rate"] is None else []
    result = results_file("eval", config.to_dict(), {
        "task": task,
        "checkpoint": bundle.label,
        "identity": identity,
        "guidance": to_dict(guidance),
        "policy": bundle.policy.config.to_dict(),
        "summary": summary,
        "episodes": episodes,
        "timing": {"wall_s": round(time.perf_counter() - started, 2), "workers": workers, "resumed_episodes": resumed},
        "env": config.env or "builtin",
        "notes": notes,
    }, command=command)
    if config.out:
        write_json(config.out, result)
    return result
