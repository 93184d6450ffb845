"""`lano3dp run "<instruction>"`: plan -> perception -> guided policy -> episodes in a few simulated scenes."""

from __future__ import annotations

from pathlib import Path

import typer

from lano3dp.cli import _options

# option parameter -> its path in RunConfig
RUN_FIELDS = {"instruction": "instruction", "checkpoint": "checkpoint", "scenes": "scenes", "compare": "compare",
              "guidance_preset": "guidance.preset", "llm": "llm", "registry": "registry", "task": "task",
              "variation": "variation", "seed": "seed", "max_steps": "max_steps", "env": "env", "rerun": "rerun_dir",
              "segmenter": "perception.segmenter", "detector": "perception.detector",
              "detector_dir": "perception.detector_dir", "sam_dir": "perception.sam_dir",
              "image_size": "perception.image_size"}
RUN_RECORD = "run.json"


def register(app: typer.Typer) -> None:
    app.command("run")(run_command)


def run_command(
    ctx: typer.Context,
    instruction: str = typer.Argument(..., help='e.g. "pour the bowl into the pan and keep clear of the mug"'),
    checkpoint: Path = typer.Option(None, "--checkpoint", "-c", help="Policy to run (default: from --registry, "
                                                                     "else the one packaged for the skill)."),
    scenes: int = typer.Option(1, min=1, help="Scenes to run in: the first from --seed with room for the "
                                              "instruction's obstacles; the first keeps its videos and top view."),
    compare: bool = typer.Option(False, "--compare", help="Also run every scene without guidance."),
    guidance_preset: str = typer.Option("tuned", "--guidance-preset", metavar="NAME", help=_options.PRESET_HELP),
    llm: bool = typer.Option(False, "--llm", help="Plan with an OpenAI-compatible LLM (LANO3DP_LLM_BASE_URL / "
                                                  "_MODEL / _API_KEY), the offline parser as its fallback."),
    out: Path = typer.Option(None, help="Folder for run.json, the videos and top_view.png (default: a new "
                                        "`outputs/run/DATE_TIME/`)."),
    overwrite: bool = typer.Option(False, "--overwrite", help=_options.OVERWRITE_HELP),
    set_: _options.SetOption = None,
    config: _options.ConfigOption = None,
    segmenter: _options.SegmenterOption = "sim",
    detector: _options.DetectorOption = "grounding_dino",
    detector_dir: _options.DetectorDirOption = None,
    sam_dir: _options.SamDirOption = None,
    image_size: _options.ImageSizeOption = None,
    registry: Path = typer.Option(None, help="Skill registry JSON naming a checkpoint per skill.",
                                  rich_help_panel=_options.PANEL_ADVANCED),
    map_: list[str] = typer.Option(None, "--map", metavar="PHRASE=OBJECT",
                                   help="Ground a phrase on this scene object (repeatable), e.g. teapot=block; a "
                                        "target the scene lacks is otherwise an error, never replaced.",
                                   rich_help_panel=_options.PANEL_ADVANCED),
    task: str = typer.Option(None, help="Simulator task (default: the plan's skill).",
                             rich_help_panel=_options.PANEL_ADVANCED),
    variation: str = typer.Option(None, help="Scene variation (default: obstacle if the plan names obstacles).",
                                  rich_help_panel=_options.PANEL_ADVANCED),
    seed: int = typer.Option(1_000_000, help="First scene seed.", rich_help_panel=_options.PANEL_ADVANCED),
    max_steps: int = typer.Option(None, min=1, help="Episode step limit (default: the task's).",
                                  rich_help_panel=_options.PANEL_ADVANCED),
    env: str = typer.Option(None, "--env", help=_options.ENV_HELP, rich_help_panel=_options.PANEL_ADVANCED),
    rerun: Path = typer.Option(None, "--rerun", metavar="DIR", help="A Rerun recording (.rrd) of every episode here "
                                                                    "(needs lano3dp[viewer]).",
                               rich_help_panel=_options.PANEL_ADVANCED),
) -> None:
    """Run one instruction in the simulator and show what happened (plan, outcomes, videos, top view)."""
    from lano3dp.cli import console as make_console
    from lano3dp.cli.eval_cmd import command_line
    from lano3dp.evaluation import RunConfig, run_instruction

    console = make_console()
    _options.env_factory(env)
    if env is None:
        _options.task_name(task)
        _options.variation(variation)
    _options.existing_path(checkpoint, "--checkpoint")
    _options.existing_path(registry, "--registry")
    _options.existing_path(config, "--config")
    data = _options.settings_options(ctx, RUN_FIELDS)
    for pair in map_ or ():
        phrase, sep, scene_object = pair.partition("=")
        if not sep or not phrase.strip() or not scene_object.strip():
            raise typer.BadParameter(f"{pair!r}: write it as PHRASE=OBJECT, e.g. teapot=block", param_hint="--map")
        data.setdefault("mapping", {})[phrase.strip()] = scene_object.strip()
    folder = _options.run_folder(out if out is not None else (Path(data["out"]) if data.get("out") else None), "run",
                                 overwrite=overwrite, marker=RUN_RECORD)
    _options.output_path(folder, folder=True)
    data["out"] = str(folder)
    config_ = _options.build_config(RunConfig, data)
    result = run_instruction(config_, log=console.print, command=command_line(ctx))
    console.print(f"videos and top view of scene {result['scenes'][0]['seed']}: {folder}   record: "
                  f"{folder / RUN_RECORD}")
