"""Resumable stages shared by `lano3dp demo` and bench/bench_protocol.py: collect, train, evaluate.

Each stage checks what is already on disk and does only what is missing, so re-running a demo or a
benchmark with the same output folder continues where it stopped:

    collect_stage    a zarr dataset with at least N episodes (collection appends to an existing store)
    train_stage      a training run up to its step count (the trainer resumes from its last checkpoint);
                     with a wall-clock budget the step count is chosen once, from a short timing probe,
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

    `options` go to `lano3dp.data.collect.collect` (e.g. variation, seed, image_size).
    """
    from lano3dp.data.collect import collect

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
def time_training_step(data: str | Path, policy_config, batch_size: int, *, warmup: int = 2, steps: int = 4,
                       seed: int = 0) -> float:
    """Seconds per optimisation step of `policy_config` on `data` at this batch size, measured here and now.

    A throwaway model does `warmup` + `steps` real steps (data windows, forward, backward, fused AdamW), so the
    number includes this machine's current load. Used only to turn a time budget into a step count.
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
        batch = default_collate([dataset[int(i)] for i in rng.integers(0, len(dataset), batch_size)])
        started = time.perf_counter()
        loss = policy.compute_loss(batch, generator=generator)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        if index >= warmup:
            times.append(time.perf_counter() - started)
    return float(np.median(times))


def train_with_deadline(config, seconds: float | None) -> tuple[Path, bool]:
    """Run a `Trainer` that stops, checkpointed, at the first step after `seconds` of wall time.

    Returns (final checkpoint, whether the deadline cut the run short). The trainer has no time limit
    of its own, so this wraps its progress bar, which the loop updates after every step and before its
    checkpoint test: lowering `config.steps` to the current step there makes the loop save this step and
    end, exactly as at a planned last step. The LR schedule keeps the planned length.
    """
    from lano3dp.train import Trainer

    trainer = Trainer(config)
    stopped = False
    if seconds is not None:
        end = time.monotonic() + seconds
        make_progress = trainer._progress

        def progress():
            bar = make_progress()
            update = bar.update

            def update_and_check(n=1):
                nonlocal stopped
                result = update(n)
                if time.monotonic() > end and trainer.step < trainer.config.steps:
                    trainer.config.steps = trainer.step
                    stopped = True
                return result

            bar.update = update_and_check
            return bar

        trainer._progress = progress
    return Path(trainer.run()), stopped


def train_stage(data: str | Path, run: str | Path, *, policy_config=None, steps: int | None = None,
                minutes: float | None = None, min_steps: int = 50, max_steps: int = 20_000, batch_size: int = 64,
                lr: float = 1e-3, warmup_steps: int | None = None, ckpt_every: int | None = None, seed: int = 0,
                log: Log = _quiet, **train_options) -> Path:
    """Train (or resume, or skip) a policy run; returns its final checkpoint folder.

    Give `steps`, or `minutes`: a wall-clock budget for the optimisation. The planned step count (and so the
    LR schedule) comes from a short timing probe (`time_training_step`), and the run stops at the deadline
    if the machine turns out slower than probed. An existing run keeps the step count it was started with;
    a run cut short by its deadline counts as complete.
    """
    from lano3dp.policy.checkpoint import checkpoint_name, list_checkpoints
    from lano3dp.train import TrainConfig, policy_config_for_dataset

    run = Path(run)
    saved = run / "train_config.json"
    if saved.exists():
        config = TrainConfig.from_dict(json.loads(saved.read_text()))
        if steps is not None and steps != config.steps:
            raise ValueError(f"{run} was started for {config.steps} steps, not {steps}; use another folder "
                             "(or the same step count to resume)")
        done = max((step for step, _ in list_checkpoints(run / "checkpoints")), default=0)
        if done >= config.steps:
            log(f"train: {run} is complete ({config.steps} steps); skipping")
            return run / "checkpoints" / checkpoint_name(config.steps)
        log(f"train: resuming {run} at step {done} of {config.steps}")
    else:
        policy_config = policy_config or policy_config_for_dataset(data)
        if steps is None:
            if minutes is None:
                raise ValueError("train_stage needs steps or minutes")
            seconds = time_training_step(data, policy_config, batch_size, seed=seed)
            steps = int(min(max(minutes * 60 / seconds, min_steps), max_steps))
            log(f"train: {seconds:.3f} s/step measured now -> {steps} steps fit {minutes:g} min")
        warmup = warmup_steps if warmup_steps is not None else min(500, max(steps // 10, 10))
        config = TrainConfig(data=str(data), out=str(run), policy=policy_config, steps=steps, batch_size=batch_size,
                             lr=lr, warmup_steps=warmup, ckpt_every=ckpt_every or steps,
                             val_every=ckpt_every or steps, seed=seed, **train_options)
        log(f"train: {steps} steps, batch {batch_size}, lr {lr:g}, UNet {tuple(policy_config.down_dims)} -> {run}")
    started = time.perf_counter()
    final, stopped = train_with_deadline(config, minutes * 60 if minutes is not None else None)
    if stopped:  # the run is complete at the step it reached: record that for re-runs
        planned = json.loads(saved.read_text())
        extra = {**planned.get("extra", {}), "planned_steps": planned["steps"], "stopped_by_budget_min": minutes}
        saved.write_text(json.dumps({**planned, "steps": config.steps, "extra": extra}, indent=2))
        log(f"train: the {minutes:g} min budget ran out at step {config.steps} (planned {planned['steps']})")
    log(f"train: done in {time.perf_counter() - started:.0f} s -> {final}")
    return final


# ---- evaluate --------------------------------------------------------------------------------------
# Fields that change how an evaluation runs, not what it measures: every episode is seeded by itself.
_EVAL_FIELDS_NOT_MEASURED = ("workers",)


def cached_eval(config) -> dict[str, Any] | None:
    """The results in `config.out` if they were made with this EvalConfig (up to the worker count), else None."""
    if config.out and Path(config.out).exists():
        previous = json.loads(Path(config.out).read_text())
        wanted = json.loads(json.dumps(asdict(config)))
        made = dict(previous.get("config") or {})
        for name in _EVAL_FIELDS_NOT_MEASURED:
            wanted.pop(name, None)
            made.pop(name, None)
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
