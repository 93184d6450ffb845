"""Training loop for DiffusionPolicy: AdamW + cosine warm-up, EMA, validation, atomic checkpoints, resume, DDP.

One code path serves one process and `torchrun --nproc_per_node N` (data-parallel: gloo on CPU,
nccl on CUDA; rank 0 writes checkpoints and logs). A run folder looks like

    <out>/train_config.json
    <out>/checkpoints/step_XXXXXXX/   (see lano3dp.policy.checkpoint; progress.json: step, CPU seconds so far)
    <out>/checkpoints/last -> step_...
    <out>/tensorboard/                 loss, val_loss, lr

Starting `train` on a folder that already has a checkpoint resumes from it (step, raw and EMA
weights, optimizer, LR schedule). Randomness is a pure function of (seed, rank, step): the data
order of an epoch comes from (seed, epoch) and the diffusion noise of a step from (seed, rank, step),
so a resumed run draws exactly what the uninterrupted run would have drawn.

Usage: python -m lano3dp.train --config train.json   (or the `lano3dp train` command).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import time
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch

from lano3dp.augment import AugmentConfig, augment_batch, widened_stats
from lano3dp.data import EpisodeStore, SequenceDataset, split_episodes
from lano3dp.errors import CorruptFileError, Lano3dpError
from lano3dp.jsonio import write_text_atomic
from lano3dp.locking import WriteLock
from lano3dp.policy import DiffusionPolicy, PolicyConfig
from lano3dp.policy.checkpoint import (
    EMA,
    TrainingState,
    atomic_directory,
    checkpoint_name,
    latest_resumable,
    load_training_state,
    prune_training_states,
    remove_stale_temporaries,
    save_training_state,
    update_last_pointer,
)
from lano3dp.policy.modeling import load_config


class TrainingConfigError(Lano3dpError, ValueError):
    """The training configuration does not fit the dataset or the run folder."""


class NonFiniteLossError(Lano3dpError, FloatingPointError):
    """The training or validation loss became NaN or infinite."""


# TrainConfig fields a resumed run must keep: its optimizer, LR schedule, EMA, data split and noise streams
# were made with them, and the optimizer state restores the old lr silently. `steps` may change (a run is
# extended, the cosine decay re-planned from there) and the change is recorded in train_config.json
# extra["resume_changes"]; the others (logging, checkpoint cadence, workers, threads, device, the CPU budget)
# may change freely between sessions.
RESUME_APPLIED_FIELDS = ("steps",)
RESUME_FIXED_FIELDS = ("data", "batch_size", "lr", "weight_decay", "betas", "warmup_steps", "ema",
                       "ema_inv_gamma", "ema_power", "ema_max", "val_ratio", "seed", "bf16", "augment",
                       "time_stride")


def changed_fields(old: dict[str, Any], new: dict[str, Any], names=None) -> list[str]:
    """'name: old -> new' for each differing field (of `names`, default all)."""
    names = sorted(set(old) | set(new)) if names is None else names
    return [f"{name}: {old.get(name)!r} -> {new.get(name)!r}" for name in names if old.get(name) != new.get(name)]


DEFAULT_STEPS = 3000  # a run's steps when neither they nor a CPU budget are given
# Validation losses, EMA updates and checkpoints on top of the probed steps (measured: 3-6%).
TRAINING_OVERHEAD = 1.06


@dataclass(frozen=True)
class BudgetPlan:
    """How a CPU budget became a run's step count (`plan_budget`); saved in train_config.json.

    Attributes:
        cpu_minutes: the budget, CPU-minutes of the training process (all its threads).
        probe_cpu_s_per_step: median CPU seconds of one optimisation step, measured by `time_training_step`
            just before the run, on its data, policy, batch size and threads.
        overhead: the factor for what the probe leaves out (validation, EMA, checkpoints): TRAINING_OVERHEAD.
        budget_steps: the steps the budget buys, cpu_minutes * 60 / (probe * overhead), within [min, max] steps.
        step_cap: the step count asked for (`--steps`), or None: the budget alone decides.
        steps: the planned steps: budget_steps, or step_cap when that is lower.
        threads: torch intra-op threads the probe (and so the run) used.
    """

    cpu_minutes: float
    probe_cpu_s_per_step: float
    overhead: float
    budget_steps: int
    step_cap: int | None
    steps: int
    threads: int


@dataclass
class TrainConfig:
    """Everything a training run needs; saved as train_config.json in the run and every checkpoint.

    Attributes:
        data: the zarr episode store.
        out: the run folder (resumed if it already holds a checkpoint).
        policy: the policy configuration; None builds the default one from the dataset (its object_names).
        steps: total optimisation steps (a resumed run continues up to this number).
        batch_size: windows per step and per process (the global batch is batch_size x world size).
        lr, weight_decay, betas: AdamW; lr 5e-4 suits CPU-length runs (notes: cpu-cost.md sec. 7).
        warmup_steps: linear warm-up before the cosine decay, which reaches 0 at the planned step count or,
            under `cpu_minutes`, where the budget runs out if that comes first (training_progress).
        ema: keep an EMA of the weights (saved as the checkpoint's policy); ema_* is DP's schedule.
        val_ratio: fraction of episodes held out for the validation loss.
        val_every, ckpt_every, log_every: in steps; the last step always checkpoints.
        val_batches: at most this many validation batches per evaluation (fixed noise, comparable across steps).
        keep_training_states: how many newest checkpoints keep their (large) training state.
        seed: weights, data order and diffusion noise all derive from it.
        num_workers: DataLoader worker processes (0: load in the training process).
        threads: torch intra-op threads (None: leave torch's default).
        cpu_minutes: a budget of this process's CPU time (all its threads) for the whole run, resumes
            included; the run stops, checkpointed, at the first step past it. CPU time, not wall time, so a
            busy machine does not shorten the training (other jobs slow the clock, not the count).
        budget_plan: how `steps` was planned from `cpu_minutes` (`plan_budget`: the timing probe's CPU-s per
            step, the cap); None when the steps were given.
        device: "cpu" or "cuda" ("cuda:<i>" is picked per rank under torchrun).
        bf16: bfloat16 autocast for the forward pass (CPU with AMX: about -19% step time for the small model).
        augment: lano3dp.augment.AugmentConfig (or its fields as a dict): a rigid planar motion of the whole
            window (and a vertical lift), point jitter and dropout; None trains on the demonstrations as recorded.
        time_stride: recorded steps between consecutive steps of a training window, observations and actions
            alike (1: every step). For an env recorded faster than a policy should plan: at 80 Hz, S = 4 makes a
            16-step horizon span 0.8 s instead of 0.2 s. The checkpoint carries it (PolicyConfig.time_stride) and
            the runtime then steps the env S times per policy action.
        progress: show a tqdm bar (rank 0).
    """

    data: str
    out: str
    policy: PolicyConfig | None = None
    steps: int = DEFAULT_STEPS
    batch_size: int = 64
    lr: float = 5e-4
    weight_decay: float = 1e-6
    betas: tuple[float, float] = (0.95, 0.999)
    warmup_steps: int = 500
    ema: bool = True
    ema_inv_gamma: float = 1.0
    ema_power: float = 0.75
    ema_max: float = 0.9999
    val_ratio: float = 0.05
    val_every: int = 500
    val_batches: int = 8
    ckpt_every: int = 1000
    log_every: int = 10
    keep_training_states: int = 1
    seed: int = 0
    num_workers: int = 0
    threads: int | None = None
    cpu_minutes: float | None = None
    budget_plan: BudgetPlan | None = None
    device: str = "cpu"
    bf16: bool = False
    augment: AugmentConfig | None = None
    time_stride: int = 1
    progress: bool = True
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        self.data, self.out = str(self.data), str(self.out)
        self.betas = tuple(float(b) for b in self.betas)
        if isinstance(self.policy, dict):
            self.policy = PolicyConfig.from_dict(self.policy)
        if isinstance(self.budget_plan, dict):
            self.budget_plan = BudgetPlan(**self.budget_plan)
        if self.budget_plan is not None and self.budget_plan.cpu_minutes != self.cpu_minutes:
            raise ValueError(f"TrainConfig: the steps were planned for {self.budget_plan.cpu_minutes} CPU-minutes, "
                             f"the budget is {self.cpu_minutes}; plan again (plan_budget)")
        self.augment = as_augment_config(self.augment)
        for name in ("steps", "batch_size", "val_every", "ckpt_every", "log_every", "val_batches"):
            if getattr(self, name) < 1:
                raise ValueError(f"TrainConfig: {name} must be >= 1, got {getattr(self, name)}")
        if self.warmup_steps < 0 or self.num_workers < 0 or self.keep_training_states < 1:
            raise ValueError("TrainConfig: warmup_steps and num_workers must be >= 0, keep_training_states >= 1")
        if not 0.0 <= self.val_ratio < 1.0:
            raise ValueError(f"TrainConfig: val_ratio must be in [0, 1), got {self.val_ratio}")
        if self.cpu_minutes is not None and self.cpu_minutes <= 0:
            raise ValueError(f"TrainConfig: cpu_minutes must be > 0, got {self.cpu_minutes}")
        if isinstance(self.time_stride, bool) or int(self.time_stride) != self.time_stride or self.time_stride < 1:
            raise ValueError(f"TrainConfig: time_stride must be an int >= 1, got {self.time_stride!r}")
        self.time_stride = int(self.time_stride)
        if self.lr <= 0 or len(self.betas) != 2:
            raise ValueError("TrainConfig: lr must be > 0 and betas a pair")

    def to_dict(self) -> dict[str, Any]:
        data = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        data["policy"] = self.policy.to_dict() if self.policy is not None else None
        data["augment"] = self.augment.to_dict() if self.augment is not None else None
        data["budget_plan"] = dataclasses.asdict(self.budget_plan) if self.budget_plan is not None else None
        data["betas"] = list(self.betas)
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrainConfig:
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"TrainConfig: unknown fields {unknown}")
        return cls(**data)

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2)


def as_augment_config(value: AugmentConfig | dict | None) -> AugmentConfig | None:
    """An AugmentConfig from itself or its fields as a dict (train_config.json, bench recipes)."""
    if isinstance(value, dict):
        return AugmentConfig(**{**value, "pivot": tuple(value.get("pivot", (0.45, 0.0)))})
    return value


# Dataset attributes that say how an observation is made (camera resolution, crop box, points, rate).
OBSERVATION_ATTRS = ("image_size", "crop_low", "crop_high", "n_points", "scene_points", "control_hz")
PROGRESS_NAME = "progress.json"  # in every checkpoint: its step and the run's CPU seconds so far


def observation_settings(attrs: dict) -> dict:
    """The dataset attributes a checkpoint carries in config.extra["observation"]."""
    return {key: attrs[key] for key in OBSERVATION_ATTRS if key in attrs}


def checkpoint_progress(checkpoint: Path) -> dict:
    """A checkpoint's progress.json ({"step", "cpu_s", "stopped_by_budget"}), or {} if it has none."""
    path = Path(checkpoint) / PROGRESS_NAME
    return json.loads(path.read_text()) if path.exists() else {}


def policy_config_for_dataset(data: str | Path, **overrides) -> PolicyConfig:
    """The default PolicyConfig for a dataset: slots from its object_names, and what each registered observation
    type reads off its key's recorded shape (n_points from the object clouds, scene_points, image_size)."""
    from lano3dp.policy.observations import get_observation_type, observation_type_names

    store = EpisodeStore.open(data)
    fields: dict[str, Any] = {}
    names = store.attrs.get("object_names")
    if names:
        fields["object_names"] = tuple(names)
    shapes = _step_shapes(store)
    task_inputs = {}
    for name in observation_type_names():
        observation = get_observation_type(name)
        if observation.key not in shapes:
            continue
        if observation.source == "obs":  # a task input the env handed over (obs["goal"]): the policy takes it too
            task_inputs[observation.key] = int(np.prod(shapes[observation.key]))
        else:
            fields |= observation.dataset_fields(shapes[observation.key])
    if task_inputs:
        fields["task_inputs"] = task_inputs
    fields["extra"] = {key: store.attrs[key] for key in ("skill", "task") if key in store.attrs}
    # How the observations were made travels with the policy, so a checkpoint acts without its dataset.
    fields["extra"]["observation"] = observation_settings(store.attrs)
    return PolicyConfig(**(fields | overrides))


def with_time_stride(policy: PolicyConfig, stride: int) -> PolicyConfig:
    """`policy` with its extra["observation"] carrying the time stride, so evaluation and `run` step the env as
    training strode through the data. Stride 1 adds nothing: a stride-1 checkpoint is what it was before."""
    if policy.time_stride == stride:
        return policy
    if "time_stride" in (policy.extra.get("observation") or {}):
        raise TrainingConfigError(f"the policy configuration says time_stride {policy.time_stride}, the training "
                                  f"configuration {stride}; give one stride")
    observation = {**(policy.extra.get("observation") or {}), "time_stride": stride}
    return policy.replace(extra={**policy.extra, "observation": observation})


def load_training_state_step(checkpoint: Path) -> int | str:
    try:
        return int(json.loads((checkpoint / PROGRESS_NAME).read_text())["step"])
    except (OSError, ValueError, KeyError):
        return checkpoint.name


def _step_shapes(store: EpisodeStore) -> dict[str, tuple[int, ...]]:
    """Per-step shape of every key, from the first episode."""
    if store.n_episodes == 0:
        raise TrainingConfigError(f"{store.path} has no episodes")
    return {key: tuple(value.shape[1:]) for key, value in store.get_episode(0).items()}


_VALIDATION_STREAM = 2**31 - 1  # a "rank" no training process has: validation noise never repeats training noise


def training_progress(step: int, steps: int, cpu_seconds: float, cpu_minutes: float | None) -> float:
    """Fraction of a run done, in [0, 1]: of its planned steps, or of its CPU budget when that runs out first.

    The step count of a budgeted run is planned from a timing probe; on a machine that gets busier the steps
    cost more and the budget ends the run early. Scheduling by this fraction still decays the learning rate
    to zero at the run's real end, instead of stopping it mid-cosine at a high rate.
    """
    done = step / steps
    if cpu_minutes is not None:
        done = max(done, cpu_seconds / (60.0 * cpu_minutes))
    return min(done, 1.0)


def cosine_with_warmup(progress: float, step: int, warmup_steps: int, steps: int) -> float:
    """LR factor: linear warm-up over the first `warmup_steps` steps, then a half cosine to 0 at progress 1
    (diffusers' get_cosine_schedule_with_warmup, with the progress given rather than derived from the step)."""
    if step < warmup_steps:
        return step / max(1, warmup_steps)
    warmup_fraction = warmup_steps / steps
    after_warmup = (progress - warmup_fraction) / max(1e-12, 1.0 - warmup_fraction)
    return max(0.0, 0.5 * (1.0 + math.cos(math.pi * min(max(after_warmup, 0.0), 1.0))))


def default_warmup_steps(steps: int) -> int:
    """Warm-up for a run of `steps` steps when none is given: a twentieth of it, between 10 and 500."""
    return min(500, max(steps // 20, 10))


# ---- CPU budgets --------------------------------------------------------------------------------------
def time_training_step(data: str | Path, policy_config: PolicyConfig, batch_size: int, *, warmup: int = 3,
                       steps: int = 8, seed: int = 0, augment: AugmentConfig | dict | None = None) -> float:
    """CPU seconds per optimisation step of `policy_config` on `data` at this batch size, measured here and now.

    A throwaway model does `warmup` + `steps` steps as the Trainer does them (batch assembly, the point subset,
    augmentation, forward, backward, fused AdamW) and the median of the process CPU time per step is returned:
    what a CPU-time budget buys, nearly independent of other jobs on the machine. The caller's torch RNG is left
    as it was. Run it with the threads the training will use.
    """
    from torch.utils.data import default_collate

    dataset = SequenceDataset(data, obs_keys=policy_config.obs_keys, n_obs_steps=policy_config.n_obs_steps,
                              horizon=policy_config.horizon, n_action_steps=policy_config.n_action_steps,
                              time_stride=policy_config.time_stride)
    key = policy_config.visual_key
    points = policy_config.observation.cloud_points(policy_config)  # None: not a cloud (an image)
    augment = as_augment_config(augment)
    rng = np.random.default_rng(seed)
    generator = torch.Generator().manual_seed(seed)
    times = []
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        policy = DiffusionPolicy(policy_config)
        policy.fit_normalizer(dataset)
        optimizer = torch.optim.AdamW(policy.parameters(), lr=1e-4, fused=True)
        for index in range(warmup + steps):
            started = time.process_time()
            batch = default_collate([dataset[int(i)] for i in rng.integers(0, len(dataset), batch_size)])
            clouds = batch["obs"][key]
            if points is not None and points < clouds.shape[-2]:  # Trainer._subsample
                keep = torch.randperm(clouds.shape[-2], generator=generator)[:points]
                batch = {**batch, "obs": {**batch["obs"], key: clouds.index_select(-2, keep)}}
            if augment is not None:
                batch = augment_batch(batch, key if points is not None else None, augment, generator)
            loss = policy.compute_loss(batch, generator=generator)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            if index >= warmup:
                times.append(time.process_time() - started)
    return float(np.median(times))


def plan_budget(data: str | Path, policy_config: PolicyConfig, batch_size: int, cpu_minutes: float, *,
                step_cap: int | None = None, threads: int | None = None, seed: int = 0,
                augment: AugmentConfig | dict | None = None, min_steps: int = 50, max_steps: int = 50_000,
                probe=None) -> BudgetPlan:
    """The steps a CPU budget buys, from a short timing probe of this run's step (`time_training_step`).

    The one planning rule of `lano3dp train --minutes` and `pipeline.train_stage`: steps = budget /
    (probed CPU-s per step x TRAINING_OVERHEAD), kept within [min_steps, max_steps], and lowered to `step_cap`
    when one is given. The learning-rate schedule then decays over the planned steps; the Trainer still stops at
    the budget if steps turn out dearer than probed (`training_progress`).

    Args:
        threads: torch intra-op threads, set here before the probe (None: leave torch's setting).
        probe: (data, policy_config, batch_size, seed=, augment=) -> CPU-s per step (None: time_training_step).
    """
    if not cpu_minutes > 0:
        raise ValueError(f"the CPU budget must be > 0 minutes, got {cpu_minutes}")
    if step_cap is not None and step_cap < 1:
        raise ValueError(f"the step cap must be >= 1, got {step_cap}")
    if threads:
        torch.set_num_threads(threads)
    seconds = float((probe or time_training_step)(data, policy_config, batch_size, seed=seed, augment=augment))
    if not (math.isfinite(seconds) and seconds > 0):
        raise ValueError(f"the timing probe measured {seconds} CPU-s per step; cannot plan a budget from it")
    budget_steps = int(min(max(cpu_minutes * 60 / (seconds * TRAINING_OVERHEAD), min_steps), max_steps))
    steps = budget_steps if step_cap is None else min(budget_steps, step_cap)
    return BudgetPlan(cpu_minutes=cpu_minutes, probe_cpu_s_per_step=round(seconds, 5), overhead=TRAINING_OVERHEAD,
                      budget_steps=budget_steps, step_cap=step_cap, steps=steps, threads=torch.get_num_threads())


def saved_train_config(run: str | Path) -> dict[str, Any] | None:
    """The train_config.json of the run in `run` as saved (None: no run there yet)."""
    path = Path(run) / "train_config.json"
    if not path.exists():
        return None
    try:
        return json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as error:
        raise CorruptFileError(path, f"not valid JSON ({error})") from error


class RunSchedule(NamedTuple):
    """A run's step count, its warm-up, and the budget plan they came from (None: the steps were given)."""

    steps: int
    warmup_steps: int
    budget_plan: BudgetPlan | None


def run_schedule(run: str | Path, data: str | Path, policy_config: PolicyConfig, batch_size: int, *,
                 cpu_minutes: float | None = None, steps: int | None = None, warmup_steps: int | None = None,
                 **probe_options) -> RunSchedule:
    """The steps and warm-up of `lano3dp train` into `run`.

    With `cpu_minutes` the steps are planned from the budget (`plan_budget`, `steps` a cap), unless the run in
    `run` was started with this budget and cap: a resumed run keeps its plan. Without, `steps` (default 3000).
    The warm-up, when not given, is the resumed run's own or `default_warmup_steps` of the steps.
    `probe_options` (threads, seed, augment, ...) go to `plan_budget`.
    """
    saved = saved_train_config(run) or {}
    plan = None
    if cpu_minutes is not None:
        previous = saved.get("budget_plan")
        if previous and previous["cpu_minutes"] == cpu_minutes and previous["step_cap"] == steps:
            plan = BudgetPlan(**previous)
        else:
            plan = plan_budget(data, policy_config, batch_size, cpu_minutes, step_cap=steps, **probe_options)
    total = plan.steps if plan is not None else steps or DEFAULT_STEPS
    if warmup_steps is None:
        warmup_steps = saved.get("warmup_steps", default_warmup_steps(total))
    return RunSchedule(total, warmup_steps, plan)


def _noise_seed(seed: int, rank: int, step: int) -> int:
    # shifted as a Python int: numpy 1.x cannot shift a uint64 by a Python int (same value on numpy 2)
    return int(np.random.SeedSequence([seed, rank, step]).generate_state(1, dtype=np.uint64)[0]) >> 1


class Trainer:
    """Builds (or resumes) a run; `run()` trains to `config.steps` and returns the final checkpoint."""

    def __init__(self, config: TrainConfig):
        self.config = config
        self.world_size = int(os.environ.get("WORLD_SIZE", "1"))
        self.distributed = self.world_size > 1
        self._init_distributed()
        self.is_main = self.rank == 0
        if config.threads:
            torch.set_num_threads(config.threads)
        self.out = Path(config.out)
        self.checkpoints = self.out / "checkpoints"
        # One writer per run folder (rank 0 writes for all ranks): a second `train` into it is refused.
        self.lock = WriteLock(self.out) if self.is_main else None
        if self.lock is not None:
            self.lock.acquire()
        try:
            self._setup()
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Release the run folder (run() does it when it returns)."""
        if self.lock is not None:
            self.lock.release()

    def _setup(self) -> None:
        config = self.config
        if self.distributed and config.budget_plan is not None:
            self._agree_on_planned_steps()
        if self.is_main:
            self.checkpoints.mkdir(parents=True, exist_ok=True)
            remove_stale_temporaries(self.checkpoints)

        resume_from = latest_resumable(self.checkpoints)
        self.resumed_from: Path | None = resume_from
        state = load_training_state(resume_from) if resume_from is not None else None
        policy_config = self._policy_config(resume_from)
        if resume_from is not None:
            self._check_resume_settings(resume_from)

        store = EpisodeStore.open(config.data)
        self.subsample_points: int | None = None
        self._check_dataset(store, policy_config)
        train_episodes, val_episodes = split_episodes(store.n_episodes, config.val_ratio, config.seed)
        window = dict(obs_keys=policy_config.obs_keys, n_obs_steps=policy_config.n_obs_steps,
                      horizon=policy_config.horizon, n_action_steps=policy_config.n_action_steps,
                      time_stride=policy_config.time_stride)
        self.train_set = SequenceDataset(store, episodes=train_episodes, **window)
        self.val_set = SequenceDataset(store, episodes=val_episodes, **window) if len(val_episodes) else None
        self.steps_per_epoch = len(self.train_set) // (config.batch_size * self.world_size)
        if self.steps_per_epoch == 0:
            raise TrainingConfigError(
                f"{config.data} has {len(self.train_set)} training windows, fewer than one batch of "
                f"{config.batch_size} x {self.world_size} process(es); lower --batch-size")

        with torch.random.fork_rng(devices=[]):  # seeded initial weights (identical on every rank), caller's RNG kept
            torch.manual_seed(config.seed)
            self.policy = DiffusionPolicy(policy_config).to(self.device)
        if state is None:
            self.policy.fit_normalizer(self.train_set)
            if config.augment is not None and (config.augment.lift > 0 or config.augment.stretch > 0):
                # lifted or stretched windows reach beyond the data
                self.policy.normalizer.set_stats(widened_stats(self.policy.normalizer_stats(), config.augment,
                                                               self._moved_key()))
        else:
            self._load_weights(self.policy, state.model, state.path)
        self.optimizer = torch.optim.AdamW(self.policy.parameters(), lr=config.lr, betas=config.betas,
                                           weight_decay=config.weight_decay, fused=True)
        self.step = 0
        self.cpu_seconds = 0.0  # spent on this run by all its sessions (restored on resume)
        # diffusers' cosine schedule counts steps only; this one follows the CPU budget too (training_progress).
        self.lr_scheduler = torch.optim.lr_scheduler.LambdaLR(self.optimizer, lambda _: self.lr_factor())
        self.ema = EMA(self.policy, config.ema_inv_gamma, config.ema_power, max_value=config.ema_max) \
            if config.ema else None
        self.stopped_by_budget = False
        if state is not None:
            self._restore(state, resume_from)
        self.model = self.policy
        if self.distributed:
            from torch.nn.parallel import DistributedDataParallel

            self.model = DistributedDataParallel(
                self.policy, device_ids=[self.device.index] if self.device.type == "cuda" else None)

    # ---- setup -------------------------------------------------------------------------
    def _init_distributed(self) -> None:
        requested = torch.device(self.config.device)
        if not self.distributed:
            self.rank = 0
            self.device = requested
            return
        import torch.distributed as dist

        self.rank = int(os.environ["RANK"])
        if requested.type == "cuda":
            self.device = torch.device("cuda", int(os.environ.get("LOCAL_RANK", self.rank)))
            torch.cuda.set_device(self.device)
        else:
            self.device = requested
        if not dist.is_initialized():
            dist.init_process_group("nccl" if self.device.type == "cuda" else "gloo")

    def _policy_config(self, resume_from: Path | None) -> PolicyConfig:
        requested = self.config.policy
        if requested is not None:
            # train_config.json then holds the policy as trained, stride included
            requested = self.config.policy = with_time_stride(requested, self.config.time_stride)
        if resume_from is not None:
            saved = load_config(resume_from / "config.json")
            if saved.time_stride != self.config.time_stride:  # named as the other fixed fields are
                raise TrainingConfigError(
                    f"{self.out} was trained to step {load_training_state_step(resume_from)} with other settings "
                    f"than this resume asks for (time_stride: {saved.time_stride!r} -> {self.config.time_stride!r}); "
                    "resume with the old values or train into a new --out folder")
            if requested is not None and requested != saved:
                differences = changed_fields(saved.to_dict(), requested.to_dict())
                raise TrainingConfigError(
                    f"{self.out} holds a run with another policy configuration ({resume_from / 'config.json'}): "
                    f"{'; '.join(differences)}; resume it with the same settings or train into a new --out folder")
            return saved
        if requested is None:
            requested = with_time_stride(policy_config_for_dataset(self.config.data), self.config.time_stride)
        return requested

    def _check_resume_settings(self, resume_from: Path) -> None:
        """Refuse to resume with another optimizer, schedule, data or seed, naming each changed field."""
        saved_path = resume_from / "train_config.json"
        if not saved_path.exists():  # checkpoints written before they carried their TrainConfig
            return
        try:
            saved = json.loads(saved_path.read_text())
        except (ValueError, UnicodeDecodeError) as error:
            raise CorruptFileError(saved_path, f"not valid JSON ({error})") from error
        new = self.config.to_dict()
        for config in (saved, new):  # the same dataset under another spelling of its path is the same dataset
            if config.get("data"):
                config["data"] = str(Path(config["data"]).resolve())
            if isinstance(config.get("betas"), tuple | list):
                config["betas"] = [float(b) for b in config["betas"]]
        step = load_training_state_step(resume_from)
        differences = changed_fields(saved, new, RESUME_FIXED_FIELDS)
        if differences:
            raise TrainingConfigError(
                f"{self.out} was trained to step {step} with other settings than this resume asks for "
                f"({'; '.join(differences)}); resume with the old values or train into a new --out folder")
        changes = list((saved.get("extra") or {}).get("resume_changes", []))
        for name in RESUME_APPLIED_FIELDS:
            if saved.get(name) != new.get(name):
                changes.append({"at_step": step, "field": name, "old": saved.get(name), "new": new.get(name)})
        if changes:
            self.config.extra = {**self.config.extra, "resume_changes": changes}

    def _check_dataset(self, store: EpisodeStore, policy_config: PolicyConfig) -> None:
        missing = [key for key in (*policy_config.obs_keys, "action") if key not in store.keys]
        if missing:
            raise TrainingConfigError(f"{store.path} has no {missing} (keys: {store.keys}); a "
                                      f"{policy_config.obs_type!r} policy needs {[*policy_config.obs_keys, 'action']}")
        for key, length in policy_config.task_inputs.items():
            stored = _step_shapes(store)[key]
            if stored != (length,):
                raise TrainingConfigError(f"{store.path} holds {key} of shape {stored} per step, the policy takes "
                                          f"({length},)")
        if policy_config.task_inputs and self.config.augment is not None:
            raise TrainingConfigError(f"--augment moves the scene but not the task inputs "
                                      f"{sorted(policy_config.task_inputs)} (obs[key] is not known to be a position); "
                                      "train without --augment")
        observation = policy_config.observation
        if observation.object_slots:
            names = store.attrs.get("object_names")
            if names is not None and tuple(names) != policy_config.object_names:
                raise TrainingConfigError(f"{store.path} stores object slots {names}, the policy expects "
                                          f"{list(policy_config.object_names)}")
            slots = _step_shapes(store)[policy_config.visual_key][0]
            if slots != policy_config.n_slots:
                raise TrainingConfigError(f"{store.path} has {slots} object slots, the policy {policy_config.n_slots}")
        wanted = observation.cloud_points(policy_config)
        if wanted is not None:
            stored = _step_shapes(store)[policy_config.visual_key][-2]
            if wanted > stored:
                raise TrainingConfigError(f"{store.path} holds {stored} points per cloud, the policy asks for "
                                          f"{wanted}; record the dataset with more points or lower n_points")
            self.subsample_points = wanted if wanted < stored else None

    def _subsample(self, batch: dict, generator: torch.Generator) -> dict:
        """Keep a random subset of n_points points of every cloud (one index set per batch).

        Training cost is linear in the number of points, so a policy may train on fewer points than
        the dataset holds; the clouds are farthest-point samples, and a random subset of one keeps
        their coverage roughly (at inference the observer samples n_points by FPS directly).
        """
        if self.subsample_points is None:
            return batch
        key = self.policy.config.visual_key
        clouds = batch["obs"][key]
        keep = torch.randperm(clouds.shape[-2], generator=generator, device=generator.device)[: self.subsample_points]
        return {**batch, "obs": {**batch["obs"], key: clouds.index_select(-2, keep.to(clouds.device))}}

    def _moved_key(self) -> str | None:
        """The visual key augmentation moves with the scene: an xyz cloud input's, None for another (an image)."""
        policy_config = self.policy.config
        return policy_config.visual_key if policy_config.observation.cloud_points(policy_config) is not None else None

    @staticmethod
    def _load_weights(module: torch.nn.Module, weights: dict, path: Path) -> None:
        try:
            module.load_state_dict(weights, strict=True)
        except RuntimeError as error:
            raise CorruptFileError(path, f"weights do not match the policy configuration: {error}") from error

    def _restore(self, state: TrainingState, path: Path) -> None:
        try:
            self.optimizer.load_state_dict(state.optimizer)
            self.lr_scheduler.load_state_dict(state.lr_scheduler)
        except (ValueError, KeyError, RuntimeError) as error:
            raise CorruptFileError(path / "training_state.json", f"cannot restore the optimizer: {error}") from error
        if self.ema is not None:
            ema_policy = DiffusionPolicy.from_pretrained(path, device=self.device)
            self.ema.model.load_state_dict(ema_policy.state_dict())
            self.ema.optimization_step = int(state.ema.get("optimization_step", state.step))
        self.step = state.step
        self.cpu_seconds = float(state.extra.get("cpu_s", 0.0))

    # ---- loop --------------------------------------------------------------------------
    def _batches(self, epoch: int, skip: int) -> list[list[int]]:
        """This rank's batches of an epoch: a (seed, epoch) permutation split across ranks, as DistributedSampler."""
        from torch.utils.data import DistributedSampler

        sampler = DistributedSampler(self.train_set, num_replicas=self.world_size, rank=self.rank, shuffle=True,
                                     seed=self.config.seed, drop_last=True)
        sampler.set_epoch(epoch)
        indices = list(sampler)
        size = self.config.batch_size
        return [indices[i * size:(i + 1) * size] for i in range(skip, self.steps_per_epoch)]

    def _loader(self, dataset, batches):
        from torch.utils.data import DataLoader

        return DataLoader(dataset, batch_sampler=batches, num_workers=self.config.num_workers)

    def run(self) -> Path:
        """Train up to config.steps; returns the final checkpoint folder (a DiffusionPolicy checkpoint)."""
        try:
            return self._run()
        finally:
            self.close()

    def _run(self) -> Path:
        config = self.config
        writer = self._writer()
        progress = self._progress()
        autocast = (torch.autocast(self.device.type, dtype=torch.bfloat16) if config.bf16 else nullcontext())
        generator = torch.Generator(self.device)
        last_checkpoint = self.resumed_from if self.resumed_from is not None and self._finished() else None
        self.model.train()
        session_start = time.process_time() - self.cpu_seconds
        try:
            while not self._finished():
                epoch, offset = divmod(self.step, self.steps_per_epoch)
                for batch in self._loader(self.train_set, self._batches(epoch, offset)):
                    generator.manual_seed(_noise_seed(config.seed, self.rank, self.step))
                    batch = self._subsample(batch, generator)
                    if config.augment is not None:
                        batch = augment_batch(batch, self._moved_key(), config.augment, generator)
                    with autocast:
                        loss = self.model(batch, generator=generator)
                    self.optimizer.zero_grad(set_to_none=True)
                    loss.backward()
                    lr = self.optimizer.param_groups[0]["lr"]  # the rate this step used
                    self.optimizer.step()
                    if self.ema is not None:
                        self.ema.update(self.policy)
                    self.step += 1
                    self.cpu_seconds = time.process_time() - session_start
                    if config.cpu_minutes is not None:
                        self._agree_on_budget()
                    self.lr_scheduler.step()
                    last_step = self._finished()
                    value = float(loss.detach())
                    if not math.isfinite(value):
                        raise NonFiniteLossError(f"training loss became {value} at step {self.step}; lower --lr "
                                                 "or check the dataset")
                    if self.is_main:
                        progress.update(1)
                        if self.step % config.log_every == 0 or self.step == config.steps:
                            progress.set_postfix(loss=f"{value:.4f}")
                            writer.add_scalar("loss", value, self.step)
                            writer.add_scalar("lr", lr, self.step)
                        if self.val_set is not None and (self.step % config.val_every == 0 or last_step):
                            val_loss = self.validation_loss()
                            writer.add_scalar("val_loss", val_loss, self.step)
                            progress.write(f"step {self.step}: val_loss {val_loss:.4f}")
                        if self.step % config.ckpt_every == 0 or last_step:
                            last_checkpoint = self.save_checkpoint()
                    if last_step:
                        break
            if last_checkpoint is None:
                last_checkpoint = self.checkpoints / checkpoint_name(self.step)
        finally:
            progress.close()
            writer.close()
            if self.distributed:
                import torch.distributed as dist

                dist.barrier()
                dist.destroy_process_group()
        return last_checkpoint

    def _agree_on_planned_steps(self) -> None:
        """Under torchrun each rank probed its own step cost: all take the fewest planned steps, so they stop at
        the same step with the same schedule."""
        import torch.distributed as dist

        steps = torch.tensor([self.config.steps], dtype=torch.int64, device=self.device)
        dist.all_reduce(steps, op=dist.ReduceOp.MIN)
        self.config.steps = int(steps.item())
        self.config.budget_plan = dataclasses.replace(self.config.budget_plan, steps=self.config.steps)

    def _agree_on_budget(self) -> None:
        """Every rank takes the largest CPU time of any rank: they then stop at the same step and, since the
        learning rate follows the budget, step with the same rate."""
        if self.distributed:
            import torch.distributed as dist

            spent = torch.tensor([self.cpu_seconds], dtype=torch.float64, device=self.device)
            dist.all_reduce(spent, op=dist.ReduceOp.MAX)
            self.cpu_seconds = float(spent.item())
        self.stopped_by_budget = self.cpu_seconds >= 60 * self.config.cpu_minutes and self.step < self.config.steps

    def lr_factor(self) -> float:
        """The learning rate's multiplier at the current step and CPU time (cosine_with_warmup)."""
        config = self.config
        progress = training_progress(self.step, config.steps, self.cpu_seconds, config.cpu_minutes)
        return cosine_with_warmup(progress, self.step, config.warmup_steps, config.steps)

    def _finished(self) -> bool:
        """The planned step count is reached, or the CPU budget is spent."""
        budget = self.config.cpu_minutes
        return self.step >= self.config.steps or (budget is not None and self.cpu_seconds >= 60 * budget)

    @torch.no_grad()
    def validation_loss(self) -> float:
        """Mean loss of the EMA policy (the one saved) over up to val_batches validation batches, fixed noise."""
        policy = self.ema.model if self.ema is not None else self.policy
        was_training = policy.training
        policy.eval()
        order = list(range(len(self.val_set)))
        batches = [order[i:i + self.config.batch_size] for i in range(0, len(order), self.config.batch_size)]
        batches = batches[: self.config.val_batches]
        generator = torch.Generator(self.device)
        losses, weights = [], []
        for index, batch in enumerate(self._loader(self.val_set, batches)):
            generator.manual_seed(_noise_seed(self.config.seed, _VALIDATION_STREAM, index))
            batch = self._subsample(batch, generator)
            losses.append(float(policy.compute_loss(batch, generator=generator)))
            weights.append(len(batches[index]))
        policy.train(was_training)
        value = float(np.average(losses, weights=weights))
        if not math.isfinite(value):
            raise NonFiniteLossError(f"validation loss became {value} at step {self.step}")
        return value

    def save_checkpoint(self) -> Path:
        """Write checkpoints/step_XXXXXXX atomically and point checkpoints/last at it (rank 0 only)."""
        final = self.checkpoints / checkpoint_name(self.step)
        with atomic_directory(final) as folder:
            (self.ema.model if self.ema is not None else self.policy).save_pretrained(folder)
            save_training_state(folder, step=self.step, model=self.policy, optimizer=self.optimizer,
                                lr_scheduler=self.lr_scheduler, ema=self.ema,
                                extra={"seed": self.config.seed, "world_size": self.world_size,
                                       "cpu_s": round(self.cpu_seconds, 3)})
            (folder / "train_config.json").write_text(self.config.to_json() + "\n")
            # what this checkpoint cost; the training state holding the same number is pruned from older ones
            (folder / PROGRESS_NAME).write_text(json.dumps({"step": self.step, "cpu_s": round(self.cpu_seconds, 3),
                                                              "stopped_by_budget": self.stopped_by_budget}) + "\n")
        update_last_pointer(self.checkpoints, final.name)
        prune_training_states(self.checkpoints, self.config.keep_training_states)
        return final

    def _writer(self):
        if not self.is_main:
            return _NullWriter()
        from torch.utils.tensorboard import SummaryWriter

        write_text_atomic(self.out / "train_config.json", self.config.to_json() + "\n")  # a full disk: never empty
        return SummaryWriter(str(self.out / "tensorboard"), purge_step=self.step or None)

    def _progress(self):
        from tqdm.auto import tqdm

        return tqdm(total=self.config.steps, initial=self.step, desc="train", unit="step",
                    disable=not (self.is_main and self.config.progress), dynamic_ncols=True)


class _NullWriter:
    def add_scalar(self, *args, **kwargs) -> None:
        pass

    def close(self) -> None:
        pass


def train(config: TrainConfig) -> Path:
    """Train (or resume) a policy; returns the final checkpoint folder, loadable by DiffusionPolicy.from_pretrained."""
    return Trainer(config).run()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Train a lano3dp diffusion policy from a TrainConfig JSON file "
                                                 "(works under torchrun).")
    parser.add_argument("--config", required=True, help="path of a TrainConfig JSON file")
    args = parser.parse_args(argv)
    config = TrainConfig.from_dict(json.loads(Path(args.config).read_text()))
    path = train(config)
    if int(os.environ.get("RANK", "0")) == 0:
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
