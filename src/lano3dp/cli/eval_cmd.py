"""`lano3dp eval`: closed-loop rollouts of a checkpoint in the simulator, to a results JSON."""

from __future__ import annotations

from pathlib import Path

import typer

from lano3dp.cli import _options


def register(app: typer.Typer) -> None:
    app.command("eval")(eval_command)


def eval_command(
    ctx: typer.Context,
    checkpoint: Path = typer.Option(None, "--checkpoint", "-c",
                                    help="Policy folder or training run (its last checkpoint); default: the policy "
                                         "packaged for --task."),
    task: str = typer.Option(None, help="Task name (default: the task the checkpoint was trained on)."),
    variation: str = typer.Option("clean", help="clean, or axes joined by '+': clutter, similar, instance, camera, "
                                                "background, obstacle."),
    episodes: int = typer.Option(20, min=1, help="Number of episodes (seeds seed, seed+1, ...)."),
    obstacles: list[str] = typer.Option(None, "--obstacles", help="Object to avoid (repeatable). Default: every "
                                                                  "object the scene marks as an obstacle."),
    guidance: str = typer.Option("none", help="none | noisy (cost on A_k) | clean (the paper's A_0|k)."),
    guidance_preset: str = _options.GUIDANCE_PRESET,
    rho: float = _options.RHO,
    last_steps: int = _options.LAST_STEPS,
    metric_push: bool = _options.METRIC_PUSH,
    per_train_step: bool = _options.PER_TRAIN_STEP,
    densify: int = _options.DENSIFY,
    guided_clip_range: float = _options.GUIDED_CLIP_RANGE,
    push_weight: str = _options.PUSH_WEIGHT,
    checked: bool = _options.CHECKED,
    guide_when_needed: bool = _options.GUIDE_WHEN_NEEDED,
    anchored: bool = _options.ANCHORED,
    repair_steps: int = _options.REPAIR_STEPS,
    hold_unclear: bool = _options.HOLD_UNCLEAR,
    push_turn: float = _options.PUSH_TURN,
    bridge_gaps: bool = _options.BRIDGE_GAPS,
    escape_inside: bool = _options.ESCAPE_INSIDE,
    follow_obstacles: bool = _options.FOLLOW_OBSTACLES,
    checkpoint_guidance: bool = _options.TUNED,
    scheduler: str = typer.Option(None, help="ddpm | ddim (default: the policy's)."),
    steps: int = typer.Option(None, min=1, help="Denoising steps (default: the policy's)."),
    obstacle_shape: str = _options.OBSTACLE_SHAPE,
    margin: float = _options.MARGIN,
    body: str = _options.BODY,
    held_radius: float = _options.HELD_RADIUS,
    refit_obstacles: bool = _options.REFIT_OBSTACLES,
    obstacle_scenes_only: bool = typer.Option(False, help="With an obstacle variation: the first --episodes seeds "
                                                          "whose scene has room for its obstacles."),
    max_steps: int = typer.Option(None, min=1, help="Episode step limit (default: the task's)."),
    workers: int = typer.Option(1, min=1, help="Parallel episode processes (1 torch thread each)."),
    video_dir: Path = typer.Option(None, help="Write MP4s of the first --n-videos episodes here."),
    n_videos: int = typer.Option(2, min=0, help="How many episodes get a video."),
    seed: int = typer.Option(1_000_000, help="First episode seed (apart from the demonstration seeds)."),
    segmenter: str = _options.SEGMENTER,
    detector: str = _options.DETECTOR,
    detector_dir: Path = _options.DETECTOR_DIR,
    sam_dir: Path = _options.SAM_DIR,
    image_size: int = _options.IMAGE_SIZE,
    env: str = typer.Option(None, "--env", help=_options.ENV_HELP),
    out: Path = typer.Option(Path("results.json"), help="Results JSON; each finished episode is also appended to "
                                                        "<out>.episodes.jsonl, from which a killed eval resumes."),
) -> None:
    """Evaluate a policy: success, obstacle contacts, minimum clearance, path length and latency per chunk."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from lano3dp.cli import _options
    from lano3dp.evaluate import EvalConfig, episode_log_path, evaluate, tuned_config
    from lano3dp.policy.pretrained import packaged_checkpoint

    console = Console(stderr=True)
    guidance_settings, obstacle, perception = _options.episode_settings(ctx.params)
    _options.existing_path(checkpoint, "--checkpoint")
    _options.output_path(out, folder=False)
    _options.output_path(video_dir, "--video-dir", folder=True)
    if checkpoint is None:
        if task is None:
            raise typer.BadParameter("give --checkpoint, or --task to evaluate the policy packaged for it",
                                     param_hint="--checkpoint")
        checkpoint = packaged_checkpoint(task)
    config = EvalConfig(
        checkpoint=str(checkpoint), task=task, variation=variation, episodes=episodes,
        obstacles=list(obstacles) if obstacles else None, guidance=guidance_settings, obstacle=obstacle,
        perception=perception, scheduler=scheduler, steps=steps, obstacle_scenes_only=obstacle_scenes_only,
        max_steps=max_steps, workers=workers, video_dir=str(video_dir) if video_dir else None, n_videos=n_videos,
        seed=seed, out=str(out), env=env)
    ran = tuned_config(config, checkpoint).guidance
    console.print(f"[bold]eval[/bold] {checkpoint} on {task or '(dataset task)'} / {variation}"
                  + (f" in {env}" if env else "") + f": {episodes} episodes, guidance {guidance}"
                  + (f" ({guidance_preset}{', as the checkpoint was tuned' if ran != config.guidance else ''}) "
                     f"rho={ran.rho:g} S={ran.last_steps}" + (f" push turn {ran.push_turn:g} deg" if ran.push_turn
                                                               else "")
                     if ran.guided else "")
                  + f", {workers} worker(s)")
    for note in ran.ineffective():
        console.print(f"[yellow]note:[/yellow] {note}")
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  TextColumn("{task.fields[status]}"), console=console) as bar:
        handle = bar.add_task("episodes", total=episodes, status="")
        successes = collisions = 0

        def progress(done: int, total: int, record: dict) -> None:
            nonlocal successes, collisions
            successes += bool(record["success"])
            collisions += bool(record["collided"])
            bar.update(handle, completed=done, status=f"success {successes}/{done}  collided {collisions}/{done}")

        result = evaluate(config, progress=progress, command=command_line(ctx))
    if result["timing"]["resumed_episodes"]:
        console.print(f"resumed {result['timing']['resumed_episodes']} finished episode(s) from "
                      f"{episode_log_path(out)}")
    console.print(summary_line(result["summary"]))
    summary = result["summary"]
    if summary.get("stage_rates"):
        console.print(stage_line(summary))
    if summary["errors"]:
        console.print(f"[yellow]episodes ended by errors:[/yellow] {', '.join(summary['errors'])}")
    for note in result.get("notes", []):
        console.print(f"[yellow]note:[/yellow] {note}")
    console.print(f"results: {out}")


def summary_line(summary: dict) -> str:
    """One human line for a results summary."""
    success = ("success not reported by the env" if summary["success_rate"] is None
               else f"success {summary['success_rate']:.0%} ({summary['successes']}/{summary['episodes']})")
    parts = [success, f"collisions {summary['collision_rate']:.0%}"]
    if summary["mean_min_clearance"] is not None:
        parts.append(f"mean min clearance {summary['mean_min_clearance'] * 100:.1f} cm")
    parts.append(f"path {summary['mean_path_length']:.2f} m")
    if summary["latency_mean_s"] is not None:
        parts.append(f"latency {summary['latency_mean_s'] * 1000:.0f} ms/chunk")
    return ", ".join(parts)


def stage_line(summary: dict) -> str:
    """One human line for the per-stage breakdown: the share of episodes reaching each stage, in order."""
    return "stages reached: " + " > ".join(f"{stage} {rate:.0%}" for stage, rate in summary["stage_rates"].items())


def command_line(ctx: typer.Context) -> str:
    """The command as typed, rebuilt from the parsed parameters (so it is right under any launcher or test
    runner); options left at their defaults are omitted."""
    import shlex

    import click

    parts = ["lano3dp", ctx.info_name or ""]
    for param in ctx.command.params:
        value = ctx.params.get(param.name)
        if value is None or value == param.default or (param.multiple and not value):
            continue
        if isinstance(param, click.Argument):
            parts.append(str(value))
        elif getattr(param, "is_flag", False):
            parts.append(param.opts[0] if value else (param.secondary_opts or param.opts)[0])
        elif param.multiple:
            for item in value:
                parts += [param.opts[0], str(item)]
        else:
            parts += [param.opts[0], str(value)]
    return shlex.join(parts)
