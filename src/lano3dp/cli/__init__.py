"""The `lano3dp` command line. Each sub-module registers its commands; heavy imports
(torch, mujoco, transformers) happen inside the commands so `--help` stays fast. Errors pass one
boundary (`_boundary.ErrorBoundaryGroup`): a user's mistake is one red line, exit 1 (2 for usage)."""

from __future__ import annotations

import importlib
import os
import sys
from typing import TYPE_CHECKING

import typer

from lano3dp.cli._boundary import ErrorBoundaryGroup

app = typer.Typer(
    cls=ErrorBoundaryGroup,
    name="lano3dp",
    help="Language-guided, object-centric 3D diffusion policies with cost-guided obstacle avoidance.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
    # Markdown, not rich markup: help strings then keep their brackets ("[embeddings]", "[repair, hold]"); the
    # panels (basic options first) stay
    rich_markup_mode="markdown",
)

if TYPE_CHECKING:
    from rich.console import Console

_COMMAND_MODULES = ("train_cmd", "collect_cmd", "plan_cmd", "guidance_cmd", "eval_cmd", "run_cmd", "demo_cmd",
                    "settings_cmd", "migrate_cmd", "checkpoint_cmd")


@app.callback()
def _global_options(ctx: typer.Context,
                    debug: bool = typer.Option(False, "--debug", help="Show the Python traceback of an error (also: "
                                                               "LANO3DP_DEBUG=1).")) -> None:
    ctx.obj = {"debug": debug}


for _module in _COMMAND_MODULES:
    importlib.import_module(f"lano3dp.cli.{_module}").register(app)


@app.command()
def version() -> None:
    """Print the versions of lano3dp and the libraries it runs on."""
    from lano3dp.data.store import library_versions

    for name, value in library_versions().items():
        typer.echo(f"{name} {value}")


def console(stderr: bool = False) -> Console:
    """A rich console for a command's output that wraps lines only on a terminal: written to a file or a pipe
    (a log), a long line stays one line instead of being broken at rich's default of 80 columns."""
    from rich.console import Console

    return Console(stderr=stderr, soft_wrap=not (sys.stderr if stderr else sys.stdout).isatty())


def main() -> None:
    # One torch thread unless the user says otherwise: sampling at batch 1 gains nothing from a second thread,
    # and on a busy 2-core machine two threads ran 11 times slower (train takes --threads to set its own). Set
    # before any command imports torch, which reads it once.
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    app()
