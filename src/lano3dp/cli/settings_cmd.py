"""`lano3dp settings`: the guidance presets and every setting `--set` can change, with each preset's values."""

from __future__ import annotations

from pathlib import Path

import typer


def register(app: typer.Typer) -> None:
    app.command("settings")(settings_command)


def settings_command(
    preset: str = typer.Option("recommended", "--guidance-preset", metavar="NAME",
                               help="The preset to show (tuned: a checkpoint's own; give --checkpoint)."),
    checkpoint: Path = typer.Option(None, "--checkpoint", "-c", help="With tuned: the policy folder whose tuning "
                                                                     "to show."),
) -> None:
    """Show a guidance preset as the settings tree `--set guidance.<path>=VALUE` changes, and what else exists."""
    import yaml

    from lano3dp.cli import _options
    from lano3dp.config_tree import SettingsError, to_dict
    from lano3dp.guidance.execution import chunk_filter_names
    from lano3dp.guidance.settings import TUNED, load_guidance_tuning, preset_names, resolve_guidance
    from lano3dp.guidance.shapes import obstacle_shape_names

    _options.existing_path(checkpoint, "--checkpoint")
    tuning = load_guidance_tuning(checkpoint) if preset == TUNED and checkpoint is not None else None
    try:
        settings = resolve_guidance(preset, None, tuning)
    except SettingsError as error:
        raise typer.BadParameter(str(error), param_hint="--guidance-preset") from None
    source = f" (from {checkpoint}: {tuning.preset} + {tuning.overrides})" if tuning else ""
    typer.echo(f"# guidance preset {preset}{source}; change a field with --set guidance.<section>.<field>=VALUE")
    typer.echo(yaml.safe_dump(to_dict(settings), sort_keys=False).rstrip())
    typer.echo(f"# presets: {', '.join(preset_names())}")
    typer.echo(f"# chunk filters (guidance.execution.filters): {', '.join(chunk_filter_names())}")
    typer.echo(f"# obstacle shapes (guidance.obstacles.shape): {', '.join(obstacle_shape_names())}")
