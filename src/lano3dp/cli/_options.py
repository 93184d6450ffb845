"""Option checks run before a command does any work, each failing as a usage error (exit 2) naming the option."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import typer

from lano3dp.evaluate import PerceptionSettings
from lano3dp.guidance.settings import (
    BODY_MODELS,
    GUIDANCE_MODES,
    GUIDANCE_PRESETS,
    PUSH_WEIGHTS,
    TUNABLE_FIELDS,
    GuidanceSettings,
    ObstacleSettings,
)

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


# ---- the settings `eval` and `run` share: one declaration each, mapped onto EvalConfig/RunConfig's sections ----
def _preset_values(name: str) -> str:
    """What each guidance preset sets `name` to, for --help: 'recommended 0.04, paper 4'."""
    def text(value) -> str:
        if isinstance(value, bool):
            return "on" if value else "off"
        if value is None:
            return "none"
        return f"{value:g}" if isinstance(value, float | int) else str(value)

    return ", ".join(f"{preset} {text(getattr(settings, name))}" for preset, settings in GUIDANCE_PRESETS.items())


# Guidance options default to None: the value of --guidance-preset, which a given option overrides.
GUIDANCE_PRESET = typer.Option(
    "recommended", "--guidance-preset",
    help="Settings of guided episodes, each overridable by its option below: recommended (A_0|k on every DDIM step, "
         "metric push, path densified) | paper (S = 10, push in normalised units, waypoints only; with --scheduler "
         "ddpm --steps 100 --body sphere, the paper's whole form).")
RHO = typer.Option(None, "--rho", help="Guidance scale rho: metres per guided step with --metric-push, else "
                                       f"normalised units (default: the preset's: {_preset_values('rho')}).")
LAST_STEPS = typer.Option(None, "--last-steps", min=0, help="S: guide while the training-scale step k <= S (100: "
                                                            f"all; default: {_preset_values('last_steps')}).")
METRIC_PUSH = typer.Option(None, "--metric-push/--paper-push",
                           help="Push isotropically in metres, or as the paper in normalised action units (which "
                                f"needs a far larger rho; default: {_preset_values('metric_gradient')}).")
PER_TRAIN_STEP = typer.Option(None, "--per-train-step/--no-per-train-step",
                              help="Scale rho by the scheduler stride (DDIM pushes as much as DDPM; default: "
                                   f"{_preset_values('per_train_step')}).")
DENSIFY = typer.Option(None, "--densify", min=1, help="Points per path segment the cost sees (1: waypoints only, as "
                                                      f"the paper; default: {_preset_values('densify')}).")
GUIDED_CLIP_RANGE = typer.Option(None, "--guided-clip-range",
                                 help="Guided steps clip x_0 to [-r, r] (normalised units) instead of the "
                                      "scheduler's [-1, 1], so a detour outside the demonstrations' range is not "
                                      f"undone (default: {_preset_values('guided_clip_range')}, the scheduler's).")
PUSH_WEIGHT = typer.Option(None, "--push-weight",
                           help="constant (the paper: every guided step pushes rho * grad) | alpha_bar (each push "
                                "times sqrt(abar_k abar_k-1), for DDIM guided on every step; default: "
                                f"{_preset_values('push_weight')}).")
CHECKED = typer.Option(None, "--checked/--no-checked", help="Checked execution: re-sample with larger rho while a "
                                                            f"chunk collides (default: {_preset_values('checked')}).")
GUIDE_WHEN_NEEDED = typer.Option(None, "--guide-when-needed/--no-guide-when-needed",
                                 help="Guide a chunk only when the policy's own one comes within the margin of an "
                                      f"obstacle (default: {_preset_values('guide_when_needed')}).")
ANCHORED = typer.Option(None, "--anchored/--no-anchored",
                        help="Cost the path from the hand's present position, so the step to the first action is "
                             f"pushed clear too (default: {_preset_values('anchored')}).")
REPAIR_STEPS = typer.Option(None, "--repair-steps", min=0,
                            help="After a guided sample, at most this many 1 cm steps of plain cost descent until "
                                 "the path the arm will take through the chunk clears by the margin (0: off; "
                                 f"default: {_preset_values('repair_steps')}).")
PUSH_TURN = typer.Option(None, "--push-turn", min=0.0, max=89.9,
                         help="Degrees to turn each obstacle's push round it, towards the side the chunk already "
                              "passes, so a chunk headed straight at it goes round rather than back (0: straight "
                              f"away; needs --anchored; default: {_preset_values('push_turn')}).")
BRIDGE_GAPS = typer.Option(None, "--bridge-gaps/--no-bridge-gaps",
                           help="Guide against a wall across every gap between two obstacles too narrow for the "
                                "hand too, so the path goes round the pair instead of stalling at the gap "
                                f"(default: {_preset_values('bridge_gaps')}).")
ESCAPE_INSIDE = typer.Option(None, "--escape-inside/--no-escape-inside",
                             help="With --hold-unclear, a hand already closer to an obstacle than the hold keeps (a "
                                  "moving obstacle came at it) moves where it gets no closer, or straight out, "
                                  f"instead of holding still (default: {_preset_values('escape_when_inside')}).")
FOLLOW_OBSTACLES = typer.Option(None, "--follow-obstacles/--no-follow-obstacles",
                                help="With --hold-unclear, a hand held still for several chunks in a row follows "
                                     "the nearest obstacle's boundary until its chunks run again with a clear way "
                                     f"on (default: {_preset_values('follow_when_stuck')}).")
TUNED = typer.Option(None, "--checkpoint-guidance/--no-checkpoint-guidance",
                     help="Take the guidance the checkpoint was tuned with (its guidance.json) for every guidance "
                          "option not given here, or keep the preset's (default: "
                          f"{_preset_values('tuned')}).")
HOLD_UNCLEAR = typer.Option(None, "--hold-unclear/--no-hold-unclear",
                            help="Execute only the start of a guided chunk predicted to keep half the margin, "
                                 "holding still when none does, and re-plan (default: "
                                 f"{_preset_values('hold_unclear')}).")
OBSTACLE_SHAPE = typer.Option(ObstacleSettings.shape, "--obstacle-shape", metavar="NAME", help=obstacle_shape_help())
MARGIN = typer.Option(ObstacleSettings.margin, "--margin", min=0.0,
                      help="Safety margin (m) beyond contact, part of Q*.")
BODY = typer.Option(ObstacleSettings.body, "--body", help="What guidance keeps clear: swept (hand + held object, "
                                                          "re-measured every chunk) | sphere (the paper: one ball "
                                                          "round the EE point).")
HELD_RADIUS = typer.Option(None, "--held-radius", min=0.0, help="--body sphere: its radius (m) in Q*; default: "
                                                                "measured from the held object's cloud.")
REFIT_OBSTACLES = typer.Option(ObstacleSettings.refit, "--refit-obstacles/--no-refit-obstacles",
                               help="Re-fit obstacles before every chunk (moving obstacles).")
SEGMENTER = typer.Option(PerceptionSettings.segmenter, "--segmenter", help=SEGMENTER_HELP)
DETECTOR = typer.Option(PerceptionSettings.detector, "--detector", help="open-vocab: grounding_dino | owlv2.")
DETECTOR_DIR = typer.Option(None, "--detector-dir", help=DETECTOR_DIR_HELP)
SAM_DIR = typer.Option(None, "--sam-dir", help=SAM_DIR_HELP)
IMAGE_SIZE = typer.Option(None, "--image-size", min=16, help="Camera resolution (default: that of the dataset the "
                                                             "checkpoint was trained on).")


def guidance_settings(mode: str, preset: str, **overrides) -> GuidanceSettings:
    """--guidance and --guidance-preset, with the guidance options that were given (not None) overriding it and
    kept over the checkpoint's tuning."""
    choice(mode, GUIDANCE_MODES, "--guidance")
    choice(preset, tuple(GUIDANCE_PRESETS), "--guidance-preset")
    choice(overrides.get("push_weight"), PUSH_WEIGHTS, "--push-weight")
    given = {name: value for name, value in overrides.items() if value is not None}
    try:
        return replace(GUIDANCE_PRESETS[preset], mode=mode, **given,
                       keep=tuple(name for name in given if name in TUNABLE_FIELDS))
    except ValueError as error:
        raise typer.BadParameter(str(error), param_hint="--guidance") from None


def obstacle_settings(shape: str, margin: float, body: str, held_radius: float | None,
                      refit: bool) -> ObstacleSettings:
    """The obstacle options; the shape is checked here, so call it after --env is imported (it may register one)."""
    choice(body, BODY_MODELS, "--body")
    obstacle_shape(shape)
    if held_radius is not None and body != "sphere":
        raise typer.BadParameter("a fixed held radius sizes the sphere body model; add --body sphere",
                                 param_hint="--held-radius")
    return ObstacleSettings(shape=shape, margin=margin, body=body, held_radius=held_radius, refit=refit)


def perception_settings(kind: str, detector: str, detector_dir: Path | None, sam_dir: Path | None,
                        image_size: int | None) -> PerceptionSettings:
    segmenter(kind, detector, detector_dir, sam_dir)
    return PerceptionSettings(segmenter=kind, detector=detector, detector_dir=detector_dir, sam_dir=sam_dir,
                              image_size=image_size)


# GuidanceSettings field -> the parameter of `eval` and `run` that overrides it
GUIDANCE_OVERRIDES = {"rho": "rho", "last_steps": "last_steps", "metric_gradient": "metric_push",
                      "per_train_step": "per_train_step", "densify": "densify",
                      "guided_clip_range": "guided_clip_range", "push_weight": "push_weight", "checked": "checked",
                      "guide_when_needed": "guide_when_needed", "anchored": "anchored",
                      "repair_steps": "repair_steps", "hold_unclear": "hold_unclear",
                      "push_turn": "push_turn", "bridge_gaps": "bridge_gaps", "escape_when_inside": "escape_inside",
                      "follow_when_stuck": "follow_obstacles", "tuned": "checkpoint_guidance"}


def episode_settings(params: Mapping[str, Any]) -> tuple[GuidanceSettings, ObstacleSettings, PerceptionSettings]:
    """The options `eval` and `run` share, from their parsed parameters (`ctx.params`), checked: --env first (it
    may register an obstacle shape), then the task and variation when the simulator is used, then the guidance,
    scheduler, obstacle and perception options, built into their settings sections."""
    env_factory(params["env"])
    if params["env"] is None:  # a user's env has its own task names and variations
        task_name(params["task"])
        variation(params["variation"])
    guidance = guidance_settings(params["guidance"], params["guidance_preset"],
                                 **{name: params[option] for name, option in GUIDANCE_OVERRIDES.items()})
    choice(params["scheduler"], SCHEDULERS, "--scheduler")
    obstacle = obstacle_settings(params["obstacle_shape"], params["margin"], params["body"], params["held_radius"],
                                 params["refit_obstacles"])
    perception = perception_settings(params["segmenter"], params["detector"], params["detector_dir"],
                                     params["sam_dir"], params["image_size"])
    return guidance, obstacle, perception
