"""`lano3dp run "<instruction>"`: plan -> perception -> guided policy -> one simulated episode."""

from __future__ import annotations

from pathlib import Path

import typer

from lano3dp.cli import _options
from lano3dp.evaluate import DEFAULT_LAST_STEPS, DEFAULT_RHO


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
    rho: float = typer.Option(DEFAULT_RHO, help="Guidance scale rho (metres per guided step with --metric-push)."),
    last_steps: int = typer.Option(DEFAULT_LAST_STEPS, help="Guide while the training-scale step k <= S (100: all)."),
    metric_push: bool = typer.Option(True, "--metric-push/--paper-push",
                                     help="Push isotropically in metres, or as the paper in normalised action units "
                                          "(which needs a far larger rho)."),
    scheduler: str = typer.Option(None, help="ddpm | ddim (default: the policy's)."),
    steps: int = typer.Option(None, help="Denoising steps (default: the policy's)."),
    checked: bool = typer.Option(False, help="Checked execution: re-sample with larger rho while a chunk collides."),
    obstacle_shape: str = typer.Option("cylinder", "--obstacle-shape", metavar="NAME",
                                       help=_options.obstacle_shape_help()),
    compare: bool = typer.Option(False, help="Also run the same scene without guidance (both paths in the plot)."),
    max_steps: int = typer.Option(None, help="Episode step limit (default: the task's)."),
    seed: int = typer.Option(1_000_000, help="Scene seed."),
    segmenter: str = typer.Option("sim", help=_options.SEGMENTER_HELP),
    detector: str = typer.Option("grounding_dino", help="open-vocab: grounding_dino | owlv2."),
    detector_dir: Path = typer.Option(None, help=_options.DETECTOR_DIR_HELP),
    sam_dir: Path = typer.Option(None, help=_options.SAM_DIR_HELP),
    env: str = typer.Option(None, "--env", help=_options.ENV_HELP),
    out: Path = typer.Option(Path("run_out"), help="Folder for run.json, video_*.mp4 and top_view.png."),
) -> None:
    """Run one instruction in the simulator and show what happened (plan, outcome, video, top-view plot)."""
    from rich.console import Console

    from lano3dp.cli import _options
    from lano3dp.cli.eval_cmd import command_line
    from lano3dp.evaluate import RunConfig, run_instruction

    console = Console()
    _options.env_factory(env)
    if env is None:  # a user's env has its own task names and variations
        _options.task_name(task)
        _options.variation(variation)
    _options.choice(guidance, _options.GUIDANCE_MODES, "--guidance")
    _options.choice(scheduler, _options.SCHEDULERS, "--scheduler")
    _options.obstacle_shape(obstacle_shape)
    _options.segmenter(segmenter, detector, detector_dir, sam_dir)
    _options.existing_path(checkpoint, "--checkpoint")
    _options.existing_path(registry, "--registry")
    _options.output_path(out, folder=True)
    config = RunConfig(instruction=instruction, checkpoint=str(checkpoint) if checkpoint else None,
                       registry=str(registry) if registry else None, task=task, variation=variation,
                       guidance=guidance, rho=rho, last_steps=last_steps, metric_gradient=metric_push,
                       scheduler=scheduler, steps=steps,
                       checked=checked, obstacle_shape=obstacle_shape, compare=compare, max_steps=max_steps,
                       seed=seed, out=str(out),
                       segmenter=segmenter, detector=detector,
                       detector_dir=str(detector_dir) if detector_dir else None,
                       sam_dir=str(sam_dir) if sam_dir else None, env=env)
    result = run_instruction(config, log=console.print, command=command_line(ctx))
    console.print(f"video(s): {', '.join(e['video'] for e in result['episodes'].values())}")
    console.print(f"top view: {result['top_view']}   record: {Path(out) / 'run.json'}")
