"""Resumable stages shared by `lano3dp demo` and bench/bench_protocol.py: collect, train, evaluate.

Each stage checks what is already on disk and does only what is missing, so re-running a demo or a
benchmark with the same output folder continues where it stopped:

    collect_stage    a zarr dataset with at least N episodes (collection appends to an existing store)
    train_stage      a training run up to its step count (the trainer resumes from its last checkpoint);
                     with a CPU-time budget the step count is chosen once, from a short timing probe,
                     and saved in the run's train_config.json, so a resumed run keeps it
    eval_stage       a results JSON, reused when it was made with the same EvalConfig
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

Log = Callable[[str], None]


def _quiet(_: str) -> None:
    pass


# ---- collect ---------------------------------------------------------------------------------------
def dataset_episodes(path: str | Path) -> int:
    """Episodes already in a store (0 when there is none)."""
    from lano3dp.data.store import EpisodeStore

    path = Path(path)
    if not path.exists():
        return 0
    return EpisodeStore.open(path).n_episodes


def collect_stage(task: str, episodes: int, out: str | Path, *, log: Log = _quiet, **options) -> Path:
    """Scripted-expert demonstrations of `task` into `out` until it holds `episodes` episodes.

    `options` go to `lano3dp.collect.collect` (e.g. variation, seed, image_size).
    """
    from lano3dp.collect import collect

    out = Path(out)
    have = dataset_episodes(out)
    if have >= episodes:
        log(f"collect: {out} already has {have} episodes of {task}; skipping")
        return out
    log(f"collect: {episodes - have} more scripted-expert episodes of {task} -> {out}")
    started = time.perf_counter()
    collect(task=task, episodes=episodes, out=out, **options)
    log(f"collect: done in {time.perf_counter() - started:.0f} s ({dataset_episodes(out)} episodes)")
    return out


# ---- train -----------------------------------------------------------------------------------------
def time_training_step(data: str | Path, policy_config, batch_size: int, *, warmup: int = 3, steps: int = 8,
                       seed: int = 0) -> float:
    """CPU seconds per optimisation step of `policy_config` on `data` at this batch size, measured here and now.

    A throwaway model does `warmup` + `steps` real steps (batch assembly, forward, backward, fused AdamW) and
    the median of the process CPU time per step is returned: what a CPU-time budget buys, nearly
    independent of other jobs on the machine. Used only to turn a budget into a step count.
    """
    import numpy as np
    import torch
    from torch.utils.data import default_collate

    from lano3dp.data import SequenceDataset
    from lano3dp.policy import DiffusionPolicy

    dataset = SequenceDataset(data, obs_keys=policy_config.obs_keys, n_obs_steps=policy_config.n_obs_steps,
                              horizon=policy_config.horizon, n_action_steps=policy_config.n_action_steps)
    torch.manual_seed(seed)
    policy = DiffusionPolicy(policy_config)
    policy.fit_normalizer(dataset)
    optimizer = torch.optim.AdamW(policy.parameters(), lr=1e-4, fused=True)
    rng = np.random.default_rng(seed)
    generator = torch.Generator().manual_seed(seed)
    times = []
    for index in range(warmup + steps):
        started = time.process_time()
        batch = default_collate([dataset[int(i)] for i in rng.integers(0, len(dataset), batch_size)])
        loss = policy.compute_loss(batch, generator=generator)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        if index >= warmup:
            times.append(time.process_time() - started)
    return float(np.median(times))


# Validation losses, EMA updates and checkpoints on top of the probed steps (measured: 3-6%).
_TRAINING_OVERHEAD = 1.06


def train_stage(data: str | Path, run: str | Path, *, policy_config=None, steps: int | None = None,
                minutes: float | None = None, min_steps: int = 50, max_steps: int = 50_000, batch_size: int = 64,
                lr: float = 1e-3, warmup_steps: int | None = None, ckpt_every: int | None = None,
                n_checkpoints: int = 1, seed: int = 0, threads: int = 1, log: Log = _quiet,
                **train_options) -> Path:
    """Train (or resume, or skip) a policy run; returns its final checkpoint folder.

    Give `steps`, or `minutes`: a budget of CPU time (this process, all threads) for the optimisation. The
    planned step count comes from a short timing probe (`time_training_step`); the trainer stops at the budget
    if the steps turn out dearer than probed, and its learning rate follows whichever ends first, the steps
    or the budget (`train.training_progress`), so such a run still ends with the rate decayed. An existing
    run keeps the step count and budget it was started with; a run stopped by its budget counts as complete. Without
    `ckpt_every`, the run checkpoints `n_checkpoints` times, evenly along its planned steps.

    One torch thread by default: under a CPU-time budget it buys the most steps (two threads run a step at
    most ~1.6x faster for twice the CPU, and spin-wait to several times slower on a busy machine).
    """
    import torch

    from lano3dp.policy.checkpoint import checkpoint_name, list_checkpoints
    from lano3dp.train import TrainConfig, Trainer, policy_config_for_dataset

    torch.set_num_threads(threads)  # before the timing probe, so it times what the run will do

    run = Path(run)
    saved = run / "train_config.json"
    if saved.exists():
        config = TrainConfig.from_dict(json.loads(saved.read_text()))
        if steps is not None and steps != config.steps:
            raise ValueError(f"{run} was started for {config.steps} steps, not {steps}; use another folder "
                             "(or the same step count to resume)")
        done = max((step for step, _ in list_checkpoints(run / "checkpoints")), default=0)
        if done >= config.steps or config.extra.get("stopped_by_budget_at") == done > 0:
            log(f"train: {run} is complete ({done} steps); skipping")
            return run / "checkpoints" / checkpoint_name(done)
        log(f"train: resuming {run} at step {done} of {config.steps}")
    else:
        policy_config = policy_config or policy_config_for_dataset(data)
        if steps is None:
            if minutes is None:
                raise ValueError("train_stage needs steps or minutes")
            seconds = time_training_step(data, policy_config, batch_size, seed=seed) * _TRAINING_OVERHEAD
            steps = int(min(max(minutes * 60 / seconds, min_steps), max_steps))
            log(f"train: {seconds:.3f} CPU-s/step measured now -> {steps} steps fit {minutes:g} CPU-min")
        warmup = warmup_steps if warmup_steps is not None else min(500, max(steps // 20, 10))
        every = ckpt_every or max(1, -(-steps // n_checkpoints))
        config = TrainConfig(data=str(data), out=str(run), policy=policy_config, steps=steps, batch_size=batch_size,
                             lr=lr, warmup_steps=warmup, ckpt_every=every, val_every=every, seed=seed,
                             cpu_minutes=minutes, threads=threads, **train_options)
        log(f"train: {steps} steps, batch {batch_size}, lr {lr:g}, UNet {tuple(policy_config.down_dims)} -> {run}")
    started = time.perf_counter()
    trainer = Trainer(config)
    final = Path(trainer.run())
    if trainer.stopped_by_budget:  # complete at the step it reached: record that for re-runs and reports
        planned = json.loads(saved.read_text())
        extra = {**planned.get("extra", {}), "stopped_by_budget_at": trainer.step}
        saved.write_text(json.dumps({**planned, "extra": extra}, indent=2))
        log(f"train: the {config.cpu_minutes:g} CPU-min budget ran out at step {trainer.step} "
            f"(planned {config.steps})")
    log(f"train: done in {time.perf_counter() - started:.0f} s wall, {trainer.cpu_seconds:.0f} CPU-s -> {final}")
    return final


# ---- evaluate --------------------------------------------------------------------------------------
def _weights_newer_than(checkpoint: str, results: Path) -> bool:
    """Whether the policy weights in `checkpoint` were written after `results` (False when there are none)."""
    from lano3dp.policy.modeling import WEIGHTS_NAME, resolve_checkpoint

    try:
        weights = resolve_checkpoint(checkpoint) / WEIGHTS_NAME
        return weights.stat().st_mtime > results.stat().st_mtime
    except FileNotFoundError:
        return False


def cached_eval(config) -> dict[str, Any] | None:
    """The results in `config.out` if they were made with this EvalConfig (up to the worker count) and the
    checkpoint's weights are not newer than them, else None. The weights matter because a folder can be
    re-written in place (a re-packaged policy keeps its path): its old results would otherwise be reused. The
    guidance compared is what runs: with the checkpoint's tuning laid over it (`evaluate.tuned_config`)."""
    from lano3dp.evaluate import measured_config, saved_config, tuned_config

    if config.out and Path(config.out).exists() and not _weights_newer_than(config.checkpoint, Path(config.out)):
        previous = json.loads(Path(config.out).read_text())
        wanted = measured_config(json.loads(json.dumps(asdict(tuned_config(config, config.checkpoint)))))
        # results saved before a field existed were made with its default (e.g. segmenter "sim"), and flat ones
        # (saved before the settings were nested) are read into their sections
        made = measured_config(saved_config(previous.get("config") or {}))
        if made == wanted:
            return previous
    return None


def eval_stage(config, *, log: Log = _quiet, progress=None, command: str | None = None) -> dict[str, Any]:
    """Evaluate unless `config.out` already holds results made with this EvalConfig (see `cached_eval`)."""
    from lano3dp.evaluate import evaluate

    if (previous := cached_eval(config)) is not None:
        log(f"eval: {config.out} is up to date; skipping")
        return previous
    return evaluate(config, progress=progress, command=command)
