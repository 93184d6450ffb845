"""`lano3dp migrate PATH ...`: convert policy folders and results files of earlier versions (docs/compat.md)."""

from __future__ import annotations

from pathlib import Path

import typer


def register(app: typer.Typer) -> None:
    app.command("migrate")(migrate_command)


def migrate_command(paths: list[Path] = typer.Argument(..., help="Policy folders, training runs, folders holding "
                                                                 "them, or results JSON files.")) -> None:
    """Convert files written by earlier versions into today's formats, in place (files already current stay)."""
    from lano3dp.cli import _options
    from lano3dp.migrate import migrate

    for path in paths:
        _options.existing_path(path, "PATH")
    changed = migrate(paths)
    for line in changed:
        typer.echo(line)
    typer.echo(f"{len(changed)} change(s)" if changed else "nothing to convert: every file is current")
