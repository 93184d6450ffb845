"""`lano3dp train`: train (or resume) a diffusion policy on a recorded dataset.

Runs the same way under torchrun for data-parallel training:
    torchrun --standalone --nproc_per_node 2 $(which lano3dp) train --data d.zarr --out runs/x
"""

from __future__ import annotations

import math
from enum import StrEnum
from pathlib import Path

import typer


class Size(StrEnum):
    compact = "compact"
    small = "small"
    medium = "medium"
    dp = "dp"


class Encoder(StrEnum):
    residual = "residual"
    mlp = "mlp"


def train_command(
    data: Path = typer.Option(..., "--data", help="Zarr episode store recorded by `lano3dp collect`."),
    out: Path = typer.Option(..., "--out", help="Run folder; an existing run there is resumed from its last "
                                                "checkpoint."),
    steps: int | None = typer.Option(None, min=1, help="Total optimisation steps (default 3000; with --minutes, a cap "
                                                       "on what the budget buys). A resumed run continues up to this."),
    batch_size: int = typer.Option(64, "--batch-size", min=1, help="Windows per step and per process."),
    lr: float = typer.Option(5e-4, help="AdamW peak learning rate (5e-4 suits CPU-length runs)."),
    warmup_steps: int | None = typer.Option(None, "--warmup-steps", help="Linear warm-up steps before the cosine "
                                                                         "decay (default: a twentieth of the steps, "
                                                                         "10-500; a resumed run keeps its own)."),
    minutes: float | None = typer.Option(None, help="A budget of CPU-minutes of this process (resumes included) the "
                                                    "run plans for: the steps come from a short timing probe "
                                                    "(capped by --steps when given) and the LR's cosine decays "
                                                    "over them; the run stops, checkpointed, if the budget runs "
                                                    "out first."),
    size: Size = typer.Option(Size.compact, help="UNet widths: compact (48,96,192), small (64,128,256), "
                                                 "medium (128,256,512), dp (256,512,1024)."),
    obs_type: str = typer.Option("objects", "--obs-type",
                                 help="objects (Lan-o3dp), scene (DP3 baseline), image (DP baseline), or another "
                                      "registered observation type (lano3dp.policy.register_observation_type)."),
    encoder: Encoder = typer.Option(Encoder.residual, help="Point encoder: residual (paper's best) or mlp (DP3)."),
    n_points: int | None = typer.Option(None, "--n-points", help="Points per object cloud to train on (default: "
                                                                 "all the dataset holds; fewer trains faster)."),
    pose_features: bool = typer.Option(False, "--pose-features/--no-pose-features",
                                       help="Give the policy each object cloud's centroid and horizontal principal "
                                            "axis beside its learned feature (objects only)."),
    pose_skew: bool = typer.Option(False, "--pose-skew/--no-pose-skew",
                                   help="With --pose-features, also each cloud's horizontal third moment: which end "
                                        "of the object its points reach farther towards (a tool's handle)."),
    horizon: int = typer.Option(16, help="Predicted trajectory length H."),
    n_obs_steps: int = typer.Option(1, "--n-obs-steps", help="Observation steps To the policy sees."),
    n_action_steps: int = typer.Option(8, "--n-action-steps", help="Actions Ta executed per chunk."),
    time_stride: int = typer.Option(1, "--time-stride", min=1,
                                    help="Recorded steps between consecutive policy steps, observations and "
                                         "actions alike (for a fast env: at 80 Hz, 4 makes a 16-step horizon "
                                         "span 0.8 s); the checkpoint keeps it and eval/run step the env that "
                                         "many times per action."),
    seed: int = typer.Option(0, help="Seed of weights, data order and diffusion noise."),
    val_ratio: float = typer.Option(0.05, "--val-ratio", help="Fraction of episodes held out for validation."),
    val_every: int = typer.Option(500, "--val-every", help="Steps between validation losses."),
    ckpt_every: int = typer.Option(1000, "--ckpt-every", help="Steps between checkpoints (the last step always "
                                                              "checkpoints)."),
    device: str = typer.Option("cpu", help="cpu or cuda."),
    threads: int | None = typer.Option(None, help="Torch intra-op threads (default: OMP_NUM_THREADS, else 1)."),
    num_workers: int = typer.Option(0, "--num-workers", help="DataLoader worker processes."),
    bf16: bool = typer.Option(False, "--bf16", help="bfloat16 autocast (CPU with AMX: about 19% faster, small)."),
    ema: bool = typer.Option(True, "--ema/--no-ema", help="Save the EMA of the weights as the policy."),
    augment: bool = typer.Option(False, "--augment/--no-augment",
                                 help="Move each window's scene, hand and actions by one small planar rigid motion "
                                      "(2 cm, 5 deg), jitter and drop cloud points (lano3dp.augment; off by "
                                      "default: its gain was inside the noise)."),
    augment_yaw: float | None = typer.Option(None, "--augment-yaw", min=0.0, max=180.0,
                                             help="With --augment, turn each window by up to this many degrees "
                                                  "instead of 5 (45 lifted the phone and the broom; 180 hurt the "
                                                  "phone)."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Show a progress bar."),
) -> None:
    """Train an object-centric diffusion policy (or a DP3 / DP baseline); resumes a killed run."""
    import os

    from lano3dp.cli import _options
    from lano3dp.policy import down_dims_for
    from lano3dp.train import TrainConfig, policy_config_for_dataset, run_schedule, train

    _options.obs_type(obs_type)
    _options.existing_path(data, "--data")
    _options.output_path(out, folder=True, kind="run")
    _options.device(device)
    # errors past here (a dataset that does not fit, a refused resume) are one line via the CLI's error boundary
    overrides = dict(obs_type=obs_type, point_encoder=encoder.value, down_dims=down_dims_for(size.value),
                     horizon=horizon, n_obs_steps=n_obs_steps, n_action_steps=n_action_steps)
    if pose_features:
        overrides["object_pose_features"] = True
    if pose_skew:
        overrides["object_pose_skew"] = True
    if n_points is not None:
        overrides["n_points"] = n_points
    policy = policy_config_for_dataset(data, **overrides)
    augmentation = augment_config(augment, augment_yaw)
    # the steps a --minutes budget buys (train.plan_budget), a resumed run's own, or --steps
    schedule = run_schedule(out, data, policy, batch_size, cpu_minutes=minutes, steps=steps, warmup_steps=warmup_steps,
                            threads=threads, seed=seed, augment=augmentation)
    if schedule.budget_plan is not None:
        typer.echo(f"{schedule.steps} steps planned for {minutes:g} CPU-min "
                   f"({schedule.budget_plan.probe_cpu_s_per_step:.3f} CPU-s per step probed)")
    config = TrainConfig(data=str(data), out=str(out), policy=policy, steps=schedule.steps, batch_size=batch_size,
                         lr=lr, warmup_steps=schedule.warmup_steps, val_ratio=val_ratio, val_every=val_every,
                         ckpt_every=ckpt_every, seed=seed, device=device, threads=threads, cpu_minutes=minutes,
                         budget_plan=schedule.budget_plan, num_workers=num_workers, bf16=bf16, ema=ema,
                         progress=progress, augment=augmentation, time_stride=time_stride)
    final = train(config)
    if int(os.environ.get("RANK", "0")) == 0:
        typer.echo(f"final checkpoint: {final}")


def register(app: typer.Typer) -> None:
    app.command("train")(train_command)


def augment_config(augment: bool, yaw_degrees: float | None):
    """The training augmentation the options ask for (None: off)."""
    from lano3dp.augment import AugmentConfig

    if yaw_degrees is not None and not augment:
        raise typer.BadParameter("--augment-yaw needs --augment", param_hint="--augment-yaw")
    if not augment:
        return None
    return AugmentConfig() if yaw_degrees is None else AugmentConfig(yaw=math.radians(yaw_degrees))
