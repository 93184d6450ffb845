"""The command line's one error boundary: a user's mistake is one red line and an exit code, never a traceback.

    exit 1   lano3dp's own errors (Lano3dpError) and bad input met while working: an unknown name
             (KeyError), a bad value (ValueError), a missing, existing or unwritable file (OSError), and the
             storage and serialisation errors of the libraries lano3dp reads and writes files with
             (safetensors, zarr, imageio / ffmpeg, Pillow, json), which are not all OSErrors: a full disk under
             safetensors is a SafetensorError. lano3dp's own writers name the file (`errors.StorageError`);
             this catches what reaches the boundary unwrapped, and names the library.
    exit 2   usage errors: an option that fails validation before any work starts (click / typer.BadParameter)

`lano3dp --debug <command>` (or LANO3DP_DEBUG=1) re-raises instead, with the traceback. Any other
exception is a bug in lano3dp and keeps its traceback.
"""

from __future__ import annotations

import os
import sys

import typer
from typer.core import TyperGroup

try:  # recent typer carries its own copy of click, whose exceptions are not the `click` package's
    from typer._click.exceptions import ClickException
except ImportError:  # pragma: no cover
    from click import ClickException

from lano3dp.errors import Lano3dpError

USER_ERRORS: tuple[type[BaseException], ...] = (Lano3dpError, KeyError, ValueError, OSError)
# top-level module of an exception's class -> the library named in its line (matched by module, so the boundary
# imports none of them)
STORAGE_LIBRARIES = {"safetensors": "safetensors", "zarr": "zarr", "numcodecs": "zarr", "imageio": "imageio",
                     "imageio_ffmpeg": "ffmpeg", "PIL": "Pillow", "json": "json"}


def storage_library(error: BaseException) -> str | None:
    """The file library that raised `error` (by its class's module), or None."""
    return STORAGE_LIBRARIES.get(type(error).__module__.split(".")[0])


def is_user_error(error: BaseException) -> bool:
    return isinstance(error, USER_ERRORS) or storage_library(error) is not None


def error_line(error: BaseException) -> str:
    """The one line printed for a user error: its message, prefixed with the library for a library's own error."""
    library = storage_library(error)
    return f"{library}: {one_line(error)}" if library and not isinstance(error, Lano3dpError) else one_line(error)


def one_line(error: BaseException) -> str:
    """The message of an error on one line (KeyError's str() adds quotes; multi-line texts are joined)."""
    text = error.args[0] if isinstance(error, KeyError) and error.args and isinstance(error.args[0], str) \
        else str(error)
    text = " ".join(part.strip() for part in text.splitlines() if part.strip())
    return text or type(error).__name__


def print_error(message: str) -> None:
    typer.secho(f"error: {message}", fg=typer.colors.RED, err=True)


def debugging(ctx: typer.Context | None = None) -> bool:
    root = ctx.find_root() if ctx is not None else None
    return bool(os.environ.get("LANO3DP_DEBUG")) or bool(root is not None and (root.obj or {}).get("debug"))


def _flags_without_type(command, ctx) -> None:
    """typer's help names a type for every option, "<bool>" for an on/off flag, which takes no value: none."""
    help_option = command.get_help_option(ctx)  # click keeps this one object per command
    for param in [*command.params, *([help_option] if help_option is not None else [])]:
        if getattr(param, "is_flag", False) and param.metavar is None:
            param.metavar = ""


class ErrorBoundaryGroup(TyperGroup):
    """A typer group whose commands report user errors as one line (see the module docstring)."""

    def get_command(self, ctx, cmd_name):
        command = super().get_command(ctx, cmd_name)
        if command is not None:
            _flags_without_type(command, ctx)
        return command

    def format_help(self, ctx, formatter):
        _flags_without_type(self, ctx)
        return super().format_help(ctx, formatter)

    def invoke(self, ctx: typer.Context):
        try:
            return super().invoke(ctx)
        except (typer.Exit, typer.Abort, ClickException, BrokenPipeError):
            raise  # a closed pipe (`lano3dp train --help | head`): click's main exits quietly
        except Exception as error:
            if not is_user_error(error) or debugging(ctx):
                raise
            print_error(error_line(error))
            raise typer.Exit(1) from None

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        try:
            code = super().main(args=args, prog_name=prog_name, complete_var=complete_var, standalone_mode=False,
                                **extra)
        except ClickException as error:  # usage errors, one line instead of click's box
            if not standalone_mode:
                raise
            if type(error).__name__ == "NoArgsIsHelpError":  # bare `lano3dp`: the help is the answer
                error.show()
                sys.exit(error.exit_code)
            context = getattr(error, "ctx", None)
            hint = f" (see '{context.command_path} --help')" if context is not None else ""
            print_error(one_line(ClickException(error.format_message())) + hint)
            sys.exit(error.exit_code)
        except typer.Abort:
            if not standalone_mode:
                raise
            print_error("aborted")
            sys.exit(1)
        if not standalone_mode:
            return code
        sys.exit(code if isinstance(code, int) else 0)
