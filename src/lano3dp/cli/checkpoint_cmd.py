"""`lano3dp checkpoint seal|verify`: a policy folder's manifest of checksums (`lano3dp.policy.integrity`).

Loading refuses a checkpoint whose files changed since it was saved; `seal` accepts a change made on purpose
(a config edited by hand, a guidance.json written by hand, a checkpoint from before manifests) once the folder
loads: the weights match their own checksum and config.json, and guidance.json is a valid tuning.
"""

from __future__ import annotations

from pathlib import Path

import typer

checkpoint_app = typer.Typer(help="Seal or verify a policy checkpoint's manifest of checksums.", no_args_is_help=True)

FOLDER = typer.Argument(..., help="Policy folder, or a training run (its last checkpoint).")


@checkpoint_app.command("seal")
def seal_command(folder: Path = FOLDER) -> None:
    """Accept a checkpoint's files as they are now: load it, then write its manifest.json."""
    from lano3dp.guidance.settings import load_guidance_tuning
    from lano3dp.policy import DiffusionPolicy
    from lano3dp.policy.integrity import CheckpointSealError, seal
    from lano3dp.policy.modeling import resolve_checkpoint

    resolved = resolve_checkpoint(folder)
    try:  # every check of loading but the manifest's, which is last (DiffusionPolicy.from_pretrained)
        DiffusionPolicy.from_pretrained(resolved)
    except CheckpointSealError:
        pass
    load_guidance_tuning(resolved)
    files = seal(resolved)
    typer.echo(f"sealed {resolved}: " + ", ".join(f"{name} {digest[:12]}" for name, digest in files.items()))


@checkpoint_app.command("verify")
def verify_command(folder: Path = FOLDER) -> None:
    """Check a checkpoint's files against its manifest and load it."""
    from lano3dp.policy import DiffusionPolicy
    from lano3dp.policy.modeling import resolve_checkpoint

    resolved = resolve_checkpoint(folder)
    DiffusionPolicy.from_pretrained(resolved)
    typer.echo(f"{resolved}: every sealed file matches its manifest, and the policy loads")


def register(app: typer.Typer) -> None:
    app.add_typer(checkpoint_app, name="checkpoint")
