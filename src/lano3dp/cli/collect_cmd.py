"""`lano3dp collect` (scripted-expert demonstrations) and `lano3dp video` (an expert episode as a video)."""

from __future__ import annotations

from pathlib import Path

import typer

_ENV_HELP = ("Your own simulator or robot: module:factory or path/to/file.py:factory (called as `lano3dp eval` "
             "calls it), returning an env meeting lano3dp.sim.protocol (default: the built-in simulator).")


def _names(text: str) -> list[str]:
    names = [name.strip() for name in text.split(",") if name.strip()]
    if not names:
        raise typer.BadParameter("give slot names separated by commas, e.g. block,drawer", param_hint="--slots")
    return names


def _point(text: str | None, option: str) -> tuple[float, float, float] | None:
    if text is None:
        return None
    try:
        point = tuple(float(v) for v in text.split(","))
    except ValueError:
        point = ()
    if len(point) != 3:
        raise typer.BadParameter(f"{text!r}: give x,y,z in metres, e.g. -0.5,-0.5,0.0", param_hint=option)
    return point


def collect_command(
    task: str = typer.Option(None, "--task", help="Task name, e.g. bowl_pour (see `lano3dp tasks`); with --env, the "
                                                  "name the dataset and its policy carry (default: the env's)."),
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
    follow_through: float = typer.Option(1.0, "--follow-through", min=0.0, max=10.0,
                                         help="Seconds recorded past the first success frame, while success "
                                              "holds (0: end there; an env must then accept steps after "
                                              "reporting success)."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Show a progress bar."),
    env: str = typer.Option(None, "--env", help=_ENV_HELP),
    expert: str = typer.Option(None, "--expert", help="With --env: module:callable or path/to/file.py:callable, "
                                                      "expert(env, obs, info) -> action (10,), called every step "
                                                      "(a class is instantiated once; its reset(env, obs, info) "
                                                      "runs after each env reset). Default: env.expert_plan()."),
    slots: str = typer.Option(None, "--slots", help="With --env: the policy's object slots, comma-separated "
                                                    "(e.g. block,drawer); default: env.task.object_slots."),
    control_hz: float = typer.Option(None, "--control-hz", min=0.0, help="With --env: its control rate "
                                                                         "(default: env.control_hz)."),
    max_steps: int = typer.Option(None, "--max-steps", min=1, help="Step limit of an expert episode "
                                                                   "(default: the task's or env.max_steps)."),
    table_height: float = typer.Option(0.0, "--table-height", help="World z (m) of the table top."),
    crop_low: str = typer.Option(None, "--crop-low", help="With --env: x,y,z (m) of the cloud crop box's low "
                                                          "corner (default: no crop)."),
    crop_high: str = typer.Option(None, "--crop-high", help="With --env: x,y,z (m) of its high corner."),
) -> None:
    """Record expert demonstrations (only successful episodes are kept) into a zarr dataset."""
    from lano3dp.cli import _options
    from lano3dp.collect import collect, collect_from_env

    _options.output_path(out, folder=True, kind="dataset")
    if env is None:
        if task is None:
            raise typer.BadParameter("give a task of the built-in simulator, or --env", param_hint="--task")
        if any(v is not None for v in (expert, slots, control_hz, crop_low, crop_high)):
            raise typer.BadParameter("--expert, --slots, --control-hz and --crop-low/high need --env",
                                     param_hint="--env")
        _options.task_name(task)
        _options.variation(variation)
        result = collect(task, episodes, out, variation=variation, seed=seed, image_size=image_size,
                         n_points=n_points, dart_noise=dart_noise, progress=progress, max_steps=max_steps,
                         table_height=table_height, follow_through_s=follow_through)
    else:
        _options.env_factory(env)
        _options.env_factory(expert, "--expert")
        if (crop_low is None) != (crop_high is None):
            raise typer.BadParameter("give both --crop-low and --crop-high, or neither", param_hint="--crop-low")
        result = collect_from_env(env, expert, episodes, out, task=task, variation=variation, seed=seed,
                                  image_size=image_size, n_points=n_points, progress=progress,
                                  slots=None if slots is None else _names(slots), control_hz=control_hz,
                                  max_steps=max_steps, table_height=table_height, follow_through_s=follow_through,
                                  crop_low=_point(crop_low, "--crop-low"), crop_high=_point(crop_high, "--crop-high"))
    failed = f", {len(result.failed_seeds)} expert failures skipped (seeds {result.failed_seeds})" \
        if result.failed_seeds else ""
    if result.unseen_seeds:
        failed += (f", {len(result.unseen_seeds)} seeds skipped with an object out of view in the first frame "
                   f"(seeds {result.unseen_seeds})")
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
    """List the simulated tasks: object slots (the policy's inputs, in order), the variation axes that change
    their scenes (`--variation`), and their instruction."""
    from lano3dp.sim.tasks import TASKS
    from lano3dp.sim.variations import OBSTACLE_KINDS, VARIATION_AXES

    def axes(cls) -> str:  # "similar" adds look-alikes of the similar_slots: a task without any has no such scenes
        return ",".join(a for a in VARIATION_AXES if a != "similar" or cls.similar_slots)

    rows = [("task", "object slots", "variations", "instruction")]
    rows += [(name, ",".join(TASKS[name].object_slots), axes(TASKS[name]), TASKS[name].instruction)
             for name in sorted(TASKS)]
    widths = [max(len(row[column]) for row in rows) for column in range(3)]
    for row in rows:
        typer.echo("  ".join([*(cell.ljust(width) for cell, width in zip(row[:3], widths, strict=True)), row[3]]))
    kinds = ", ".join(f"obstacle:{kind}" for kind in OBSTACLE_KINDS)
    typer.echo(f"\nclean (the default) is none of them; axes combine with '+' (clutter+camera); obstacle takes "
               f"modifiers: a count (obstacle:2), a kind ({kinds}) and obstacle:moving.")


def register(app: typer.Typer) -> None:
    app.command("collect")(collect_command)
    app.command("video")(video_command)
    app.command("tasks")(tasks_command)
