"""What the fault-injection tests share: how a command's outcome is judged, and the faults themselves."""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import stat
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE_ENV = ROOT / "examples" / "own_env.py"
FULL_DEVICE = Path("/dev/full")  # every write to it fails with ENOSPC: a full disk, for one file


def subprocess_env() -> dict:
    return os.environ | {"OMP_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1", "MUJOCO_GL": "egl",
                         "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), os.environ.get("PYTHONPATH", "")])}


def tree_digest(folder: Path) -> str:
    """One hash over every file's relative path and bytes: equal digests, unchanged data."""
    digest = hashlib.sha256()
    for path in sorted(Path(folder).rglob("*")):
        if path.is_file():
            digest.update(str(path.relative_to(folder)).encode() + path.read_bytes())
    return digest.hexdigest()


def error_lines(result) -> list[str]:
    return [line for line in result.stderr.splitlines() if line.startswith("error: ")]


def assert_one_line(result, code: int, *texts: str) -> str:
    """The command exited with `code` after printing exactly one error line, holding every one of `texts`, and
    no traceback. Returns the line."""
    errors = error_lines(result)
    assert result.exit_code == code, (result.output, result.exception)
    assert len(errors) == 1, result.stderr
    for text in texts:
        assert text in errors[0], (text, errors[0])
    assert "Traceback" not in result.output
    return errors[0]


def full_disk_under(path: Path) -> None:
    """Make the next write to `path` meet a full disk: `path` becomes a link to /dev/full (the writers of
    lano3dp write a temporary file first; pointing it there fails that write as a full disk fails it)."""
    if not (FULL_DEVICE.exists() and stat.S_ISCHR(FULL_DEVICE.stat().st_mode)):
        pytest.skip("/dev/full is not a character device here")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.symlink_to(FULL_DEVICE)


@contextlib.contextmanager
def read_only(folder: Path) -> Iterator[Path]:
    """`folder` read-only for this process while the block runs: its write bits off (a user), or a read-only
    bind mount of it over itself (root ignores write bits); skipped where neither can be had."""
    folder = Path(folder)
    if os.geteuid() != 0:
        modes = {path: path.stat().st_mode for path in [folder, *folder.rglob("*")] if not path.is_symlink()}
        for path, mode in modes.items():
            path.chmod(mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))
        try:
            yield folder
        finally:
            for path, mode in modes.items():
                path.chmod(mode)
        return
    mount = shutil.which("mount")
    if mount is None or subprocess.run([mount, "--bind", "-o", "ro", str(folder), str(folder)],
                                       capture_output=True).returncode != 0:
        pytest.skip("root without a way to make a folder read-only (no bind mount allowed here)")
    try:
        yield folder
    finally:
        subprocess.run(["umount", str(folder)], check=True, capture_output=True)
