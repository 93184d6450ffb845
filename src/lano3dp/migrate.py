"""One-shot conversion of files written by earlier versions into today's formats (`lano3dp migrate PATH ...`).

The readers of lano3dp read the current format only; this module is the one place that knows the earlier ones,
and docs/compat.md lists each break. It converts, in place (atomically, leaving files already current as they
are):

    policy folders      guidance.json version 1 (flat tuned fields) -> version 2 (a preset plus dotted overrides);
                        config.json without action_frame / object_pose_features / object_pose_skew -> with the
                        values such configs were trained with; a training run's train_config.json without
                        time_stride -> 1
    results files       an evaluation's results (its flat or sectioned EvalConfig) -> today's config and
                        guidance tree; every other results JSON gets the schema, its kind and a provenance block
                        that says what is known of how it was made (its command, moved there; the last commit that
                        changed the file and that commit's date, when the file lies in a git checkout); obstacle
                        descriptions without a "kind" get their built-in shape's
"""

from __future__ import annotations

import json
import re
import subprocess
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from lano3dp.config_tree import to_dict
from lano3dp.guidance.settings import (
    GUIDANCE_TUNING_FORMAT,
    GUIDANCE_TUNING_NAME,
    GUIDANCE_TUNING_VERSION,
    CostSettings,
    ExecutionSettings,
    GuidanceSettings,
    ObstacleSettings,
    SamplerSettings,
    guidance_preset,
)
from lano3dp.jsonio import write_json
from lano3dp.provenance import RESULTS_SCHEMA

# ---- guidance settings before the tree (flat GuidanceSettings + ObstacleSettings + EvalConfig's scheduler) ----
# What the flat settings defaulted to (the recommended preset of that version).
_FLAT_DEFAULTS: dict[str, Any] = {
    "mode": "clean", "rho": 0.04, "last_steps": 100, "per_train_step": False, "metric_gradient": True, "densify": 4,
    "guided_clip_range": None, "push_weight": "constant", "checked": False, "guide_when_needed": False,
    "anchored": True, "repair_steps": 20, "hold_unclear": True, "push_turn": 0.0, "bridge_gaps": True,
    "escape_when_inside": True, "follow_when_stuck": True,
}
# What results saved before a field existed were made with, where that is not the flat default.
_FLAT_BEFORE = {"anchored": False, "repair_steps": 0, "hold_unclear": False, "push_turn": 0.0, "bridge_gaps": False,
                "escape_when_inside": False, "follow_when_stuck": False}
# Flat EvalConfig fields (before the settings had sections) -> (section, field).
_FLAT_EVAL_FIELDS = {
    "guidance": ("guidance", "mode"), "rho": ("guidance", "rho"), "last_steps": ("guidance", "last_steps"),
    "per_train_step": ("guidance", "per_train_step"), "metric_gradient": ("guidance", "metric_gradient"),
    "densify": ("guidance", "densify"), "checked": ("guidance", "checked"),
    "guide_when_needed": ("guidance", "guide_when_needed"), "obstacle_shape": ("obstacle", "shape"),
    "margin": ("obstacle", "margin"), "body": ("obstacle", "body"), "held_radius": ("obstacle", "held_radius"),
    "refit_obstacles": ("obstacle", "refit"), "segmenter": ("perception", "segmenter"),
    "detector": ("perception", "detector"), "detector_dir": ("perception", "detector_dir"),
    "sam_dir": ("perception", "sam_dir"), "image_size": ("perception", "image_size"),
}


def guidance_tree(flat: Mapping[str, Any], obstacle: Mapping[str, Any] | None = None,
                  scheduler: str | None = None, steps: int | None = None) -> GuidanceSettings:
    """Today's settings tree for the flat guidance fields of earlier versions (missing ones at their defaults),
    an obstacle section, and EvalConfig's scheduler and steps. A setting that did nothing in its combination
    (escape or follow without hold, filters while unguided) is left out, as it changed no episode."""
    g = {**_FLAT_DEFAULTS, **{k: v for k, v in flat.items() if k in _FLAT_DEFAULTS}}
    guided = g["mode"] != "none"
    strategy = "checked" if g["checked"] else "when_needed" if g["guide_when_needed"] and guided else "always"
    filters, options = [], {}
    if guided and g["repair_steps"]:
        filters.append("repair")
        if g["repair_steps"] != 20:
            options["repair"] = {"steps": int(g["repair_steps"])}
    if guided and g["hold_unclear"]:
        filters += ["hold"] + (["escape"] if g["escape_when_inside"] else []) \
            + (["follow"] if g["follow_when_stuck"] else [])
    obstacle = dict(obstacle or {})
    return GuidanceSettings(
        sampler=SamplerSettings(mode=g["mode"], rho=g["rho"], last_steps=g["last_steps"],
                                per_train_step=g["per_train_step"], clip_range=g["guided_clip_range"],
                                push_weight=g["push_weight"], scheduler=scheduler, steps=steps, strategy=strategy),
        cost=CostSettings(metric_push=g["metric_gradient"], densify=g["densify"], anchored=g["anchored"],
                          push_turn=g["push_turn"] if g["anchored"] else 0.0),
        obstacles=ObstacleSettings(**{k: v for k, v in obstacle.items() if k in ObstacleSettings.__dataclass_fields__},
                                   bridge_gaps=g["bridge_gaps"]),
        execution=ExecutionSettings(filters=tuple(filters), options=options))


def changes_from(settings: GuidanceSettings, preset_name: str) -> dict[str, Any]:
    """The dotted overrides that turn the named preset into `settings`."""
    def flatten(node, prefix=""):
        out = {}
        for key, value in node.items():
            if isinstance(value, dict) and value and key != "options":
                out.update(flatten(value, f"{prefix}{key}."))
            else:
                out[f"{prefix}{key}"] = value
        return out

    base, wanted = flatten(to_dict(guidance_preset(preset_name))), flatten(to_dict(settings))
    return {path: value for path, value in wanted.items() if base.get(path) != value}


# ---- policy folders -----------------------------------------------------------------------------------
# PolicyConfig fields added after checkpoints were first shipped, and what earlier configs were trained with.
_POLICY_FIELDS_BEFORE = {"action_frame": "absolute", "object_pose_features": False, "object_pose_skew": False}
_TRAIN_FIELDS_BEFORE = {"time_stride": 1}


def _state_train_fields(train: Path) -> list[str]:
    """A training run's train_config.json with the fields added since, at what such runs were trained with."""
    data = json.loads(train.read_text())
    missing = {k: v for k, v in _TRAIN_FIELDS_BEFORE.items() if k not in data}
    if not missing:
        return []
    write_json(train, {**data, **missing})
    return [f"{train}: stated {', '.join(missing)}"]


def migrate_policy_folder(folder: Path) -> list[str]:
    """Convert a policy folder's files in place; returns what changed (one line each). A sealed folder is
    re-sealed over the converted files only (an edit by hand still shows); an unsealed one is left for its owner
    to check and seal (`lano3dp checkpoint seal`)."""
    from lano3dp.policy.integrity import read_manifest, reseal_after_writing

    changed, converted = [], []
    tuning = folder / GUIDANCE_TUNING_NAME
    if tuning.exists():
        data = json.loads(tuning.read_text())
        if data.get("format") == GUIDANCE_TUNING_FORMAT and "version" not in data:
            settings = guidance_tree(data["settings"])
            write_json(tuning, {"format": GUIDANCE_TUNING_FORMAT, "version": GUIDANCE_TUNING_VERSION,
                                "preset": "recommended", "overrides": changes_from(settings, "recommended"),
                                "measured": data.get("measured", "")})
            changed.append(f"{tuning}: version 1 -> 2")
            converted.append(tuning.name)
    config = folder / "config.json"
    if config.exists():
        data = json.loads(config.read_text())
        missing = {k: v for k, v in _POLICY_FIELDS_BEFORE.items() if k not in data}
        if missing:
            config.write_text(json.dumps({**data, **missing}, indent=2, sort_keys=True) + "\n")
            changed.append(f"{config}: stated {', '.join(missing)}")
            converted.append(config.name)
    if converted and read_manifest(folder) is not None:
        reseal_after_writing(folder, converted)
        changed.append(f"{folder}: re-sealed over {', '.join(converted)}")
    return changed


# ---- results files ------------------------------------------------------------------------------------
def _sectioned_eval_config(made: Mapping[str, Any]) -> dict[str, Any]:
    """An EvalConfig dict of an earlier version (flat, or with guidance/obstacle/perception sections)."""
    made = json.loads(json.dumps(dict(made)))
    flat = not any(isinstance(made.get(name), Mapping) for name in ("guidance", "obstacle", "perception"))
    for old, (section, name) in _FLAT_EVAL_FIELDS.items():
        if old in made and not isinstance(made[old], Mapping):
            made.setdefault(section, {})[name] = made.pop(old)
        elif flat and old == "body":
            made.setdefault("obstacle", {})["body"] = "sphere"  # flat results predate the swept body
    for source, name in (("obstacle", "bridge_gaps"), ("obstacle", "escape_when_inside")):
        if isinstance(made.get(source), dict) and name in made[source]:
            made.setdefault("guidance", {})[name] = made[source].pop(name)
    guidance = made.get("guidance") or {}
    if guidance.get("mode", "none") != "none":
        made["guidance"] = {**_FLAT_BEFORE, **guidance}
    return made


def eval_config_now(made: Mapping[str, Any]) -> dict[str, Any]:
    """Today's EvalConfig dict for one saved by an earlier version: the guidance that ran, as the recommended (or,
    unguided, the none) preset plus the overrides that make it."""
    old = _sectioned_eval_config(made)
    settings = guidance_tree(old.get("guidance") or {"mode": "none"}, old.get("obstacle"), old.get("scheduler"),
                             old.get("steps"))
    preset_name = "recommended" if settings.guided else "none"
    fields = ("checkpoint", "task", "variation", "episodes", "seed", "obstacles", "n_action_steps", "max_steps",
              "obstacle_scenes_only", "workers", "video_dir", "n_videos", "out", "env")
    config = {name: old[name] for name in fields if name in old}
    config["guidance"] = {"preset": preset_name, "overrides": changes_from(settings, preset_name)}
    if isinstance(old.get("perception"), Mapping):
        config["perception"] = dict(old["perception"])
    return config


def _git_last_change(path: Path) -> tuple[str | None, str | None]:
    """(commit, its ISO date) of the last commit that changed `path`, or (None, None) outside a git checkout."""
    try:
        out = subprocess.run(["git", "log", "-1", "--format=%H %cI", "--", path.name], cwd=path.parent,
                             capture_output=True, text=True, timeout=20, check=True).stdout.split()
    except (OSError, subprocess.SubprocessError):
        return None, None
    return (out[0], out[1]) if len(out) == 2 else (None, None)


def _commands(data: Mapping[str, Any]) -> str | list[str] | None:
    """The command(s) a results file says made it: its own, its "meta" block's, or those of the evaluations it
    gathers (one entry each under "runs" or "tasks"); a list when several."""
    meta = data.get("meta") if isinstance(data.get("meta"), Mapping) else {}
    found = data.get("command") or data.get("commands") or meta.get("command") or meta.get("commands")
    if not found:
        found = [entry["command"] for section in ("runs", "tasks") if isinstance(data.get(section), Mapping)
                 for entry in data[section].values() if isinstance(entry, Mapping) and entry.get("command")]
    if isinstance(found, list) and len(found) == 1:
        return found[0]
    return found or None


def _results_kind(path: Path, command: str | list[str] | None) -> str:
    """The bench script that made the file (`bench/bench_obstacles.py` -> "obstacles"), else its name's first
    word."""
    for text in [command] if isinstance(command, str) else command or []:
        if match := re.search(r"bench/bench_(\w+)\.py", text):
            return match.group(1)
    return path.stem.split("_")[0]


# Cost classes of the built-in obstacle shapes: obstacles described before they named their shape ("kind")
_SHAPE_OF_COST = {"Cylinder": "cylinder", "OrientedBox": "box", "PointCloudObstacle": "points"}


def _name_obstacle_shapes(node: Any) -> int:
    """Give every obstacle description (`guidance.shapes.describe_obstacle`) without a "kind" the built-in shape
    that drew it (by its cost class, else by its numbers: a radius a cylinder, corners a box); returns how many."""
    named = 0
    if isinstance(node, dict):
        if isinstance(node.get("shape"), str) and "repr" in node and "kind" not in node:
            kind = _SHAPE_OF_COST.get(node["shape"]) or ("cylinder" if "radius" in node else
                                                         "box" if "corners" in node else None)
            if kind is not None:
                node["kind"] = kind
                named += 1
        return named + sum(_name_obstacle_shapes(value) for value in node.values())
    if isinstance(node, list):
        return sum(_name_obstacle_shapes(value) for value in node)
    return 0


def migrate_results_file(path: Path) -> list[str]:
    """Convert one results JSON in place; returns what changed."""
    data = json.loads(path.read_text())
    if not isinstance(data, dict) or data.get("schema") == RESULTS_SCHEMA:
        return []
    is_eval = isinstance(data.get("config"), Mapping) and "summary" in data and "episodes" in data
    command = _commands(data)
    for name in ("command", "commands"):  # moved into the provenance block
        data.pop(name, None)
    # a few files recorded their commit already, at the top level: it moves into the provenance block too
    commit = data.pop("commit", None) if isinstance(data.get("commit"), str) else None
    dirty = data.pop("dirty", None) if commit else None
    machine = data.get("machine") if isinstance(data.get("machine"), Mapping) else None
    if commit and isinstance(data.get("machine"), str):
        machine = {"description": data.pop("machine"), "python": data.pop("python", None)}
    committed_in, committed_utc = _git_last_change(path)
    record: dict[str, Any] = {
        "schema": RESULTS_SCHEMA, "kind": "eval" if is_eval else _results_kind(path, command),
        "provenance": {"command": command, "commit": commit, "dirty": dirty, "behaviour_version": 0,
                       "versions": data.get("versions") or (machine or {}).get("versions"), "machine": machine,
                       "created_utc": (data.get("timing") or {}).get("started_utc") or data.get("when_utc"),
                       "config": data.get("config") if isinstance(data.get("config"), Mapping) else None,
                       "committed_in": committed_in, "committed_utc": committed_utc,
                       "note": "made before the results format had a provenance block; behaviour version 0 is "
                               "the code before the runtime redesign" + ("" if commit else "; committed_in is the "
                               "last commit that changed the file before `lano3dp migrate` converted it")},
    }
    if is_eval:
        record["config"] = eval_config_now(data.pop("config"))
        record["provenance"]["config"] = record["config"]
    named = _name_obstacle_shapes(data)
    write_json(path, {**record, **data})
    return [f"{path}: {'an evaluation' if is_eval else 'a results file'} given schema and provenance"
            + (f"; {named} obstacle descriptions given their shape's kind" if named else "")]


def migrate(paths: list[Path]) -> list[str]:
    """Convert every policy folder and results JSON under `paths`; returns what changed."""
    changed: list[str] = []
    for path in paths:
        path = Path(path)
        if path.is_file() and path.suffix == ".json":
            changed += migrate_results_file(path)
            continue
        for folder in sorted({p.parent for p in path.rglob("config.json")} | ({path} if path.is_dir() else set())):
            if (folder / "config.json").exists() and (folder / "model.safetensors").exists():
                changed += migrate_policy_folder(folder)
        for train in sorted({p.resolve() for p in path.rglob("train_config.json")}):
            changed += _state_train_fields(train)
    return changed
