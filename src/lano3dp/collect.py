"""Expert demonstrations -> zarr episode store (`lano3dp collect`).

Each episode runs an expert in an environment and records, per control step, the observation
before the action and the action. The environment is the built-in `TabletopEnv` of a task (its
scripted open-loop plan the expert), or any env meeting `lano3dp.sim.protocol.SimulatorProtocol`
with a closed-loop expert `expert(env, obs, info) -> action (10,)` called every step
(`collect_from_env`; on the command line `lano3dp collect --env module:factory --expert module:callable
--slots block,drawer`). For a user's env the slots, control rate and step limit come from the caller or
the env (`env.control_hz`, `env.max_steps`), the frame from `geometry.frame.observe` (obs["frame"], env.frame(),
or obs rgb/depth/intrinsics/cam_to_world), and success from `info["success"]`. Recorded:

    action          (10,) float32   absolute EE pose + gripper the expert commanded
    state           (11,) float32   EE pose, gripper opening, grasp flag
    object_clouds   (K, N, 3)       per-slot clouds (slot order = task.object_slots or the slots given),
                                    ground-truth segmentation through `perception.ObjectObserver` +
                                    `SimOracleSegmenter` (phrases: info["target_phrases"][slot], else the slot)
    scene_cloud     (512, 3)        cropped scene above the table height (DP3 baseline)
    rgb             (96, 96, 3)     uint8 (Diffusion Policy baseline)
    goal            (D,) float32    obs["goal"] when the env hands a goal over (a task input,
                                    `policy.observations.vector`); likewise any registered task input
    ...                             the key of any other observation type registered before collecting

Each observation key is recorded by its observation type's module (`lano3dp.policy.observations`).

Only successful expert episodes are kept. Recording goes on for `follow_through_s` seconds after the step
info["success"] first becomes true (the expert's own follow-through: the cap pulled on past the 3 cm that
count, the gripper opened and backed away), and ends at the last of those steps where success still holds.
Demonstrations cut at the first success frame taught policies to stop exactly at the threshold, where a
policy a few millimetres short then hovered until its time ran out.

Episode i (0-based, in the store) uses the first successful seed among `seed + i`, `seed + i + SEED_STRIDE`,
`seed + i + 2 * SEED_STRIDE`, ... so the dataset is the same whether it was collected in one run or resumed:
re-running with the same output appends only the missing episodes (the store's episode count says how many
exist).

Noise injection (DART, Laskey et al. 2017; `dart_noise` > 0): the executed action is the expert's plus a
smooth random offset of the position (an Ornstein-Uhlenbeck process, `dart_noise` metres stationary
spread, one second correlation, half as much in z), while the recorded action stays the expert's own.
The stored states then include positions off the expert's path, each labelled with the way back, which
a plain expert never shows: a policy pushed off its path (an obstacle detour) has seen how to return.
The offset fades out below 12 cm above the table and within a second of the expert closing or opening
the gripper, so grasps and placements stay the expert's own.

Occlusion: when an object has fewer than `min_points` visible points in a frame (e.g. the pan
under the tilted bowl), its cloud from the previous step is reused, as a video tracker would
hold it; a slot missing in the first frame discards the episode. The count of such frames is
kept in the store attribute `held_clouds`.
"""

from __future__ import annotations

import inspect
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lano3dp.data.store import EpisodeStore
from lano3dp.errors import Lano3dpError
from lano3dp.geometry.frame import observe

SEED_STRIDE = 100_003  # fallback seeds of episode i: seed + i + k * SEED_STRIDE (k = 0, 1, ...)
MAX_TRIES = 10         # seeds tried per episode before giving up (under 4 cm DART noise the bottle expert fails ~45%)
# Workspace crop for clouds (world frame, metres): the table area up to 0.6 m high.
CROP_LOW = (0.0, -0.6, -0.02)
CROP_HIGH = (0.95, 0.6, 0.6)
CONTROL_HZ = 10.0


class CollectionError(Lano3dpError, RuntimeError):
    """The expert could not produce an episode (every seed tried failed)."""


class ExpertError(CollectionError):
    """An expert raised, or returned something that is not an action (10,) of finite numbers."""


@dataclass
class CollectConfig:
    """What `collect` records. Sizes in pixels/points; crop box in metres, world frame."""

    task: str | None  # None only with an env that names its own (env.task.name) or a factory (its name)
    episodes: int
    out: Path
    variation: str = "clean"
    seed: int = 0
    image_size: int = 128
    n_points: int = 64  # what the default policy trains on (PolicyConfig.n_points)
    scene_points: int = 512
    rgb_size: int = 96
    crop_low: tuple[float, float, float] = CROP_LOW
    crop_high: tuple[float, float, float] = CROP_HIGH
    min_points: int = 10
    max_steps: int | None = None  # episode limit (default: the task's); an expert that needs more fails
    dart_noise: float = 0.0  # m, spread of the injected position offset (0: the expert as it is)
    follow_through_s: float = 1.0  # s recorded past the first success (0: end at the first success frame)
    progress: bool = True
    # A user's env (see collect_from_env); all None: the built-in simulator and the task's open-loop plan.
    env: Any = None  # 'module:factory', 'path/to/file.py:factory', a factory, or an env object
    expert: Any = None  # 'module:callable' or expert(env, obs, info) -> (10,); None: env.expert_plan()
    slots: Sequence[str] | Mapping[str, str] | None = None  # policy slots (None: env.task.object_slots)
    skill: str | None = None  # default: env.task.skill, else the task name
    control_hz: float | None = None  # default: env.control_hz (the built-in simulator: CONTROL_HZ)
    table_height: float = 0.0  # m, world z of the table top; the scene cloud keeps what is above it

    def __post_init__(self):
        # Checked before anything is written: a bad value must not leave a store that blocks the corrected run.
        for name in ("episodes", "image_size", "n_points", "scene_points", "rgb_size", "min_points"):
            if getattr(self, name) < 1:
                raise ValueError(f"CollectConfig: {name} must be >= 1, got {getattr(self, name)}")
        if not 0 <= self.dart_noise <= 0.1:
            raise ValueError(f"CollectConfig: dart_noise is metres in [0, 0.1], got {self.dart_noise}")
        if not 0 <= self.follow_through_s <= 10:
            raise ValueError(f"CollectConfig: follow_through_s is seconds in [0, 10], got {self.follow_through_s}")
        if self.max_steps is not None and self.max_steps < 1:
            raise ValueError(f"CollectConfig: max_steps must be >= 1, got {self.max_steps}")
        if self.dart_noise > 0 and self.expert is not None:
            raise ValueError("CollectConfig: dart_noise needs the open-loop plan of the built-in simulator (its "
                             "fade-outs are planned ahead); a closed-loop expert can add its own noise")
        if self.control_hz is not None and self.control_hz <= 0:
            raise ValueError(f"CollectConfig: control_hz must be > 0, got {self.control_hz}")


@dataclass
class CollectResult:
    path: Path
    added: int
    total: int
    failed_seeds: list[int] = field(default_factory=list)  # the expert did not succeed
    seconds: float = 0.0
    steps: int = 0
    unseen_seeds: list[int] = field(default_factory=list)  # an object out of view in the first frame


def collect(task: str, episodes: int, out: str | Path, variation: str = "clean", seed: int = 0,
            image_size: int = 128, n_points: int = 64, progress: bool = True, **options) -> CollectResult:
    """Record scripted-expert episodes of `task` into `out` until it holds `episodes` episodes."""
    config = CollectConfig(task=task, episodes=episodes, out=Path(out), variation=variation, seed=seed,
                           image_size=image_size, n_points=n_points, progress=progress, **options)
    return collect_episodes(config)


def collect_from_env(env, expert: str | Callable | None, episodes: int, out: str | Path, *,
                     slots: Sequence[str] | Mapping[str, str] | None = None, task: str | None = None,
                     control_hz: float | None = None, max_steps: int | None = None, seed: int = 0,
                     crop_low: Sequence[float] | None = None, crop_high: Sequence[float] | None = None,
                     table_height: float = 0.0, n_points: int = 64, image_size: int = 128, progress: bool = True,
                     **options) -> CollectResult:
    """Record successful expert episodes from any environment into `out` until it holds `episodes` (resumable).

    Args:
        env: 'module:factory', 'path/to/file.py:factory', a factory callable (called as `lano3dp eval` calls it:
            task, seed, variation, image_size, render_rgb, max_steps, those it names), or an env object; None:
            the built-in simulator of `task`.
        expert: `expert(env, obs, info) -> (10,)` absolute action (position m, rotation 6D, gripper 0 open ..
            1 closed), called every step, closed loop; an object with `reset(env, obs, info)` has it called
            after each env reset. A 'module:callable' name is imported. None: the env's open-loop
            `expert_plan()` (the built-in simulator's).
        slots: the policy's object slots in order, e.g. ("block", "drawer"), or {slot: phrase}; each episode's
            phrase of a slot is info["target_phrases"][slot], else the phrase given, else the slot itself.
            Default: env.task.object_slots.
        task: the task name the dataset and the policy trained on it carry (default: env.task.name, else
            the env factory's name).
        control_hz: the env's control rate (default: env.control_hz); stored for training and evaluation.
        max_steps: step limit of an expert episode (default: env.max_steps).
        seed: episode i resets with seed + i (a failed seed is replaced by seed + i + k * SEED_STRIDE).
        crop_low, crop_high: (3,) world-frame box (m) clouds are cropped to; None: no crop.
        table_height: world z (m) of the table top; the scene cloud keeps what is above it.
        options: other `CollectConfig` fields (scene_points, rgb_size, min_points, variation, skill).

    Returns:
        CollectResult: episodes added and held, seeds that failed, seconds, steps.

    Raises:
        CollectionError: the expert failed on MAX_TRIES seeds for one episode, or the store at `out` was
            collected with other settings.
    """
    config = CollectConfig(task=task, episodes=episodes, out=Path(out), seed=seed, image_size=image_size,
                           n_points=n_points, progress=progress, max_steps=max_steps,
                           crop_low=None if crop_low is None else tuple(crop_low),
                           crop_high=None if crop_high is None else tuple(crop_high), env=env,
                           expert=expert, slots=slots, control_hz=control_hz, table_height=table_height,
                           **options)
    return collect_episodes(config)


class OpenLoopPlan:
    """The built-in simulator's scripted plan as an expert: `env.expert_plan()` at reset, one action a step."""

    def __init__(self):
        self.actions: np.ndarray | None = None
        self.step = 0

    def reset(self, env, obs, info) -> None:
        plan = getattr(env, "expert_plan", None)
        if not callable(plan):
            raise CollectionError("no expert given and the env has no expert_plan(); pass a closed-loop "
                                  "expert(env, obs, info) -> action (10,)")
        self.actions, self.step = np.asarray(plan().actions()), 0

    def __call__(self, env, obs, info) -> np.ndarray:
        action = self.actions[min(self.step, len(self.actions) - 1)]
        self.step += 1
        return action


def load_expert(spec: str | Callable | None) -> Callable:
    """'module:callable' or 'path/to/file.py:callable' (imported as --env factories are), a callable, or None
    (the env's open-loop plan) -> the expert."""
    from lano3dp.env_factory import EnvFactoryError, load_factory

    if spec is None:
        return OpenLoopPlan()
    if not isinstance(spec, str):
        if not callable(spec):
            raise CollectionError(f"the expert must be callable as expert(env, obs, info), got {type(spec).__name__}")
        return spec
    try:
        expert = load_factory(spec)
    except EnvFactoryError as error:
        raise CollectionError(str(error).replace("--env", "--expert", 1).replace("callable factory", "callable "
                                                                                  "expert")) from None
    return expert() if inspect.isclass(expert) else expert  # a class: one instance, reset each episode


def collect_episodes(config: CollectConfig) -> CollectResult:
    """Append episodes to `config.out` until it holds `config.episodes`; one collector per store at a time."""
    import shutil

    from lano3dp.locking import WriteLock

    with WriteLock(config.out):
        created = not Path(config.out).exists()
        try:
            return _collect_episodes(config)
        except BaseException:
            # a first collection that failed before its first episode leaves nothing behind to block a re-run
            if created and Path(config.out).exists() and EpisodeStore.open(config.out).n_episodes == 0:
                shutil.rmtree(config.out, ignore_errors=True)
            raise


def _collect_episodes(config: CollectConfig) -> CollectResult:
    from tqdm.auto import tqdm

    from lano3dp.perception import ObjectObserver, SimOracleSegmenter
    from lano3dp.policy.observations import UnrecordableEpisode

    started = time.perf_counter()
    env, label, owned = _make_env(config)
    try:
        source = _Source.of(env, label, config)
        expert = load_expert(config.expert)
        attrs = {
            "skill": source.skill,
            "task": source.task,
            "object_names": list(source.slots),
            "control_hz": source.control_hz,
            "crop_low": None if config.crop_low is None else list(config.crop_low),
            "crop_high": None if config.crop_high is None else list(config.crop_high),
            "n_points": config.n_points,
            "scene_points": config.scene_points,
            "variation": source.variation,
            "image_size": config.image_size,
            "base_seed": config.seed,
            "seed_stride": SEED_STRIDE,
            "source": "scripted expert, successful episodes only",
            "dart_noise": config.dart_noise,
            "follow_through_s": config.follow_through_s,
        }
        if source.env_name is not None:  # a user's env: what made the data, and where its table is
            attrs |= {"env": source.env_name, "expert": _name(config.expert), "table_height": config.table_height}
        if not (Path(config.out).exists() and EpisodeStore.open(config.out).n_episodes):
            check_first_frame(env, source, config)  # before anything is written
        store = EpisodeStore.open_or_create(config.out, attrs)
        existing = dict(store.attrs)
        existing.setdefault("follow_through_s", 0.0)  # stores from before it ended at the first success
        for key in ("task", "variation", "n_points", "base_seed", "dart_noise", "follow_through_s", "env",
                    "table_height"):
            if key in existing and existing.get(key) != attrs.get(key):
                raise CollectionError(f"{config.out} was collected with {key}={existing[key]!r}, not "
                                      f"{attrs.get(key)!r}; use another --out or the same settings to resume")
        observer = ObjectObserver(SimOracleSegmenter(), n_points=config.n_points, crop_low=config.crop_low,
                                  crop_high=config.crop_high, min_points=config.min_points, seed=0)
        result = CollectResult(config.out, 0, store.n_episodes)
        seeds = list(existing.get("episode_seeds", []))
        held_total = int(existing.get("held_clouds", 0))
        bar = tqdm(total=config.episodes, initial=store.n_episodes, desc=f"collect {source.task}",
                   disable=not config.progress, unit="ep")
        try:
            for index in range(store.n_episodes, config.episodes):
                failed, unseen = [], []
                for attempt in range(MAX_TRIES):
                    episode_seed = config.seed + index + attempt * SEED_STRIDE
                    try:
                        episode, held, camera = record_episode(env, observer, episode_seed, config, expert, source)
                    except UnrecordableEpisode:
                        unseen.append(episode_seed)
                        continue
                    if episode is not None:
                        break
                    failed.append(episode_seed)
                else:
                    causes = [f"the {source.task} expert failed on {len(failed)} seeds {failed}"] if failed else []
                    if unseen:
                        causes.append(f"an object was out of view in the first frame on {len(unseen)} seeds "
                                      f"{unseen} (at --image-size {config.image_size})")
                    raise CollectionError(" and ".join(causes) + f" for episode {index}")
                result.failed_seeds += failed
                result.unseen_seeds += unseen
                append_episode(store, episode, config.out)
                seeds.append(episode_seed)
                held_total += held
                result.added += 1
                result.steps += len(episode["action"])
                store.update_attrs(episode_seeds=seeds, held_clouds=held_total,
                                   failed_seeds=list(existing.get("failed_seeds", [])) + result.failed_seeds,
                                   camera=camera)
                bar.update(1)
        finally:
            bar.close()
    finally:
        if owned:
            env.close()
    result.total = store.n_episodes
    result.seconds = time.perf_counter() - started
    return result


@dataclass(frozen=True)
class _Source:
    """What the store says about the env the episodes come from."""

    task: str
    skill: str
    slots: tuple[str, ...]
    phrases: dict[str, str]  # default phrase per slot (info["target_phrases"] overrides it)
    control_hz: float
    max_steps: int
    variation: str
    env_name: str | None  # None: the built-in simulator

    @classmethod
    def of(cls, env, label: str, config: CollectConfig) -> _Source:
        inner = getattr(env, "env", env)
        task = getattr(inner, "task", None)
        builtin = config.env is None
        if config.slots is not None:
            phrases = dict(config.slots) if isinstance(config.slots, Mapping) else {s: s for s in config.slots}
        elif task is not None and hasattr(task, "object_slots"):
            phrases = {slot: slot for slot in task.object_slots}
        else:
            raise CollectionError(f"{label}: give the policy's object slots (slots=('block', ...) or --slots "
                                  "block,...); the env has no task.object_slots")
        if not phrases:
            raise CollectionError("slots: give at least one object slot")
        control_hz = config.control_hz or getattr(inner, "control_hz", None)
        if not control_hz:
            raise CollectionError(f"{label}: give control_hz (--control-hz) or set env.control_hz; training and "
                                  "evaluation need the rate the actions were recorded at")
        max_steps = config.max_steps or getattr(inner, "max_steps", None)
        if not max_steps:
            raise CollectionError(f"{label}: give max_steps (--max-steps) or set env.max_steps, the step limit of "
                                  "an expert episode")
        name = config.task or getattr(task, "name", None) or (None if builtin else _name(config.env).split(":")[-1])
        variation = config.variation
        if builtin:
            from lano3dp.sim import Variation

            variation = Variation.parse(config.variation).name
        return cls(task=str(name), skill=str(config.skill or getattr(task, "skill", None) or name),
                   slots=tuple(phrases), phrases={k: str(v) for k, v in phrases.items()},
                   control_hz=float(control_hz), max_steps=int(max_steps), variation=variation,
                   env_name=None if builtin else _name(config.env))


def _make_env(config: CollectConfig):
    """(env, label for errors, whether collection closes it): the built-in simulator, a factory's, or the given."""
    from lano3dp.env_factory import CheckedEnv, make_env

    spec = config.env
    if spec is not None and not isinstance(spec, str) and not inspect.isclass(spec) and \
            callable(getattr(spec, "reset", None)) and callable(getattr(spec, "step", None)):
        return CheckedEnv(spec, f"the env {type(spec).__name__}"), type(spec).__name__, False
    if spec is None and config.task is None:
        raise CollectionError("give a task of the built-in simulator or an env")
    options = {"task": config.task, "seed": config.seed, "variation": config.variation,
               "image_size": config.image_size, "render_rgb": True, "max_steps": config.max_steps}
    env = make_env(spec, **options)
    return env, env.label, True


def _name(value) -> str | None:
    """How the store names an env or expert: its spec, its 'module:qualname', or its type."""
    if value is None or isinstance(value, str):
        return value
    from lano3dp.env_factory import EnvFactoryError, factory_name

    try:
        return factory_name(value)
    except EnvFactoryError:
        return getattr(value, "__qualname__", type(value).__qualname__)


def record_episode(env, observer, seed: int, config: CollectConfig, expert: Callable | None = None,
                   source: _Source | None = None) -> tuple[dict[str, np.ndarray] | None, int, dict | None]:
    """Run the expert on `seed`; the episode's arrays if it succeeded, else None. Also the held-cloud count
    and the camera of the last frame (`PinholeCamera.to_dict()`).

    Raises:
        UnrecordableEpisode: a recorder cannot record this seed (a slot out of view in the first frame).
        ExpertError: the expert raised or returned something that is not a finite (10,) action.
    """
    from lano3dp.env_factory import EnvContractError
    from lano3dp.policy.observations import RecordContext, held_frames, recorders, task_inputs_of

    expert = OpenLoopPlan() if expert is None else expert
    source = _Source.of(env, "the env", config) if source is None else source
    obs, info = env.reset(seed=seed)
    if callable(getattr(expert, "reset", None)):
        expert.reset(env, obs, info)
    named = info.get("target_phrases") or {}
    phrases = [named.get(slot, source.phrases[slot]) for slot in source.slots]
    # every registered observation type's input: the built-in ones, and a user's registered before collecting
    record = recorders(RecordContext(observer, tuple(phrases), config))
    # the task inputs the env hands over (obs["goal"], ...): those of registered types its first observation holds
    task_inputs = list(task_inputs_of(obs))
    rows: dict[str, list[np.ndarray]] = {k: [] for k in ("action", "state", *record, *task_inputs)}
    follow_steps = int(round(config.follow_through_s * source.control_hz))
    first_success = last_success = None  # step indices
    noise = DartNoise(config.dart_noise, seed, getattr(expert, "actions", None), source.control_hz)
    frame = None
    for t in range(source.max_steps + follow_steps):
        frame, state = observe(env, obs)
        # an UnrecordableEpisode here (e.g. a slot out of view in the first frame) discards the seed (the caller)
        visual = {key: recorder(frame) for key, recorder in record.items()}
        action = checked_action(expert, env, obs, info, seed=seed, step=t, label=_expert_label(config))
        rows["action"].append(action)
        rows["state"].append(state)
        for key, value in (visual | task_inputs_of(obs, task_inputs)).items():
            rows[key].append(value)
        try:
            obs, _, terminated, truncated, info = env.step(noise.perturb(action, t))
        except EnvContractError as error:  # a demonstration is never recorded from a broken env: say which seed
            raise type(error)(f"{error} (seed {seed})") from None
        if info.get("success"):
            first_success = t if first_success is None else first_success
            last_success = t
        # after the first success an env's `terminated` only repeats it; a truncation still ends the episode
        if truncated or (terminated and first_success is None):
            break
        if first_success is not None and t - first_success >= follow_steps:
            break
    if first_success is None:
        return None, 0, None
    episode = {key: np.stack(values[:last_success + 1]) for key, values in rows.items()}
    for key in ("action", "state"):
        episode[key] = episode[key].astype(np.float32)
    camera = getattr(getattr(env, "env", env), "camera", None)
    camera = camera if hasattr(camera, "to_dict") else frame.camera
    return episode, held_frames(record), camera.to_dict()


ACTION_LAYOUT = "(10,) finite numbers: position (m), rotation 6D, gripper (0 open .. 1 closed), absolute"


def _expert_label(config: CollectConfig) -> str:
    if config.expert is None:
        return "the scripted expert" if config.env is None else "the env's expert_plan()"
    return f"--expert {config.expert}" if isinstance(config.expert, str) else f"the expert {_name(config.expert)}"


def checked_action(expert: Callable, env, obs, info, *, seed: int, step: int, label: str) -> np.ndarray:
    """The expert's action for this step as (10,) float32, checked at the boundary: a raise, a wrong shape or
    type, or a NaN is an ExpertError naming the expert, the seed and step, and what was expected."""
    where = f"seed {seed}, step {step}"
    try:
        raw = expert(env, obs, info)
    except Lano3dpError:
        raise
    except Exception as error:  # the user's code: one line naming it, not its traceback (--debug shows that)
        text = " ".join(str(error).split())
        raise ExpertError(f"{label} raised {type(error).__name__}{': ' + text if text else ''} ({where})") \
            from error
    try:
        action = np.asarray(raw, dtype=np.float32)
    except (TypeError, ValueError):
        raise ExpertError(f"{label} returned {type(raw).__name__} {raw!r:.60} ({where}); it must be "
                          f"{ACTION_LAYOUT}") from None
    if action.shape != (10,):
        raise ExpertError(f"{label} returned an action of shape {action.shape} ({where}); it must be "
                          f"{ACTION_LAYOUT}")
    bad = np.flatnonzero(~np.isfinite(action))
    if len(bad):
        raise ExpertError(f"{label} returned {action[bad[0]]} at action[{bad[0]}] ({where}); it must be "
                          f"{ACTION_LAYOUT}")
    return action


def check_first_frame(env, source: _Source, config: CollectConfig) -> None:
    """Before anything is written: at the first seed, every object slot has `min_points` points in view.

    Too small an image (`--image-size 16`) leaves an object a few pixels, which would otherwise be reported, ten
    seeds later, as failed episodes. Checked only below the default size (128 px), where the size is the likely
    cause; at or above it an object out of view is left to the seed retries (occlusion in one scene)."""
    from lano3dp.perception import ObjectObserver, PerceptionError, SimOracleSegmenter

    if config.image_size >= CollectConfig.image_size:
        return
    obs, info = env.reset(seed=config.seed)
    frame, _ = observe(env, obs)
    observer = ObjectObserver(SimOracleSegmenter(), n_points=config.n_points, crop_low=config.crop_low,
                              crop_high=config.crop_high, min_points=1, seed=0)
    named = info.get("target_phrases") or {}
    for slot in source.slots:
        phrase = named.get(slot, source.phrases[slot])
        try:
            count = int(observer.observe(frame, [phrase]).point_counts[0])
        except PerceptionError:
            count = 0
        if count < config.min_points:
            raise CollectionError(f"--image-size {config.image_size} is too small for {source.task}: the camera sees "
                                  f"{count} points of {phrase!r} in the first frame of seed {config.seed}, and "
                                  f"each object needs {config.min_points}; use a larger --image-size (default "
                                  f"{CollectConfig.image_size})")


def append_episode(store: EpisodeStore, episode: Mapping[str, np.ndarray], out: Path) -> None:
    """Append one episode; a write that fails (a full disk) is one line naming the store, which still holds
    every episode it held before (the episode count is written last, `EpisodeStore.append_episode`)."""
    from lano3dp.errors import StorageError, describe_os_error

    try:
        store.append_episode(episode)
    except OSError as error:
        raise StorageError(out, f"adding episode {store.n_episodes} failed ({describe_os_error(error)}); the "
                                f"dataset still holds its {store.n_episodes} complete episodes") from error


class DartNoise:
    """The smooth position offset of noise injection (see the module docstring); zero spread: no offset."""

    CORRELATION_S = 1.0
    FADE_HEIGHT = (0.06, 0.12)  # m above the table: no offset below the first height, all of it above the second
    QUIET_STEPS, FADE_STEPS = 4, 6  # no offset this close to a gripper change, all of it QUIET + FADE away

    def __init__(self, spread: float, seed: int, actions: np.ndarray | None, control_hz: float = CONTROL_HZ):
        self.spread = float(spread)
        self.rng = np.random.default_rng([int(seed), 0xDA27])
        self.keep = float(np.exp(-1.0 / (control_hz * self.CORRELATION_S)))
        self.offset = np.zeros(3)
        self.scale = np.array([1.0, 1.0, 0.5]) * self.spread
        if actions is None:  # a closed-loop expert: no plan to fade by (spread 0, see CollectConfig)
            self.weights = np.zeros(1)
            return
        actions = np.asarray(actions, dtype=np.float64)
        low, high = self.FADE_HEIGHT
        height = np.clip((actions[:, 2] - low) / (high - low), 0.0, 1.0)
        changes = np.flatnonzero(np.abs(np.diff(actions[:, 9])) > 1e-3)
        steps = np.arange(len(actions))
        distance = np.abs(steps[:, None] - changes[None, :]).min(1) if len(changes) else np.full(len(actions), 1e9)
        quiet = np.clip((distance - self.QUIET_STEPS) / self.FADE_STEPS, 0.0, 1.0)
        self.weights = height * quiet

    def perturb(self, action: np.ndarray, step: int) -> np.ndarray:
        if self.spread <= 0:
            return action
        fresh = self.rng.standard_normal(3) * self.scale
        self.offset = self.keep * self.offset + np.sqrt(1.0 - self.keep**2) * fresh
        perturbed = np.array(action, dtype=np.float32, copy=True)
        perturbed[:3] += self.weights[min(step, len(self.weights) - 1)] * self.offset
        return perturbed


def config_dict(config: CollectConfig) -> dict:
    data = asdict(config)
    data["out"] = str(config.out)
    return data
