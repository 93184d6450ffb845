"""Placeholder until its owner lands the command."""

import typer


def register(app: typer.Typer) -> None:
    pass
