"""`lano3dp run "<instruction>"`: plan -> perception -> guided policy -> one simulated episode."""

from __future__ import annotations

from pathlib import Path

import typer

from lano3dp.cli import _options


def register(app: typer.Typer) -> None:
    app.command("run")(run_command)


def run_command(
    ctx: typer.Context,
    instruction: str = typer.Argument(..., help='e.g. "pour the bowl into the pan and keep clear of the obstacle"'),
    checkpoint: Path = typer.Option(None, "--checkpoint", "-c", help="Policy to run (default: from --registry, "
                                                                     "else the one packaged for the skill)."),
    registry: Path = typer.Option(None, help="Skill registry JSON naming a checkpoint per skill."),
    task: str = typer.Option(None, help="Simulator task (default: the plan's skill)."),
    variation: str = typer.Option(None, help="Scene variation (default: obstacle if the plan names obstacles)."),
    guidance: str = typer.Option("clean", help="none | noisy | clean (the paper's A_0|k guidance)."),
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
    compare: bool = typer.Option(False, help="Also run the same scene without guidance (both paths in the plot)."),
    max_steps: int = typer.Option(None, help="Episode step limit (default: the task's)."),
    seed: int = typer.Option(1_000_000, help="Scene seed."),
    segmenter: str = _options.SEGMENTER,
    detector: str = _options.DETECTOR,
    detector_dir: Path = _options.DETECTOR_DIR,
    sam_dir: Path = _options.SAM_DIR,
    image_size: int = _options.IMAGE_SIZE,
    env: str = typer.Option(None, "--env", help=_options.ENV_HELP),
    out: Path = typer.Option(Path("run_out"), help="Folder for run.json, video_*.mp4 and top_view.png."),
) -> None:
    """Run one instruction in the simulator and show what happened (plan, outcome, video, top-view plot)."""
    from rich.console import Console

    from lano3dp.cli import _options
    from lano3dp.cli.eval_cmd import command_line
    from lano3dp.evaluate import RunConfig, run_instruction

    console = Console()
    guidance_settings, obstacle, perception = _options.episode_settings(ctx.params)
    _options.existing_path(checkpoint, "--checkpoint")
    _options.existing_path(registry, "--registry")
    _options.output_path(out, folder=True)
    config = RunConfig(instruction=instruction, checkpoint=str(checkpoint) if checkpoint else None,
                       registry=str(registry) if registry else None, task=task, variation=variation,
                       guidance=guidance_settings, obstacle=obstacle, perception=perception, scheduler=scheduler,
                       steps=steps, compare=compare, max_steps=max_steps, seed=seed, out=str(out), env=env)
    result = run_instruction(config, log=console.print, command=command_line(ctx))
    console.print(f"video(s): {', '.join(e['video'] for e in result['episodes'].values())}")
    console.print(f"top view: {result['top_view']}   record: {Path(out) / 'run.json'}")
