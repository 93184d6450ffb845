"""Resumable stages shared by `lano3dp demo` and bench/bench_protocol.py: collect, train, evaluate.

Each stage checks what is already on disk and does only what is missing, so re-running a demo or a
benchmark with the same output folder continues where it stopped:

    collect_stage    a zarr dataset with at least N episodes (collection appends to an existing store)
    train_stage      a training run up to its step count (the trainer resumes from its last checkpoint);
                     with a CPU-time budget the step count is chosen once, from a short timing probe,
                     and saved in the run's train_config.json, so a resumed run keeps it
    eval_stage       a results JSON, reused when it is current (same evaluation, same behaviour version)
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
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
def train_stage(data: str | Path, run: str | Path, *, policy_config=None, steps: int | None = None,
                minutes: float | None = None, min_steps: int = 50, max_steps: int = 50_000, batch_size: int = 64,
                lr: float = 1e-3, warmup_steps: int | None = None, ckpt_every: int | None = None,
                n_checkpoints: int = 1, seed: int = 0, threads: int = 1, log: Log = _quiet,
                **train_options) -> Path:
    """Train (or resume, or skip) a policy run; returns its final checkpoint folder.

    Give `steps`, or `minutes`: a budget of CPU time (this process, all threads) the run plans for. The step
    count then comes from a short timing probe (`train.plan_budget`, the planning `lano3dp train --minutes`
    uses too), lowered to `steps` when both are given; the trainer stops at the budget if the steps turn out
    dearer than probed, and its learning rate follows whichever ends first, the steps or the budget
    (`train.training_progress`), so such a run still ends with the rate decayed. An existing run keeps the step
    count and budget it was started with; a run stopped by its budget counts as complete. Without `ckpt_every`,
    the run checkpoints `n_checkpoints` times, evenly along its planned steps.

    One torch thread by default: under a CPU-time budget it buys the most steps (two threads run a step at
    most ~1.6x faster for twice the CPU, and spin-wait to several times slower on a busy machine).
    """
    import torch

    from lano3dp.policy.checkpoint import checkpoint_name, list_checkpoints
    from lano3dp.train import TrainConfig, Trainer, default_warmup_steps, plan_budget, policy_config_for_dataset

    torch.set_num_threads(threads)  # before the timing probe, so it times what the run will do

    run = Path(run)
    saved = run / "train_config.json"
    if saved.exists():
        config = TrainConfig.from_dict(json.loads(saved.read_text()))
        started_for = config.budget_plan.step_cap if config.budget_plan is not None else config.steps
        if steps is not None and steps != started_for:
            raise ValueError(f"{run} was started for {started_for} steps, not {steps}; use another folder "
                             "(or the same step count to resume)")
        done = max((step for step, _ in list_checkpoints(run / "checkpoints")), default=0)
        if done >= config.steps or config.extra.get("stopped_by_budget_at") == done > 0:
            log(f"train: {run} is complete ({done} steps); skipping")
            return run / "checkpoints" / checkpoint_name(done)
        log(f"train: resuming {run} at step {done} of {config.steps}")
    else:
        policy_config = policy_config or policy_config_for_dataset(data)
        plan = None
        if minutes is not None:
            plan = plan_budget(data, policy_config, batch_size, minutes, step_cap=steps, seed=seed,
                               augment=train_options.get("augment"), min_steps=min_steps, max_steps=max_steps)
            steps = plan.steps
            capped = f", capped at {plan.step_cap}" if plan.steps < plan.budget_steps else ""
            log(f"train: {plan.probe_cpu_s_per_step:.3f} CPU-s/step measured now -> {plan.budget_steps} steps fit "
                f"{minutes:g} CPU-min{capped}")
        elif steps is None:
            raise ValueError("train_stage needs steps or minutes")
        warmup = warmup_steps if warmup_steps is not None else default_warmup_steps(steps)
        every = ckpt_every or max(1, -(-steps // n_checkpoints))
        config = TrainConfig(data=str(data), out=str(run), policy=policy_config, steps=steps, batch_size=batch_size,
                             lr=lr, warmup_steps=warmup, ckpt_every=every, val_every=every, seed=seed,
                             cpu_minutes=minutes, budget_plan=plan, threads=threads, **train_options)
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
def cached_eval(config) -> dict[str, Any] | None:
    """The results in `config.out` if they are current: made by code of this behaviour version, with this
    evaluation's identity (the config up to where it writes, the guidance that runs, the exact weights), else
    None. A folder re-written in place (a re-packaged policy keeps its path) has other weights, so its old
    results are not reused."""
    from lano3dp.evaluation.evaluator import current_identity
    from lano3dp.provenance import result_is_current

    if not (config.out and Path(config.out).exists()):
        return None
    try:
        previous = json.loads(Path(config.out).read_text())
    except ValueError:
        return None  # a results file cut short: evaluate again
    if result_is_current(previous) and previous.get("identity") == json.loads(json.dumps(current_identity(config))):
        return previous
    return None


def eval_stage(config, *, log: Log = _quiet, progress=None, command: str | None = None) -> dict[str, Any]:
    """Evaluate unless `config.out` already holds current results of this evaluation (see `cached_eval`)."""
    from lano3dp.evaluation import evaluate

    if (previous := cached_eval(config)) is not None:
        log(f"eval: {config.out} is up to date; skipping")
        return previous
    return evaluate(config, progress=progress, command=command)
