"""Configuration of the diffusion policy: a validated dataclass that round-trips through JSON.

Defaults follow the paper's CNN diffusion policy (Chi et al.) on object clouds (DP3 encoder), sized so
that a training sample costs about a quarter of the CPU time of the first default (2 x 128 points, two
observation steps, encoder widths 64-128-256, UNet 64-128-256): fewer points, one observation step, a
narrower point MLP and UNet. `bench/bench_policy.py` measures both side by side, and
`bench/bench_learning.py` what they learn per CPU-minute.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from lano3dp.policy.observations import ObservationType

POINT_ENCODERS = ("residual", "mlp")
INFERENCE_SCHEDULERS = ("ddpm", "ddim")
ACTION_FRAMES = ("absolute", "relative")

# UNet widths by name. "compact" is the CPU default (2.9 M parameters with the default encoder; its fp16
# weights fit the 6 MB a packaged checkpoint may take), "small" the earlier default (5.9 M), "dp" Chi et
# al.'s real-robot size. bench/bench_policy.py measures what each costs per training sample.
DOWN_DIMS_PRESETS: dict[str, tuple[int, ...]] = {
    "compact": (48, 96, 192),
    "small": (64, 128, 256),
    "medium": (128, 256, 512),
    "dp": (256, 512, 1024),
}

@dataclass
class PolicyConfig:
    """Everything needed to rebuild a DiffusionPolicy (saved as config.json beside its weights).

    Attributes:
        obs_type: "objects" (Lan-o3dp: one cloud per named object), "scene" (DP3: the cropped scene cloud),
            "image" (Diffusion Policy: a 96x96 RGB image) or another registered type (`policy.observations`).
        object_names: the object slots, in the order the dataset stores them (obs_type "objects").
        n_points: points per object cloud the policy was trained on (any N works at inference: max-pool).
        scene_points: points of the scene cloud (obs_type "scene").
        image_size: side of the square RGB image (obs_type "image").
        state_dim: EE position (3) + rotation 6D (6) + gripper opening (1) + grasp flag (1).
        action_dim: EE position (3) + rotation 6D (6) + gripper command (1).
        n_obs_steps, horizon, n_action_steps: To, H, Ta of Diffusion Policy; the executed actions are
            trajectory[To - 1 : To - 1 + Ta].
        down_dims: UNet channel widths per level; see DOWN_DIMS_PRESETS.
        diffusion_step_embed_dim, kernel_size, n_groups: UNet step embedding, Conv1d kernel, GroupNorm groups.
        point_encoder: "residual" (the paper's best: 68.8% vs 64.1%) or "mlp" (DP3's encoder).
        point_hidden_dims: widths of the shared per-point MLP (DP3: 64, 128, 256; default half that: the
            per-point MLP was over half of a training step, and the task objects are simple shapes).
        encoder_out: feature size of each cloud (per object slot) and of the image.
        state_feature_dim: feature size of the state MLP.
        num_train_timesteps, beta_schedule, prediction_type, clip_sample: the diffusion process.
        inference_scheduler: "ddpm" or "ddim", used when predict_action_chunk is not told otherwise.
        num_inference_steps: denoising steps at inference (None: num_train_timesteps).
        action_frame: what the UNet predicts for the action positions: "absolute" (world frame) or "relative"
            (offsets from the EE position at the last observation; rotation and gripper stay absolute). The
            policy converts both ways itself, so its inputs and outputs are world-frame either way. Relative
            positions did not help where absolute ones reached 94-96%, and were worse on the grasp-and-carry
            tasks (results/learning.md), so absolute stays the default.
        object_pose_features: give the UNet, beside each object cloud's learned feature, the cloud's centroid
            and its horizontal principal axis (ObjectCloudsEncoder.pose_features): the yaw an object lies at
            decides the grasp, and a point MLP learned it poorly from 40 demonstrations (objects only).
        object_pose_skew: add to those features each cloud's horizontal third moment (which end of the object
            its points reach farther towards): the principal axis cannot tell a broom's head from its handle. It
            did not lift the broom's success (README, "Learning efficiency"), so it is opt-in (needs
            object_pose_features).
        task_inputs: low-dimensional inputs the env hands over as obs[key] beside the state, {key: length}, e.g.
            {"goal": 3} for a goal position that renders nothing; each key is a registered task-input type
            (`policy.observations.vector`). Read off the dataset by training; empty for a policy without.
        extra: free-form notes the model does not use. extra["observation"] says how the training observations
            were made (camera, crop box, points, control_hz and, when not 1, time_stride: recorded steps between
            consecutive window steps; see `time_stride`), so a checkpoint acts without its dataset.
    """

    obs_type: str = "objects"
    object_names: tuple[str, ...] = ()
    n_points: int = 64
    scene_points: int = 512
    image_size: int = 96
    state_dim: int = 11
    action_dim: int = 10
    n_obs_steps: int = 1
    horizon: int = 16
    n_action_steps: int = 8
    down_dims: tuple[int, ...] = DOWN_DIMS_PRESETS["compact"]
    diffusion_step_embed_dim: int = 64
    kernel_size: int = 5
    n_groups: int = 8
    point_encoder: str = "residual"
    point_hidden_dims: tuple[int, ...] = (32, 64, 128)
    encoder_out: int = 64
    state_feature_dim: int = 64
    num_train_timesteps: int = 100
    beta_schedule: str = "squaredcos_cap_v2"
    prediction_type: str = "epsilon"
    clip_sample: bool = True
    inference_scheduler: str = "ddim"
    num_inference_steps: int | None = 10
    action_frame: str = "absolute"
    object_pose_features: bool = False
    object_pose_skew: bool = False
    task_inputs: dict[str, int] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)  # free-form notes (dataset, skill), not used by the model

    def __post_init__(self):
        self.object_names = tuple(self.object_names)
        self.down_dims = tuple(int(d) for d in self.down_dims)
        self.point_hidden_dims = tuple(int(d) for d in self.point_hidden_dims)
        self.task_inputs = {str(key): int(length) for key, length in dict(self.task_inputs).items()}
        self.validate()

    def validate(self) -> None:
        def need(condition: bool, message: str) -> None:
            if not condition:
                raise ValueError(f"PolicyConfig: {message}")

        try:
            observation = self.observation
        except ValueError as error:  # UnknownObservationTypeError, naming the registered types
            raise ValueError(f"PolicyConfig: {error}") from None
        need(self.point_encoder in POINT_ENCODERS,
             f"point_encoder must be one of {POINT_ENCODERS}, got {self.point_encoder!r}")
        need(self.inference_scheduler in INFERENCE_SCHEDULERS,
             f"inference_scheduler must be one of {INFERENCE_SCHEDULERS}, got {self.inference_scheduler!r}")
        need(self.action_frame in ACTION_FRAMES,
             f"action_frame must be one of {ACTION_FRAMES}, got {self.action_frame!r}")
        need(self.object_pose_features or not self.object_pose_skew, "object_pose_skew needs object_pose_features")
        need(observation.source == "frame", f"obs_type {self.obs_type!r} is a task input (obs[{observation.key!r}]), "
                                            "not a visual input; give it in task_inputs")
        try:
            observation.validate(self)
        except ValueError as error:
            raise ValueError(f"PolicyConfig: {error}") from None
        from lano3dp.policy.observations import get_observation_type

        for key, length in self.task_inputs.items():
            try:
                task_input = get_observation_type(key)
            except ValueError as error:
                raise ValueError(f"PolicyConfig: task_inputs: {error}") from None
            need(task_input.source == "obs", f"task_inputs: {key!r} is a visual input (obs_type), not one the env "
                                             "hands over as obs[key]")
            need(length >= 1, f"task_inputs: {key!r} needs a length >= 1, got {length}")
        for name in ("n_points", "scene_points", "image_size", "state_dim", "action_dim", "n_obs_steps", "horizon",
                     "n_action_steps", "diffusion_step_embed_dim", "kernel_size", "n_groups", "encoder_out",
                     "state_feature_dim", "num_train_timesteps"):
            need(int(getattr(self, name)) >= 1, f"{name} must be >= 1, got {getattr(self, name)}")
        need(self.kernel_size % 2 == 1, f"kernel_size must be odd (same-length convolution), got {self.kernel_size}")
        need(len(self.down_dims) >= 1, "down_dims needs at least one level")
        need(len(self.point_hidden_dims) >= 1, "point_hidden_dims needs at least one layer")
        need(all(d % self.n_groups == 0 for d in self.down_dims),
             f"every down_dims entry must be divisible by n_groups={self.n_groups}, got {self.down_dims}")
        need(self.n_obs_steps - 1 + self.n_action_steps <= self.horizon,
             f"n_obs_steps - 1 + n_action_steps must be <= horizon, got {self.n_obs_steps} - 1 + "
             f"{self.n_action_steps} > {self.horizon}")
        factor = 2 ** (len(self.down_dims) - 1)
        need(self.horizon % factor == 0,
             f"horizon {self.horizon} must be divisible by 2^(levels-1) = {factor} for down_dims {self.down_dims} "
             "(each level but the last halves the time axis); pick another horizon or fewer levels")
        need(self.prediction_type == "epsilon",
             "prediction_type must be 'epsilon': the paper found sample prediction makes A_0|k guidance ineffective")
        stride = (self.extra.get("observation") or {}).get("time_stride", 1)
        need(isinstance(stride, int) and not isinstance(stride, bool) and stride >= 1,
             f"extra['observation']['time_stride'] must be an int >= 1, got {stride!r}")
        if self.num_inference_steps is not None:
            need(1 <= self.num_inference_steps <= self.num_train_timesteps,
                 f"num_inference_steps must be in [1, {self.num_train_timesteps}], got {self.num_inference_steps}")

    # ---- derived -----------------------------------------------------------------------
    @property
    def observation(self) -> ObservationType:
        """The registered observation type `obs_type` names (`policy.observations`)."""
        from lano3dp.policy.observations import get_observation_type  # the registry's modules import this one

        return get_observation_type(self.obs_type)

    def task_input_type(self, key: str) -> ObservationType:
        """The registered task-input type of `key` (`policy.observations.vector`)."""
        from lano3dp.policy.observations import get_observation_type

        return get_observation_type(key)

    @property
    def visual_key(self) -> str:
        """The dataset / observation key of the visual input ("object_clouds", "scene_cloud", "rgb", ...)."""
        return self.observation.key

    @property
    def obs_keys(self) -> tuple[str, ...]:
        """The keys of one observation step: the visual input, the state, then the task inputs."""
        return (self.visual_key, "state", *self.task_inputs)

    @property
    def time_stride(self) -> int:
        """Env steps one policy step spans: the recorded steps between consecutive steps of the training windows
        (`extra["observation"]["time_stride"]`; 1, every recorded step, when absent)."""
        return int((self.extra.get("observation") or {}).get("time_stride", 1))

    @property
    def n_slots(self) -> int:
        """K, the number of object clouds (1 for the scene cloud and image baselines)."""
        return len(self.object_names) if self.observation.object_slots else 1

    # ---- serialisation -----------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        data = dataclasses.asdict(self)
        for key, value in data.items():
            if isinstance(value, tuple):
                data[key] = list(value)
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PolicyConfig:
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"PolicyConfig: unknown fields {unknown}")
        return cls(**data)

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2, sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> PolicyConfig:
        return cls.from_dict(json.loads(text))

    def save(self, path: str | Path) -> None:
        Path(path).write_text(self.to_json() + "\n")

    def replace(self, **changes) -> PolicyConfig:
        return dataclasses.replace(self, **changes)


def down_dims_for(size: str) -> tuple[int, ...]:
    """UNet widths of a named size ("small", "medium", "dp")."""
    if size not in DOWN_DIMS_PRESETS:
        raise ValueError(f"unknown model size {size!r}; choose one of {sorted(DOWN_DIMS_PRESETS)}")
    return DOWN_DIMS_PRESETS[size]
