"""`lano3dp collect` (scripted-expert demonstrations) and `lano3dp video` (an expert episode as a video)."""

from __future__ import annotations

from pathlib import Path

import typer


def collect_command(
    task: str = typer.Option(..., "--task", help="Task name, e.g. bowl_pour (see `lano3dp tasks`)."),
    episodes: int = typer.Option(40, "--episodes", min=1, help="Episodes the dataset should hold; an existing dataset "
                                                        "at --out is resumed and only missing ones are added."),
    out: Path = typer.Option(..., "--out", help="Zarr dataset folder to create or append to."),
    variation: str = typer.Option("clean", "--variation", help="Variation axes joined by '+' (clean, clutter, "
                                                               "similar, instance, camera, background, obstacle)."),
    seed: int = typer.Option(0, "--seed", help="Base seed; episode i uses seed + i (a failed expert seed is "
                                               "replaced by seed + i + k * 100003)."),
    image_size: int = typer.Option(128, "--image-size", min=16, help="Camera image side in pixels."),
    n_points: int = typer.Option(64, "--n-points", min=1,
                                 help="Points per object cloud (the default policy trains on 64; record more to "
                                      "train on more)."),
    dart_noise: float = typer.Option(0.0, "--dart-noise", min=0.0, max=0.1,
                                     help="Noise injection (DART): spread (m) of a smooth offset added to the "
                                          "executed positions while the expert's own actions are recorded."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Show a progress bar."),
) -> None:
    """Record scripted-expert demonstrations (only successful episodes are kept) into a zarr dataset."""
    from lano3dp.cli import _options
    from lano3dp.data.collect import collect

    _options.task_name(task)
    _options.variation(variation)
    _options.output_path(out, folder=True)
    result = collect(task, episodes, out, variation=variation, seed=seed, image_size=image_size,
                     n_points=n_points, dart_noise=dart_noise, progress=progress)
    failed = f", {len(result.failed_seeds)} expert failures skipped (seeds {result.failed_seeds})" \
        if result.failed_seeds else ""
    typer.echo(f"{result.path}: added {result.added} episodes ({result.steps} steps) in {result.seconds:.1f} s; "
               f"holds {result.total}{failed}")


def video_command(
    task: str = typer.Option(..., "--task", help="Task name."),
    out: Path = typer.Option(..., "--out", help="Output file, .mp4 or .gif."),
    seed: int = typer.Option(0, "--seed", help="Episode seed."),
    variation: str = typer.Option("clean", "--variation", help="Variation axes joined by '+'."),
    image_size: int = typer.Option(256, "--image-size", min=16, help="Frame side in pixels."),
    camera: str = typer.Option("front", "--camera", help="front (training) or shifted."),
) -> None:
    """Write a video of the scripted expert solving one episode."""
    from lano3dp.cli import _options
    from lano3dp.sim.video import record_expert_video

    _options.task_name(task)
    _options.variation(variation)
    _options.choice(camera, ("front", "shifted"), "--camera")
    _options.output_path(out, folder=False)
    if out.suffix not in (".mp4", ".gif"):
        raise typer.BadParameter(f"{out} must end in .mp4 or .gif", param_hint="--out")

    summary = record_expert_video(task, out, seed=seed, variation=variation, image_size=image_size, camera=camera)
    typer.echo(f"{summary['path']}: {summary['task']} seed {summary['seed']} ({summary['variation']}), "
               f"{summary['steps']} steps, success={summary['success']}: {summary['instruction']!r}")


def tasks_command() -> None:
    """List the simulated tasks with their skill, object slots and instruction."""
    from lano3dp.sim.tasks import TASKS

    for name in sorted(TASKS):
        cls = TASKS[name]
        typer.echo(f"{name:20s} skill={cls.skill:10s} slots={','.join(cls.object_slots):24s} {cls.instruction}")


def register(app: typer.Typer) -> None:
    app.command("collect")(collect_command)
    app.command("video")(video_command)
    app.command("tasks")(tasks_command)
