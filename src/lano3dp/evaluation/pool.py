"""Running an evaluation's episodes: in this process, or in spawned worker processes with one torch thread each.

Each worker loads the policy and builds the env once (`EpisodeRunner`), then takes episodes from a queue until it
is told to stop; results come back as they finish and are put in seed order by the caller, so nothing depends on
the number of workers. Spawned processes know only the built-in plug-ins, so a user's obstacle shape, observation
type or chunk filter travels to them pickled. Two OpenMP threads per process stall on a shared 2-core machine
(notes/cpu-cost.md), hence one each.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import queue
from collections.abc import Callable, Iterable
from typing import Any, NamedTuple

from lano3dp.config_tree import to_dict
from lano3dp.errors import Lano3dpError
from lano3dp.evaluation.config import EvalConfig
from lano3dp.guidance.settings import GuidanceSettings


class Job(NamedTuple):
    """One episode to run: its index in the evaluation, its seed, and where its video and recording go."""

    index: int
    seed: int
    video: str | None = None
    rerun: str | None = None


class WorkerError(Lano3dpError, RuntimeError):
    """A worker process failed to start or died."""


Finished = Callable[[int, dict[str, Any]], None]


def run_jobs(config: EvalConfig, guidance: GuidanceSettings, jobs: list[Job], finished: Finished,
             bundle) -> int:
    """Run every job, calling `finished(index, record)` as each ends (`bundle`: the loaded checkpoint, which this
    process uses); returns the number of processes used."""
    from lano3dp.evaluation.episodes import EpisodeRunner

    workers = max(1, min(config.workers, len(jobs)))
    if not jobs:
        return 0
    if config.batch > 1:
        from lano3dp.evaluation.batched import run_batched

        return run_batched(config, guidance, jobs, finished, bundle)
    if workers == 1:
        runner = EpisodeRunner(config, guidance, bundle)
        try:
            for job in jobs:
                finished(job.index, runner.run(job.seed, job.video, job.rerun))
        finally:
            runner.close()
        return 1
    _run_in_workers(config, guidance, jobs, finished, workers, _plugins(bundle, guidance))
    return workers


def _plugins(bundle, guidance: GuidanceSettings) -> dict[str, dict[str, bytes]]:
    """The user's plug-ins the workers need, pickled (built-in ones travel as nothing)."""
    from lano3dp.guidance.execution import filters_for_workers
    from lano3dp.guidance.shapes import shape_for_workers
    from lano3dp.policy.observations import observation_type_for_workers

    obs_type = bundle.policy.config.obs_type
    return {"shapes": shape_for_workers(guidance.obstacles.shape),
            "observation_types": observation_type_for_workers(obs_type),
            "filters": filters_for_workers(guidance.execution.filters)}


def _run_in_workers(config: EvalConfig, guidance: GuidanceSettings, jobs: list[Job], finished: Finished,
                    workers: int, plugins: dict) -> None:
    context = mp.get_context("spawn")
    todo, done = context.Queue(), context.Queue()
    for job in jobs:
        todo.put(job)
    for _ in range(workers):
        todo.put(None)  # one stop sign per worker
    args = (config.to_dict(), to_dict(guidance), plugins, todo, done)
    processes = [context.Process(target=_worker_main, args=args, daemon=True) for _ in range(workers)]
    for process in processes:
        process.start()
    try:
        for _ in range(len(jobs)):
            index, record, error = _next_result(done, processes)
            if error is not None:
                raise WorkerError(f"episode {jobs_by_index(jobs)[index].seed}: {error}")
            finished(index, record)
    finally:
        for process in processes:
            if process.is_alive():
                process.terminate()
            process.join(timeout=10)


def jobs_by_index(jobs: Iterable[Job]) -> dict[int, Job]:
    return {job.index: job for job in jobs}


def _next_result(done, processes) -> tuple[int, dict | None, str | None]:
    while True:
        try:
            return done.get(timeout=1.0)
        except queue.Empty:
            if not any(process.is_alive() for process in processes):
                codes = sorted({process.exitcode for process in processes})
                raise WorkerError(f"every worker process ended before the evaluation did (exit codes {codes}); "
                                  "run with --workers 1 to see why") from None


def _worker_main(config_dict: dict, guidance_dict: dict, plugins: dict, todo, done) -> None:
    os.environ["OMP_NUM_THREADS"] = "1"
    import pickle

    import torch

    torch.set_num_threads(1)
    try:
        if config_dict.get("env"):  # a plug-in class may live in the --env file, imported under its own name
            from lano3dp import env_factory

            env_factory.load_factory(config_dict["env"])
        from lano3dp.guidance.execution import register_worker_filters
        from lano3dp.guidance.shapes import register_obstacle_shape
        from lano3dp.policy.observations import register_observation_type

        for name, payload in plugins["shapes"].items():
            register_obstacle_shape(name, pickle.loads(payload), replace=True)
        for name, payload in plugins["observation_types"].items():
            register_observation_type(name, pickle.loads(payload), replace=True)
        register_worker_filters(plugins["filters"])
        from lano3dp.evaluation.episodes import EpisodeRunner

        runner = EpisodeRunner(EvalConfig.from_dict(config_dict), GuidanceSettings.from_dict(guidance_dict))
    except Exception as error:  # every job of this worker reports it, so the caller names the cause
        while (job := todo.get()) is not None:
            done.put((job.index, None, f"{type(error).__name__}: {error}"))
        return
    while (job := todo.get()) is not None:
        try:
            done.put((job.index, runner.run(job.seed, job.video, job.rerun), None))
        except Exception as error:
            done.put((job.index, None, f"{type(error).__name__}: {error}"))
    runner.close()
