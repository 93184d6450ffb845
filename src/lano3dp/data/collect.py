"""Scripted-expert demonstrations -> zarr episode store (`lano3dp collect`).

Each episode runs the task's scripted expert in `TabletopEnv` and records, per control step,
the observation before the action and the action:

    action          (10,) float32   absolute EE pose + gripper the expert commanded
    state           (11,) float32   EE pose, gripper opening, grasp flag
    object_clouds   (K, N, 3)       per-slot clouds (slot order = task.object_slots), ground-truth
                                    segmentation through `perception.ObjectObserver` + `SimOracleSegmenter`
    scene_cloud     (512, 3)        cropped scene without the table (DP3 baseline)
    rgb             (96, 96, 3)     uint8 (Diffusion Policy baseline)

Only successful expert episodes are kept; an episode ends at the step the task first
succeeds. Episode i (0-based, in the store) uses the first successful seed among
`seed + i`, `seed + i + SEED_STRIDE`, `seed + i + 2 * SEED_STRIDE`, ... so the dataset is
the same whether it was collected in one run or resumed: re-running with the same output
appends only the missing episodes (the store's episode count says how many exist).

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

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from lano3dp.data.store import EpisodeStore
from lano3dp.errors import Lano3dpError

SEED_STRIDE = 100_003  # fallback seeds of episode i: seed + i + k * SEED_STRIDE (k = 0, 1, ...)
MAX_TRIES = 5          # seeds tried per episode before giving up
# Workspace crop for clouds (world frame, metres): the table area up to 0.6 m high.
CROP_LOW = (0.0, -0.6, -0.02)
CROP_HIGH = (0.95, 0.6, 0.6)
CONTROL_HZ = 10.0


class CollectionError(Lano3dpError, RuntimeError):
    """The expert could not produce an episode (every seed tried failed)."""


@dataclass
class CollectConfig:
    """What `collect` records. Sizes in pixels/points; crop box in metres, world frame."""

    task: str
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
    progress: bool = True

    def __post_init__(self):
        # Checked before anything is written: a bad value must not leave a store that blocks the corrected run.
        for name in ("episodes", "image_size", "n_points", "scene_points", "rgb_size", "min_points"):
            if getattr(self, name) < 1:
                raise ValueError(f"CollectConfig: {name} must be >= 1, got {getattr(self, name)}")
        if not 0 <= self.dart_noise <= 0.1:
            raise ValueError(f"CollectConfig: dart_noise is metres in [0, 0.1], got {self.dart_noise}")
        if self.max_steps is not None and self.max_steps < 1:
            raise ValueError(f"CollectConfig: max_steps must be >= 1, got {self.max_steps}")


@dataclass
class CollectResult:
    path: Path
    added: int
    total: int
    failed_seeds: list[int] = field(default_factory=list)
    seconds: float = 0.0
    steps: int = 0


def collect(task: str, episodes: int, out: str | Path, variation: str = "clean", seed: int = 0,
            image_size: int = 128, n_points: int = 64, progress: bool = True, **options) -> CollectResult:
    """Record scripted-expert episodes of `task` into `out` until it holds `episodes` episodes."""
    config = CollectConfig(task=task, episodes=episodes, out=Path(out), variation=variation, seed=seed,
                           image_size=image_size, n_points=n_points, progress=progress, **options)
    return collect_episodes(config)


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
    from lano3dp.sim import TabletopEnv, Variation

    started = time.perf_counter()
    variation = Variation.parse(config.variation)
    env = TabletopEnv(config.task, variation=variation, image_size=config.image_size, render_rgb=True,
                      control_hz=CONTROL_HZ, max_steps=config.max_steps)
    task = env.task
    attrs = {
        "skill": task.skill,
        "task": task.name,
        "object_names": list(task.object_slots),
        "control_hz": CONTROL_HZ,
        "crop_low": list(config.crop_low),
        "crop_high": list(config.crop_high),
        "n_points": config.n_points,
        "scene_points": config.scene_points,
        "variation": variation.name,
        "image_size": config.image_size,
        "base_seed": config.seed,
        "seed_stride": SEED_STRIDE,
        "source": "scripted expert, successful episodes only",
        "dart_noise": config.dart_noise,
    }
    store = EpisodeStore.open_or_create(config.out, attrs)
    existing = store.attrs
    for key in ("task", "variation", "n_points", "base_seed", "dart_noise"):
        if key in existing and existing[key] != attrs[key]:
            raise CollectionError(f"{config.out} was collected with {key}={existing[key]!r}, not {attrs[key]!r}; "
                                  "use another --out or the same settings to resume")
    observer = ObjectObserver(SimOracleSegmenter(), n_points=config.n_points, crop_low=config.crop_low,
                              crop_high=config.crop_high, min_points=config.min_points, seed=0)
    result = CollectResult(config.out, 0, store.n_episodes)
    seeds = list(existing.get("episode_seeds", []))
    held_total = int(existing.get("held_clouds", 0))
    bar = tqdm(total=config.episodes, initial=store.n_episodes, desc=f"collect {task.name}",
               disable=not config.progress, unit="ep")
    try:
        for index in range(store.n_episodes, config.episodes):
            for attempt in range(MAX_TRIES):
                episode_seed = config.seed + index + attempt * SEED_STRIDE
                episode, held = record_episode(env, observer, episode_seed, config)
                if episode is not None:
                    break
                result.failed_seeds.append(episode_seed)
            else:
                raise CollectionError(f"the {task.name} expert failed on {MAX_TRIES} seeds for episode {index} "
                                      f"(seeds {result.failed_seeds[-MAX_TRIES:]})")
            store.append_episode(episode)
            seeds.append(episode_seed)
            held_total += held
            result.added += 1
            result.steps += len(episode["action"])
            store.update_attrs(episode_seeds=seeds, held_clouds=held_total,
                               failed_seeds=list(existing.get("failed_seeds", [])) + result.failed_seeds,
                               camera=env.camera.to_dict())
            bar.update(1)
    finally:
        bar.close()
        env.close()
    result.total = store.n_episodes
    result.seconds = time.perf_counter() - started
    return result


def record_episode(env, observer, seed: int, config: CollectConfig) -> tuple[dict[str, np.ndarray] | None, int]:
    """Run the expert on `seed`; the episode's arrays if it succeeded, else None. Also the held-cloud count."""
    from lano3dp.perception import PerceptionError, scene_cloud

    obs, info = env.reset(seed=seed)
    phrases = [info["target_phrases"][slot] for slot in env.task.object_slots]
    actions = env.expert_plan().actions()
    rows: dict[str, list[np.ndarray]] = {k: [] for k in ("action", "state", "object_clouds", "scene_cloud", "rgb")}
    last_clouds: list[np.ndarray | None] = [None] * len(phrases)
    held = 0
    success = False
    noise = DartNoise(config.dart_noise, seed, actions)
    for t in range(env.max_steps):
        frame = env.frame()
        try:
            clouds = list(observer.observe(frame, phrases).points)
        except PerceptionError:  # some slot is occluded: hold its last cloud
            clouds = []
            for k, phrase in enumerate(phrases):
                try:
                    clouds.append(observer.observe(frame, [phrase]).points[0])
                except PerceptionError:
                    if last_clouds[k] is None:
                        return None, 0
                    clouds.append(last_clouds[k])
                    held += 1
        last_clouds = clouds
        action = actions[min(t, len(actions) - 1)]
        rows["action"].append(action)
        rows["state"].append(obs["state"])
        rows["object_clouds"].append(np.stack(clouds))
        rows["scene_cloud"].append(scene_cloud(frame, config.scene_points, config.crop_low, config.crop_high,
                                               table_height=0.0))
        rows["rgb"].append(resize_rgb(obs["rgb"], config.rgb_size))
        obs, _, terminated, truncated, info = env.step(noise.perturb(action, t))
        if terminated:
            success = True
            break
        if truncated:
            break
    if not success:
        return None, 0
    episode = {key: np.stack(values) for key, values in rows.items()}
    for key in ("action", "state", "object_clouds", "scene_cloud"):
        episode[key] = episode[key].astype(np.float32)
    return episode, held


class DartNoise:
    """The smooth position offset of noise injection (see the module docstring); zero spread: no offset."""

    CORRELATION_S = 1.0
    FADE_HEIGHT = (0.06, 0.12)  # m above the table: no offset below the first height, all of it above the second
    QUIET_STEPS, FADE_STEPS = 4, 6  # no offset this close to a gripper change, all of it QUIET + FADE away

    def __init__(self, spread: float, seed: int, actions: np.ndarray):
        self.spread = float(spread)
        self.rng = np.random.default_rng([int(seed), 0xDA27])
        self.keep = float(np.exp(-1.0 / (CONTROL_HZ * self.CORRELATION_S)))
        self.offset = np.zeros(3)
        self.scale = np.array([1.0, 1.0, 0.5]) * self.spread
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


def resize_rgb(rgb: np.ndarray, size: int) -> np.ndarray:
    """(H, W, 3) uint8 -> (size, size, 3) uint8, area-averaged (PIL's box filter)."""
    if rgb.shape[0] == size and rgb.shape[1] == size:
        return rgb
    from PIL import Image

    return np.asarray(Image.fromarray(rgb).resize((size, size), Image.Resampling.BOX))


def config_dict(config: CollectConfig) -> dict:
    data = asdict(config)
    data["out"] = str(config.out)
    return data
