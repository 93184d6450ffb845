"""`lano3dp guidance-figures`: the paper's Fig. 5 and Fig. 6 for a trained policy (or the analytic prior)."""

from __future__ import annotations

from pathlib import Path

import typer

from lano3dp.guidance.settings import SAFETY_MARGIN


def register(app: typer.Typer) -> None:
    app.command("guidance-figures")(guidance_figures)


def _obs_window(store, episode: int, step: int, keys, n_obs_steps: int, batch: int, stride: int = 1) -> dict:
    """The observation window ending at `step` of `episode`, its steps `stride` recorded steps apart and
    edge-padded like training, repeated `batch` times."""
    import numpy as np

    data = store.get_episode(episode, keys)
    length = len(next(iter(data.values())))
    if not 0 <= step < length:
        raise typer.BadParameter(f"step {step} is outside episode {episode} (length {length})")
    rows = np.clip(step - stride * np.arange(n_obs_steps - 1, -1, -1), 0, length - 1)
    return {key: np.repeat(value[rows][None], batch, axis=0) for key, value in data.items()}


def guidance_figures(
    out: Path = typer.Option(..., help="Folder for the PNGs (created)."),
    obstacle: tuple[float, float, float] = typer.Option(..., help="Cylinder obstacle X Y RADIUS (m), world frame."),
    checkpoint: Path | None = typer.Option(None, help="Policy folder (or training run). Omit with --analytic."),
    data: Path | None = typer.Option(None, help="Dataset (zarr) to take the observation from."),
    episode: int = typer.Option(0, help="Episode of --data."),
    step: int = typer.Option(0, help="Step of the episode whose observation window is used."),
    analytic: bool = typer.Option(False, help="Use the analytic Gaussian prior of a straight path through the "
                                              "obstacle instead of a policy (no checkpoint needed)."),
    held_radius: float = typer.Option(0.0, help="Radius (m) of what the gripper holds."),
    margin: float = typer.Option(SAFETY_MARGIN, help="Extra safety margin (m); Q* = radius + held radius + margin."),
    mode: str = typer.Option("clean", help="Guidance for Fig. 5: clean (A_0|k, the paper) or noisy (A_k)."),
    rho: float = typer.Option(1.0, help="Guidance scale for Fig. 5."),
    rhos: str = typer.Option("0,0.25,1,4", help="Comma-separated guidance scales for Fig. 6."),
    last_steps: int = typer.Option(10, help="S: guide while k <= S (training-scale steps)."),
    cost_kind: str = typer.Option("paper", "--cost", help="paper (the xy hinge as is), metric (MetricGradient: "
                                  "isotropic push, rho in m per step) or metric+dense (also pushes segments)."),
    push_weight: str = typer.Option("constant", help="constant (paper) or alpha_bar (for DDIM on every step)."),
    clip_range: float | None = typer.Option(None, help="Guided steps clip x_0 to [-r, r] (default: the scheduler's)."),
    scheduler: str = typer.Option("ddpm", help="ddpm or ddim."),
    steps: int | None = typer.Option(None, help="Inference steps (default: DDPM 100, DDIM the policy's)."),
    ks: str = typer.Option("100,50,20,10,5,1", help="Denoising steps k shown in Fig. 5."),
    samples: int = typer.Option(8, help="Trajectories per panel."),
    seed: int = typer.Option(0, help="Seed of the sampling noise (same for every rho)."),
) -> None:
    """Write fig5_denoising.png (A_k vs A_0|k over the denoising steps) and fig6_rho.png (final
    trajectories for several rho), top view, with the obstacle's body, contact line and Q*."""
    import torch

    from lano3dp.cli import _options
    from lano3dp.guidance import Cylinder, GuidanceConfig, GuidanceMode, obstacle_guidance_cost
    from lano3dp.guidance.diagnostics import DenoiseRecorder, plot_denoising, plot_trajectories_by_scale

    _options.output_path(out, folder=True)
    _options.choice(mode, ("clean", "noisy"), "--mode")
    _options.choice(scheduler, _options.SCHEDULERS, "--scheduler")
    _options.existing_path(checkpoint, "--checkpoint")
    _options.existing_path(data, "--data")
    obstacle_cost = Cylinder(obstacle[:2], obstacle[2], held_radius=held_radius, margin=margin)
    if cost_kind not in ("paper", "metric", "metric+dense"):
        raise typer.BadParameter(f"--cost must be paper, metric or metric+dense, got {cost_kind!r}")
    wanted_k = [int(k) for k in ks.split(",") if k.strip()]
    scales = [float(r) for r in rhos.split(",") if r.strip()]
    mode = GuidanceMode(mode)

    if analytic:
        sample_chunk, to_metric, label, action_scale = _analytic_sampler(obstacle_cost, scheduler, steps, samples)
    else:
        if checkpoint is None or data is None:
            raise typer.BadParameter("give --checkpoint and --data, or --analytic")
        sample_chunk, to_metric, label, action_scale = _policy_sampler(checkpoint, data, episode, step, scheduler,
                                                                       steps, samples)
    cost = obstacle_guidance_cost([obstacle_cost], densify=4 if cost_kind == "metric+dense" else 1,
                                  action_scale=None if cost_kind == "paper" else action_scale)

    def config(guide_mode, scale):
        return GuidanceConfig(guide_mode, scale, last_steps, push_weight=push_weight, guided_clip_range=clip_range)

    recorder = DenoiseRecorder(to_metric, timesteps=[k - 1 for k in wanted_k])
    sample_chunk(config(mode, rho), cost, torch.Generator().manual_seed(seed), recorder)
    recorder.steps.sort(key=lambda s: -s.timestep)
    if not recorder.steps:
        raise typer.BadParameter(f"none of the steps k={wanted_k} is visited by this scheduler")
    title = f"{label}: guidance on {mode.value} ({cost_kind} cost, {push_weight} push), S={last_steps}"
    fig5 = plot_denoising(recorder.steps, obstacle_cost, out / "fig5_denoising.png", title=f"{title}, rho={rho:g}")
    finals = {}
    for scale in scales:
        guidance = config(mode if scale > 0 else GuidanceMode.NONE, scale)
        finals[scale] = sample_chunk(guidance, cost, torch.Generator().manual_seed(seed), None)
    fig6 = plot_trajectories_by_scale(finals, obstacle_cost, out / "fig6_rho.png", title=title)
    typer.echo(f"wrote {fig5}\nwrote {fig6}")


def _policy_sampler(checkpoint, data, episode, step, scheduler, steps, samples):
    from lano3dp.data import EpisodeStore
    from lano3dp.policy import DiffusionPolicy

    policy = DiffusionPolicy.from_pretrained(checkpoint)
    store = EpisodeStore.open(data)
    obs = _obs_window(store, episode, step, policy.config.obs_keys, policy.config.n_obs_steps, samples,
                      policy.config.time_stride)

    def to_metric(trajectory):
        return policy.unnormalize_actions(trajectory, obs["state"])[..., :3]

    def sample_chunk(guidance, cost, generator, on_step):
        chunk = policy.predict_action_chunk(obs, guidance=guidance, position_cost=cost, scheduler=scheduler,
                                            num_inference_steps=steps, generator=generator, on_step=on_step)
        return chunk.trajectory[..., :3].numpy()

    return sample_chunk, to_metric, f"{Path(checkpoint).name} ({scheduler})", policy.normalizer.scale("action")[:3]


def _analytic_sampler(cost, scheduler_kind, steps, samples):
    from lano3dp.guidance import denoise
    from lano3dp.guidance.analytic import GaussianPathPrior, straight_line
    from lano3dp.policy import PolicyConfig, make_scheduler

    config = PolicyConfig(object_names=("target",))
    scheduler = make_scheduler(config, scheduler_kind)
    steps = steps or (config.num_train_timesteps if scheduler_kind == "ddpm" else config.num_inference_steps)
    center, reach = cost.center.numpy(), 4 * cost.safety_distance
    line = straight_line([center[0], center[1] - reach, 0.0], [center[0], center[1] + reach, 0.0], config.horizon)
    prior = GaussianPathPrior(line, cost.safety_distance / 4, scheduler.alphas_cumprod)

    def sample_chunk(guidance, cost, generator, on_step):
        return denoise(prior, scheduler, (samples, config.horizon, 3), num_inference_steps=steps, generator=generator,
                       guidance=guidance, cost_fn=cost, on_step=on_step).numpy()

    return sample_chunk, None, f"analytic prior ({scheduler_kind})", [1.0] * 3  # identity normaliser
