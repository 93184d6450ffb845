"""Task base class: what every tabletop task defines.

A task is a class with

    name            registry key, e.g. "bowl_pour"
    skill           the name of its skill in the language layer's skill registry: the task's name
    object_slots    ordered slot words the policy is trained on, e.g. ("bowl", "pan"); the
                    dataset's `object_clouds` are in this order
    instruction     a template over the slots, e.g. "pour the contents of the {bowl} into the {pan}"
    max_steps       episode limit at 10 Hz control
    similar_slots   slots whose kind gets look-alike instances under the "similar" variation

and says how language asks for it (`skill_spec()` turns these into its skill registry entry):

    description     one sentence, shown to the LLM, e.g. "grasp the bowl and pour its contents into the pan"
    verbs           verb lemmas and phrasal verbs that ask for it, e.g. ("pour", "empty", "tip into")
    synonyms        slot word -> other nouns for that object, e.g. {"pan": ("skillet", "frying pan")}
    carried         the slot whose object the gripper carries (obstacles keep clear of it too), or None
    accepts_any     slots any graspable object fills ("put an item in the drawer")

and implements

    sample_layout(rng, variation) -> Layout
        Object placements from a seeded `np.random.Generator` (never global state). Slot
        objects are keyed by their slot word in `layout.objects`; other task objects (e.g.
        the bowl's items) by any other key. Honour `variation.has("instance")` (sizes/shapes)
        and "similar" (use `layout.name_for(slot)` style names, see `Layout.set_names`).
    build(builder, layout) -> None
        Add the objects to the `SceneBuilder` (see `sim/scene.py`, `sim/objects/primitives.py`),
        naming each slot object `layout.names[slot]`.
    plan_expert(sim, layout) -> MotionPlan
        The scripted expert as a `MotionPlan` (sim/experts.py), from the settled scene.
    is_success(sim, layout) -> bool
        Success check on the simulator state (`SimState` below).
    nominal_path(layout) -> (M, 3)   [default: plan_expert(None, layout).path()]
        The expert's EE waypoints, used to keep distractors off the path.
    obstacle_region(layout) -> (M, 3)  [default: the path's transport part]
        Polyline near which "obstacle" cylinders are placed.
    stages, stage_reached(sim, layout) -> dict[str, bool]   [default: ("success",)]
        The ordered milestones of the task (reached the handle, grasped, lifted, ...) and which
        of them the current state shows, so a failed episode says how far it got. Each is a
        geometric check with its threshold in metres; the last one is `is_success`.

`plan_expert` gets `sim=None` when only the path is needed (before the scene exists), so
plan from the layout and use `sim` only for refinements. The registry is in
`tasks/__init__.py`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import mujoco
import numpy as np

from lano3dp.language.registry import SkillSpec, Slot
from lano3dp.sim.experts import MotionPlan
from lano3dp.sim.objects import ObjectInfo, object_of_body
from lano3dp.sim.robot import GripperHandle
from lano3dp.sim.variations import Variation


@dataclass
class Placement:
    """Where and how one task object is placed. position: (3,) metres; yaw: rad about +z."""

    kind: str
    position: np.ndarray
    yaw: float = 0.0
    color: str = "red"
    scale: float = 1.0
    radius: float = 0.05  # footprint radius on the table, metres (already scaled)
    params: dict[str, Any] = field(default_factory=dict)


@dataclass
class Layout:
    """One episode's task layout. `objects` maps slot words (and auxiliary keys) to placements;
    `names` maps each slot to the scene object name (the slot word, or "<color>_<kind>" under
    the "similar" variation); `params` holds task-specific extras."""

    seed: int
    objects: dict[str, Placement]
    names: dict[str, str] = field(default_factory=dict)
    params: dict[str, Any] = field(default_factory=dict)
    keepout: list[tuple[np.ndarray, float]] = field(default_factory=list)  # extra (xy, radius) discs, e.g. a handle

    def footprints(self) -> list[tuple[np.ndarray, float]]:
        """Table discs (xy (2,), radius m) other objects must not overlap: placements plus `keepout`."""
        discs = [(np.asarray(p.position[:2], float), p.radius) for p in self.objects.values() if p.radius > 0]
        return discs + [(np.asarray(xy, float)[:2], r) for xy, r in self.keepout]

    def set_names(self, slots, variation: Variation) -> None:
        """Slot object names: the slot word, or "<color>_<kind>" when look-alikes share the scene."""
        for slot in slots:
            placement = self.objects[slot]
            self.names[slot] = f"{placement.color}_{placement.kind}" if variation.has("similar") else slot


# Stage thresholds shared by the tasks. 3 cm is about a finger's length: closer than that the
# expert's grasp and push points are reached, while the approach pose above them (8-10 cm) is not.
REACH_TOLERANCE = 0.03  # m, TCP to the part that is grasped or pushed
LIFT_HEIGHT = 0.03  # m, a held object's bottom above the table (or where it rested)
TILT_COS = 0.5  # a held container's axis more than 60 degrees from vertical: pouring has begun


def segment_distance(point: np.ndarray, start: np.ndarray, end: np.ndarray) -> float:
    """Distance (m) from `point` (3,) to the segment start -> end (each (3,))."""
    along = end - start
    t = float(np.clip(np.dot(point - start, along) / max(float(np.dot(along, along)), 1e-12), 0.0, 1.0))
    return float(np.linalg.norm(point - (start + t * along)))


def rim_distance(sim: SimState, name: str, radius: float, height: float) -> float:
    """Distance (m) from the TCP to the rim (a circle of `radius` at `height`, m) of the open container
    `name`, whose body origin is the centre of its bottom."""
    local = sim.body_rotation(name).T @ (sim.ee_pose()[0] - sim.body_position(name))
    return float(np.hypot(np.hypot(local[0], local[1]) - radius, local[2] - height))


def furthest_stage(stages: dict[str, bool]) -> str | None:
    """The last stage, in task order, that was reached (None if none was)."""
    reached = [stage for stage, flag in stages.items() if flag]
    return reached[-1] if reached else None


class SimState:
    """Read access to a running scene for success checks and experts."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, objects: dict[str, ObjectInfo],
                 gripper: GripperHandle):
        self.model, self.data, self.objects, self.gripper = model, data, objects, gripper

    def body_position(self, name: str) -> np.ndarray:
        return self.data.xpos[self._body(name)].copy()

    def body_rotation(self, name: str) -> np.ndarray:
        return self.data.xmat[self._body(name)].reshape(3, 3).copy()

    def body_velocity(self, name: str) -> np.ndarray:
        """(6,) [angular, linear] velocity of a body in the world frame."""
        velocity = np.zeros(6)
        mujoco.mj_objectVelocity(self.model, self.data, mujoco.mjtObj.mjOBJ_BODY, self._body(name), velocity, 0)
        return velocity

    def geom_position(self, name: str) -> np.ndarray:
        return self.data.geom_xpos[self.model.geom(name).id].copy()

    def joint_qpos(self, name: str) -> float:
        return float(self.data.qpos[self.model.joint(name).qposadr[0]])

    def site_position(self, name: str) -> np.ndarray:
        return self.data.site_xpos[self.model.site(name).id].copy()

    def tcp_distance(self, point: np.ndarray) -> float:
        """Distance (m) from the EE's tool centre point to a world point (3,)."""
        return float(np.linalg.norm(self.ee_pose()[0] - np.asarray(point, float)))

    def holds(self, name: str) -> bool:
        """Whether the fingers hold body `name` or a body of scene object `name`."""
        body = self.gripper.held_body(self.data)
        if body < 0:
            return False
        body_name = self.model.body(body).name
        return name in (body_name, object_of_body(body_name))

    def held_object(self) -> str | None:
        """Name of the object held between the fingers, or None."""
        body = self.gripper.held_body(self.data)
        return None if body < 0 else object_of_body(self.model.body(body).name)

    def ee_pose(self) -> tuple[np.ndarray, np.ndarray]:
        return self.gripper.ee_pose(self.data)

    def _body(self, name: str) -> int:
        try:
            return self.model.body(name).id
        except KeyError:
            raise KeyError(f"no body named {name!r} in the scene; objects: {sorted(self.objects)}") from None


class Task(ABC):
    """Base class of every tabletop task; see the module docstring for the contract."""

    name: ClassVar[str]
    skill: ClassVar[str]
    object_slots: ClassVar[tuple[str, ...]]
    instruction: ClassVar[str]
    max_steps: ClassVar[int] = 200
    similar_slots: ClassVar[tuple[str, ...]] = ()
    stages: ClassVar[tuple[str, ...]] = ("success",)
    # How language asks for the task's skill; see the module docstring.
    description: ClassVar[str]
    verbs: ClassVar[tuple[str, ...]]
    synonyms: ClassVar[Mapping[str, tuple[str, ...]]] = {}
    carried: ClassVar[str | None] = None
    accepts_any: ClassVar[tuple[str, ...]] = ()
    # The oldest MuJoCo (major, minor) whose contacts the task's expert was shown to succeed under; on an older one
    # `TabletopEnv` warns (docs/simulator-versions.md). Every MuJoCo the package supports, by default.
    reliable_from_mujoco: ClassVar[tuple[int, int]] = (3, 3)
    simulator_note: ClassVar[str] = ""  # what goes wrong on an older MuJoCo

    @classmethod
    def skill_spec(cls) -> SkillSpec:
        """This task's entry in the skill registry: its words, its slots in `object_slots` order.

        Raises:
            ValueError: the skill is not named after the task, or its words name a slot the task lacks.
        """
        if cls.skill != cls.name:  # evaluate and collect look a task's skill up by the task's name
            raise ValueError(f"task {cls.name!r}: its skill must be named after it, got skill={cls.skill!r}")
        named = {*cls.synonyms, *cls.accepts_any, *([cls.carried] if cls.carried is not None else [])}
        if not named <= set(cls.object_slots):
            raise ValueError(f"task {cls.name!r}: the skill's words name {sorted(named - set(cls.object_slots))}, "
                             f"which are not among its object_slots {cls.object_slots}")
        slots = tuple(Slot(word=word, synonyms=cls.synonyms.get(word, ()), accepts_any=word in cls.accepts_any,
                           carried=word == cls.carried) for word in cls.object_slots)
        return SkillSpec(name=cls.name, description=cls.description, verbs=cls.verbs, slots=slots)

    @abstractmethod
    def sample_layout(self, rng: np.random.Generator, variation: Variation) -> Layout: ...

    @abstractmethod
    def build(self, builder, layout: Layout) -> None: ...

    @abstractmethod
    def plan_expert(self, sim: SimState | None, layout: Layout) -> MotionPlan: ...

    @abstractmethod
    def is_success(self, sim: SimState, layout: Layout) -> bool: ...

    def nominal_path(self, layout: Layout) -> np.ndarray:
        return self.plan_expert(None, layout).path()

    def stage_reached(self, sim: SimState, layout: Layout) -> dict[str, bool]:
        """Which of `stages` the current state shows; memoryless (`TabletopEnv` latches them).

        Returns:
            stage -> bool with exactly the keys of `stages`, in order; the last one is `is_success`.
            The default (a task that declares no stages) reports success only.
        """
        return {"success": bool(self.is_success(sim, layout))}

    def obstacle_region(self, layout: Layout) -> np.ndarray:
        """Default: the path's waypoints above 8 cm (the transport phase), else the whole path."""
        path = self.nominal_path(layout)
        high = path[path[:, 2] > 0.08]
        return high if len(high) >= 2 else path

    def instruction_text(self, layout: Layout) -> str:
        """The instruction with each slot replaced by the phrase naming this episode's target."""
        return self.instruction.format(**self.target_phrases(layout))

    def target_phrases(self, layout: Layout) -> dict[str, str]:
        """Slot -> phrase naming the target in this scene ("bowl", or "blue bowl" among look-alikes)."""
        return {slot: layout.names.get(slot, slot).replace("_", " ") for slot in self.object_slots}

    @staticmethod
    def instance_scale(rng: np.random.Generator, variation: Variation) -> float:
        """1.0, or under "instance" a small (0.8) or large (1.2) variant."""
        return float(rng.choice([0.8, 1.2])) if variation.has("instance") else 1.0
