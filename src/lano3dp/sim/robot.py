"""The robot: a 6-DoF end-effector-controlled parallel gripper.

A mocap body `gripper_target` is welded to a free `gripper` body (gravity-compensated), so
the hand follows the commanded pose through a stiff constraint and, unlike a bare mocap
body, has a velocity: friction at the fingers can carry objects. Two box fingers on
slide joints are coupled by an equality constraint and driven by one position actuator.

End-effector (EE) frame = the `gripper` body frame, origin at the tool centre point
(between the fingertips, 1 cm above their ends):
    z axis: approach direction (from the wrist towards the fingertips),
    y axis: the finger closing axis, x = y cross z.
A top-down grasp therefore has R = diag(1, -1, -1) (`TOP_DOWN`), and a yaw `psi` about
the world z axis gives `Rz(psi) @ TOP_DOWN` (`top_down(psi)`).

Gripper command (action[9]): 0 = open, 1 = closed, continuous in between.
State gripper opening: distance between the inner finger faces, metres (0 .. 0.09).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from lano3dp.sim.objects import ObjectInfo

if TYPE_CHECKING:
    from lano3dp.sim.scene import SceneBuilder

TOP_DOWN = np.diag([1.0, -1.0, -1.0])
HOME_POSITION = np.array([0.30, 0.0, 0.30])
GRIPPER_FOOTPRINT_RADIUS = 0.07  # covers the open palm's 6.5 cm half-width about the EE axis
GRIPPER_BODIES = ("gripper", "gripper/left_finger", "gripper/right_finger")


def rot_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot_axis(axis, angle: float) -> np.ndarray:
    """Rotation matrix of `angle` radians about the unit `axis` (Rodrigues)."""
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def top_down(yaw: float = 0.0) -> np.ndarray:
    """EE rotation of a top-down grasp whose finger axis is the world y axis rotated by `yaw`."""
    return rot_z(yaw) @ TOP_DOWN


@dataclass(frozen=True)
class GripperSpec:
    """Gripper geometry and gains. Units: metres, kilograms, newtons."""

    half_gap: float = 0.045          # half of the maximal opening between inner finger faces
    finger_half: tuple[float, float, float] = (0.012, 0.007, 0.03)
    finger_center_z: float = -0.02   # finger box centre below the TCP along the EE z axis (negative = wrist side)
    hand_mass: float = 0.5
    finger_mass: float = 0.05
    kp: float = 2500.0
    max_force: float = 60.0
    finger_friction: tuple[float, float, float] = (1.5, 0.02, 0.0005)
    home: tuple[float, float, float] = tuple(HOME_POSITION)

    @property
    def max_opening(self) -> float:
        return 2.0 * self.half_gap


def add_gripper(builder: SceneBuilder, gripper: GripperSpec) -> ObjectInfo:
    """Add the mocap target, the welded hand and the fingers to `builder.spec`."""
    spec, world = builder.spec, builder.world
    home_quat = np.zeros(4)
    mujoco.mju_mat2Quat(home_quat, TOP_DOWN.reshape(-1))
    world.add_body(name="gripper_target", mocap=True, pos=list(gripper.home), quat=list(home_quat))
    hand = world.add_body(name="gripper", pos=list(gripper.home), quat=list(home_quat), gravcomp=1.0)
    hand.add_freejoint(name="gripper_free")
    grey, dark = [0.55, 0.55, 0.6, 1.0], [0.2, 0.2, 0.22, 1.0]
    fx, fy, fz = gripper.finger_half
    palm_z = gripper.finger_center_z - fz - 0.012
    hand.add_geom(name="gripper/palm", type=mujoco.mjtGeom.mjGEOM_BOX,
                  size=[0.02, gripper.half_gap + 2 * fy + 0.006, 0.012], pos=[0, 0, palm_z],
                  rgba=grey, mass=gripper.hand_mass * 0.6)
    hand.add_geom(name="gripper/mount", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.025, 0.04, 0],
                  pos=[0, 0, palm_z - 0.052], rgba=dark, mass=gripper.hand_mass * 0.4)
    for side, sign in (("left", 1.0), ("right", -1.0)):
        finger = hand.add_body(name=f"gripper/{side}_finger", pos=[0, sign * (gripper.half_gap + fy),
                                                                     gripper.finger_center_z], gravcomp=1.0)
        finger.add_joint(name=f"gripper/{side}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, -sign, 0],
                         range=[0.0, gripper.half_gap + 0.001], damping=15.0, armature=0.01)
        finger.add_geom(name=f"gripper/{side}_pad", type=mujoco.mjtGeom.mjGEOM_BOX, size=[fx, fy, fz],
                        rgba=dark, mass=gripper.finger_mass, friction=list(gripper.finger_friction),
                        condim=6, solref=[0.01, 1.0])
    coupling = spec.add_equality(type=mujoco.mjtEq.mjEQ_JOINT, name1="gripper/left", name2="gripper/right")
    _set_equality_data(coupling, [0, 1])  # polynomial coefficients: right = 0 + 1 * left
    weld = spec.add_equality(type=mujoco.mjtEq.mjEQ_WELD, name1="gripper_target", name2="gripper",
                             objtype=mujoco.mjtObj.mjOBJ_BODY, solref=[0.01, 1.0])
    _set_equality_data(weld, [0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 1])  # anchor, relative pose (pos, quat), torque scale
    actuator = spec.add_actuator(name="fingers", target="gripper/left", trntype=mujoco.mjtTrn.mjTRN_JOINT)
    if hasattr(actuator, "set_to_position"):
        actuator.set_to_position(kp=gripper.kp)
    else:  # MuJoCo 3.3.0: the same position servo by its gains, force = kp * (ctrl - q)
        actuator.gaintype, actuator.biastype = mujoco.mjtGain.mjGAIN_FIXED, mujoco.mjtBias.mjBIAS_AFFINE
        actuator.gainprm[:3] = [gripper.kp, 0, 0]
        actuator.biasprm[:3] = [0, -gripper.kp, 0]
    actuator.ctrlrange = [0.0, gripper.half_gap + 0.001]
    actuator.forcerange = [-gripper.max_force, gripper.max_force]
    actuator.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
    info = ObjectInfo(name="gripper", kind="gripper", color="grey", body_names=GRIPPER_BODIES,
                      footprint_radius=GRIPPER_FOOTPRINT_RADIUS, position=np.asarray(gripper.home), role="robot",
                      extents=np.array([0.02, gripper.half_gap + 0.02, 0.12]))
    return builder.register(info)


def _set_equality_data(equality, values) -> None:
    """The first values of an equality's data, the rest zero: MuJoCo 3.x holds 11 numbers there, 4.x 12."""
    data = np.zeros(len(equality.data))
    data[:len(values)] = values
    equality.data = data


class GripperHandle:
    """Reads and commands the gripper of a compiled model (ids resolved once per model)."""

    def __init__(self, model: mujoco.MjModel, gripper: GripperSpec):
        self.model = model
        self.gripper = gripper
        self.mocap_id = model.body("gripper_target").mocapid[0]
        self.hand_id = model.body("gripper").id
        self.left_joint_qpos = model.joint("gripper/left").qposadr[0]
        self.actuator_id = model.actuator("fingers").id
        self.left_pad = model.geom("gripper/left_pad").id
        self.right_pad = model.geom("gripper/right_pad").id
        self.body_ids = np.array([model.body(name).id for name in GRIPPER_BODIES])
        self.close_target = gripper.half_gap + 0.001

    def command(self, data: mujoco.MjData, position, quat, grip: float) -> None:
        data.mocap_pos[self.mocap_id] = position
        data.mocap_quat[self.mocap_id] = quat
        data.ctrl[self.actuator_id] = min(max(float(grip), 0.0), 1.0) * self.close_target

    def target(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        return data.mocap_pos[self.mocap_id].copy(), data.mocap_quat[self.mocap_id].copy()

    def ee_pose(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """(position (3,), rotation (3, 3)) of the EE frame in the world."""
        return data.xpos[self.hand_id].copy(), data.xmat[self.hand_id].reshape(3, 3).copy()

    def opening(self, data: mujoco.MjData) -> float:
        """Distance between the inner finger faces, metres."""
        return float(2.0 * (self.gripper.half_gap - data.qpos[self.left_joint_qpos]))

    def command_closed(self, data: mujoco.MjData) -> bool:
        return bool(data.ctrl[self.actuator_id] > 0.5 * self.close_target)

    def held_body(self, data: mujoco.MjData) -> int:
        """Body id squeezed between both finger pads while the gripper is commanded closed, else -1."""
        if not self.command_closed(data):
            return -1
        ncon = data.ncon
        geom1, geom2 = data.contact.geom1[:ncon], data.contact.geom2[:ncon]
        touched = []
        for pad in (self.left_pad, self.right_pad):
            other = np.concatenate([geom2[geom1 == pad], geom1[geom2 == pad]])
            touched.append(set(self.model.geom_bodyid[other].tolist()))
        # Only movable bodies count: static bodies (table, obstacles) are welded to the world.
        both = {b for b in touched[0] & touched[1] if self.model.body_weldid[b] != 0}
        both -= set(self.body_ids.tolist())
        return min(both) if both else -1
