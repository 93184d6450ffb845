"""A policy bundle: everything a checkpoint brings to an evaluation, loaded once.

    PolicyBundle.load(checkpoint)   the policy, how its observations were made (camera resolution, crop, points
                                    per cloud: its config's `extra["observation"]`), its task and skill, its
                                    guidance tuning (`guidance.json`), and the checksum of its weights
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from lano3dp.errors import Lano3dpError
from lano3dp.evaluation.config import SEGMENTERS, PerceptionSettings
from lano3dp.guidance.settings import GuidanceTuning, load_guidance_tuning


class PolicyTaskMismatchError(Lano3dpError, ValueError):
    """A checkpoint asked to act on a task of another skill."""


@dataclass(frozen=True)
class ObservationSpec:
    """How the checkpoint's training observations were made; evaluation makes them the same way."""

    image_size: int | None = None
    n_points: int | None = None
    crop_low: tuple[float, ...] | None = None
    crop_high: tuple[float, ...] | None = None

    @classmethod
    def from_extra(cls, extra: dict[str, Any]) -> ObservationSpec:
        attrs = extra.get("observation") or {}
        low, high = attrs.get("crop_low"), attrs.get("crop_high")
        return cls(image_size=attrs.get("image_size"), n_points=attrs.get("n_points"),
                   crop_low=None if low is None else tuple(low), crop_high=None if high is None else tuple(high))


@dataclass
class PolicyBundle:
    """A loaded checkpoint and what it says about itself.

    Attributes:
        folder: the checkpoint folder (a training run resolves to its last checkpoint).
        policy: the `DiffusionPolicy`.
        observation: `ObservationSpec`.
        task, skill: what it was trained on (None when its config does not say).
        tuning: its `guidance.json` (None without one), which the "tuned" preset starts from.
        weights: the weights' checksum, which tells two checkpoints apart in caches and logs.
    """

    folder: Path
    policy: Any
    observation: ObservationSpec
    task: str | None
    skill: str | None
    tuning: GuidanceTuning | None
    weights: str

    @property
    def label(self) -> str:
        """How results name the checkpoint: "packaged:<task>" for a policy shipped in the package, else its folder
        (no machine path of an installed package goes into results)."""
        from lano3dp.policy.pretrained import packaged_checkpoints

        for task, folder in packaged_checkpoints().items():
            if folder.resolve() == self.folder.resolve():
                return f"packaged:{task}"
        return str(self.folder)

    @classmethod
    def load(cls, checkpoint: str | Path | None, device: str = "cpu", *, task: str | None = None) -> PolicyBundle:
        """`checkpoint`: a policy folder, a training run (its last checkpoint), "packaged:<task>", or None for the
        policy packaged for `task`."""
        from lano3dp.policy import DiffusionPolicy
        from lano3dp.policy.integrity import verify_checkpoint

        folder = resolve_folder(checkpoint, task)
        verify_checkpoint(folder)  # before its tuning is read or anything is written on its behalf
        policy = DiffusionPolicy.from_pretrained(folder, device=device)
        extra = policy.config.extra
        return cls(folder=folder, policy=policy, observation=ObservationSpec.from_extra(extra),
                   task=extra.get("task"), skill=extra.get("skill"), tuning=load_guidance_tuning(folder),
                   weights=weights_checksum(folder))

    def check_task(self, task: str, env: str | None) -> None:
        """Refuse a task of another skill (its object slots would get the wrong clouds): always in the
        simulator; in a user's env only when its task has a simulator task's name."""
        from lano3dp.sim.tasks import TASKS, make_task

        if env is not None and task not in TASKS:
            return
        skill = make_task(task).skill
        if self.skill is not None and self.skill != skill:
            raise PolicyTaskMismatchError(
                f"the checkpoint was trained for skill '{self.skill}' (task {self.task!r}), not '{skill}' (task "
                f"{task!r}); pass a checkpoint of '{skill}' or --task {self.task or self.skill}")

    def observer(self, perception: PerceptionSettings):
        """The `ObjectObserver` for this policy: the perception's segmenter, the policy's points per cloud and
        the crop box its data was recorded with."""
        from lano3dp.perception import ObjectObserver

        return ObjectObserver(build_segmenter(perception), n_points=self.policy.config.n_points,
                              crop_low=self.observation.crop_low, crop_high=self.observation.crop_high)


def resolve_folder(checkpoint: str | Path | None, task: str | None = None) -> Path:
    """The checkpoint folder of a policy folder, a training run (its last checkpoint), "packaged:<task>", or None
    (the policy packaged for `task`)."""
    from lano3dp.policy.modeling import resolve_checkpoint
    from lano3dp.policy.pretrained import packaged_checkpoint

    if checkpoint is None or str(checkpoint).startswith("packaged:"):
        name = str(checkpoint).removeprefix("packaged:") if checkpoint is not None else task
        if name is None:
            raise ValueError("give a checkpoint, or a task to use the policy packaged for it")
        checkpoint = packaged_checkpoint(name)
    return resolve_checkpoint(checkpoint)


def weights_checksum(folder: Path) -> str:
    """The checksum the weights file carries in its metadata (size and time when it has none)."""
    from safetensors import safe_open

    from lano3dp.policy.modeling import CHECKSUM_KEY, WEIGHTS_NAME

    weights = folder / WEIGHTS_NAME
    try:
        with safe_open(str(weights), framework="pt") as handle:
            checksum = (handle.metadata() or {}).get(CHECKSUM_KEY)
    except Exception:  # loading the policy reports the damage
        checksum = None
    if checksum is None:
        stat = weights.stat()
        checksum = f"size={stat.st_size},mtime_ns={stat.st_mtime_ns}"
    return checksum


def build_segmenter(perception: PerceptionSettings):
    """The segmenter `perception` names (`perception.factory.build_segmenter`); a weight folder that does not
    exist or is incomplete raises MissingWeightsError."""
    from lano3dp.perception import factory

    return factory.build_segmenter(factory.SegmenterConfig(
        kind=SEGMENTERS[perception.segmenter], detector=perception.detector,
        detector_dir=Path(perception.detector_dir) if perception.detector_dir else None,
        sam_dir=Path(perception.sam_dir) if perception.sam_dir else None))


def carried_slot_word(task: str) -> str | None:
    """The slot word of what the gripper carries in a registered task (its extent enlarges Q*), else None."""
    from lano3dp.sim.tasks import skill_registry

    registry = skill_registry()
    if task not in registry:
        return None
    spec = registry.get(task)
    return None if spec.carried_slot is None else spec.slot_words[spec.carried_slot]
