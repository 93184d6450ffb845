"""Option checks run before a command does any work, each failing as a usage error (exit 2) naming the option."""

from __future__ import annotations

from pathlib import Path

import typer

GUIDANCE_MODES = ("none", "noisy", "clean")
SCHEDULERS = ("ddpm", "ddim")


def output_path(path: Path | None, option: str = "--out", *, folder: bool) -> Path | None:
    """`path` can be written: no regular file on the way to it, a file where a file is wanted and a folder
    where a folder is (an existing one is fine: commands resume into it), and a writable nearest folder."""
    import os

    if path is None:
        return None
    absolute = Path(path).absolute()
    if absolute.exists():
        if folder and not absolute.is_dir():
            raise typer.BadParameter(f"{path} is a file; give a folder", param_hint=option)
        if not folder and absolute.is_dir():
            raise typer.BadParameter(f"{path} is a folder; give a file name", param_hint=option)
    for ancestor in absolute.parents:
        if ancestor.exists():
            if not ancestor.is_dir():
                raise typer.BadParameter(f"cannot write {path}: {ancestor} is a file, not a folder", param_hint=option)
            if not os.access(ancestor, os.W_OK):
                raise typer.BadParameter(f"cannot write {path}: {ancestor} is not writable", param_hint=option)
            break
    return path


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


SEGMENTERS = ("sim", "open-vocab")
DETECTORS = ("grounding_dino", "owlv2")
SEGMENTER_HELP = "Perception: sim (the simulator's ground-truth masks) | open-vocab (detector + SAM, the paper's)."
DETECTOR_DIR_HELP = "open-vocab: local folder of the detector's weights (never downloaded)."
SAM_DIR_HELP = "open-vocab: local folder of SAM's weights (never downloaded)."


def segmenter(kind: str, detector: str, detector_dir: Path | None, sam_dir: Path | None) -> None:
    """--segmenter and its weight folders, checked before any episode runs."""
    choice(kind, SEGMENTERS, "--segmenter")
    choice(detector, DETECTORS, "--detector")
    existing_path(detector_dir, "--detector-dir")
    existing_path(sam_dir, "--sam-dir")
    if kind == "open-vocab":
        missing = [name for name, path in (("--detector-dir", detector_dir), ("--sam-dir", sam_dir)) if path is None]
        if missing:
            raise typer.BadParameter(f"open-vocab needs local weight folders: give {' and '.join(missing)}",
                                     param_hint="--segmenter")


def obstacle_shape_help() -> str:
    """--obstacle-shape's help: the names registered when the command line is imported (torch-free)."""
    from lano3dp.guidance.shapes import obstacle_shape_names

    return (f"Shape fitted to each obstacle's points: {' | '.join(obstacle_shape_names())} (cylinder: the paper's); "
            "more with lano3dp.guidance.register_obstacle_shape, e.g. in the --env module.")


def obstacle_shape(name: str, option: str = "--obstacle-shape") -> str:
    """A registered shape; checked after --env is imported, since that module may register one."""
    from lano3dp.guidance.shapes import UnknownObstacleShapeError, get_obstacle_shape

    try:
        get_obstacle_shape(name)
    except UnknownObstacleShapeError as error:
        raise typer.BadParameter(str(error), param_hint=option) from None
    return name


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
