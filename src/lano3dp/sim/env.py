"""`TabletopEnv`: a gymnasium environment over the MuJoCo tabletop.

Action (10,) float: absolute EE target = position (3, metres, world frame) + rotation 6D
(6: first two columns of the EE rotation matrix) + gripper command (1: 0 open .. 1 closed).
Each `step` moves the mocap target from the previous target towards this one over the control
period (1 / control_hz s = 25 physics steps of 4 ms at 10 Hz), by at most what a real arm moves in
that time (`MotionLimits`: 0.5 m/s, 2.5 rad/s by default). A target farther away is reached over
several steps, so no policy succeeds by teleporting the hand; `info["motion_limited"]` says when
a step was cut short.

Bad actions:
  * NaN / inf anywhere, wrong shape, or a degenerate rotation 6D (zero or parallel columns)
    -> `InvalidActionError` naming the problem (nothing is simulated).
  * position outside `workspace_low .. workspace_high` -> clipped to the box; gripper outside
    [0, 1] -> clipped. `info["action_clipped"]` is True for that step.

Observation (dict): "rgb" (H, W, 3) uint8 (if render_rgb), "depth" (H, W) float32 metres
(0 = no surface), "segmentation" (H, W) int32 body ids (-1 = sky), "state" (11,) float32
[EE position, EE rotation 6D, gripper opening (m), grasp flag], "intrinsics" (3, 3) and
"cam_to_world" (4, 4) float32 (OpenCV convention). `env.frame()` returns the same images as
an `RGBDFrame` with `instance_names` and `instance_attributes` for the ground-truth segmenter.

Info: "success", "is_success", "action_clipped", "motion_limited", "obstacle_contacts" (contact events of the
gripper or held object with obstacles during this step: dicts with obstacle, body, depth),
"n_obstacle_contacts" (episode total), "min_obstacle_clearance" (metres at the end of the step;
inf without obstacles; negative = penetration: the hand follows its target through a stiff
weld, so a target inside an obstacle pushes the hand centimetres into it), "held_object",
"seed", "variation", "instruction", "target_phrases", "slot_objects" (slot -> scene object name),
"stages" (the task's stages in order -> reached at some step of this episode: latched, judged
after every step like success) and "stage" (the furthest of them reached, or None).
Reward: 1.0 on success, else 0.0; `terminated` on success, `truncated` at `max_steps`.
"""

from __future__ import annotations

import copy
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces

from lano3dp.errors import Lano3dpError
from lano3dp.geometry import RGBDFrame
from lano3dp.geometry.rotations import matrix_to_rot6d
from lano3dp.sim.experts import CONTROL_HZ, MotionPlan, slerp
from lano3dp.sim.objects import ObjectInfo, primitives
from lano3dp.sim.render import CameraImages, FusedRenderer
from lano3dp.sim.robot import GripperHandle, GripperSpec
from lano3dp.sim.scene import (
    FRONT_CAMERA,
    SHIFTED_CAMERA,
    SHIFTED_LEFT_CAMERA,
    TIMESTEP,
    CameraPose,
    SceneBuilder,
)
from lano3dp.sim.tasks import make_task
from lano3dp.sim.tasks.base import Layout, SimState, Task, furthest_stage
from lano3dp.sim.variations import SceneExtras, Variation, sample_extras

WORKSPACE_LOW = np.array([0.05, -0.55, 0.0])
WORKSPACE_HIGH = np.array([0.95, 0.55, 0.60])
CAMERAS = {"front": FRONT_CAMERA, "shifted": SHIFTED_CAMERA, "shifted_left": SHIFTED_LEFT_CAMERA}
# Physics substeps between obstacle checks / mocap updates within one control step.
_CHUNK = 5
_COPY_IN_PLACE = hasattr(mujoco, "mj_copyData")  # MuJoCo 3.x binds none: `frame_later` takes a fresh copy there
_SETTLE_STEPS = 75  # 0.3 s for objects to come to rest after building


def mujoco_version() -> tuple[int, int]:
    """(major, minor) of the MuJoCo installed."""
    major, minor = mujoco.__version__.split(".")[:2]
    return int(major), int(minor)


def warn_if_simulator_too_old(task: Task) -> None:
    """Warn once per task when the installed MuJoCo is older than the one the task's contacts need."""
    needed = task.reliable_from_mujoco
    if mujoco_version() < tuple(needed) and task.name not in _WARNED_TASKS:
        _WARNED_TASKS.add(task.name)
        warnings.warn(f"{task.name} on MuJoCo {mujoco.__version__}: {task.simulator_note or 'its expert fails'}; it "
                      f"works from MuJoCo {needed[0]}.{needed[1]} on (docs/simulator-versions.md)", stacklevel=3)


_WARNED_TASKS: set[str] = set()


@dataclass(frozen=True)
class MotionLimits:
    """Largest end-effector speeds the simulated arm follows (m/s, rad/s).

    The angular limit is the Franka Panda's Cartesian rotation limit (2.5 rad/s, Franka's interface
    specification); the linear one is well inside the Panda's 1.7 m/s and a UR5e's 1 m/s TCP limits and
    twice the scripted experts' fastest segment (0.25 m/s peak), so demonstrations never meet it. Before
    the limit, one 10 Hz step could move the hand 25 cm, and an untrained policy "closed" the microwave
    by jumping through it.
    """

    linear: float = 0.5
    angular: float = 2.5


class InvalidActionError(Lano3dpError, ValueError):
    """An action that cannot be executed (NaN, wrong shape, degenerate rotation)."""


class SimulationError(Lano3dpError, RuntimeError):
    """The physics diverged (MuJoCo reported an unstable state)."""


class EnvClosedError(Lano3dpError, RuntimeError):
    """The environment was used after close()."""


@dataclass
class EpisodeInfo:
    seed: int
    layout: Layout
    extras: SceneExtras
    variation: Variation


def sample_episode(task: Task, seed: int, variation: Variation) -> tuple[Layout, SceneExtras]:
    """The layout and extras of episode `seed`, without building it (cheap: e.g. to find scenes with room for
    an obstacle). `reset` builds exactly these."""
    rng = np.random.default_rng(int(seed))
    layout = task.sample_layout(rng, variation)
    layout.seed = int(seed)
    return layout, sample_extras(task, layout, rng, variation)


# A task none of whose first NO_ROOM_SEEDS scenes has room for a variation's obstacles is taken to have none. Measured
# on seeds 0-399: open_drawer and close_microwave placed no obstacle of any kind (their short paths run between the
# start keep-out and the drawer or microwave), while the rarest variation with room, bottle_upright obstacle:2, had
# 2 of 400 (its first at seed 294): at 1 in 200, 1000 seeds miss it with probability 0.7%. Deciding costs 1000
# layout samples, 5-30 ms each, instead of the 100,000 (about 20 CPU-minutes) searched before giving up.
NO_ROOM_SEEDS = 1000


class NoObstacleRoomError(Lano3dpError, ValueError):
    """No scene of the task has room for the variation's obstacles (`obstacle_scene_seeds`)."""


def obstacle_scene_seeds(task: str | Task, variation, start: int, count: int, max_tries: int = 100_000) -> list[int]:
    """The first `count` seeds from `start` on whose scene got every obstacle the variation asks for.

    Raises:
        NoObstacleRoomError: none of the first NO_ROOM_SEEDS seeds has room (the task's layout leaves none), or
            fewer than `count` of `max_tries` do.
    """
    task = make_task(task) if isinstance(task, str) else task
    variation = Variation.parse(variation)
    if not variation.has("obstacle"):
        return list(range(start, start + count))
    wanted = variation.n_obstacles * (2 if variation.obstacle_kind == "cluster" else 1)
    seeds: list[int] = []
    for seed in range(start, start + max_tries):
        if not seeds and seed - start == NO_ROOM_SEEDS:
            raise NoObstacleRoomError(
                f"none of {NO_ROOM_SEEDS} {task.name} scenes (seeds {start}-{seed - 1}) has room for "
                f"{variation.name}: the task's layout leaves none; evaluate that variation on another task "
                "(e.g. bowl_pour, put_item_in_drawer) or without obstacle_scenes_only (--obstacle-scenes-only)")
        _, extras = sample_episode(task, seed, variation)
        if sum(extra.role == "obstacle" for extra in extras.objects) >= wanted:
            seeds.append(seed)
            if len(seeds) == count:
                return seeds
    raise NoObstacleRoomError(f"only {len(seeds)} of {max_tries} {task.name} scenes (from seed {start}) have room "
                              f"for {variation.name}; ask for fewer episodes or use another task")


def _camera_pose(camera: str | CameraPose) -> CameraPose:
    if isinstance(camera, CameraPose):
        return camera
    if camera not in CAMERAS:
        raise ValueError(f"unknown camera {camera!r}; use one of {sorted(CAMERAS)} or a CameraPose")
    return CAMERAS[camera]


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """np.cross of two 3-vectors, the same products and differences in the same order (so the same bits): np.cross
    costs ~0.1 ms a call in its axis handling, a third of a step's Python time."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = b.tolist()
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


class TabletopEnv(gym.Env):
    """Gymnasium env for one task; every `reset` builds a fresh scene from the seed.

    Args:
        task: registry name ("bowl_pour") or a `Task` instance.
        variation: "clean", axes joined by "+", an iterable of axes, or a `Variation`.
        camera: "front" (training), "shifted" or "shifted_left", or a `CameraPose`; the "camera" variation forces
            "shifted".
        other_cameras: cameras `other_views` renders on request, for a target or obstacle the observation camera
            cannot see; any at the episode's observation camera is left out.
        image_size: square image side in pixels (or (height, width)).
        render_rgb: also render the colour image (depth + segmentation are always rendered).
        control_hz: control rate (physics runs at 250 Hz, 4 ms steps; 1 / control_hz must be a multiple of 20 ms).
        max_steps: episode limit (default: the task's).
        motion_limits: the EE speed limits each step's target motion is bounded by.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": int(CONTROL_HZ)}

    def __init__(self, task: str | Task = "bowl_pour", variation=None, camera: str | CameraPose = "front",
                 image_size: int | tuple[int, int] = 128, render_rgb: bool = True, control_hz: float = CONTROL_HZ,
                 max_steps: int | None = None, render_mode: str | None = "rgb_array",
                 motion_limits: MotionLimits = MotionLimits(),
                 other_cameras: Sequence[str | CameraPose] = ("front", "shifted", "shifted_left")):
        self.task = make_task(task) if isinstance(task, str) else task
        warn_if_simulator_too_old(self.task)
        self.variation = Variation.parse(variation)
        self.camera_pose = _camera_pose(camera)
        self.other_camera_poses = [_camera_pose(other) for other in other_cameras]
        height, width = (image_size, image_size) if np.isscalar(image_size) else tuple(image_size)
        self.height, self.width = int(height), int(width)
        self.render_rgb = render_rgb
        self.render_mode = render_mode
        self.control_hz = float(control_hz)
        self.substeps = int(round(1.0 / (self.control_hz * TIMESTEP)))
        if self.substeps % _CHUNK:
            raise ValueError(f"control_hz must give a multiple of {_CHUNK} physics steps, got {self.substeps}")
        self.max_steps = int(max_steps or self.task.max_steps)
        self.motion_limits = motion_limits
        self.gripper_spec = GripperSpec()
        self.workspace_low, self.workspace_high = WORKSPACE_LOW.copy(), WORKSPACE_HIGH.copy()

        image = (self.height, self.width)
        obs = {
            "depth": spaces.Box(0.0, 100.0, image, np.float32),  # metres; 0 = no surface
            "segmentation": spaces.Box(-1, np.iinfo(np.int32).max, image, np.int32),
            "state": spaces.Box(-np.inf, np.inf, (11,), np.float32),
            "intrinsics": spaces.Box(-np.inf, np.inf, (3, 3), np.float32),
            "cam_to_world": spaces.Box(-np.inf, np.inf, (4, 4), np.float32),
        }
        if render_rgb:
            obs["rgb"] = spaces.Box(0, 255, (*image, 3), np.uint8)
        self.observation_space = spaces.Dict(obs)
        low = np.concatenate([self.workspace_low, -np.ones(6), [0.0]]).astype(np.float32)
        high = np.concatenate([self.workspace_high, np.ones(6), [1.0]]).astype(np.float32)
        self.action_space = spaces.Box(low, high, dtype=np.float32)

        self._renderer: FusedRenderer | None = None
        self.model: mujoco.MjModel | None = None
        self.data: mujoco.MjData | None = None
        self.episode: EpisodeInfo | None = None
        self._frame: RGBDFrame | None = None
        self._images: CameraImages | None = None
        self._defer_images = False
        # copies of the state for `frame_later`, back for reuse once rendered or dropped (allocating one zeroes
        # its 15 MB arena: 0.4 ms, a fifth of a render)
        self._spare: list[mujoco.MjData] = []
        self._spare_of: mujoco.MjModel | None = None

    # ---- episode construction -------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Build the scene of episode `seed`. options: {"variation": ...} overrides the variation."""
        self._check_open()
        super().reset(seed=seed)
        options = options or {}
        variation = Variation.parse(options["variation"]) if "variation" in options else self.variation
        episode_seed = int(seed) if seed is not None else int(self.np_random.integers(0, 2**31 - 1))
        layout, extras = sample_episode(self.task, episode_seed, variation)
        if not variation.has("camera"):
            extras.camera = self.camera_pose
        self.episode = EpisodeInfo(episode_seed, layout, extras, variation)
        self._build(layout, extras)
        self._steps = 0
        self._n_contacts = 0
        self._success = False
        self._stages = dict.fromkeys(self.task.stages, False)
        self._frame = None
        obs = self._observe()
        return obs, self._info(clipped=False, contacts=[], clearance=self._clearance())

    def _build(self, layout: Layout, extras: SceneExtras) -> None:
        builder = SceneBuilder(extras.style, self.gripper_spec, max_image_size=max(self.height, self.width))
        self.task.build(builder, layout)
        for extra in extras.objects:
            if extra.role == "obstacle" and extra.kind == "box":
                primitives.add_box_obstacle(builder, extra.name, extra.position_at(0.0), extra.half_extents,
                                            extra.yaw, height=extra.height, color=extra.color,
                                            moving=extra.motion is not None)
            elif extra.role == "obstacle":
                primitives.add_cylinder_obstacle(builder, extra.name, extra.position_at(0.0), radius=extra.radius,
                                                 height=extra.height, color=extra.color,
                                                 moving=extra.motion is not None)
            else:
                primitives.add_object(builder, extra.kind, extra.name, extra.position, yaw=extra.yaw,
                                      color=extra.color, scale=extra.scale, role=extra.role)
        builder.add_camera(CameraPose("front", extras.camera.position, extras.camera.target, extras.camera.fovy))
        self._other_cameras = []
        for pose in self.other_camera_poses:
            if pose.position != extras.camera.position:
                name = f"other_{len(self._other_cameras)}"
                builder.add_camera(CameraPose(name, pose.position, pose.target, pose.fovy))
                self._other_cameras.append(name)
        self.builder = builder
        self.objects: dict[str, ObjectInfo] = dict(builder.objects)
        model = builder.compile()
        data = mujoco.MjData(model)
        self.model, self.data = model, data
        self.gripper = GripperHandle(model, self.gripper_spec)
        mujoco.mj_forward(model, data)
        mujoco.mj_step(model, data, nstep=_SETTLE_STEPS)
        self.sim = SimState(model, data, self.objects, self.gripper)
        self._target_pos, self._target_quat = self.gripper.target(data)
        self._body_object = np.full(model.nbody, "", dtype=object)
        self.instance_names: dict[str, list[int]] = {}
        for name, info in self.objects.items():
            ids = [model.body(b).id for b in info.body_names]
            self.instance_names[name] = ids
            self._body_object[ids] = name
        self.instance_attributes = {name: info.attributes() for name, info in self.objects.items()}
        obstacle_bodies = [i for n, info in self.objects.items() if info.role == "obstacle"
                           for i in self.instance_names[n]]
        # per geom, whether it is an obstacle's or the robot's: contacts are checked five times a step
        self._is_obstacle_geom = np.isin(model.geom_bodyid, obstacle_bodies)
        self._is_robot_geom = np.isin(model.geom_bodyid, self.gripper.body_ids)
        self._obstacle_geoms = np.flatnonzero(self._is_obstacle_geom)
        self._robot_geoms = np.flatnonzero(self._is_robot_geom)
        # moving obstacles are mocap bodies, slid along their swing in step()
        self._moving = [(int(model.body_mocapid[model.body(extra.name).id]), extra)
                        for extra in extras.objects if extra.role == "obstacle" and extra.motion is not None]
        if self._renderer is None:
            self._renderer = FusedRenderer(self.width, self.height)
        self._renderer.set_model(model)

    # ---- stepping -------------------------------------------------------------------------
    def validate_action(self, action) -> tuple[np.ndarray, np.ndarray, float, bool]:
        """Check and clip one action. Returns (position, quaternion wxyz, gripper, clipped)."""
        action = np.asarray(action, dtype=np.float64)
        if action.shape != (10,):
            raise InvalidActionError(
                f"action must have shape (10,) = position 3 + rotation 6D 6 + gripper 1, got {action.shape}")
        if not np.all(np.isfinite(action)):
            bad = [i for i in range(10) if not np.isfinite(action[i])]
            raise InvalidActionError(f"action has NaN/inf at indices {bad}: {action.tolist()}")
        a1, a2 = action[3:6], action[6:9]
        n1 = np.linalg.norm(a1)
        if n1 < 1e-6 or np.linalg.norm(_cross(a1 / n1, a2)) < 1e-6:
            raise InvalidActionError(f"rotation 6D {action[3:9].tolist()} is degenerate (zero or parallel columns)")
        position = np.clip(action[:3], self.workspace_low, self.workspace_high)
        gripper = min(max(float(action[9]), 0.0), 1.0)
        clipped = bool(np.any(position != action[:3]) or gripper != action[9])
        b1 = a1 / n1
        b2 = a2 - np.dot(b1, a2) * b1
        b2 /= np.linalg.norm(b2)
        rotation = np.stack([b1, b2, _cross(b1, b2)], axis=1)
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, rotation.reshape(-1))
        return position, quat, gripper, clipped

    def _check_open(self) -> None:
        if getattr(self, "_closed", False):
            raise EnvClosedError("this TabletopEnv was closed; make a new one to run more episodes")

    def step(self, action):
        self._check_open()
        if self.data is None:
            raise RuntimeError("call reset() before step()")
        position, quat, gripper, clipped = self.validate_action(action)
        model, data = self.model, self.data
        start_pos, start_quat = self._target_pos, self._target_quat
        if np.dot(start_quat, quat) < 0:
            quat = -quat
        position, quat, limited = self._bounded_target(start_pos, start_quat, position, quat)
        chunks = self.substeps // _CHUNK
        contacts, clearance = [], np.inf
        for k in range(1, chunks + 1):
            s = k / chunks
            blended = (1 - s) * start_quat + s * quat  # nlerp: the per-chunk angle is small
            self.gripper.command(data, start_pos + s * (position - start_pos), blended / np.linalg.norm(blended),
                                 gripper)
            for mocap, extra in self._moving:
                data.mocap_pos[mocap, :2] = extra.position_at((self._steps + s) / self.control_hz)[:2]
            mujoco.mj_step(model, data, nstep=_CHUNK)
            if len(self._obstacle_geoms):
                contacts.extend(self._obstacle_contacts())
        if not np.all(np.isfinite(data.qacc)) or data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number > 0:
            raise SimulationError(f"physics became unstable at step {self._steps} (seed {self.episode.seed})")
        if len(self._obstacle_geoms):
            clearance = self._clearance()
        self._target_pos, self._target_quat = position, quat
        self._steps += 1
        self._n_contacts += len(contacts)
        self._success = bool(self.task.is_success(self.sim, self.episode.layout))
        self._frame = None
        obs = self._observe()
        truncated = self._steps >= self.max_steps and not self._success
        return obs, float(self._success), self._success, truncated, self._info(clipped, contacts, clearance,
                                                                               limited)

    @property
    def max_ee_step(self) -> float:
        """Metres the end effector moves at most in one step (the linear motion limit over a control period)."""
        return self.motion_limits.linear / self.control_hz

    def _bounded_target(self, start_pos: np.ndarray, start_quat: np.ndarray, position: np.ndarray,
                        quat: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        """The target this step reaches: `position` / `quat` (wxyz, same hemisphere as `start_quat`),
        moved back towards the start so that neither speed limit is exceeded. Returns (position, quat, limited)."""
        max_distance = self.max_ee_step
        max_angle = self.motion_limits.angular / self.control_hz
        offset = position - start_pos
        distance = float(np.linalg.norm(offset))
        angle = 2.0 * float(np.arccos(np.clip(abs(np.dot(start_quat, quat)), 0.0, 1.0)))
        limited = False
        if distance > max_distance:
            position = start_pos + offset * (max_distance / distance)
            limited = True
        if angle > max_angle:
            quat = slerp(start_quat, quat, max_angle / angle)
            limited = True
        return position, quat, limited

    def _obstacle_contacts(self) -> list[dict]:
        data, model = self.data, self.model
        ncon = data.ncon
        if ncon == 0:
            return []
        g1, g2 = data.contact.geom1[:ncon], data.contact.geom2[:ncon]
        obstacle1, obstacle2 = self._is_obstacle_geom[g1], self._is_obstacle_geom[g2]
        if not (obstacle1.any() or obstacle2.any()):
            return []  # nothing touches an obstacle: what the gripper holds need not be known
        mover = self._is_robot_geom.copy()
        held = self.gripper.held_body(data)
        if held >= 0:
            mover |= model.geom_bodyid == held
        hits = (obstacle1 & mover[g2]) | (obstacle2 & mover[g1])
        events = []
        for i in np.flatnonzero(hits):
            a, b = (g1[i], g2[i]) if obstacle1[i] else (g2[i], g1[i])
            events.append({"step": self._steps, "obstacle": self._body_object[model.geom_bodyid[a]],
                           "body": model.body(model.geom_bodyid[b]).name, "depth": float(-data.contact.dist[i])})
        return events

    def _mover_geoms(self) -> np.ndarray:
        held = self.gripper.held_body(self.data)
        if held < 0:
            return self._robot_geoms
        return np.concatenate([self._robot_geoms, np.flatnonzero(self.model.geom_bodyid == held)])

    def _clearance(self) -> float:
        """Smallest distance (m) between obstacle geoms and the gripper or held object; inf if none."""
        if self.model is None or not len(self._obstacle_geoms):
            return float(np.inf)
        best = np.inf
        fromto = np.zeros(6)
        for movable in self._mover_geoms():
            for obstacle in self._obstacle_geoms:
                best = min(best, mujoco.mj_geomDistance(self.model, self.data, int(movable), int(obstacle), 0.5,
                                                        fromto))
        return float(best)

    # ---- observations ---------------------------------------------------------------------
    def state(self) -> np.ndarray:
        """(11,) float32: EE position (3), EE rotation 6D (6), gripper opening (m), grasp flag."""
        position, rotation = self.gripper.ee_pose(self.data)
        grasped = float(self.gripper.held_body(self.data) >= 0)
        return np.concatenate([position, matrix_to_rot6d(rotation), [self.gripper.opening(self.data), grasped]]
                              ).astype(np.float32)

    def _observe(self) -> dict:
        self._images = None  # this moment's, rendered now or when a frame is asked for
        if self._defer_images:
            return {"state": self.state()}
        images = self._current_images()
        obs = {
            "depth": images.depth,
            "segmentation": images.body_ids,
            "state": self.state(),
            "intrinsics": images.camera.K.astype(np.float32),
            "cam_to_world": images.camera.cam_to_world.astype(np.float32),
        }
        if self.render_rgb:
            obs["rgb"] = images.rgb
        return obs

    def _current_images(self) -> CameraImages:
        if self._images is None:
            self._images = self._renderer.render(self.data, "front", rgb=self.render_rgb)
        return self._images

    def defer_images(self, defer: bool = True) -> None:
        """Render the camera only when a frame is asked for (`frame`, `frame_later`), not at every step: for a
        control loop that sees some frames (a policy observing every 8th step). Observations then hold "state"
        only. Off again with `defer_images(False)`."""
        self._defer_images = bool(defer)

    def frame(self) -> RGBDFrame:
        """The current camera images as an `RGBDFrame` with ground-truth instance names and attributes."""
        self._check_open()
        if self._frame is None:
            self._frame = self._as_frame(self._current_images())
        return self._frame

    def frame_later(self) -> Callable[[], RGBDFrame]:
        """This moment's `frame`, rendered only if and when the returned callable is called within this episode:
        a copy of the simulation state, rendered as it would be now."""
        self._check_open()
        if self._spare_of is not self.model:
            self._spare, self._spare_of = [], self.model
        if self._spare and _COPY_IN_PLACE:
            state = self._spare.pop()
            mujoco.mj_copyData(state, self.model, self.data)
        else:
            state = copy.copy(self.data)
        return _LaterFrame(self, state, self._steps)

    def other_views(self) -> list[RGBDFrame]:
        """This moment seen from the other cameras (`other_cameras`), rendered now: they cost a render each,
        so the runtime asks only when the observation camera cannot see a target or an obstacle."""
        self._check_open()
        return [self._as_frame(self._renderer.render(self.data, name, rgb=self.render_rgb))
                for name in self._other_cameras]

    def _as_frame(self, images: CameraImages, steps: int | None = None) -> RGBDFrame:
        rgb = images.rgb if images.rgb is not None else np.zeros((self.height, self.width, 3), np.uint8)
        return RGBDFrame(rgb=rgb, depth=images.depth, camera=images.camera, segmentation=images.body_ids,
                         instance_names=self.instance_names, instance_attributes=self.instance_attributes,
                         timestamp=(self._steps if steps is None else steps) / self.control_hz)

    @property
    def camera(self):
        """The observation camera (PinholeCamera) of the current episode."""
        return self._current_images().camera

    def _latch_stages(self) -> dict[str, bool]:
        """Stages reached so far this episode. Judged after each step (not at reset, like success), and
        a stage once reached stays reached: "grasped" still counts after the object is put down."""
        if self._steps:
            reached = self.task.stage_reached(self.sim, self.episode.layout)
            if tuple(reached) != self.task.stages:
                raise ValueError(f"{type(self.task).__name__}.stage_reached returned stages {tuple(reached)}; "
                                 f"it must return exactly its declared `stages` {self.task.stages}, in order")
            for stage, now in reached.items():
                self._stages[stage] = self._stages[stage] or bool(now)
        return dict(self._stages)

    def _info(self, clipped: bool, contacts: list, clearance: float, limited: bool = False) -> dict:
        layout = self.episode.layout
        stages = self._latch_stages()
        return {
            "success": self._success,
            "is_success": self._success,
            "action_clipped": clipped,
            "motion_limited": limited,
            "obstacle_contacts": contacts,
            "n_obstacle_contacts": self._n_contacts,
            "min_obstacle_clearance": clearance,
            "held_object": self.sim.held_object(),
            "seed": self.episode.seed,
            "variation": self.episode.variation.name,
            "instruction": self.task.instruction_text(layout),
            "target_phrases": self.task.target_phrases(layout),
            "slot_objects": {slot: layout.names.get(slot, slot) for slot in self.task.object_slots},
            "stages": stages,
            "stage": furthest_stage(stages),
        }

    # ---- experts and rendering ------------------------------------------------------------
    def expert_plan(self) -> MotionPlan:
        """The task's scripted expert for the current episode (privileged: reads the true scene)."""
        return self.task.plan_expert(self.sim, self.episode.layout)

    def render(self):
        self._check_open()
        if self._images is not None and self._images.rgb is not None:
            return self._images.rgb
        return self._renderer.render(self.data, "front", rgb=True).rgb

    def close(self):
        self._closed = True
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


class _LaterFrame:
    """`TabletopEnv.frame_later`'s callable: renders its copy of the state once, then gives the copy back."""

    def __init__(self, env: TabletopEnv, data: mujoco.MjData, steps: int):
        self._env, self._model, self._data, self._steps = env, env.model, data, steps
        self._frame: RGBDFrame | None = None

    def __call__(self) -> RGBDFrame:
        if self._frame is None:
            env = self._env
            if env.model is not self._model:
                raise RuntimeError("frame_later: that moment belongs to an earlier episode of this env")
            images = env._renderer.render(self._data, "front", rgb=env.render_rgb)
            self._frame = env._as_frame(images, self._steps)
            self._release()
        return self._frame

    def _release(self) -> None:
        data = getattr(self, "_data", None)
        if data is not None and self._env._spare_of is self._model and _COPY_IN_PLACE:
            self._env._spare.append(data)
        self._data = None

    __del__ = _release
