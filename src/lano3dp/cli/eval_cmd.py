"""`lano3dp eval`: closed-loop rollouts of a checkpoint in the simulator, to a results JSON."""

from __future__ import annotations

from pathlib import Path

import typer

from lano3dp.cli import _options
from lano3dp.evaluate import DEFAULT_DENSIFY, DEFAULT_LAST_STEPS, DEFAULT_RHO


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
    rho: float = typer.Option(DEFAULT_RHO, help="Guidance scale rho (metres per guided step with --metric-push)."),
    last_steps: int = typer.Option(DEFAULT_LAST_STEPS, help="Guide while the training-scale step k <= S (100: all)."),
    metric_push: bool = typer.Option(True, "--metric-push/--paper-push",
                                     help="Push isotropically in metres, or as the paper in normalised action units "
                                          "(which needs a far larger rho)."),
    per_train_step: bool = typer.Option(False, help="Scale rho by the scheduler stride (DDIM pushes as much as DDPM)."),
    densify: int = typer.Option(DEFAULT_DENSIFY, min=1, help="Points per path segment the cost sees (1: waypoints "
                                                            "only, as the paper)."),
    scheduler: str = typer.Option(None, help="ddpm | ddim (default: the policy's)."),
    steps: int = typer.Option(None, min=1, help="Denoising steps (default: the policy's)."),
    checked: bool = typer.Option(False, help="Checked execution: re-sample with larger rho while a chunk collides."),
    margin: float = typer.Option(0.02, help="Safety margin (m) beyond contact, part of Q*."),
    obstacle_scenes_only: bool = typer.Option(False, help="With an obstacle variation: the first --episodes seeds "
                                                          "whose scene has room for its obstacles."),
    refit_obstacles: bool = typer.Option(False, help="Re-fit obstacles before every chunk (moving obstacles)."),
    guide_when_needed: bool = typer.Option(False, help="Guide a chunk only when the policy's own one comes within "
                                                       "the margin of an obstacle."),
    obstacle_shape: str = typer.Option("cylinder", "--obstacle-shape", metavar="NAME",
                                       help=_options.obstacle_shape_help()),
    body: str = typer.Option("swept", help="What guidance keeps clear: swept (hand + held object, re-measured "
                                          "every chunk) | sphere (the paper: one ball round the EE point)."),
    held_radius: float = typer.Option(None, help="--body sphere: its radius (m) in Q*; default: measured from the "
                                                 "held object's cloud."),
    max_steps: int = typer.Option(None, min=1, help="Episode step limit (default: the task's)."),
    workers: int = typer.Option(1, min=1, help="Parallel episode processes (1 torch thread each)."),
    video_dir: Path = typer.Option(None, help="Write MP4s of the first --n-videos episodes here."),
    n_videos: int = typer.Option(2, min=0, help="How many episodes get a video."),
    seed: int = typer.Option(1_000_000, help="First episode seed (apart from the demonstration seeds)."),
    segmenter: str = typer.Option("sim", help=_options.SEGMENTER_HELP),
    detector: str = typer.Option("grounding_dino", help="open-vocab: grounding_dino | owlv2."),
    detector_dir: Path = typer.Option(None, help=_options.DETECTOR_DIR_HELP),
    sam_dir: Path = typer.Option(None, help=_options.SAM_DIR_HELP),
    env: str = typer.Option(None, "--env", help=_options.ENV_HELP),
    out: Path = typer.Option(Path("results.json"), help="Results JSON; each finished episode is also appended to "
                                                        "<out>.episodes.jsonl, from which a killed eval resumes."),
) -> None:
    """Evaluate a policy: success, obstacle contacts, minimum clearance, path length and latency per chunk."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from lano3dp.cli import _options
    from lano3dp.evaluate import EvalConfig, episode_log_path, evaluate
    from lano3dp.policy.pretrained import packaged_checkpoint

    console = Console(stderr=True)
    _options.env_factory(env)
    if env is None:  # a user's env has its own task names and variations
        _options.task_name(task)
        _options.variation(variation)
    _options.choice(guidance, _options.GUIDANCE_MODES, "--guidance")
    _options.choice(scheduler, _options.SCHEDULERS, "--scheduler")
    _options.choice(body, ("swept", "sphere"), "--body")
    _options.obstacle_shape(obstacle_shape)
    if held_radius is not None and body != "sphere":
        raise typer.BadParameter("a fixed held radius sizes the sphere body model; add --body sphere",
                                 param_hint="--held-radius")
    _options.segmenter(segmenter, detector, detector_dir, sam_dir)
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
        obstacles=list(obstacles) if obstacles else None, guidance=guidance, rho=rho, last_steps=last_steps,
        per_train_step=per_train_step, metric_gradient=metric_push, densify=densify, scheduler=scheduler, steps=steps,
        checked=checked, margin=margin, obstacle_shape=obstacle_shape,
        body=body, obstacle_scenes_only=obstacle_scenes_only, refit_obstacles=refit_obstacles,
        guide_when_needed=guide_when_needed,
        held_radius=held_radius, max_steps=max_steps, workers=workers,
        video_dir=str(video_dir) if video_dir else None, n_videos=n_videos, seed=seed, out=str(out),
        segmenter=segmenter, detector=detector, detector_dir=str(detector_dir) if detector_dir else None,
        sam_dir=str(sam_dir) if sam_dir else None, env=env)
    console.print(f"[bold]eval[/bold] {checkpoint} on {task or '(dataset task)'} / {variation}"
                  + (f" in {env}" if env else "") + f": {episodes} episodes, "
                  f"guidance {guidance}" + (f" rho={rho} S={last_steps}" if guidance != "none" else "")
                  + f", {workers} worker(s)")
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
