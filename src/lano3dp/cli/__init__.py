"""The `lano3dp` command line. Each sub-module registers its commands; heavy imports
(torch, mujoco, transformers) happen inside the commands so `--help` stays fast. Errors pass one
boundary (`_boundary.ErrorBoundaryGroup`): a user's mistake is one red line, exit 1 (2 for usage)."""

from __future__ import annotations

import importlib

import typer

from lano3dp.cli._boundary import ErrorBoundaryGroup

app = typer.Typer(
    cls=ErrorBoundaryGroup,
    name="lano3dp",
    help="Language-guided, object-centric 3D diffusion policies with cost-guided obstacle avoidance.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)

_COMMAND_MODULES = ("train_cmd", "collect_cmd", "plan_cmd", "guidance_cmd", "eval_cmd", "run_cmd", "demo_cmd")


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


def main() -> None:
    app()
