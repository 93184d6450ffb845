"""The CLI's error boundary covers the storage and serialisation errors of the libraries lano3dp reads and writes
files with (safetensors, zarr, imageio / ffmpeg, Pillow, json), which are not all OSErrors: each is one line
naming the library and its cause; --debug shows the traceback; a bug of lano3dp keeps its traceback."""

from __future__ import annotations

import pytest
import typer
from typer.testing import CliRunner

from faults_common import assert_one_line
from lano3dp.cli._boundary import ErrorBoundaryGroup


def real_library_errors(tmp_path) -> dict[str, Exception]:
    """Errors raised by the libraries themselves, on a file that is not theirs."""
    import zarr
    from PIL import Image
    from safetensors import safe_open

    garbage = tmp_path / "garbage.bin"
    garbage.write_bytes(b"\x07not a file of any of them")
    zarr.create_array(store=str(tmp_path / "array.zarr"), shape=(2,), dtype="f4")
    errors = {}
    for name, read in (("safetensors", lambda: safe_open(str(garbage), framework="pt")),
                       ("zarr", lambda: zarr.open_group(str(tmp_path / "array.zarr"), mode="r")),
                       ("Pillow", lambda: Image.open(garbage))):
        with pytest.raises(Exception) as caught:  # noqa: B017 (whatever each library raises is the point)
            read()
        errors[name] = caught.value
    return errors


def boundary_app(error: BaseException) -> typer.Typer:
    app = typer.Typer(cls=ErrorBoundaryGroup, pretty_exceptions_enable=False, add_completion=False)

    @app.callback()
    def options(ctx: typer.Context, debug: bool = typer.Option(False, "--debug")) -> None:
        ctx.obj = {"debug": debug}

    @app.command()
    def fail() -> None:
        raise error

    return app


def test_each_library_error_is_one_line_naming_the_library(tmp_path):
    for library, error in real_library_errors(tmp_path).items():
        result = CliRunner().invoke(boundary_app(error), ["fail"])
        line = assert_one_line(result, 1, f"error: {library}: ")
        assert len(line) > len(f"error: {library}: "), line
        debugged = CliRunner().invoke(boundary_app(error), ["--debug", "fail"])
        assert debugged.exception is error


def test_a_safetensors_error_that_is_not_an_os_error_reaches_the_user_as_one_line():
    from safetensors import SafetensorError

    error = SafetensorError("Error while serializing: I/O error: No space left on device (os error 28)")
    assert not isinstance(error, OSError)
    assert_one_line(CliRunner().invoke(boundary_app(error), ["fail"]), 1,
                    "error: safetensors: Error while serializing: I/O error: No space left on device")


def test_a_bug_keeps_its_traceback():
    result = CliRunner().invoke(boundary_app(ZeroDivisionError("a bug")), ["fail"])
    assert isinstance(result.exception, ZeroDivisionError)
