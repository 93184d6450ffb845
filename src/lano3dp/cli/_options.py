"""Option checks run before a command does any work, each failing as a usage error (exit 2) naming the option."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from lano3dp.guidance.settings import SCHEDULERS  # noqa: F401 (the guidance-figures command's choices)


def output_path(path: Path | None, option: str = "--out", *, folder: bool, kind: str | None = None) -> Path | None:
    """`path` can be written: no regular file on the way to it, a file where a file is wanted and a folder
    where a folder is (an existing one is fine: commands resume into it), and a nearest existing folder that
    takes a new file (tried, so a read-only mount, a permission or an ACL is found now, not when the first
    result is written). Symlinks are followed: what counts is the folder written into.

    No folder is written inside a dataset (a zarr store); with `kind` ("dataset" for collect, "run" for train),
    none inside a training run or a policy checkpoint either, and an existing folder must be of that kind (a
    dataset is not resumed as a run, nor a folder of other files made into a dataset).
    """
    import tempfile

    if path is None:
        return None
    absolute = Path(path).absolute()
    real = absolute.resolve()  # through symlinks, so a folder reached by a link is judged where it is
    shown = f"{path}" if real == absolute else f"{path} (= {real})"
    if real.exists():
        if folder and not real.is_dir():
            raise typer.BadParameter(f"{shown} is a file; give a folder", param_hint=option)
        if not folder and real.is_dir():
            raise typer.BadParameter(f"{shown} is a folder; give a file name", param_hint=option)
        if folder and kind is not None:
            _check_existing_kind(real, shown, kind, option)
    for ancestor in real.parents:
        if folder and _is_dataset(ancestor):
            raise typer.BadParameter(f"{shown} is inside the dataset {ancestor}; give a folder outside it",
                                     param_hint=option)
        if folder and kind is not None and (found := _run_or_checkpoint(ancestor)):
            raise typer.BadParameter(f"{shown} is inside the {found} {ancestor}; give a folder outside it",
                                     param_hint=option)
    # an existing output folder is written into (a resumed run, a dataset added to): it must take files itself
    for ancestor in ([real] if folder else []) + list(real.parents):
        if ancestor.exists():
            if not ancestor.is_dir():
                raise typer.BadParameter(f"cannot write {path}: {ancestor} is a file, not a folder", param_hint=option)
            try:
                with tempfile.TemporaryFile(dir=ancestor):
                    pass
            except OSError as error:
                raise typer.BadParameter(f"cannot write {path}: {ancestor} does not take new files "
                                         f"({error.strerror or error})", param_hint=option) from None
            break
    return path


def _is_dataset(folder: Path) -> bool:
    return (folder / "zarr.json").is_file() or (folder / ".zgroup").is_file()


def _run_or_checkpoint(folder: Path) -> str | None:
    if (folder / "train_config.json").is_file() or (folder / "checkpoints" / "last").exists():
        return "training run"
    if (folder / "config.json").is_file() and (folder / "model.safetensors").is_file():
        return "policy checkpoint"
    return None


def _check_existing_kind(folder: Path, shown: str, kind: str, option: str) -> None:
    """An existing output folder of `kind` ("dataset" or "run") is resumed; one of another kind is refused."""
    other = "dataset" if _is_dataset(folder) else _run_or_checkpoint(folder)
    if kind == "dataset" and other != "dataset" and (other or any(folder.iterdir())):
        raise typer.BadParameter(f"{shown} is {'a ' + other if other else 'a folder of other files'}, not a "
                                 "dataset; give a new folder (or an existing dataset to add to)", param_hint=option)
    if kind == "run" and other in ("dataset", "policy checkpoint"):
        raise typer.BadParameter(f"{shown} is a {other}, not a training run; give a new folder (or an existing "
                                 "run to resume)", param_hint=option)


def existing_path(path: Path | None, option: str) -> Path | None:
    if path is not None and not Path(path).exists():
        raise typer.BadParameter(f"{path} does not exist", param_hint=option)
    return path


def task_name(task: str | None, option: str = "--task") -> str | None:
    from lano3dp.sim.tasks import TASKS

    if task is not None and task not in TASKS:
        raise typer.BadParameter(f"unknown task {task!r}; tasks: {', '.join(sorted(TASKS))} (see `lano3dp tasks`)",
                                 param_hint=option)
    return task


def variation(value: str | None, option: str = "--variation") -> str | None:
    from lano3dp.sim import Variation
    from lano3dp.sim.variations import VariationError

    if value is not None:
        try:
            Variation.parse(value)
        except VariationError as error:
            raise typer.BadParameter(str(error), param_hint=option) from None
    return value


def choice(value: str | None, choices: tuple[str, ...], option: str) -> str | None:
    if value is not None and value not in choices:
        raise typer.BadParameter(f"{value!r} is not one of {', '.join(choices)}", param_hint=option)
    return value


def device(value: str, option: str = "--device") -> str:
    import torch

    try:
        parsed = torch.device(value)
    except (RuntimeError, ValueError):
        raise typer.BadParameter(f"{value!r} is not a torch device; use cpu or cuda", param_hint=option) from None
    if parsed.type == "cuda" and not torch.cuda.is_available():
        raise typer.BadParameter(f"{value}: CUDA is not available here (torch {torch.__version__}); use --device cpu",
                                 param_hint=option)
    if parsed.type not in ("cpu", "cuda"):
        raise typer.BadParameter(f"{value!r}: lano3dp trains on cpu or cuda", param_hint=option)
    return value


def obs_type(name: str, option: str = "--obs-type") -> str:
    """A registered observation type (`lano3dp.policy.observations`), as a usage error naming the registered ones."""
    from lano3dp.policy.observations import UnknownObservationTypeError, get_observation_type

    try:
        get_observation_type(name)
    except UnknownObservationTypeError as error:
        raise typer.BadParameter(str(error), param_hint=option) from None
    return name


ENV_HELP = ("Your own simulator or robot: module:factory or path/to/file.py:factory, called with task, seed, "
            "variation, image_size, render_rgb, max_steps (those it names) and returning an env meeting "
            "lano3dp.sim.protocol (default: the built-in simulator).")


def env_factory(spec: str | None, option: str = "--env") -> str | None:
    """--env names an importable callable (the module is imported here, before any episode runs)."""
    from lano3dp.env_factory import EnvFactoryError, load_factory

    if spec is not None:
        try:
            load_factory(spec)
        except EnvFactoryError as error:
            raise typer.BadParameter(str(error).removeprefix(f"--env {spec}: "), param_hint=option) from None
    return spec


# ---- the settings `eval` and `run` share: a config file, basic options, `--set` for every other field ----------
PRESET_HELP = ("Guidance: none | a_k | paper | recommended | tuned (the policy's own, else recommended); "
               "`lano3dp settings` shows them.")
SET_HELP = (r"Change any setting by its dotted path, e.g. guidance.sampler.rho=0.02, "
            r"guidance.execution.filters=\[repair,hold], max_steps=200 (repeatable; after --config and options).")
CONFIG_HELP = "A YAML or JSON file of settings (a results JSON re-runs what made it); options and --set override it."
OVERWRITE_HELP = "Replace what --out already holds (never done without it)."
SEGMENTERS = ("sim", "error-model", "open-vocab")
DETECTORS = ("grounding_dino", "owlv2")
SEGMENTER_HELP = ("sim (the simulator's ground-truth masks) | error-model (those masks through a published-numbers "
                  "model of detector, SAM and tracker errors) | open-vocab (detector + SAM, the paper's).")
DETECTOR_DIR_HELP = "open-vocab: local folder of the detector's weights (never downloaded)."
SAM_DIR_HELP = "open-vocab: local folder of SAM's weights (never downloaded)."
PANEL_SETTINGS, PANEL_PERCEPTION, PANEL_ADVANCED = "Settings", "Perception", "Advanced"

# The settings and perception options `eval` and `run` share, declared once (typer's Annotated form).
SetOption = Annotated[list[str] | None, typer.Option("--set", metavar="PATH=VALUE", help=SET_HELP,
                                                     rich_help_panel=PANEL_SETTINGS)]
ConfigOption = Annotated[Path | None, typer.Option("--config", metavar="FILE", help=CONFIG_HELP,
                                                   rich_help_panel=PANEL_SETTINGS)]
SegmenterOption = Annotated[str, typer.Option(help=SEGMENTER_HELP, rich_help_panel=PANEL_PERCEPTION)]
DetectorOption = Annotated[str, typer.Option(help="open-vocab: grounding_dino | owlv2.",
                                             rich_help_panel=PANEL_PERCEPTION)]
DetectorDirOption = Annotated[Path | None, typer.Option(help=DETECTOR_DIR_HELP, rich_help_panel=PANEL_PERCEPTION)]
SamDirOption = Annotated[Path | None, typer.Option(help=SAM_DIR_HELP, rich_help_panel=PANEL_PERCEPTION)]
ImageSizeOption = Annotated[int | None, typer.Option(help="Camera resolution (default: that of the checkpoint's "
                                                          "data).", rich_help_panel=PANEL_PERCEPTION)]


def settings_options(ctx, fields: dict[str, str]) -> dict:
    """The config dict a command line gives: `--config` first, then each option given on the command line (its
    parameter -> dotted config path in `fields`; an option left out keeps the file's value or the config class's
    default, which the option's default states), then `--set`; checked by the config class afterwards."""
    from lano3dp.config_tree import SettingsError
    from lano3dp.evaluation.config import load_config_file, with_assignments

    params = ctx.params
    try:
        data = load_config_file(params["config"]) if params.get("config") else {}
        for name, path in fields.items():
            value = params[name]
            # by name: typer's click and the installed click each have a ParameterSource enum; a repeatable option
            # left out arrives empty, whatever its source says
            source = getattr(ctx.get_parameter_source(name), "name", None)
            if source in (None, "DEFAULT", "DEFAULT_MAP") or value in ([], ()):
                continue
            node, keys = data, path.split(".")
            for key in keys[:-1]:
                node = node.setdefault(key, {})
            node[keys[-1]] = str(value) if isinstance(value, Path) else list(value) if isinstance(value, tuple) \
                else value
        data = with_assignments(data, params.get("set_") or ())
        if "guidance" in data and "preset" not in data["guidance"]:  # the command's default preset, not the class's
            data["guidance"]["preset"] = params["guidance_preset"]
        return data
    except SettingsError as error:
        raise typer.BadParameter(str(error), param_hint="--config / --set") from None


def build_config(cls, data: dict):
    """`cls` (EvalConfig or RunConfig) from a config dict, each problem one usage error naming the setting."""
    from lano3dp.config_tree import SettingsError, from_dict

    try:
        return from_dict(cls, data)
    except SettingsError as error:
        raise typer.BadParameter(str(error), param_hint="settings") from None


def run_folder(out: Path | None, command: str, *, overwrite: bool, marker: str) -> Path:
    """Where a command writes: `out`, or a new `outputs/<command>/<date>_<time>/` (a suffix when two start in one
    second). An existing `out` that holds `marker` (a finished result) is refused unless `overwrite`."""
    from datetime import datetime

    if out is None:
        base = Path("outputs") / command / datetime.now().strftime("%Y-%m-%d_%H-%M-%S")
        out, number = base, 1
        while out.exists():
            number += 1
            out = base.with_name(f"{base.name}_{number}")
        return out
    if (Path(out) / marker).exists() and not overwrite:
        raise typer.BadParameter(f"{out} already holds a finished {command} ({marker}); pass --overwrite to replace "
                                 "it, or another --out", param_hint="--out")
    return Path(out)
