"""A checkpoint verified as a whole: a manifest of checksums over every file that shapes what the policy does,
and safetensors files known whole before they are renamed into place.

    manifest.json   {"format": "lano3dp-checkpoint-manifest", "version": 1,
                     "files": {"config.json": "<sha256 of the file's bytes>", "model.safetensors": ..., ...}}

The sealed files are `SEALED_FILES` when present: the weights (which carry the normaliser statistics the policy
uses), config.json (architecture, cloud sizes, observation settings), normalizer.json (the same statistics,
readable) and guidance.json (the guidance the checkpoint was tuned with). Provenance (record.json,
train_config.json) and the training state are not: they do not change what the policy does.

Writing through the library keeps the manifest current (`DiffusionPolicy.save_pretrained`,
`save_guidance_tuning`, `export_fp16`); loading (`DiffusionPolicy.from_pretrained`) checks it, so an edit
by hand, a file added or a file deleted is refused naming the file. A change made on purpose is accepted by
re-sealing: `lano3dp checkpoint seal FOLDER` (`seal`). The weights keep their own checksum and format version
in their header (`modeling.load_safetensors`); the manifest adds the files around them.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from collections.abc import Iterable, Mapping
from pathlib import Path

from lano3dp.errors import CorruptFileError, StorageError, describe_os_error
from lano3dp.jsonio import discard, write_text_atomic

MANIFEST_NAME = "manifest.json"
MANIFEST_FORMAT = "lano3dp-checkpoint-manifest"
MANIFEST_VERSION = 1
SEALED_FILES = ("config.json", "model.safetensors", "normalizer.json", "guidance.json")
SEAL_COMMAND = "lano3dp checkpoint seal"


class CheckpointSealError(CorruptFileError):
    """A checkpoint's file does not match its manifest (edited, added or deleted after sealing), or the
    checkpoint has no manifest."""


def file_sha256(path: str | Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _reseal_hint(folder: Path, undo: str = "restore it") -> str:
    return f"{undo}, or if the change is meant, re-seal the checkpoint: {SEAL_COMMAND} {folder}"


def read_manifest(folder: str | Path) -> dict[str, str] | None:
    """{file name: sha256} of the folder's manifest, or None when it has none."""
    path = Path(folder) / MANIFEST_NAME
    if not path.exists():
        return None
    try:
        data = json.loads(path.read_text())
        files = data["files"]
        if data.get("format") != MANIFEST_FORMAT or not isinstance(files, dict) or \
                not all(isinstance(k, str) and isinstance(v, str) for k, v in files.items()):
            raise ValueError(f"not a {MANIFEST_FORMAT} file")
        if int(data.get("version", 1)) > MANIFEST_VERSION:
            raise ValueError(f"written by a newer lano3dp (manifest version {data['version']}; this one reads "
                             f"{MANIFEST_VERSION}); upgrade lano3dp")
    except (ValueError, KeyError, TypeError, UnicodeDecodeError) as error:
        raise CheckpointSealError(path, f"unreadable manifest ({error}); {_reseal_hint(Path(folder))}") from None
    return dict(files)


def present_sealed_files(folder: str | Path) -> list[str]:
    return [name for name in SEALED_FILES if (Path(folder) / name).is_file()]


def verify_checkpoint(folder: str | Path) -> dict[str, str]:
    """Check every sealed file of `folder` against its manifest; returns the manifest's {file: sha256}.

    Raises:
        CheckpointSealError: naming the file that changed, appeared or went missing since the checkpoint was
            sealed, or the manifest itself when it is missing or unreadable.
    """
    folder = Path(folder)
    manifest = read_manifest(folder)
    if manifest is None:
        raise CheckpointSealError(folder / MANIFEST_NAME,
                                  "missing: this checkpoint was saved before lano3dp sealed checkpoints, or put "
                                  "together by hand; check its files and seal it with "
                                  f"`{SEAL_COMMAND} {folder}` (docs/compat.md)")
    for name, expected in manifest.items():
        path = folder / name
        if not path.is_file():
            raise CheckpointSealError(path, f"listed in {MANIFEST_NAME} but missing; {_reseal_hint(folder)}")
        found = file_sha256(path)
        if found != expected:
            raise CheckpointSealError(path, f"changed since the checkpoint was sealed (sha256 {found[:12]}, "
                                            f"{MANIFEST_NAME} says {expected[:12]}); {_reseal_hint(folder)}")
    for name in present_sealed_files(folder):
        if name not in manifest:
            raise CheckpointSealError(folder / name, f"added after the checkpoint was sealed (not in "
                                                     f"{MANIFEST_NAME}); {_reseal_hint(folder, 'delete it')}")
    return manifest


def seal(folder: str | Path) -> dict[str, str]:
    """Write `folder`'s manifest over its sealed files as they are now; returns {file: sha256}.

    Only for files known good: the library's own writes (`reseal_after_writing`) and `lano3dp checkpoint seal`,
    which loads the checkpoint first."""
    folder = Path(folder)
    files = {name: file_sha256(folder / name) for name in present_sealed_files(folder)}
    text = json.dumps({"format": MANIFEST_FORMAT, "version": MANIFEST_VERSION, "files": files}, indent=2) + "\n"
    write_text_atomic(folder / MANIFEST_NAME, text)
    return files


def reseal_after_writing(folder: str | Path, written: Iterable[str]) -> dict[str, str]:
    """Update the manifest after the library wrote the files `written` into `folder`.

    The folder's other sealed files must still match the manifest they were sealed with, so a library write never
    seals an edit made by hand; a folder without a manifest (a first save) is sealed as it is.

    Raises:
        CheckpointSealError: another sealed file changed since the last seal (names it).
    """
    folder = Path(folder)
    written = set(written)
    manifest = read_manifest(folder)
    if manifest is not None:
        for name in present_sealed_files(folder):
            if name in written:
                continue
            if name not in manifest:
                raise CheckpointSealError(folder / name, f"added after the checkpoint was sealed (not in "
                                                         f"{MANIFEST_NAME}); {_reseal_hint(folder, 'delete it')}")
            if file_sha256(folder / name) != manifest[name]:
                raise CheckpointSealError(folder / name, f"changed since the checkpoint was sealed; "
                                                         f"{_reseal_hint(folder)}")
    return seal(folder)


# ---- safetensors, written whole -------------------------------------------------------------------------
def write_safetensors(tensors: Mapping, path: str | Path, metadata: Mapping[str, str]) -> Path:
    """`safetensors.torch.save_file` through a temporary file, renamed into place once its size matches what its
    own header promises; any failure removes the temporary file and raises StorageError naming `path`.

    safetensors reports a full disk as a SafetensorError (not an OSError), whose text is translated here."""
    from safetensors.torch import save_file

    path = Path(path)
    temporary = path.with_name(path.name + ".tmp")
    try:
        save_file(dict(tensors), str(temporary), metadata=dict(metadata))
        _check_safetensors_size(temporary)
        os.replace(temporary, path)
    except OSError as error:
        discard(temporary)
        raise StorageError(path, error.cause if isinstance(error, StorageError) else describe_os_error(error)) \
            from error
    except Exception as error:
        discard(temporary)
        if type(error).__name__ != "SafetensorError":
            raise
        raise StorageError(path, safetensors_cause(error)) from error
    except BaseException:
        discard(temporary)
        raise
    return path


def safetensors_cause(error: BaseException) -> str:
    """'Error while serializing: I/O error: No space left on device (os error 28) at path ...' -> 'No space left
    on device'; other texts as they are, on one line."""
    text = " ".join(str(error).split())
    match = re.search(r"I/O error: (.+?) \(os error \d+\)", text) or re.search(r'message: "([^"]+)"', text)
    return match.group(1) if match else text or type(error).__name__


def _check_safetensors_size(path: Path) -> None:
    """The file is as long as its header says: 8 bytes of header length, the JSON header, then the tensor data up
    to the largest end offset."""
    with open(path, "rb") as handle:
        raw = handle.read(8)
        if len(raw) != 8:
            raise StorageError(path, f"{len(raw)} bytes written, not even a header")
        header_length = int.from_bytes(raw, "little")
        try:
            header = json.loads(handle.read(header_length))
        except ValueError as error:
            raise StorageError(path, f"the header does not read back ({error})") from None
    data_end = max((int(entry["data_offsets"][1]) for key, entry in header.items() if key != "__metadata__"),
                   default=0)
    expected, found = 8 + header_length + data_end, path.stat().st_size
    if found != expected:
        raise StorageError(path, f"{found} bytes written, the header promises {expected}")
