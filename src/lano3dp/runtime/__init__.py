"""Closed-loop runtime: frames -> the policy's observations -> (guided) action chunks -> env steps.

The loop of the paper's deployment phase (Fig. 1), for any environment that meets the simulator protocol
(`lano3dp.sim.protocol`): `reset(seed, options) -> (obs, info)` and `step(action (10,)) -> (obs, reward,
terminated, truncated, info)`, where `obs` carries an `RGBDFrame` and the 11-D robot state.

    PolicyRunner    observe -> update the obstacle tracker -> sample (runtime.sampling) -> chunk filters -> act
    rollout         one episode with a runner, measured (EpisodeResult)

This package imports torch and the policy/guidance layers but never the simulator: the env is duck-typed, so a
user's own robot plugs in the same way.
"""

from lano3dp.runtime.rollout import SUCCESS_AT, EpisodeResult, path_length, rollout, scene_obstacles
from lano3dp.runtime.runner import ChunkRecord, ClosedLoopError, PolicyRunner, interpolate_action

__all__ = ["SUCCESS_AT", "ChunkRecord", "ClosedLoopError", "EpisodeResult", "PolicyRunner", "interpolate_action",
           "path_length", "rollout", "scene_obstacles"]
