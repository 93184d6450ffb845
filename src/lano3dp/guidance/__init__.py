"""Training-free, cost-guided sampling (the paper's Algorithm 1), obstacle costs and checked execution.

Names are imported on first use (module __getattr__, as `lano3dp` itself does), so the command line can read
the obstacle-shape registry (`guidance.shapes`) for its --help without importing torch.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

# public name -> module that defines it
_EXPORTS = {
    "CheckConfig": "checked", "CheckedResult": "checked", "checked_sample": "checked",
    "AnchoredPath": "costs", "Cylinder": "costs", "Densified": "costs", "MetricGradient": "costs", "Obstacle": "costs",
    "ObstacleSet": "costs", "OrientedBox": "costs", "PointCloudObstacle": "costs", "PositionCost": "costs",
    "Sphere": "costs", "SweptBody": "costs", "densify": "costs", "min_clearance": "costs",
    "obstacle_guidance_cost": "costs", "push_clear": "costs", "ExecutedPath": "costs", "clear_prefix": "costs",
    "reached_positions": "costs", "TurnedPush": "costs", "ObstacleTracker": "obstacles", "CostRecipe": "recipe",
    "ChunkFilter": "execution", "FilterContext": "execution", "FilterResult": "execution", "Proposal": "execution",
    "register_chunk_filter": "execution", "chunk_filter_names": "execution",
    "CollisionError": "exceptions", "GuidanceError": "exceptions",
    "fit_box": "fitting", "fit_cylinder": "fitting", "bridge_narrow_gaps": "fitting",
    "DenoiseStep": "sampler", "GuidanceConfig": "sampler", "GuidanceMode": "sampler", "denoise": "sampler",
    "ObstacleShape": "shapes", "UnknownObstacleShapeError": "shapes", "get_obstacle_shape": "shapes",
    "obstacle_shape_names": "shapes", "register_obstacle_shape": "shapes", "unregister_obstacle_shape": "shapes",
    "GuidanceSettings": "settings", "SamplerSettings": "settings", "CostSettings": "settings",
    "ObstacleSettings": "settings", "ExecutionSettings": "settings", "SAFETY_MARGIN": "settings",
    "guidance_preset": "settings", "register_guidance_preset": "settings", "resolve_guidance": "settings",
    "load_guidance_tuning": "settings", "save_guidance_tuning": "settings",
}

__all__ = [
    "SAFETY_MARGIN", "AnchoredPath", "CheckConfig", "CheckedResult", "ChunkFilter", "CollisionError", "CostRecipe",
    "CostSettings", "Cylinder", "DenoiseStep", "Densified", "ExecutedPath", "ExecutionSettings", "FilterContext",
    "FilterResult", "GuidanceConfig", "GuidanceError", "GuidanceMode", "GuidanceSettings", "MetricGradient",
    "Obstacle", "ObstacleSet", "ObstacleSettings", "ObstacleShape", "ObstacleTracker", "OrientedBox",
    "PointCloudObstacle", "PositionCost", "Proposal", "SamplerSettings", "Sphere", "SweptBody", "TurnedPush",
    "UnknownObstacleShapeError", "bridge_narrow_gaps", "checked_sample", "chunk_filter_names", "clear_prefix",
    "denoise", "densify", "fit_box", "fit_cylinder", "get_obstacle_shape", "guidance_preset", "load_guidance_tuning",
    "min_clearance", "obstacle_guidance_cost", "obstacle_shape_names", "push_clear", "reached_positions",
    "register_chunk_filter", "register_guidance_preset", "register_obstacle_shape", "resolve_guidance",
    "save_guidance_tuning", "unregister_obstacle_shape",
]

if TYPE_CHECKING:  # for type checkers and IDEs; at run time __getattr__ imports on demand
    from lano3dp.guidance.checked import CheckConfig, CheckedResult, checked_sample
    from lano3dp.guidance.costs import (
        AnchoredPath,
        Cylinder,
        Densified,
        ExecutedPath,
        MetricGradient,
        Obstacle,
        ObstacleSet,
        OrientedBox,
        PointCloudObstacle,
        PositionCost,
        Sphere,
        SweptBody,
        TurnedPush,
        clear_prefix,
        densify,
        min_clearance,
        obstacle_guidance_cost,
        push_clear,
        reached_positions,
    )
    from lano3dp.guidance.exceptions import CollisionError, GuidanceError
    from lano3dp.guidance.execution import (
        ChunkFilter,
        FilterContext,
        FilterResult,
        Proposal,
        chunk_filter_names,
        register_chunk_filter,
    )
    from lano3dp.guidance.fitting import bridge_narrow_gaps, fit_box, fit_cylinder
    from lano3dp.guidance.obstacles import ObstacleTracker
    from lano3dp.guidance.recipe import CostRecipe
    from lano3dp.guidance.sampler import DenoiseStep, GuidanceConfig, GuidanceMode, denoise
    from lano3dp.guidance.settings import (
        SAFETY_MARGIN,
        CostSettings,
        ExecutionSettings,
        GuidanceSettings,
        ObstacleSettings,
        SamplerSettings,
        guidance_preset,
        load_guidance_tuning,
        register_guidance_preset,
        resolve_guidance,
        save_guidance_tuning,
    )
    from lano3dp.guidance.shapes import (
        ObstacleShape,
        UnknownObstacleShapeError,
        get_obstacle_shape,
        obstacle_shape_names,
        register_obstacle_shape,
        unregister_obstacle_shape,
    )


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value  # later look-ups skip __getattr__
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
