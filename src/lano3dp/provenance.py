"""Where a number came from: every results file records the command, the code, the libraries and the machine.

    provenance(command, config)   {"command", "commit", "dirty", "behaviour_version", "versions", "machine",
                                   "created_utc", "config"}: the block every results file carries
    result_is_current(record)     whether a saved result still describes what this code would do

BEHAVIOUR_VERSION is bumped by every change that alters episodes (what a policy does, what the simulator does,
how an episode is measured). A cached result counts as current only when it was made at this behaviour version:
the commit alone would invalidate a long benchmark at every documentation edit, and a setting-only key let
behaviour changes that added no setting leave stale results counted as current.
`tests/test_behaviour_version.py` keeps the number honest: it replays short reference episodes and fails when their
outcome changes while BEHAVIOUR_VERSION does not (on the processor model they were recorded on: float rounding
differs between CPU models, so a stored outcome is the same only there).
"""

from __future__ import annotations

import functools
import importlib.metadata
import os
import platform
import shlex
import subprocess
import sys
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

BEHAVIOUR_VERSION = 1
RESULTS_SCHEMA = "lano3dp-results/1"
PACKAGES = ("lano3dp", "numpy", "torch", "mujoco", "zarr", "diffusers", "safetensors", "transformers")
_SOURCE = Path(__file__).resolve().parent


def library_versions() -> dict[str, str]:
    """Python and the versions of the packages that shape results (those installed)."""
    versions = {"python": platform.python_version()}
    for package in PACKAGES:
        try:
            versions[package] = importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            pass
    return versions


@functools.cache
def source_commit() -> tuple[str | None, bool | None]:
    """(commit, dirty) of the git checkout this package runs from; (None, None) for an installed package or
    where git is missing. Dirty: tracked files differ from the commit."""
    def git(*args: str) -> str:
        return subprocess.run(["git", *args], cwd=_SOURCE, capture_output=True, text=True, timeout=10,
                              check=True).stdout.strip()

    try:
        commit = git("rev-parse", "HEAD")
        dirty = bool(git("status", "--porcelain", "--untracked-files=no"))
    except (OSError, subprocess.SubprocessError):
        return None, None
    return commit, dirty


def machine() -> dict[str, Any]:
    """What ran it: the platform, CPU model and count, and the torch threads of this process (no host names)."""
    model = None
    try:
        model = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                      if line.startswith("model name")), None)
    except OSError:
        pass
    info: dict[str, Any] = {"platform": platform.platform(), "processor": model or platform.processor() or None,
                            "cpu_count": os.cpu_count()}
    if "torch" in sys.modules:
        info["torch_threads"] = sys.modules["torch"].get_num_threads()
    return info


def command_line() -> str:
    """This process's command line, as a user would type it (`lano3dp ...` for the CLI, else the script)."""
    program = Path(sys.argv[0]).name if sys.argv and sys.argv[0] else "python"
    if program in ("lano3dp", "__main__.py"):
        return shlex.join(["lano3dp", *sys.argv[1:]])
    return shlex.join(["python", *(_relative(arg) for arg in sys.argv)])


def _relative(arg: str) -> str:
    """A script path inside the working folder, written relative to it (no machine paths in results)."""
    try:
        return str(Path(arg).resolve().relative_to(Path.cwd()))
    except ValueError:
        return arg


def provenance(command: str | None = None, config: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The provenance block of a results file (`command`: default this process's command line)."""
    commit, dirty = source_commit()
    return {"command": command if command is not None else command_line(), "commit": commit, "dirty": dirty,
            "behaviour_version": BEHAVIOUR_VERSION, "versions": library_versions(), "machine": machine(),
            "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
            "config": dict(config) if config is not None else None}


def result_is_current(record: Mapping[str, Any]) -> bool:
    """Whether a saved results file was made by code that behaves as this code does (its behaviour version)."""
    made = (record.get("provenance") or {}).get("behaviour_version")
    return made == BEHAVIOUR_VERSION
