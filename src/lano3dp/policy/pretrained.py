"""Policies that ship inside the package, found by task (skill) name, and the fp16 export that makes them.

A packaged checkpoint is an ordinary policy folder (config.json, model.safetensors, normalizer.json) under
`lano3dp/checkpoints/<task>/`, with its weights stored in float16 to keep the wheel small, the normaliser
statistics in float32 (they scale metres: fp16 would cost millimetres), and a `record.json` saying how it
was made and what it scored. Loading casts the weights back to float32.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import torch

from lano3dp.errors import Lano3dpError
from lano3dp.jsonio import write_json
from lano3dp.policy.integrity import seal
from lano3dp.policy.modeling import (
    CONFIG_NAME,
    NORMALIZER_NAME,
    WEIGHTS_NAME,
    DiffusionPolicy,
    format_version_for,
    resolve_checkpoint,
    save_safetensors,
)

PACKAGED_ROOT = Path(__file__).resolve().parent.parent / "checkpoints"
RECORD_NAME = "record.json"


class PackagedCheckpointNotFoundError(Lano3dpError, LookupError):
    """No policy ships for this task."""


def packaged_checkpoints() -> dict[str, Path]:
    """{task name: folder} of every policy shipped with the package."""
    if not PACKAGED_ROOT.is_dir():
        return {}
    return {folder.name: folder for folder in sorted(PACKAGED_ROOT.iterdir())
            if (folder / CONFIG_NAME).exists() and (folder / WEIGHTS_NAME).exists()}


def packaged_checkpoint(task: str) -> Path:
    """The shipped policy folder of `task` (also its skill name in the default registry)."""
    available = packaged_checkpoints()
    if task not in available:
        shipped = ", ".join(available) or "none"
        raise PackagedCheckpointNotFoundError(
            f"no packaged policy for {task!r} (packaged: {shipped}); pass --checkpoint with one you trained "
            "(`lano3dp demo` or `lano3dp collect` + `lano3dp train`)")
    return available[task]


def packaged_record(task: str) -> dict[str, Any]:
    """How the shipped policy of `task` was made and what it scored (its record.json)."""
    path = packaged_checkpoint(task) / RECORD_NAME
    return json.loads(path.read_text()) if path.exists() else {}


def export_fp16(checkpoint: str | Path, out: str | Path, record: dict[str, Any] | None = None) -> Path:
    """Write `checkpoint` (a policy folder or run) to `out` with float16 weights and float32 statistics.

    The policy's config must carry its observation settings (extra["observation"]): a shipped folder has
    no dataset beside it to read them from.
    """
    source = resolve_checkpoint(checkpoint)
    policy = DiffusionPolicy.from_pretrained(source)
    if "observation" not in policy.config.extra:
        raise ValueError(f"{source} does not record how its observations were made (config extra 'observation'); "
                         "re-save it with the crop box and image size of its dataset first")
    out = Path(out)
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    state = {}
    for key, value in policy.state_dict().items():
        value = value.detach().cpu().contiguous()
        if value.is_floating_point() and not key.startswith("normalizer."):
            value = value.to(torch.float16)
        state[key] = value
    # the checksum is over the fp16 values the file holds, so loading checks what is on disk
    save_safetensors(state, out / WEIGHTS_NAME, metadata={"format": "lano3dp-policy",
                                                          "format_version": str(format_version_for(policy.config)),
                                                          "weights_dtype": "float16"})
    for name in (CONFIG_NAME, NORMALIZER_NAME):
        shutil.copy2(source / name, out / name)
    seal(out)  # what was just written from a verified source (the source's guidance tuning is not carried)
    if record is not None:
        write_json(out / RECORD_NAME, record)  # verified, like every file of the checkpoint
    return out
