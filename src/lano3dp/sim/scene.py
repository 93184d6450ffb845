"""Scene builder on `mujoco.MjSpec`: the tabletop, the gripper, cameras, lights and objects.

A scene is built from scratch for every episode (compiling the lean scene takes ~2 ms), so
layouts, object kinds, colours, obstacles and camera poses are free per episode.

World frame = robot base frame: z up, the table top is the plane z = 0, the table spans
x in [0.0, 0.9] and y in [-0.6, 0.6]; objects sit around x = 0.45. The front camera faces the
robot from +x.

Usage (what a task's `build` sees):

    builder = SceneBuilder(style)                 # table, floor, lights, gripper
    bowl = primitives.add_bowl(builder, "bowl", pos=(0.45, 0.1, 0), color="blue")
    builder.add_camera(FRONT_CAMERA)
    model = builder.compile()

`builder.spec` is the raw `mujoco.MjSpec` and `builder.world` its world body, for objects
the primitives do not cover. Pitfalls: give every free body an explicit inertia with
`body.ipos = [0, 0, 0]` (MjSpec leaves ipos NaN), or use `add_geom(..., mass=...)` and let
the compiler infer inertia (what `primitives` does).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from lano3dp.errors import Lano3dpError
from lano3dp.sim.objects import ObjectInfo
from lano3dp.sim.robot import GripperSpec, add_gripper

TABLE_CENTER = np.array([0.45, 0.0])
TABLE_HALF = np.array([0.45, 0.6])
TIMESTEP = 0.004  # s; half the cost of 2 ms, and every expert still succeeds (see bench/bench_sim.py)


class SceneError(Lano3dpError, ValueError):
    """A scene could not be built (duplicate object name, unknown camera, compile failure)."""


@dataclass(frozen=True)
class CameraPose:
    """A fixed camera looking from `position` at `target`, vertical field of view in degrees."""

    name: str
    position: tuple[float, float, float]
    target: tuple[float, float, float]
    fovy: float = 45.0

    def rotation(self) -> np.ndarray:
        """(3, 3) MuJoCo/OpenGL camera axes as columns (x right, y up, looking along -z)."""
        position = np.asarray(self.position, dtype=float)
        back = position - np.asarray(self.target, dtype=float)
        z = back / np.linalg.norm(back)
        x = np.cross([0.0, 0.0, 1.0], z)
        if np.linalg.norm(x) < 1e-6:  # looking straight down: any horizontal x works
            x = np.array([0.0, -1.0, 0.0])
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        return np.stack([x, y, z], axis=1)

    def quat(self) -> np.ndarray:
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, self.rotation().reshape(-1))
        return quat


# The training camera and the shifted camera used only at test time ("camera" variation):
# rotated ~30 degrees about the vertical axis through the workspace centre and raised 10 cm.
FRONT_CAMERA = CameraPose("front", position=(1.0, 0.0, 0.72), target=(0.42, 0.0, 0.10), fovy=45.0)
SHIFTED_CAMERA = CameraPose("front", position=(0.93, 0.35, 0.80), target=(0.42, 0.0, 0.10), fovy=45.0)
# Its mirror image: with SHIFTED_CAMERA, a second look at what an obstacle hides from the front (env.other_views).
SHIFTED_LEFT_CAMERA = CameraPose("front", position=(0.93, -0.35, 0.80), target=(0.42, 0.0, 0.10), fovy=45.0)


@dataclass(frozen=True)
class SceneStyle:
    """Background appearance: table, floor and sky colours, optional checker texture on the table."""

    table_rgba: tuple[float, float, float, float] = (0.62, 0.48, 0.33, 1.0)
    table_texture_rgba: tuple[float, float, float, float] | None = None  # second checker colour
    floor_rgba: tuple[float, float, float, float] = (0.35, 0.35, 0.37, 1.0)
    sky_rgb: tuple[tuple[float, float, float], tuple[float, float, float]] = ((0.55, 0.65, 0.8), (0.15, 0.2, 0.3))
    light_diffuse: float = 0.7


@dataclass
class SceneBuilder:
    """Builds one episode's MjSpec. See the module docstring for the frame conventions."""

    style: SceneStyle = field(default_factory=SceneStyle)
    gripper: GripperSpec = field(default_factory=GripperSpec)
    max_image_size: int = 128  # offscreen buffer side; rendering cost grows with it, so match the image

    def __post_init__(self):
        self.spec = mujoco.MjSpec()
        self.spec.modelname = "lano3dp_tabletop"
        self.world = self.spec.worldbody
        self.objects: dict[str, ObjectInfo] = {}
        self.cameras: dict[str, CameraPose] = {}
        self._set_options()
        self._add_environment()
        add_gripper(self, self.gripper)

    # ---- construction ------------------------------------------------------------------
    def _set_options(self) -> None:
        option = self.spec.option
        option.timestep = TIMESTEP
        option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
        option.impratio = 10.0
        # MuJoCo 4 makes several contacts between flat convex surfaces by default (a cube on the bowl's base);
        # before it, one contact let the pourable cubes sink through the 8 mm base: switch it on there too
        if hasattr(mujoco.mjtEnableBit, "mjENBL_MULTICCD"):
            option.enableflags |= mujoco.mjtEnableBit.mjENBL_MULTICCD
        visual = self.spec.visual
        # Fast offscreen rendering on llvmpipe: shadow maps and multisampling cost 10-80x.
        visual.quality.shadowsize = 0
        visual.quality.offsamples = 0
        # Coarser tessellation of cylinders/spheres: ~20% cheaper passes, invisible at 128x128.
        visual.quality.numslices = 16
        visual.quality.numstacks = 4
        visual.quality.numquads = 1
        visual.global_.offwidth = self.max_image_size
        visual.global_.offheight = self.max_image_size
        visual.headlight.ambient = [0.35, 0.35, 0.35]
        visual.headlight.diffuse = [0.3, 0.3, 0.3]
        visual.headlight.specular = [0.0, 0.0, 0.0]
        # Extent sets the clip planes: near = 0.01 * extent must stay below the camera distance.
        self.spec.stat.extent = 2.0
        self.spec.stat.center = [0.45, 0.0, 0.2]

    def _add_environment(self) -> None:
        style = self.style
        sky = self.spec.add_texture(name="sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX,
                                    builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT, width=64, height=64)
        sky.rgb1, sky.rgb2 = list(style.sky_rgb[0]), list(style.sky_rgb[1])
        table_material = self.spec.add_material(name="table_mat", rgba=list(style.table_rgba), reflectance=0.0)
        if style.table_texture_rgba is not None:
            tex = self.spec.add_texture(name="table_tex", type=mujoco.mjtTexture.mjTEXTURE_2D,
                                        builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER, width=64, height=64)
            tex.rgb1 = list(style.table_rgba[:3])
            tex.rgb2 = list(style.table_texture_rgba[:3])
            table_material.rgba = [1.0, 1.0, 1.0, 1.0]
            table_material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "table_tex"
            table_material.texrepeat = [4.0, 4.0]
            table_material.texuniform = False

        table = self.world.add_body(name="table", pos=[*TABLE_CENTER, 0.0])
        # The top is a plane: it collides everywhere (nothing falls off) and gives the dedicated
        # plane-cylinder/box colliders with several contacts, so bottles stand stably.
        table.add_geom(name="table_top", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[*TABLE_HALF, 0.01],
                       material="table_mat", friction=[0.8, 0.005, 0.0001])
        table.add_geom(name="table_body", type=mujoco.mjtGeom.mjGEOM_BOX, size=[*TABLE_HALF, 0.37],
                       pos=[0, 0, -0.3705], rgba=[s * 0.7 for s in style.table_rgba[:3]] + [1.0],
                       contype=0, conaffinity=0)
        floor = self.world.add_body(name="floor", pos=[0, 0, -0.75])
        floor.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[3.0, 3.0, 0.05],
                       rgba=list(style.floor_rgba), contype=0, conaffinity=0)
        d = style.light_diffuse
        for light in (self.world.add_light(name="top", pos=[0.45, 0.0, 2.0], dir=[0, 0, -1], castshadow=False,
                                           diffuse=[d, d, d], specular=[0.1, 0.1, 0.1]),
                      self.world.add_light(name="front", pos=[1.5, 0.0, 1.2], dir=[-0.7, 0, -0.6],
                                           castshadow=False, diffuse=[0.3, 0.3, 0.3], specular=[0, 0, 0])):
            _make_directional(light)

    # ---- objects and cameras -----------------------------------------------------------
    def register(self, info: ObjectInfo) -> ObjectInfo:
        """Record an object whose bodies were added to `spec`; names must be unique."""
        if info.name in self.objects:
            raise SceneError(f"an object named {info.name!r} is already in the scene")
        if "/" in info.name:
            raise SceneError(f"object names may not contain '/': {info.name!r}")
        self.objects[info.name] = info
        return info

    def add_camera(self, pose: CameraPose) -> None:
        if pose.name in self.cameras:
            raise SceneError(f"camera {pose.name!r} already exists")
        self.cameras[pose.name] = pose
        self.world.add_camera(name=pose.name, pos=list(pose.position), quat=list(pose.quat()), fovy=pose.fovy)

    def compile(self) -> mujoco.MjModel:
        try:
            return self.spec.compile()
        except ValueError as error:
            raise SceneError(f"the scene does not compile: {error}") from error


def _make_directional(light) -> None:
    """A directional light in every MuJoCo the package supports: a light type from 3.3.1 on (mjtLightType), the
    `directional` flag before."""
    if hasattr(mujoco, "mjtLightType"):
        light.type = mujoco.mjtLightType.mjLIGHT_DIRECTIONAL
    else:
        light.directional = True
