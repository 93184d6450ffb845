"""Task inputs: a low-dimensional vector the env hands over as obs[key] beside the state (source "obs").

A goal-conditioned task draws a new goal every episode, often a site that renders nothing, so no camera shows it:
the env puts it in its observation, obs["goal"] (D,) (a position in metres, world frame, or any task state), and a
policy trained on data that holds it conditions on it. "goal" is registered built in; another key is one call:

    register_observation_type("door_angle", VectorObservation("door_angle"))   # before collecting

Normalised per component (min-max over the dataset, like the state) and encoded by a small MLP whose feature joins
the state's; `PolicyConfig.task_inputs` holds {key: D} (a task-input type is registered under its key). Augmentation
does not move it (it is not known to be a position), so a policy with task inputs trains without --augment.
"""

from __future__ import annotations

from torch import nn

from lano3dp.policy.observations import ObservationType


class VectorEncoder(nn.Module):
    """One normalised task-input vector (M, D) -> (M, out_dim), as the state's MLP (DP3)."""

    def __init__(self, in_dim: int, out_dim: int):
        super().__init__()
        self.mlp = nn.Sequential(nn.Linear(in_dim, out_dim), nn.ReLU(), nn.Linear(out_dim, out_dim))
        self.out_dim = out_dim

    def forward(self, vector):
        return self.mlp(vector)


class VectorObservation(ObservationType):
    """obs[key], a (D,) float vector the env reports every step; D is read off the dataset."""

    source = "obs"

    def __init__(self, key: str):
        self.key = key

    def _length(self, config) -> int:
        if self.key not in config.task_inputs:
            raise ValueError(f"the policy has no task input {self.key!r} (task_inputs {config.task_inputs})")
        return int(config.task_inputs[self.key])

    def encoder(self, config):
        return VectorEncoder(self._length(config), config.state_feature_dim)

    def normalizer_dim(self, config):
        return self._length(config)

    def runtime_input(self, runner, frame):
        raise TypeError(f"obs[{self.key!r}] comes from the env's observation, not from a camera frame")

    def validate(self, config):
        pass  # a task input sits beside any visual input
