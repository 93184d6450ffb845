"""Training checkpoints: atomic folders, a `last` pointer, EMA, and training state without pickle.

A training checkpoint is a folder `<run>/checkpoints/step_XXXXXXX/` holding

    config.json, model.safetensors, normalizer.json    the EMA policy (DiffusionPolicy.from_pretrained loads it)
    training_state.safetensors                          raw weights ("model.*") and optimizer tensors ("optimizer.*")
    training_state.json                                 step, optimizer hyper-parameters, LR schedule, EMA counter
    train_config.json                                   the TrainConfig that made it

It is written to a hidden temporary folder and renamed into place, so a crash never leaves a
half-written checkpoint under a real name; `checkpoints/last` is a symlink swapped atomically.
"""

from __future__ import annotations

import copy
import json
import os
import re
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from torch import nn

from lano3dp.errors import CorruptFileError, StorageError, describe_os_error
from lano3dp.jsonio import discard, to_jsonable, write_text_atomic
from lano3dp.policy.integrity import MANIFEST_NAME, verify_checkpoint
from lano3dp.policy.modeling import load_safetensors, save_safetensors

STATE_TENSORS = "training_state.safetensors"
STATE_JSON = "training_state.json"
CHECKPOINT_PATTERN = re.compile(r"^step_(\d{7,})$")


def checkpoint_name(step: int) -> str:
    return f"step_{step:07d}"


# ---- EMA ------------------------------------------------------------------------------------
class EMA:
    """Exponential moving average of a model's weights with Diffusion Policy's warm-up schedule.

    decay(step) = clip(1 - (1 + step / inv_gamma) ** -power, min_value, max_value), and 0 at step 0, so
    the average starts as a copy and forgets less as training goes on. Written here (a few lines) so the
    average is a whole DiffusionPolicy that saves with save_pretrained. Buffers (normaliser) are copied.
    """

    def __init__(self, model: nn.Module, inv_gamma: float = 1.0, power: float = 0.75, min_value: float = 0.0,
                 max_value: float = 0.9999):
        self.model = copy.deepcopy(model).eval().requires_grad_(False)
        self.inv_gamma, self.power, self.min_value, self.max_value = inv_gamma, power, min_value, max_value
        self.optimization_step = 0

    def decay(self, step: int) -> float:
        if step <= 0:
            return 0.0
        value = 1.0 - (1.0 + step / self.inv_gamma) ** -self.power
        return max(self.min_value, min(value, self.max_value))

    @torch.no_grad()
    def update(self, model: nn.Module) -> None:
        decay = self.decay(self.optimization_step)
        averaged = list(self.model.parameters())
        current = [p.detach() for p in model.parameters()]
        torch._foreach_lerp_(averaged, current, 1.0 - decay)  # ema <- decay * ema + (1 - decay) * current
        for mine, theirs in zip(self.model.buffers(), model.buffers(), strict=True):
            mine.copy_(theirs)
        self.optimization_step += 1

    def state(self) -> dict[str, Any]:
        return {"optimization_step": self.optimization_step, "inv_gamma": self.inv_gamma, "power": self.power,
                "min_value": self.min_value, "max_value": self.max_value}


# ---- optimizer state <-> safetensors + JSON --------------------------------------------------
def flatten_optimizer_state(state_dict: dict) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    """Split torch optimizer state into tensors ("optimizer.<param>.<name>") and JSON-able metadata."""
    tensors, scalars = {}, {}
    for index, entries in state_dict["state"].items():
        for name, value in entries.items():
            if torch.is_tensor(value):
                tensors[f"optimizer.{index}.{name}"] = value.detach().cpu().contiguous()
            else:
                scalars.setdefault(str(index), {})[name] = value
    groups = [{key: (list(value) if isinstance(value, tuple) else value) for key, value in group.items()}
              for group in state_dict["param_groups"]]
    return tensors, {"param_groups": groups, "scalars": scalars}


def unflatten_optimizer_state(tensors: dict[str, torch.Tensor], meta: dict[str, Any]) -> dict:
    state: dict[int, dict[str, Any]] = {}
    for key, value in tensors.items():
        if key.startswith("optimizer."):
            _, index, name = key.split(".", 2)
            state.setdefault(int(index), {})[name] = value
    for index, entries in meta["scalars"].items():
        state.setdefault(int(index), {}).update(entries)
    groups = [{key: (tuple(value) if key == "betas" else value) for key, value in group.items()}
              for group in meta["param_groups"]]
    return {"state": state, "param_groups": groups}


@dataclass
class TrainingState:
    """What a resumed run needs, read back from a checkpoint folder."""

    path: Path
    step: int
    model: dict[str, torch.Tensor]  # raw (non-EMA) weights
    optimizer: dict  # torch optimizer state_dict
    lr_scheduler: dict
    ema: dict[str, Any]
    extra: dict[str, Any]


def save_training_state(directory: Path, *, step: int, model: nn.Module, optimizer: torch.optim.Optimizer,
                        lr_scheduler, ema: EMA | None, extra: dict[str, Any] | None = None) -> None:
    tensors, optimizer_meta = flatten_optimizer_state(optimizer.state_dict())
    tensors |= {f"model.{key}": value.detach().cpu().contiguous() for key, value in model.state_dict().items()}
    save_safetensors(tensors, directory / STATE_TENSORS, metadata={"format": "lano3dp-training-state"})
    meta = {"step": step, "optimizer": optimizer_meta, "lr_scheduler": lr_scheduler.state_dict(),
            "ema": ema.state() if ema is not None else None, "extra": extra or {}}
    write_text_atomic(directory / STATE_JSON, json.dumps(to_jsonable(meta, finite=False), indent=2))


def load_training_state(directory: str | Path) -> TrainingState:
    """Read training_state.{json,safetensors}; damage raises CorruptFileError naming the file."""
    directory = Path(directory)
    meta_path = directory / STATE_JSON
    if not meta_path.exists():
        raise FileNotFoundError(f"{meta_path} does not exist (no training state in this checkpoint)")
    try:
        meta = json.loads(meta_path.read_text())
        step = int(meta["step"])
        optimizer_meta, lr_state = meta["optimizer"], meta["lr_scheduler"]
    except (ValueError, KeyError, TypeError, UnicodeDecodeError) as error:
        raise CorruptFileError(meta_path, f"not a valid training state ({type(error).__name__}: {error})") from error
    tensors = load_safetensors(directory / STATE_TENSORS)
    model = {key[len("model."):]: value for key, value in tensors.items() if key.startswith("model.")}
    if not model:
        raise CorruptFileError(directory / STATE_TENSORS, "holds no model weights")
    try:
        optimizer = unflatten_optimizer_state(tensors, optimizer_meta)
    except (ValueError, KeyError, TypeError) as error:
        raise CorruptFileError(meta_path, f"inconsistent optimizer state ({error})") from error
    return TrainingState(directory, step, model, optimizer, lr_state, meta.get("ema") or {}, meta.get("extra", {}))


# ---- folders ----------------------------------------------------------------------------------
@contextmanager
def atomic_directory(final: Path) -> Iterator[Path]:
    """Yield a temporary sibling folder; on success it replaces `final` in one rename.

    Before the rename its policy files are read back against the manifest they were sealed with (a full disk
    that cut a file short is found here, not at the next load); any failure removes the temporary folder and
    leaves `final` as it was.
    """
    final = Path(final)
    temporary = final.with_name(f".{final.name}.tmp-{os.getpid()}")
    shutil.rmtree(temporary, ignore_errors=True)
    temporary.mkdir(parents=True)
    try:
        yield temporary
        _fsync_tree(temporary)
        if (temporary / MANIFEST_NAME).exists():
            try:
                verify_checkpoint(temporary)
            except CorruptFileError as error:
                raise StorageError(error.path, "it does not read back as written "
                                               f"({error.reason.split(';')[0]})") from error
        if final.exists():  # os.replace cannot replace a non-empty folder: move it aside first
            old = final.with_name(f".{final.name}.old-{os.getpid()}")
            os.replace(final, old)
            os.replace(temporary, final)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(temporary, final)
    except StorageError as error:  # named by the checkpoint it was for, not the hidden folder it was written in
        shutil.rmtree(temporary, ignore_errors=True)
        raise StorageError(error.path.replace(str(temporary), str(final)), error.cause) from error
    except BaseException:
        shutil.rmtree(temporary, ignore_errors=True)
        raise


def _fsync_tree(directory: Path) -> None:
    for path in directory.iterdir():
        if path.is_file():
            with open(path, "rb") as handle:
                os.fsync(handle.fileno())


def update_last_pointer(checkpoints: Path, name: str) -> Path:
    """Point `checkpoints/last` at `checkpoints/<name>` (relative symlink, swapped atomically)."""
    link = checkpoints / "last"
    temporary = checkpoints / f".last.tmp-{os.getpid()}"
    try:
        if temporary.is_symlink() or temporary.exists():
            temporary.unlink()
        os.symlink(name, temporary)
        os.replace(temporary, link)
    except OSError as error:
        discard(temporary)
        raise StorageError(link, describe_os_error(error)) from error
    return link


def list_checkpoints(checkpoints: Path) -> list[tuple[int, Path]]:
    """(step, folder) of every complete checkpoint, in step order."""
    if not checkpoints.is_dir():
        return []
    found = []
    for path in checkpoints.iterdir():
        match = CHECKPOINT_PATTERN.match(path.name)
        if match and path.is_dir() and not path.is_symlink():
            found.append((int(match.group(1)), path))
    return sorted(found)


def latest_resumable(checkpoints: Path) -> Path | None:
    """The newest checkpoint that still has its training state, or None."""
    for _, path in reversed(list_checkpoints(checkpoints)):
        if (path / STATE_JSON).exists():
            return path
    return None


def remove_stale_temporaries(checkpoints: Path) -> None:
    """Delete leftovers of a run killed while writing (hidden .step_*.tmp-* / .old-* folders, .last.tmp-* links)."""
    if checkpoints.is_dir():
        for path in checkpoints.iterdir():
            if path.name.startswith(".step_") and (".tmp-" in path.name or ".old-" in path.name):
                shutil.rmtree(path, ignore_errors=True)
            elif path.name.startswith(".last.tmp-") and path.is_symlink():
                path.unlink(missing_ok=True)


def prune_training_states(checkpoints: Path, keep: int) -> None:
    """Drop training_state.* from all but the newest `keep` checkpoints; the EMA policies stay."""
    if keep <= 0:
        return
    for _, path in list_checkpoints(checkpoints)[:-keep]:
        for name in (STATE_JSON, STATE_TENSORS):  # the JSON first: without it a folder is not resumable
            (path / name).unlink(missing_ok=True)
