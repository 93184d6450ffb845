"""Episodes you can inspect: a Rerun recording (.rrd) of what the policy saw and did, on one timeline "step".

    recording = EpisodeRecording("episode_0.rrd")     # the optional extra: pip install 'lano3dp[viewer]'
    recording.log_frame(step, frame.rgb, frame.depth, frame.camera)
    recording.log_clouds(step, {"bowl": cloud, "pan": cloud})        # (N, 3) m, world frame, as the policy got them
    recording.log_hand(step, state[:3])
    recording.log_obstacles(step, [describe_obstacle(o) for o in obstacles], margin=0.02)
    recording.log_chunk(step, sampled, executed, before_guidance)
    recording.log_path(ee_path)
    recording.close()
    # then: rerun episode_0.rrd

The file is written offline: no viewer is spawned and nothing goes over the network. Entity paths, all in the
world frame (metres, z up):

    world/camera                 the camera's pose (Transform3D) and intrinsics (Pinhole)
    world/camera/rgb, /depth     the images (depth in metres)
    world/clouds/<name>          each object's cloud as the policy received it
    world/hand                   the end effector; world/hand/body the balls of its swept body, when given
    world/obstacles/<i>/body     a fitted obstacle's outline at the table and at `height`
    world/obstacles/<i>/safety   the same grown by the safety distance (cylinders: Q*; boxes: + margin)
    world/chunk/sampled          the sampled horizon (H, 3); /executed the waypoints run (T, 3);
    world/chunk/before_guidance  the same noise sampled without guidance, when the runner drew it
    world/path                   the executed end-effector path (logged at its last step)
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from lano3dp.errors import Lano3dpError

TIMELINE = "step"
OBSTACLE_HEIGHT = 0.4  # m: fitted obstacles are vertical columns; their outlines are drawn up to this height
_RING_POINTS = 32
_COLOURS = {"sampled": (70, 130, 255), "executed": (40, 200, 80), "before_guidance": (160, 160, 160),
            "path": (255, 160, 0), "body": (200, 60, 60), "safety": (255, 120, 120), "hand": (30, 30, 30)}


class RecordingUnavailableError(Lano3dpError, ImportError):
    """rerun-sdk, the optional extra `viewer`, is not installed."""


def _rerun():
    try:
        import rerun
    except ImportError:
        raise RecordingUnavailableError("Rerun recordings need the optional extra: install lano3dp[viewer] "
                                        "(pip install 'lano3dp[viewer]')") from None
    return rerun


class EpisodeRecording:
    """One episode's recording, streamed to a .rrd file as it is logged.

    Args:
        path: the .rrd file to write (its folder is created).
        name: the recording's application id, shown by the viewer.

    Raises:
        RecordingUnavailableError: rerun-sdk is not installed (one line: install lano3dp[viewer]).
    """

    def __init__(self, path: str | Path, name: str = "lano3dp"):
        rr = _rerun()
        self.rr = rr
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.stream = rr.RecordingStream(application_id=name)
        rr.set_log_time_enabled(False, recording=self.stream)  # one timeline, "step": the file is the same each run
        self.stream.save(str(self.path))
        self.stream.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self._obstacle_count = 0

    def _at(self, step: int) -> None:
        self.stream.set_time(TIMELINE, sequence=int(step))

    def log_frame(self, step: int, rgb: np.ndarray | None, depth: np.ndarray | None = None, camera=None) -> None:
        """The camera images: rgb (H, W, 3) uint8, depth (H, W) float32 metres (0: no surface), and the calibrated
        camera (`geometry.PinholeCamera`: K and the OpenCV camera-to-world pose), which places them in the world."""
        rr = self.rr
        self._at(step)
        if camera is not None:
            pose = np.asarray(camera.cam_to_world, dtype=np.float64)
            self.stream.log("world/camera", rr.Transform3D(translation=pose[:3, 3], mat3x3=pose[:3, :3]))
            self.stream.log("world/camera", rr.Pinhole(image_from_camera=np.asarray(camera.K, dtype=np.float64),
                                                       resolution=[int(camera.width), int(camera.height)],
                                                       camera_xyz=rr.ViewCoordinates.RDF))
        if rgb is not None:
            self.stream.log("world/camera/rgb", rr.Image(np.asarray(rgb, dtype=np.uint8)))
        if depth is not None:
            self.stream.log("world/camera/depth", rr.DepthImage(np.asarray(depth, dtype=np.float32), meter=1.0))

    def log_clouds(self, step: int, clouds: Mapping[str, np.ndarray]) -> None:
        """Each object's cloud as the policy received it: {name: (N, 3) metres, world frame}."""
        self._at(step)
        for name, points in clouds.items():
            points = np.asarray(points, dtype=np.float32).reshape(-1, 3)
            self.stream.log(f"world/clouds/{_entity(name)}", self.rr.Points3D(points, radii=0.003))

    def log_hand(self, step: int, position: np.ndarray, body_balls: np.ndarray | None = None,
                 body_radii: np.ndarray | float | None = None) -> None:
        """The end effector's position (3,) m; `body_balls` (B, 3) the centres of the balls guidance keeps clear of
        obstacles (the hand, a held object), with `body_radii` (B,) or one radius (m)."""
        rr = self.rr
        self._at(step)
        self.stream.log("world/hand", rr.Points3D(np.asarray(position, dtype=np.float32).reshape(1, 3), radii=0.01,
                                                  colors=[_COLOURS["hand"]]))
        if body_balls is not None:
            balls = np.asarray(body_balls, dtype=np.float32).reshape(-1, 3)
            radii = np.broadcast_to(np.asarray(0.02 if body_radii is None else body_radii, np.float32), len(balls))
            self.stream.log("world/hand/body", rr.Points3D(balls, radii=radii, colors=[_COLOURS["body"]]))

    def log_obstacles(self, step: int, shapes: Sequence[Mapping[str, Any]], margin: float = 0.0,
                      height: float = OBSTACLE_HEIGHT) -> None:
        """Fitted obstacles as `guidance.shapes.describe_obstacle` gives them: a cylinder ("center", "radius",
        "safety_distance") or a box ("corners" (4, 2)) outlined at the table and at `height` (m); the safety
        outline is the cylinder's Q*, a box grown by `margin` (m). A shape without those numbers (points) logs
        nothing. Obstacles logged before and not now are cleared."""
        rr = self.rr
        self._at(step)
        for index, shape in enumerate(shapes):
            outlines = _outlines(shape, margin)
            for part in ("body", "safety"):
                if part in outlines:
                    strips = [np.c_[ring, np.full(len(ring), z)] for ring in [outlines[part]] for z in (0.0, height)]
                    self.stream.log(f"world/obstacles/{index}/{part}",
                                    rr.LineStrips3D(strips, colors=[_COLOURS[part]]))
        for index in range(len(shapes), self._obstacle_count):
            self.stream.log(f"world/obstacles/{index}", rr.Clear(recursive=True))
        self._obstacle_count = len(shapes)

    def log_chunk(self, step: int, sampled: np.ndarray, executed: np.ndarray,
                  before_guidance: np.ndarray | None = None) -> None:
        """One chunk's positions (m, world frame): the sampled horizon (H, 3), the waypoints executed (T, 3) and,
        when the runner drew it, the same sample without guidance (H, 3)."""
        self._at(step)
        for name, positions in (("sampled", sampled), ("executed", executed), ("before_guidance", before_guidance)):
            if positions is None:
                self.stream.log(f"world/chunk/{name}", self.rr.Clear(recursive=False))
                continue
            positions = np.asarray(positions, dtype=np.float32).reshape(-1, 3)
            self.stream.log(f"world/chunk/{name}", self.rr.LineStrips3D([positions], colors=[_COLOURS[name]]))

    def log_path(self, positions: np.ndarray, step: int | None = None) -> None:
        """The executed end-effector path (T + 1, 3) m, at `step` (default: its last, T)."""
        positions = np.asarray(positions, dtype=np.float32).reshape(-1, 3)
        self._at(len(positions) - 1 if step is None else step)
        self.stream.log("world/path", self.rr.LineStrips3D([positions], colors=[_COLOURS["path"]]))

    def close(self) -> None:
        """Write everything logged to the file and close it."""
        if self.stream is None:
            return
        self.stream.flush()
        self.stream.disconnect()
        self.stream = None

    def __enter__(self) -> EpisodeRecording:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _entity(name: str) -> str:
    """A name as one entity-path part (the viewer splits paths at '/'; spaces are kept readable)."""
    return str(name).replace("/", "_").replace(" ", "_") or "_"


def _outlines(shape: Mapping[str, Any], margin: float) -> dict[str, np.ndarray]:
    """{"body": (P, 2) closed ring, "safety": (P, 2)} in the table plane for a described obstacle, {} if unknown."""
    if "radius" in shape and "center" in shape:
        centre = np.asarray(shape["center"], dtype=np.float64)[:2]
        angles = np.linspace(0.0, 2 * np.pi, _RING_POINTS + 1)
        circle = np.c_[np.cos(angles), np.sin(angles)]
        safety = float(shape.get("safety_distance", shape["radius"] + margin))
        return {"body": centre + float(shape["radius"]) * circle, "safety": centre + safety * circle}
    if "corners" in shape:  # an oriented box's corners in order round it
        corners = np.asarray(shape["corners"], dtype=np.float64).reshape(-1, 2)
        centre = corners.mean(axis=0)
        axes = [edge / max(np.linalg.norm(edge), 1e-12) for edge in (corners[1] - corners[0], corners[2] - corners[1])]
        # each corner moves out by `margin` along both box axes: the box grown by the margin on every side
        grown = corners + margin * sum(np.sign((corners - centre) @ axis)[:, None] * axis for axis in axes)
        return {"body": np.vstack([corners, corners[:1]]), "safety": np.vstack([grown, grown[:1]])}
    return {}


def record_episode(path: str | Path, runner, on_frame=None):
    """A recording of the episode `runner` is about to run and the `on_frame` hook (rollout's) that feeds it:
    each frame with the policy's target clouds, the fitted obstacles and every chunk planned since the last frame,
    then `on_frame` (e.g. a video's) as before. The caller logs the path (`log_path`) and closes the recording."""
    from lano3dp.guidance.shapes import describe_obstacle

    recording = EpisodeRecording(path)
    logged = 0

    def feed(frame, info) -> None:
        nonlocal logged
        step = runner.step_count
        recording.log_frame(step, frame.rgb, frame.depth, frame.camera)
        clouds = runner.targets.last
        if clouds is not None and runner.target_phrases:
            recording.log_clouds(step, dict(zip(runner.target_phrases, clouds, strict=False)))
        obstacles = runner.tracker.obstacles
        shapes = [describe_obstacle(o) for o in obstacles.obstacles] if obstacles is not None else []
        recording.log_obstacles(step, shapes, margin=runner.guidance.obstacles.margin)
        for chunk in runner.chunks[logged:]:
            if chunk.trajectory is not None:
                kept = runner.n_action_steps if chunk.executed is None else chunk.executed
                positions = chunk.trajectory[:, :3]
                recording.log_chunk(chunk.step, positions, positions[runner.start:runner.start + kept])
        logged = len(runner.chunks)
        if on_frame is not None:
            on_frame(frame, info)

    return recording, feed
