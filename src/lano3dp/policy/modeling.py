"""DiffusionPolicy: P(action trajectory | object clouds, robot state) by DDPM, with cost-guided sampling.

Training: `compute_loss` (epsilon prediction, Chi et al.). Inference: `predict_action_chunk`, whose
denoising loop is `lano3dp.guidance.sampler.denoise`, so guided and unguided sampling share one loop;
`reset` / `select_action` are the control-loop contract (LeRobot's): one observation in, one action out; the
policy owns the observation window and the action queue (`ChunkedControl`, `ControlPolicy`).
Checkpoints are folders: config.json + model.safetensors (weights and normaliser statistics) +
normalizer.json (the same statistics, human-readable); loading never unpickles.
"""

from __future__ import annotations

import json
from collections import deque
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import NamedTuple, Protocol

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from lano3dp.errors import CorruptFileError, IncompatibleFormatError
from lano3dp.guidance.schedulers import SCHEDULERS, DiffusionScheduler, SchedulerConfig
from lano3dp.jsonio import write_text_atomic
from lano3dp.policy.config import PolicyConfig
from lano3dp.policy.encoders import ObservationEncoder
from lano3dp.policy.integrity import reseal_after_writing, verify_checkpoint, write_safetensors
from lano3dp.policy.normalizer import LinearNormalizer
from lano3dp.policy.unet import ConditionalUnet1D

CONFIG_NAME = "config.json"
WEIGHTS_NAME = "model.safetensors"
NORMALIZER_NAME = "normalizer.json"
# Bump when a saved checkpoint's meaning changes (keys, normalisation, action layout); loading refuses
# newer versions instead of producing silently wrong actions. Files without the field are version 1;
# version 2 adds relative action positions (config.action_frame), so only such checkpoints are written as 2
# and a release that predates them refuses them rather than reading offsets as world positions; version 3
# adds the object pose features (config.object_pose_features), whose UNet input is wider; version 4 widens it
# again by their third moments (config.object_pose_skew); version 5 adds task inputs (config.task_inputs, e.g. a
# goal the env hands over as obs["goal"]), which a release without them would not feed.
CHECKPOINT_FORMAT_VERSION = 5


def format_version_for(config: PolicyConfig) -> int:
    """The oldest checkpoint format that can hold a policy of this config."""
    if config.task_inputs:
        return 5
    if config.object_pose_skew:
        return 4
    if config.object_pose_features:
        return 3
    return 2 if config.action_frame == "relative" else 1

PositionCost = Callable[[torch.Tensor], torch.Tensor]


class ActionChunk(NamedTuple):
    """A sampled chunk, un-normalised (metres, 6D rotation, gripper command as predicted: threshold at 0.5).

    actions: (B, n_action_steps, action_dim), the steps to execute: trajectory[:, To-1 : To-1+Ta].
    trajectory: (B, horizon, action_dim), the whole sampled horizon (index To-1 is "now").
    """

    actions: torch.Tensor
    trajectory: torch.Tensor

    def numpy(self) -> ActionChunk:
        return ActionChunk(self.actions.detach().cpu().numpy(), self.trajectory.detach().cpu().numpy())


def make_scheduler(config: PolicyConfig, kind: str) -> DiffusionScheduler:
    """A DDPM or DDIM scheduler (`guidance.schedulers`) with the policy's diffusion process (epsilon, clip_sample)."""
    if kind not in SCHEDULERS:
        raise ValueError(f"unknown scheduler {kind!r}; use one of {sorted(SCHEDULERS)}")
    process = SchedulerConfig(num_train_timesteps=config.num_train_timesteps, beta_schedule=config.beta_schedule,
                              prediction_type=config.prediction_type, clip_sample=config.clip_sample)
    return SCHEDULERS[kind](process)


SampleFn = Callable[[dict[str, torch.Tensor]], ActionChunk]


class ControlPolicy(Protocol):
    """What a control loop (`runtime.PolicyRunner`) drives: a chunk sampler with LeRobot's control contract.

    config: the PolicyConfig (obs_keys, n_obs_steps, n_action_steps, horizon, time_stride, ...).
    predict_action_chunk(window, **sample_kwargs): sample an ActionChunk from observation windows (B, To, ...).
    reset(): start an episode: forget the observation window and the queued actions.
    select_action(obs, sample=None, **sample_kwargs): one observation (B, ...) in, one (B, action_dim) action out;
        `sample(window) -> ActionChunk`, when given, samples the chunk instead of predict_action_chunk.

    `ChunkedControl` provides reset / select_action for any class with config, device and predict_action_chunk.
    """

    config: PolicyConfig

    def predict_action_chunk(self, obs: Mapping[str, np.ndarray | torch.Tensor], **sample_kwargs) -> ActionChunk: ...

    def reset(self) -> None: ...

    def select_action(self, obs: Mapping[str, np.ndarray | torch.Tensor], sample: SampleFn | None = None,
                      **sample_kwargs) -> torch.Tensor: ...


class ChunkedControl:
    """The control contract (`reset`, `select_action`) on top of `predict_action_chunk`: the observation window
    and the action queue live here, so every control loop (a user's, `runtime.PolicyRunner`) pads, slides and
    re-plans the same way. The class using it provides `config` (PolicyConfig), `device` and
    `predict_action_chunk`; `DiffusionPolicy` does, and so can a wrapper or a test double.
    """

    config: PolicyConfig
    device: torch.device

    def reset(self) -> None:
        """Start a new episode: forget the observation window, the queued actions and the last chunk."""
        self._obs_queue: dict[str, deque[torch.Tensor]] = {key: deque(maxlen=self.config.n_obs_steps)
                                                          for key in self.config.obs_keys}
        self._action_queue: deque[torch.Tensor] = deque()
        self.last_chunk: ActionChunk | None = None

    def observation_needed(self) -> bool:
        """Whether the observation the next `select_action` pushes can reach a sampled window: False while at
        least n_obs_steps more actions are queued, since as many later observations push it out first."""
        return len(self._action_queue) < self.config.n_obs_steps

    def select_queued_action(self) -> torch.Tensor:
        """`select_action` for a step whose observation no window will hold (`observation_needed` is False): the
        next queued action, the same as `select_action` returns, without building that observation."""
        if self.observation_needed():
            raise RuntimeError("the next observation reaches a sampled window; pass it to select_action")
        return self._action_queue.popleft()

    def select_action(self, obs: Mapping[str, np.ndarray | torch.Tensor], sample: SampleFn | None = None,
                      **sample_kwargs) -> torch.Tensor:
        """One control step: push one observation, sample a chunk when no action is queued, pop one action.

        The window holds the last n_obs_steps observations; the first observation of an episode fills it
        (Diffusion Policy's edge padding, as training windows are padded). A chunk's actions are executed one
        per call before the next chunk is sampled, so a new chunk is sampled every n_action_steps calls;
        `last_chunk` keeps it (its trajectory, for drawing or checking).

        Args:
            obs: one step, numpy or torch, raw units: {visual key: (B, ...) e.g. object_clouds (B, K, N, 3)
                metres, "state": (B, 11), each task input (B, D) e.g. "goal"}; other keys are ignored.
            sample: window {key: (B, To, ...) tensors} -> ActionChunk, called instead of predict_action_chunk
                when a chunk is due; its `actions` are the ones queued, so it also decides how many run before
                the next chunk (a control loop that guides, checks or records its chunks passes it).
            **sample_kwargs: passed to predict_action_chunk when a chunk is sampled (guidance, position_cost,
                generator, scheduler, num_inference_steps, ...); not with `sample`.

        Returns:
            (B, action_dim) un-normalised action on the policy's device.
        """
        if sample is not None and sample_kwargs:
            raise TypeError(f"select_action got both a sample function and sampling options {sorted(sample_kwargs)}; "
                            "give the options to the sample function")
        for key in self.config.obs_keys:
            if key not in obs:
                raise KeyError(f"observation is missing {key!r}; a {self.config.obs_type!r} policy needs "
                               f"{self.config.obs_keys}")
        step = {key: torch.as_tensor(obs[key], device=self.device) for key in self.config.obs_keys}
        if step["state"].ndim != 2 or step["state"].shape[-1] != self.config.state_dim:
            raise ValueError(f"select_action takes one step: state must be (batch, {self.config.state_dim}), got "
                             f"{tuple(step['state'].shape)}; pass windows to predict_action_chunk instead")
        for key, value in step.items():
            queue = self._obs_queue[key]
            if queue and queue[-1].shape != value.shape:
                raise ValueError(f"{key} changed shape from {tuple(queue[-1].shape)} to {tuple(value.shape)} "
                                 "within an episode; call reset() first")
            if not queue:
                queue.extend([value] * self.config.n_obs_steps)
            else:
                queue.append(value)
        if not self._action_queue:
            window = {key: torch.stack(list(queue), dim=1) for key, queue in self._obs_queue.items()}
            chunk = sample(window) if sample is not None else self.predict_action_chunk(window, **sample_kwargs)
            if chunk.actions.shape[1] < 1:
                raise ValueError(f"the sampled chunk holds no actions (actions {tuple(chunk.actions.shape)})")
            self.last_chunk = chunk
            self._action_queue.extend(chunk.actions.transpose(0, 1))  # Ta tensors of (B, D)
        return self._action_queue.popleft()


class DiffusionPolicy(ChunkedControl, nn.Module):
    """Object-centric 3D diffusion policy (or a baseline, by `config.obs_type`).

    Observations: {"object_clouds": (B, To, K, N, 3) metres, world frame, slots in config.object_names order;
    "state": (B, To, 11)}; the baselines use "scene_cloud" (B, To, N, 3) or "rgb" (B, To, H, W, 3) uint8, and a
    registered observation type its own key (`policy.observations`).

    Control: `reset` / `select_action` (from `ChunkedControl`) run it one observation at a time;
    `predict_action_chunk` samples from whole windows (planning, guidance, batches).
    """

    def __init__(self, config: PolicyConfig):
        super().__init__()
        self.config = config
        stats_dims = {"action": config.action_dim, "state": config.state_dim}
        visual_dim = config.observation.normalizer_dim(config)  # None: e.g. images, scaled by their encoder
        if visual_dim is not None:
            stats_dims[config.visual_key] = visual_dim
        stats_dims |= config.task_inputs  # each task input (obs["goal"], ...) gets a min-max range per component
        self.normalizer = LinearNormalizer(stats_dims)
        self.obs_encoder = ObservationEncoder(config)
        self.unet = ConditionalUnet1D(config.action_dim, self.obs_encoder.out_dim, config.diffusion_step_embed_dim,
                                      config.down_dims, config.kernel_size, config.n_groups)
        self.noise_scheduler = make_scheduler(config, "ddpm")
        self._schedulers: dict[str, DiffusionScheduler] = {}
        self.reset()

    @property
    def device(self) -> torch.device:
        return next(self.parameters()).device

    @property
    def dtype(self) -> torch.dtype:
        """The weights' floating-point type: what observations, noise and actions are computed in."""
        return next(self.parameters()).dtype

    # ---- normaliser --------------------------------------------------------------------
    def set_normalizer(self, stats: Mapping[str, Mapping[str, np.ndarray]]) -> None:
        """Set min/max statistics: {"action": {"min": (10,), "max": (10,)}, "state": ..., visual key: (3,)}."""
        self.normalizer.set_stats(stats)

    def fit_normalizer(self, dataset) -> None:
        """Fit the statistics on every step of a lano3dp.data.SequenceDataset's episodes (relative actions: on
        every offset a training window can hold)."""
        if self.config.action_frame == "relative":
            actions = relative_action_rows(dataset.episode_arrays(dataset.action_key), dataset.episode_arrays("state"),
                                           self.config.n_obs_steps, self.config.horizon)
        else:
            actions = dataset.all_actions()
        data = {key: dataset.all_obs(key) for key in self.normalizer.keys if key != "action"}
        data["action"] = actions
        self.normalizer.fit(data)

    def normalizer_stats(self) -> dict[str, dict[str, np.ndarray]]:
        return self.normalizer.stats()

    # ---- action frame ------------------------------------------------------------------
    def _action_anchor(self, state: np.ndarray | torch.Tensor) -> torch.Tensor | float:
        """What turns predicted actions into world-frame ones: (B, 1, action_dim) holding the EE position of the
        last observed step (state (B, To, state_dim), raw) in the position columns, or 0 for absolute actions."""
        if self.config.action_frame == "absolute":
            return 0.0
        state = torch.as_tensor(state, device=self.device).to(self.dtype)
        anchor = torch.zeros(state.shape[0], 1, self.config.action_dim, device=self.device, dtype=self.dtype)
        anchor[:, 0, :3] = state[:, -1, :3]
        return anchor

    def normalize_actions(self, actions: torch.Tensor, state: np.ndarray | torch.Tensor) -> torch.Tensor:
        """World-frame actions (B, H, action_dim) -> the normalised trajectory the UNet denoises."""
        return self.normalizer.normalize("action", actions - self._action_anchor(state))

    def unnormalize_actions(self, trajectory: torch.Tensor, state: np.ndarray | torch.Tensor) -> torch.Tensor:
        """The UNet's normalised trajectory (B, H, action_dim) -> world-frame actions (differentiable)."""
        return self.normalizer.unnormalize("action", trajectory) + self._action_anchor(state)

    # ---- observation -------------------------------------------------------------------
    def _prepare_obs(self, obs: Mapping[str, np.ndarray | torch.Tensor]) -> dict[str, torch.Tensor]:
        """Raw obs window (numpy or torch) -> normalised tensors of the last n_obs_steps steps."""
        config = self.config
        prepared = {}
        for key in config.obs_keys:
            if key not in obs:
                raise KeyError(f"observation is missing {key!r}; a {config.obs_type!r} policy needs {config.obs_keys}")
            value = torch.as_tensor(obs[key], device=self.device)
            if key in self.normalizer.keys:  # an unnormalised input (uint8 images) goes to its encoder as it is
                value = value.to(self.dtype)
            if value.ndim < 3 or value.shape[1] < config.n_obs_steps:
                raise ValueError(f"{key} must be (batch, steps >= n_obs_steps={config.n_obs_steps}, ...), "
                                 f"got {tuple(value.shape)}")
            value = value[:, -config.n_obs_steps:]
            if key in self.normalizer.keys:
                value = self.normalizer.normalize(key, value)
            prepared[key] = value
        return prepared

    def encode_obs(self, obs: Mapping[str, np.ndarray | torch.Tensor]) -> torch.Tensor:
        """Raw observation window -> global condition (B, To * features)."""
        return self.obs_encoder(self._prepare_obs(obs))

    # ---- training ----------------------------------------------------------------------
    def compute_loss(self, batch: Mapping, generator: torch.Generator | None = None) -> torch.Tensor:
        """Epsilon-prediction MSE on a batch {"obs": {key: (B, To, ...)}, "action": (B, H, action_dim)}.

        `generator` draws the diffusion noise and timesteps (None: torch's global RNG).
        """
        actions = torch.as_tensor(batch["action"], device=self.device).to(self.dtype)
        if actions.shape[1:] != (self.config.horizon, self.config.action_dim):
            raise ValueError(f"action batch must be (B, {self.config.horizon}, {self.config.action_dim}), "
                             f"got {tuple(actions.shape)}")
        cond = self.encode_obs(batch["obs"])
        trajectory = self.normalize_actions(actions, batch["obs"]["state"])
        noise = torch.randn(trajectory.shape, generator=generator, device=self.device, dtype=trajectory.dtype)
        timesteps = torch.randint(0, self.config.num_train_timesteps, (trajectory.shape[0],), generator=generator,
                                  device=self.device)
        noisy = self.noise_scheduler.add_noise(trajectory, noise, timesteps)
        return F.mse_loss(self.unet(noisy, timesteps, cond), noise)

    def forward(self, batch: Mapping, generator: torch.Generator | None = None) -> torch.Tensor:
        """Same as compute_loss; lets DistributedDataParallel see the call."""
        return self.compute_loss(batch, generator)

    # ---- inference ---------------------------------------------------------------------
    def get_scheduler(self, kind: str | None = None) -> DiffusionScheduler:
        """The cached inference scheduler ("ddpm" or "ddim"; default config.inference_scheduler)."""
        kind = kind or self.config.inference_scheduler
        if kind not in self._schedulers:
            self._schedulers[kind] = make_scheduler(self.config, kind)
        return self._schedulers[kind]

    def predict_action_chunk(self, obs: Mapping[str, np.ndarray | torch.Tensor], *, guidance=None,
                             position_cost: PositionCost | None = None, scheduler=None,
                             num_inference_steps: int | None = None, generator: torch.Generator | None = None,
                             initial_noise: torch.Tensor | None = None, on_step=None) -> ActionChunk:
        """Sample an action chunk for a batch of observation windows.

        Args:
            obs: {visual key: (B, To, ...), "state": (B, To, 11)}, numpy or torch, raw units; the last
                n_obs_steps steps are used.
            guidance: lano3dp.guidance.GuidanceConfig, or None for plain sampling.
            position_cost: metric EE positions (B, H, 3) -> cost (B,); required when guidance is enabled.
                It sees the un-normalised A_0|k (or A_k), through a differentiable un-normalisation.
            scheduler: "ddpm", "ddim", a scheduler instance (`guidance.schedulers`, or a diffusers one of the same
                process), or None (config.inference_scheduler).
            num_inference_steps: default config.num_inference_steps (DDPM: every training step).
            generator: seeds the initial noise and DDPM's per-step noise; or one generator per observation (B),
                so each sample is what it would be alone. A CPU generator gives the same noise on any device
                (drawn on the CPU, then moved).
            initial_noise: (B, H, action_dim) A_T, to reproduce a sample exactly.
            on_step: callback after every denoising step (lano3dp.guidance.sampler.DenoiseStep).

        Returns:
            ActionChunk(actions (B, Ta, D), trajectory (B, H, D)), un-normalised, on the policy's device and in
            its dtype.
        """
        from lano3dp.guidance.sampler import GuidanceMode, denoise

        config = self.config
        if scheduler is None or isinstance(scheduler, str):
            kind = scheduler or config.inference_scheduler
            scheduler = self.get_scheduler(kind)
            if num_inference_steps is None:
                num_inference_steps = config.num_inference_steps if kind == "ddim" else None
        guided = guidance is not None and guidance.mode is not GuidanceMode.NONE
        if guided and position_cost is None:
            raise ValueError("guidance was requested but no position_cost was given (build one from the obstacles)")
        was_training = self.training
        if was_training:  # eval() walks every module: a few ms a chunk, for a flag already off outside training
            self.eval()
        try:
            with torch.no_grad():
                cond = self.encode_obs(obs)
            batch = cond.shape[0]
            state = obs["state"]

            def noise_fn(sample: torch.Tensor, timesteps: torch.Tensor) -> torch.Tensor:
                return self.unet(sample, timesteps, cond)

            def cost_fn(trajectory: torch.Tensor) -> torch.Tensor:
                return position_cost(self.unnormalize_actions(trajectory, state)[..., :3])

            if initial_noise is not None:
                initial_noise = torch.as_tensor(initial_noise, device=self.device).to(self.dtype)
                expected = (batch, config.horizon, config.action_dim)
                if tuple(initial_noise.shape) != expected:
                    raise ValueError(f"initial_noise must be {expected}, got {tuple(initial_noise.shape)}")
            normalised = denoise(noise_fn, scheduler, (batch, config.horizon, config.action_dim),
                                 num_inference_steps=num_inference_steps, generator=generator, guidance=guidance,
                                 cost_fn=cost_fn if guided else None, initial_noise=initial_noise, on_step=on_step,
                                 device=self.device, dtype=self.dtype)
            with torch.no_grad():
                trajectory = self.unnormalize_actions(normalised.detach(), state)
        finally:
            if was_training:
                self.train()
        start = config.n_obs_steps - 1
        return ActionChunk(trajectory[:, start:start + config.n_action_steps], trajectory)

    # ---- persistence -------------------------------------------------------------------
    def save_pretrained(self, directory: str | Path) -> Path:
        """Write config.json, model.safetensors and normalizer.json into `directory` (created if needed), sealed by
        its manifest.json (`lano3dp.policy.integrity`)."""
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        state = {key: value.detach().cpu().contiguous() for key, value in self.state_dict().items()}
        metadata = {"format": "lano3dp-policy", "format_version": str(format_version_for(self.config))}
        save_safetensors(state, directory / WEIGHTS_NAME, metadata=metadata)
        stats = {key: {name: value.tolist() for name, value in item.items()}
                 for key, item in self.normalizer_stats().items()}
        write_text_atomic(directory / NORMALIZER_NAME, json.dumps(stats, indent=2))
        write_text_atomic(directory / CONFIG_NAME, self.config.to_json() + "\n")
        reseal_after_writing(directory, (WEIGHTS_NAME, NORMALIZER_NAME, CONFIG_NAME))
        return directory

    @classmethod
    def from_pretrained(cls, directory: str | Path, device: str | torch.device = "cpu") -> DiffusionPolicy:
        """Load a folder written by save_pretrained, or a training run's folder (its last checkpoint).

        Raises:
            FileNotFoundError: no checkpoint there.
            CorruptFileError: config.json or model.safetensors is truncated, unparsable or inconsistent.
            CheckpointSealError: a file changed since the checkpoint was saved (`lano3dp.policy.integrity`).
        """
        directory = resolve_checkpoint(directory)
        check_format_version(directory / WEIGHTS_NAME)
        config = load_config(directory / CONFIG_NAME)
        policy = cls(config)
        state = load_safetensors(directory / WEIGHTS_NAME)
        try:
            policy.load_state_dict(state, strict=True)
        except RuntimeError as error:
            raise CorruptFileError(directory / WEIGHTS_NAME, f"weights do not match config.json: {error}") from error
        if not bool(policy.normalizer.fitted):
            raise CorruptFileError(directory / WEIGHTS_NAME, "holds no normaliser statistics")
        verify_checkpoint(directory)  # last: a file that is damaged as well as edited gets its own message first
        return policy.to(device).eval()


def relative_action_rows(actions: list[np.ndarray], states: list[np.ndarray], n_obs_steps: int,
                         horizon: int) -> np.ndarray:
    """Every action of every training window as an offset from the window's EE position "now" (the last
    observed step), as (rows, action_dim): what the normaliser of relative actions is fitted on.

    actions, states: per episode, (T, action_dim) and (T, state_dim). Windows are edge-padded as in training.
    """
    rows = []
    for episode_actions, episode_states in zip(actions, states, strict=True):
        length = len(episode_actions)
        take = np.clip(np.arange(length)[:, None] - (n_obs_steps - 1) + np.arange(horizon)[None], 0, length - 1)
        windows = np.array(episode_actions[take], dtype=np.float64)  # (T, H, action_dim), "now" = row t
        windows[..., :3] -= episode_states[:, None, :3]
        rows.append(windows.reshape(-1, windows.shape[-1]))
    return np.concatenate(rows, axis=0)


def resolve_checkpoint(directory: str | Path) -> Path:
    """A policy folder; a training run's folder resolves to <run>/checkpoints/last."""
    directory = Path(directory)
    if (directory / CONFIG_NAME).exists() or (directory / WEIGHTS_NAME).exists():
        return directory
    last = directory / "checkpoints" / "last"
    if last.exists():
        return last.resolve()
    raise FileNotFoundError(f"no policy checkpoint in {directory} (expected {CONFIG_NAME} and {WEIGHTS_NAME}, "
                            "or checkpoints/last of a training run)")


def check_format_version(path: Path) -> int:
    """The checkpoint format version in the weights' metadata; raise if this release cannot read it."""
    from safetensors import safe_open

    if not path.exists():
        raise FileNotFoundError(f"{path} does not exist")
    try:
        with safe_open(str(path), framework="pt") as handle:
            metadata = handle.metadata() or {}
        version = int(metadata.get("format_version", 1))
    except Exception as error:  # a damaged header raises SafetensorError / ValueError
        raise CorruptFileError(path, f"unreadable safetensors header ({type(error).__name__}: {error})") from error
    if version > CHECKPOINT_FORMAT_VERSION:
        raise IncompatibleFormatError(path, version, CHECKPOINT_FORMAT_VERSION)
    return version


def load_config(path: Path) -> PolicyConfig:
    if not path.exists():
        raise FileNotFoundError(f"{path} does not exist")
    try:
        return PolicyConfig.from_json(path.read_text())
    except (ValueError, TypeError, UnicodeDecodeError) as error:  # JSONDecodeError is a ValueError
        raise CorruptFileError(path, f"not a valid policy config ({type(error).__name__}: {error})") from error


CHECKSUM_KEY = "weights_sha256"


def tensors_checksum(tensors: Mapping[str, torch.Tensor]) -> str:
    """SHA-256 over every tensor's name, dtype, shape and bytes, in name order: what a file holds, as stored
    (an fp16 export is summed over its fp16 values)."""
    import hashlib

    digest = hashlib.sha256()
    for name in sorted(tensors):
        value = tensors[name].detach().cpu().contiguous()
        digest.update(f"{name}|{value.dtype}|{tuple(value.shape)}|".encode())
        digest.update(value.reshape(-1).view(torch.uint8).numpy().tobytes())
    return digest.hexdigest()


def save_safetensors(tensors: Mapping[str, torch.Tensor], path: Path, metadata: Mapping[str, str]) -> Path:
    """Write tensors with their checksum in the metadata, atomically (temporary file + rename), checked whole."""
    return write_safetensors(tensors, path, metadata={**metadata, CHECKSUM_KEY: tensors_checksum(tensors)})


def load_safetensors(path: Path) -> dict[str, torch.Tensor]:
    """Read a safetensors file and check it against the checksum in its metadata (files written before
    checksums are checked for non-finite weights only); any damage becomes a CorruptFileError naming the file."""
    from safetensors import safe_open

    if not path.exists():
        raise FileNotFoundError(f"{path} does not exist")
    try:
        with safe_open(str(path), framework="pt") as handle:
            metadata = handle.metadata() or {}
            tensors = {name: handle.get_tensor(name) for name in handle.keys()}
    except Exception as error:  # safetensors raises SafetensorError / OSError / ValueError on damage
        raise CorruptFileError(path, f"unreadable safetensors file ({type(error).__name__}: {error})") from error
    expected = metadata.get(CHECKSUM_KEY)
    if expected is not None and tensors_checksum(tensors) != expected:
        raise CorruptFileError(path, "the weights do not match the checksum written with them (the file was "
                                     "damaged after it was saved); restore it from a copy or retrain")
    if expected is None:
        for name, value in tensors.items():
            if value.is_floating_point() and not torch.isfinite(value).all():
                raise CorruptFileError(path, f"tensor {name} holds NaN or inf")
    return tensors
