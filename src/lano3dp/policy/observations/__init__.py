"""Observation types as a registry: one module per type owns everything the type means, wherever it is used.

    key                           the dataset / observation key of the visual input (one array per step)
    recorder(context)             `collect`'s per-episode recorder: frame -> one step of that array
    encoder(config)               nn.Module: one normalised step (M, ...) -> (M, out_dim), with `out_dim`
    normalizer_dim(config)        the last axis the min-max statistics are per (None: the input is not normalised)
    runtime_input(runner, frame)  `PolicyRunner`'s one step of visual input from an RGB-D frame
    dataset_fields(shape)         PolicyConfig fields read off one recorded step (`train.policy_config_for_dataset`)
    cloud_points(config)          points per cloud when the input is world-frame xyz clouds (..., N, 3): training
                                  then subsamples N and augmentation moves them with the scene; None otherwise
    object_slots                  one entry per object slot, in config.object_names order (needs target phrases)
    needs_rgb                     the env must render colour for it
    validate(config)              raise ValueError for settings the type cannot use

Built in: "objects" (Lan-o3dp), "scene" (DP3) and "image" (Diffusion Policy), one module each, the visual input a
policy's `obs_type` names. Beside it a policy may take task inputs (`PolicyConfig.task_inputs`): low-dimensional
vectors the env hands over itself as obs[key], such as a goal that changes every episode and renders nothing. Their
types have `source = "obs"` (`vector.VectorObservation`; "goal" is built in, key "goal"): `collect` records
obs[key] whenever the env's observation holds it, training reads the vector's length off the dataset, the policy
normalises and encodes it like the state, and evaluation passes obs[key] every step (`task_inputs_of`).

A new type is one subclass and one call, from any module imported before a policy of it is built or loaded:

    class Tops(ObservationType):
        key = "object_tops"
        ...
    register_observation_type("tops", Tops())     # then PolicyConfig(obs_type="tops")

Evaluation with workers > 1 sends a registered type to its spawned worker processes pickled
(`evaluate.observation_types_for_workers`), so its class must live at the top level of an importable module (the
`--env` module is imported in the workers first). Other spawned processes (`executor` cells, `torchrun` ranks) run
the user's script again, so register at its top level or in a module it imports, not under `if __name__ ==`.
`lano3dp collect` records the key of every registered type that has a recorder, so register a type before
collecting the data it trains on.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from lano3dp.errors import Lano3dpError
from lano3dp.registry import Registry

if TYPE_CHECKING:
    import numpy as np
    from torch import nn

    from lano3dp.geometry.frame import RGBDFrame
    from lano3dp.policy.config import PolicyConfig


class UnknownObservationTypeError(Lano3dpError, ValueError):
    """No observation type is registered under that name."""


class UnrecordableEpisode(Lano3dpError):
    """A recorder cannot record this episode (e.g. an object slot out of view in its first frame): `collect`
    discards it and tries the next seed, as it does an episode the expert failed."""


@dataclass(frozen=True)
class RecordContext:
    """What `collect` hands a recorder at the start of an episode.

    Attributes:
        observer: the `perception.ObjectObserver` (ground-truth segmenter, FPS to `n_points`, the crop box).
        phrases: the scene's words for the object slots, in slot order.
        settings: the `CollectConfig` (scene_points, rgb_size, crop_low, crop_high, table_height, ...).
    """

    observer: Any
    phrases: tuple[str, ...]
    settings: Any


Recorder = Callable[["RGBDFrame"], "np.ndarray"]


class ObservationType:
    """One kind of visual input of a policy. Subclass it, set `key`, implement `encoder`, `runtime_input` and
    (to train on data `collect` records) `recorder`; override the rest where the defaults do not fit.

    The defaults: an unnormalised input, not a point cloud, no object slots, no RGB needed, no PolicyConfig
    fields read from a dataset, and no recorder (the key is recorded by another type or by the user).
    """

    key: str = ""
    object_slots: bool = False
    needs_rgb: bool = False
    source: str = "frame"  # "frame": made from the camera frame; "obs": the env's observation holds it as obs[key]

    def encoder(self, config: PolicyConfig) -> nn.Module:
        """The module mapping one normalised step (M, ...) to (M, out_dim) features; it sets `out_dim`.
        Its parameters are part of the checkpoint (`obs_encoder.visual.*`)."""
        raise NotImplementedError(f"{type(self).__name__} defines no encoder")

    def runtime_input(self, runner, frame: RGBDFrame) -> np.ndarray:
        """One step of the input from a frame, for `runtime.PolicyRunner` (`runner.policy_config`, `.observer`,
        `.target_phrases`, `.object_clouds(frame)` hold what the runner knows)."""
        raise NotImplementedError(f"{type(self).__name__} defines no runtime input")

    def recorder(self, context: RecordContext) -> Recorder | None:
        """A callable for one episode, frame -> one step of the input (called on every frame, in order; it may
        raise `UnrecordableEpisode`, and count frames it held from an earlier one in a `held` attribute). None:
        this type records nothing."""
        return None

    def normalizer_dim(self, config: PolicyConfig) -> int | None:
        """Size of the last axis, whose components get one min-max range each over every other axis; None: the
        policy passes the raw input to the encoder."""
        return None

    def cloud_points(self, config: PolicyConfig) -> int | None:
        """Points per cloud the policy trains on, when the input is world-frame xyz clouds (..., N, 3)."""
        return None

    def dataset_fields(self, step_shape: tuple[int, ...]) -> dict[str, Any]:
        """PolicyConfig fields that one recorded step of shape `step_shape` implies (e.g. the point count)."""
        return {}

    def validate(self, config: PolicyConfig) -> None:
        """Raise ValueError naming a setting this type cannot use."""
        # only the object-clouds encoder reads pose features off its clouds
        if config.object_pose_features:
            raise ValueError(f"object_pose_features needs obs_type 'objects' (one cloud per object), "
                             f"got {config.obs_type!r}")


def _check_key(name: str, observation_type) -> None:
    if not isinstance(getattr(observation_type, "key", None), str) or not observation_type.key:
        raise TypeError(f"observation type {name!r} needs a key (its dataset and observation key)")
    if getattr(observation_type, "source", "frame") == "obs" and observation_type.key != name:
        raise TypeError(f"a task input (source 'obs') is registered under its key: register "
                        f"{observation_type.key!r}, not {name!r}")


_REGISTRY: Registry[ObservationType] = Registry(
    "observation type", UnknownObservationTypeError,
    ("encoder", "runtime_input", "recorder", "normalizer_dim", "cloud_points", "dataset_fields", "validate"),
    "lano3dp.policy.ObservationType", check=_check_key, field="obs_type",
    hint=" (a policy of another type needs its module imported first: lano3dp.policy.register_observation_type)")


def register_observation_type(name: str, observation_type, *, replace: bool = False) -> ObservationType:
    """Make `observation_type` (an ObservationType, or a class of one taking no arguments) available as
    `PolicyConfig(obs_type=name)` (same-class re-registration replaces; another class needs `replace=True`)."""
    return _REGISTRY.register(name, observation_type, replace=replace)


def unregister_observation_type(name: str) -> None:
    """Remove a registered type (the built-in ones stay: configs and checkpoints default to them)."""
    _REGISTRY.unregister(name)


def observation_type_names() -> tuple[str, ...]:
    """Registered names, built-in ones first, then in the order they were registered."""
    return _REGISTRY.names()


def get_observation_type(name: str) -> ObservationType:
    """The type registered as `name`; UnknownObservationTypeError naming the registered ones otherwise."""
    return _REGISTRY.get(name)


def observation_type_for_workers(name: str) -> dict[str, bytes]:
    """{name: pickled type} for a user's type, {} for a built-in one (spawned workers know the built-ins)."""
    return _REGISTRY.worker_payload(name)


def recorders(context: RecordContext) -> dict[str, Recorder]:
    """{key: recorder} for one episode: every registered type's that records, the first type of a key winning."""
    found: dict[str, Recorder] = {}
    for observation_type in _REGISTRY:
        if observation_type.key not in found:
            recorder = observation_type.recorder(context)
            if recorder is not None:
                found[observation_type.key] = recorder
    return found


def task_input_types() -> dict[str, ObservationType]:
    """{name: type} of every registered type the env hands over as obs[key] (source "obs"), in registry order."""
    return {name: _REGISTRY.get(name) for name in _REGISTRY.names() if _REGISTRY.get(name).source == "obs"}


def task_inputs_of(obs: Mapping[str, Any], names: Sequence[str] | None = None) -> dict[str, np.ndarray]:
    """{key: (D,) float32} of the task inputs an observation holds: those of `names` (each required, KeyError naming
    the missing key), or, with None, of every registered task-input type whose key `obs` has (what `collect`
    records)."""
    import numpy as np

    types = task_input_types()
    if names is None:
        chosen = [t for t in types.values() if isinstance(obs, Mapping) and t.key in obs]
    else:
        chosen = [get_observation_type(name) for name in names]
    found = {}
    for observation_type in chosen:
        if not isinstance(obs, Mapping) or observation_type.key not in obs:
            held = ", ".join(sorted(map(str, obs))) if isinstance(obs, Mapping) else type(obs).__name__
            raise KeyError(f"the policy takes obs[{observation_type.key!r}] (a task input) but the env's observation "
                           f"has no {observation_type.key!r} (it holds {held})")
        value = np.asarray(obs[observation_type.key], dtype=np.float32).reshape(-1)
        if value.size == 0 or not np.all(np.isfinite(value)):
            raise ValueError(f"obs[{observation_type.key!r}] must be a non-empty finite vector, got "
                             f"{np.asarray(obs[observation_type.key]).tolist()}")
        found[observation_type.key] = value
    return found


def held_frames(recorders: Mapping[str, Recorder]) -> int:
    """Frames the recorders held from an earlier frame (the store's `held_clouds`)."""
    return sum(int(getattr(recorder, "held", 0)) for recorder in recorders.values())


def _register_builtins() -> tuple[str, ...]:
    from lano3dp.policy.observations.image import ImageObservation
    from lano3dp.policy.observations.objects import ObjectCloudsObservation
    from lano3dp.policy.observations.scene import SceneCloudObservation
    from lano3dp.policy.observations.vector import VectorObservation

    for name, observation_type in (("objects", ObjectCloudsObservation()), ("scene", SceneCloudObservation()),
                                   ("image", ImageObservation()), ("goal", VectorObservation("goal"))):
        register_observation_type(name, observation_type)
    return _REGISTRY.mark_builtin()


BUILTIN_OBSERVATION_TYPES = _register_builtins()

__all__ = [
    "BUILTIN_OBSERVATION_TYPES", "ObservationType", "RecordContext", "UnknownObservationTypeError",
    "UnrecordableEpisode", "get_observation_type", "held_frames", "observation_type_names", "recorders",
    "register_observation_type", "task_input_types", "task_inputs_of", "unregister_observation_type",
]
