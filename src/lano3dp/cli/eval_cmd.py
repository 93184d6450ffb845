"""`lano3dp eval`: closed-loop rollouts of a checkpoint in the simulator, to a results JSON."""

from __future__ import annotations

from pathlib import Path

import typer

from lano3dp.cli import _options


def register(app: typer.Typer) -> None:
    app.command("eval")(eval_command)


# option parameter -> its path in EvalConfig
EVAL_FIELDS = {"checkpoint": "checkpoint", "task": "task", "variation": "variation", "episodes": "episodes",
               "seed": "seed", "guidance_preset": "guidance.preset", "workers": "workers", "batch": "batch",
               "env": "env",
               "obstacles": "obstacles", "obstacle_scenes_only": "obstacle_scenes_only", "max_steps": "max_steps",
               "success_at": "success_at", "video_dir": "video_dir", "n_videos": "n_videos", "rerun": "rerun_dir",
               "segmenter": "perception.segmenter", "detector": "perception.detector",
               "detector_dir": "perception.detector_dir", "sam_dir": "perception.sam_dir",
               "image_size": "perception.image_size"}
RESULTS_NAME = "results.json"


def eval_command(
    ctx: typer.Context,
    checkpoint: Path = typer.Option(None, "--checkpoint", "-c", help="Policy folder or training run (default: the "
                                                                     "policy packaged for --task)."),
    task: str = typer.Option(None, help="Task (default: the checkpoint's; `lano3dp tasks` lists them)."),
    variation: str = typer.Option("clean", help="clean, or axes joined by '+' (`lano3dp tasks` lists them)."),
    episodes: int = typer.Option(20, min=1, help="Episodes: seeds --seed, --seed + 1, ..."),
    seed: int = typer.Option(1_000_000, help="First episode seed."),
    guidance_preset: str = typer.Option("none", "--guidance-preset", metavar="NAME", help=_options.PRESET_HELP),
    out: Path = typer.Option(None, help="Results JSON (default: in a new `outputs/eval/DATE_TIME/`); a killed eval "
                                        "resumes from `OUT.episodes.jsonl`."),
    overwrite: bool = typer.Option(False, "--overwrite", help=_options.OVERWRITE_HELP),
    workers: int = typer.Option(1, min=1, help="Parallel episode processes."),
    set_: _options.SetOption = None,
    config: _options.ConfigOption = None,
    segmenter: _options.SegmenterOption = "sim",
    detector: _options.DetectorOption = "grounding_dino",
    detector_dir: _options.DetectorDirOption = None,
    sam_dir: _options.SamDirOption = None,
    image_size: _options.ImageSizeOption = None,
    env: str = typer.Option(None, "--env", help=_options.ENV_HELP, rich_help_panel=_options.PANEL_ADVANCED),
    batch: int = typer.Option(1, min=1, help="Episodes stepped together in one process, their chunks sampled in "
                                             "one call (1.8-3.3x the episodes per CPU-second at 16 to 50 in the "
                                             "runs measured, by CPU).",
                              rich_help_panel=_options.PANEL_ADVANCED),
    obstacles: list[str] = typer.Option(None, "--obstacles", help="Object to avoid (repeatable; default: every "
                                                                  "object the scene marks as an obstacle).",
                                        rich_help_panel=_options.PANEL_ADVANCED),
    obstacle_scenes_only: bool = typer.Option(False, "--obstacle-scenes-only",
                                              help="With an obstacle variation: the first --episodes seeds whose "
                                                   "scene has room for its obstacles.",
                                              rich_help_panel=_options.PANEL_ADVANCED),
    max_steps: int = typer.Option(None, min=1, help="Episode step limit (default: the task's).",
                                  rich_help_panel=_options.PANEL_ADVANCED),
    success_at: str = typer.Option("first", "--success-at", help="first: success at any step ends the episode | "
                                                                 "end: success at the episode's last step (as "
                                                                 "benchmarks such as Fetch count it).",
                                   rich_help_panel=_options.PANEL_ADVANCED),
    video_dir: Path = typer.Option(None, help="MP4s of the first --n-videos episodes here.",
                                   rich_help_panel=_options.PANEL_ADVANCED),
    n_videos: int = typer.Option(2, min=0, help="How many episodes get a video.",
                                 rich_help_panel=_options.PANEL_ADVANCED),
    rerun: Path = typer.Option(None, "--rerun", metavar="DIR", help="A Rerun recording (.rrd) of every episode here "
                                                                    "(needs lano3dp[viewer]).",
                                   rich_help_panel=_options.PANEL_ADVANCED),
) -> None:
    """Evaluate a policy: success, obstacle contacts, minimum clearance, path length and latency per chunk."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from lano3dp.cli import console as make_console
    from lano3dp.evaluation import EvalConfig, evaluate
    from lano3dp.evaluation.results import episode_log_path

    console = make_console(stderr=True)
    _options.env_factory(env)  # imported first: it may register plug-ins the settings name
    if env is None:  # a user's env has its own task names and variations
        _options.task_name(task)
        _options.variation(variation)
    _options.existing_path(checkpoint, "--checkpoint")
    _options.existing_path(config, "--config")
    data = _options.settings_options(ctx, EVAL_FIELDS)
    if out is None and data.get("out") and Path(data["out"]).exists() and not overwrite:
        raise typer.BadParameter(f"{data['out']} (the --config's out) holds a finished evaluation; pass --overwrite "
                                 "to replace it, or another --out", param_hint="--config")
    if out is None and not data.get("out"):
        out = _options.run_folder(None, "eval", overwrite=overwrite, marker=RESULTS_NAME) / RESULTS_NAME
    elif out is not None and out.exists() and not out.is_dir() and not overwrite:
        raise typer.BadParameter(f"{out} holds a finished evaluation; pass --overwrite to replace it, or another "
                                 "--out", param_hint="--out")
    if out is not None:
        _options.output_path(out, folder=False)
        data["out"] = str(out)
        if overwrite:
            out.unlink(missing_ok=True)
            episode_log_path(out).unlink(missing_ok=True)
    _options.output_path(video_dir, "--video-dir", folder=True)
    config_ = _options.build_config(EvalConfig, data)
    if config_.checkpoint is None and config_.task is None:
        raise typer.BadParameter("give --checkpoint, or --task to evaluate the policy packaged for it",
                                 param_hint="--checkpoint")
    console.print(f"[bold]eval[/bold] {config_.checkpoint or f'the policy packaged for {config_.task}'} on "
                  f"{config_.task or '(its task)'} / {config_.variation}"
                  + (f" in {config_.env}" if config_.env else "")
                  + f": {config_.episodes} episodes, guidance {config_.guidance.preset}"
                  + (f" with {config_.guidance.overrides}" if config_.guidance.overrides else "")
                  + f", {config_.workers} worker(s)")
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  TextColumn("{task.fields[status]}"), console=console) as bar:
        handle = bar.add_task("episodes", total=config_.episodes, status="")
        successes = collisions = 0

        def progress(done: int, total: int, record: dict) -> None:
            nonlocal successes, collisions
            successes += bool(record["success"])
            collisions += bool(record["collided"])
            bar.update(handle, completed=done, status=f"success {successes}/{done}  collided {collisions}/{done}")

        result = evaluate(config_, progress=progress, command=command_line(ctx))
    if result["timing"]["resumed_episodes"]:
        console.print(f"resumed {result['timing']['resumed_episodes']} finished episode(s) from "
                      f"{episode_log_path(config_.out)}")
    console.print(summary_line(result["summary"]))
    summary = result["summary"]
    if summary.get("stage_rates"):
        console.print(stage_line(summary))
    if summary["errors"]:
        console.print(f"[yellow]episodes ended by errors:[/yellow] {', '.join(summary['errors'])}")
    for note in result.get("notes", []):
        console.print(f"[yellow]note:[/yellow] {note}")
    console.print(f"results: {config_.out}")


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

    parts = ["lano3dp", ctx.info_name or ""]
    for param in ctx.command.params:
        value = ctx.params.get(param.name)
        if value is None or value == param.default or (param.multiple and not value):
            continue
        if param.param_type_name == "argument":
            parts.append(str(value))
        elif getattr(param, "is_flag", False):
            parts.append(param.opts[0] if value else (param.secondary_opts or param.opts)[0])
        elif param.multiple:
            for item in value:
                parts += [param.opts[0], str(item)]
        else:
            parts += [param.opts[0], str(value)]
    return shlex.join(parts)
