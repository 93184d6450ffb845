"""What a user chooses about guidance and obstacles, as plain data: the one place their defaults are written.

    GuidanceSettings   how a chunk is guided: mode, rho, S, the push (metric or the paper's), densify, clipping,
                       checked execution. Its defaults are the recommended preset, GUIDANCE_PRESETS["recommended"].
    ObstacleSettings   how an obstacle's points become a cost: the fitted shape, the body kept clear, the margin.
    SAFETY_MARGIN      the 2 cm beyond contact at which every obstacle cost starts pushing.
    load_guidance_tuning / save_guidance_tuning
                       the guidance a checkpoint was tuned with (its `guidance.json`), which
                       `GuidanceSettings.tuned_for` lays over the recommended preset.

`evaluate.EvalConfig` and `RunConfig` nest these (and save them verbatim in results); `runtime.RuntimeConfig.
from_settings` turns them into what the runner executes, and `RuntimeConfig`'s own defaults are read from here,
so the README's stated defaults, the command line's and the runtime's are one set (tests/test_config_defaults.py).

This module imports neither torch nor the sampler, so the command line can read defaults for its --help cheaply.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

from lano3dp.errors import CorruptFileError
from lano3dp.jsonio import write_json

# Metres beyond contact at which an obstacle cost starts pushing (part of Q*).
SAFETY_MARGIN = 0.02
GUIDANCE_MODES = ("none", "noisy", "clean")  # none; the cost on A_k (prior work); on A_0|k (the paper)
PUSH_WEIGHTS = ("constant", "alpha_bar")  # see guidance.sampler's module docstring
BODY_MODELS = ("swept", "sphere")


@dataclass(frozen=True)
class GuidanceSettings:
    """How chunks are guided. The defaults are the recommended preset: A_0|k cost on every DDIM step (S = 100
    training steps covers all 10), an isotropic push of 4 cm per guided step on the path densified x4, every push
    of the same weight and the scheduler's clipping, the path costed from the hand, pushed clear after sampling
    along the path the arm will take, and only its predicted-clear start executed. Closed-loop results
    (results/obstacles*.md): results/obstacles_hold.md has these (results/obstacles_rho02.md the same with a
    2 cm push: bowl_pour up, the drawer tasks down, more touches of a moving obstacle; results/obstacles_turn.md
    with each push turned 60 degrees round its obstacle: bowl_pour stalls less but misses more pours, and
    touches rose; results/obstacles_turn_half.md that with rho 0.02: bowl_pour 82%, the drawer tasks down);
    those before it lack the cut, and those before results/obstacles_anchored.md the anchored path and the
    repair too. The synthetic sweep (results/bench_guidance.json, issue 3) has no row of them: its nearest,
    DDIM-10 at rho 0.04 on every step with push_weight "alpha_bar" and guided_clip_range 3, left 1% of sampled
    paths with a segment through the obstacle (2 cm: 19%).
    GUIDANCE_PRESETS["paper"] is the paper's form.

    Attributes:
        mode: "none", "noisy" (cost on A_k) or "clean" (the paper's A_0|k).
        rho: the guidance scale: metres per guided step with `metric_gradient`, else normalised action units.
        last_steps: S; guide while the training-scale step k <= S (100: every step).
        per_train_step: multiply rho by the scheduler stride, so DDIM pushes as much in total as DDPM-100.
        metric_gradient: push isotropically in metres (`guidance.MetricGradient`); False is the paper's push in
            the normaliser's units (rho then needs to be far larger).
        densify: points per path segment the cost and the check see (1: waypoints only, as the paper).
        guided_clip_range: guided steps clip the x_0 estimate to [-r, r] (normalised units) instead of the
            scheduler's [-1, 1]; None keeps the scheduler's. Finite, as results JSON cannot hold inf.
        push_weight: "constant" (the paper) or "alpha_bar" (each push times sqrt(abar_k abar_k-1); for DDIM).
        checked: checked execution (re-sample with a larger rho while the executed part collides).
        guide_when_needed: guide a chunk only when the policy's own one comes within the margin of an obstacle.
        anchored: cost the path from the EE's present position through the waypoints, so the step from
            the hand to the first action is pushed clear too (`guidance.AnchoredPath`; the paper costs the
            horizon's waypoints alone).
        repair_steps: after sampling, at most this many 1 cm steps of plain descent move the chunk's waypoints
            until the path the arm will take through them clears every obstacle by the margin
            (`guidance.push_clear` on `guidance.ExecutedPath`; 0: off, the paper's): guidance pushes while the
            network pulls back, so a guided chunk can end inside the margin.
        hold_unclear: execute only the start of a guided chunk predicted to keep half the margin, holding still
            when none does, and re-plan (`guidance.clear_prefix`; the paper executes every chunk whole).
        push_turn: degrees by which each obstacle's push is turned round it, towards the side the chunk already
            passes (`guidance.TurnedPush`; needs `anchored`; 0: straight away from it, the paper's): a chunk
            headed straight at an obstacle is then carried round it instead of back.
        bridge_gaps: also guide against a wall across every gap between two obstacles too narrow for the hand
            (`guidance.bridge_narrow_gaps`), so the path goes round the pair rather than stalling at the gap
            (two-obstacle tuning scenes, 50 each: put_item 29 against 18 successes, bottle_in_drawer 31 against 21).
        escape_when_inside: with `hold_unclear`, a hand already closer to an obstacle than the hold keeps (a
            moving obstacle came at it) executes the start of a chunk that gets no closer, or steps straight out
            when every chunk leads deeper, rather than holding still while the obstacle walks into it.
        follow_when_stuck: with `hold_unclear`, a hand held still for several chunks in a row (a blocked way, the
            network aiming through) follows the nearest obstacle's boundary, a step at a time, until its chunks
            run again with a clear way to their end (`PolicyRunner.follow_obstacles`, the Bug algorithm's
            boundary following).
        tuned: take the settings the checkpoint was tuned with (its `guidance.json`, see `tuned_for`) for
            every field not in `keep` (the paper preset: off, its form is fixed).
        keep: fields the user chose, which a checkpoint's tuning leaves as they are (the command line fills it
            with the guidance options given).
    """

    mode: str = "clean"
    rho: float = 0.04
    last_steps: int = 100
    per_train_step: bool = False
    metric_gradient: bool = True
    densify: int = 4
    guided_clip_range: float | None = None
    push_weight: str = "constant"
    checked: bool = False
    guide_when_needed: bool = False
    anchored: bool = True
    repair_steps: int = 20
    hold_unclear: bool = True
    push_turn: float = 0.0
    bridge_gaps: bool = True
    escape_when_inside: bool = True
    follow_when_stuck: bool = True
    tuned: bool = True
    keep: tuple[str, ...] = ()

    def __post_init__(self):
        object.__setattr__(self, "keep", tuple(self.keep))  # a saved config holds a list
        if unknown := sorted(set(self.keep) - set(TUNABLE_FIELDS)):
            raise ValueError(f"keep names no tunable guidance setting: {', '.join(unknown)} (tunable: "
                             f"{', '.join(TUNABLE_FIELDS)})")
        if self.mode not in GUIDANCE_MODES:
            raise ValueError(f"guidance must be 'none', 'noisy' or 'clean', got {self.mode!r}")
        if self.rho < 0 or self.last_steps < 0:
            raise ValueError(f"guidance rho and S must be >= 0, got {self.rho}, {self.last_steps}")
        if self.densify < 1:
            raise ValueError(f"densify must be >= 1, got {self.densify}")
        if self.repair_steps < 0:
            raise ValueError(f"repair_steps must be >= 0, got {self.repair_steps}")
        if not 0 <= self.push_turn < 90:
            raise ValueError(f"push_turn must be in [0, 90) degrees, got {self.push_turn}")
        if self.guided_clip_range is not None and not (0 < self.guided_clip_range < math.inf):
            raise ValueError(f"guided_clip_range must be a finite number > 0 or None, got {self.guided_clip_range}")
        if self.push_weight not in PUSH_WEIGHTS:
            raise ValueError(f"push_weight must be one of {', '.join(PUSH_WEIGHTS)}, got {self.push_weight!r}")

    @property
    def guided(self) -> bool:
        return self.mode != "none"

    def ineffective(self) -> list[str]:
        """Notes for the user on settings that change nothing in this combination."""
        if self.guided and self.push_turn and not self.anchored:
            return [f"push_turn {self.push_turn:g} has no effect without anchored (--anchored): the turn needs the "
                    "hand's position"]
        return []

    def tuning_taken(self, tuning: Mapping[str, Any]) -> dict[str, Any]:
        """What of a checkpoint's tuning (`load_guidance_tuning`) these settings take: every field not in `keep`,
        none when `tuned` is off or the mode unguided."""
        if not (self.tuned and self.guided):
            return {}
        return {name: value for name, value in tuning.items() if name not in self.keep}

    def tuned_for(self, tuning: Mapping[str, Any]) -> GuidanceSettings:
        """These settings with what they take of a checkpoint's tuning laid over them (applying it twice changes
        nothing more)."""
        taken = self.tuning_taken(tuning)
        return replace(self, **taken) if taken else self


# The settings a checkpoint's tuning may set: how a chunk is guided, not whether (mode) or the tuning's own switches.
TUNABLE_FIELDS = tuple(f.name for f in fields(GuidanceSettings) if f.name not in ("mode", "tuned", "keep"))
GUIDANCE_TUNING_NAME = "guidance.json"
GUIDANCE_TUNING_FORMAT = "lano3dp-guidance-tuning"


def load_guidance_tuning(checkpoint: str | Path) -> dict[str, Any]:
    """The guidance settings a policy folder was tuned with ({} when it has no `guidance.json`).

    Tuning belongs to the weights it was measured with: re-packaging a policy (`export_fp16`) does not carry it.
    A file that is not JSON, or names a setting that is not tunable or a value out of range, fails here with
    its path, before any episode runs."""
    path = Path(checkpoint) / GUIDANCE_TUNING_NAME
    if not path.exists():
        return {}
    try:
        data = json.loads(path.read_text())
        settings = data["settings"]
        if data.get("format") != GUIDANCE_TUNING_FORMAT or not isinstance(settings, dict):
            raise ValueError(f"not a {GUIDANCE_TUNING_FORMAT} file")
        _check_tuning(settings)
    except (ValueError, KeyError, TypeError) as error:
        raise CorruptFileError(path, f"not a guidance tuning ({error}); fix or delete it to use the recommended "
                                     "guidance") from None
    return dict(settings)


def _check_tuning(settings: Mapping[str, Any]) -> None:
    if unknown := sorted(set(settings) - set(TUNABLE_FIELDS)):
        raise ValueError(f"{', '.join(unknown)} cannot be tuned (tunable: {', '.join(TUNABLE_FIELDS)})")
    GuidanceSettings(**settings)  # the values' own checks


def save_guidance_tuning(checkpoint: str | Path, settings: Mapping[str, Any], measured: str) -> Path:
    """Write the guidance `checkpoint` was tuned with (atomically), with `measured`: where the tuning was chosen
    and confirmed (results files and commands), which travels with it."""
    _check_tuning(settings)
    return write_json(Path(checkpoint) / GUIDANCE_TUNING_NAME,
                      {"format": GUIDANCE_TUNING_FORMAT, "settings": dict(settings), "measured": measured})


GUIDANCE_PRESETS: dict[str, GuidanceSettings] = {
    "recommended": GuidanceSettings(),
    # The paper's Algorithm 1 as published: S = 10, the push in normalised units, waypoints only (rho 4 is the
    # smallest with which bench_guidance's DDPM-100 waypoints cleared the obstacle, 1% colliding; the segments
    # between them did not). The paper also sampled with DDPM-100 and kept a ball of the held object's diameter
    # clear: add scheduler "ddpm", steps 100 and ObstacleSettings(body="sphere").
    "paper": GuidanceSettings(rho=4.0, last_steps=10, metric_gradient=False, densify=1, anchored=False,
                              repair_steps=0, hold_unclear=False, push_turn=0.0, bridge_gaps=False,
                              escape_when_inside=False, follow_when_stuck=False, tuned=False),
}


@dataclass(frozen=True)
class ObstacleSettings:
    """How obstacles become costs (the fields of `guidance.obstacle_model.ObstacleModel` a user chooses).

    Attributes:
        shape: the registered shape fitted to each obstacle's points: "cylinder" (the paper), "box", "points",
            or one registered with `lano3dp.guidance.register_obstacle_shape` (see `guidance.shapes`).
        margin: metres beyond contact at which the cost starts pushing (part of Q*).
        body: what guidance keeps clear: "swept" (hand and held object as balls re-measured every chunk) or
            "sphere" (the paper: one ball of held_radius round the EE point).
        held_radius: ("sphere") its radius in m; None measures it from the held object's cloud.
        refit: re-segment and re-fit the obstacles before every chunk (moving obstacles).
    """

    shape: str = "cylinder"
    margin: float = SAFETY_MARGIN
    body: str = "swept"
    held_radius: float | None = None
    refit: bool = False

    def __post_init__(self):
        from lano3dp.guidance.shapes import get_obstacle_shape

        get_obstacle_shape(self.shape)  # an unknown name fails here, naming the registered ones
        if self.body not in BODY_MODELS:
            raise ValueError(f"body must be 'swept' or 'sphere', got {self.body!r}")
        if self.held_radius is not None and self.body != "sphere":
            raise ValueError("a fixed held radius sizes the 'sphere' body model; add body='sphere' (--body sphere)")
        if self.margin < 0 or (self.held_radius is not None and self.held_radius < 0):
            raise ValueError(f"margin and held_radius must be >= 0, got {self.margin}, {self.held_radius}")
