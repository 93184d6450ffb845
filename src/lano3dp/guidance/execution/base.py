"""The chunk-filter protocol: what runs on a guided sample between the sampler and the robot.

A filter receives the chunk as a `Proposal` (the sampled horizon and the actions about to run) and the chunk's
`FilterContext` (the robot state, the executed-path cost, the margin), and returns a `FilterResult`: the proposal,
changed or not, and a small note of what it did (recorded per chunk in `ChunkRecord.notes`). Filters run in the
order `ExecutionSettings.filters` lists them, only on chunks that were guided against at least one obstacle.

A filter is one class and one registration, from any module imported before the settings name it:

    class SlowDown(ChunkFilter):
        name = "slow_down"
        @dataclass(frozen=True)
        class Options:
            fraction: float = 0.5
        def __call__(self, proposal, context):
            ...
            return FilterResult(proposal._replace(actions=slower), {"fraction": self.options.fraction})
    register_chunk_filter(SlowDown)     # then execution.filters: [repair, hold, slow_down]

`requires` names filters that must run earlier in the list (escape and follow act on what hold decided); a list
that breaks it, an unknown name or an unknown option is refused when the settings are built (`check_filters`).
"""

from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import numpy as np
import torch

from lano3dp.config_tree import SettingsError, from_dict
from lano3dp.guidance.costs import ExecutedPath
from lano3dp.guidance.settings import ExecutionSettings
from lano3dp.registry import Registry


class Proposal(NamedTuple):
    """A guided chunk on its way to the robot.

    trajectory: (1, H, 10) the whole sampled horizon, metric (a repair moves its executed waypoints).
    actions: (1, T, 10) what runs now, one action per policy step: the n_action_steps from "now" in the
        horizon, fewer when cut short, one holding action when held still.
    executed: actions kept when the chunk was cut short to its predicted-clear start (0: held still); None: it
        runs whole.
    held: the actions are a hold (the present pose, or a step out of the margin), not the policy's.
    """

    trajectory: torch.Tensor
    actions: torch.Tensor
    executed: int | None = None
    held: bool = False


@dataclass(frozen=True)
class FilterContext:
    """What a filter may read about the chunk.

    state: (11,) the robot state now (EE position, rotation 6D, gripper opening, grasp flag).
    start: index of "now" in the horizon (n_obs_steps - 1).
    n_action_steps: actions a whole chunk runs.
    path: the cost on the path the arm will take through the planned actions (`CostRecipe.executed_path`).
    margin: metres beyond contact the obstacle costs push from.
    """

    state: np.ndarray
    start: int
    n_action_steps: int
    path: ExecutedPath
    margin: float

    def planned(self, proposal: Proposal) -> torch.Tensor:
        """(1, n_action_steps, 10) the actions the sampled horizon plans from now."""
        return proposal.trajectory[:, self.start:self.start + self.n_action_steps]

    def hold_here(self, proposal: Proposal) -> torch.Tensor:
        """(1, 1, 10) an action holding the present pose, with the chunk's first gripper command."""
        actions = proposal.trajectory[:, self.start:self.start + 1].clone()
        actions[0, 0, :9] = torch.as_tensor(np.asarray(self.state[:9]), dtype=actions.dtype)
        return actions


class FilterResult(NamedTuple):
    """A filter's output: the proposal to pass on, and what it did (JSON values, recorded with the chunk)."""

    proposal: Proposal
    note: dict[str, Any]


@dataclass(frozen=True)
class NoOptions:
    """A filter without options."""


class ChunkFilter(ABC):
    """One step between sampling and execution. Subclass it, set `name`, implement `__call__`, register it.

    One instance serves one runner, so per-episode memory (e.g. chunks held in a row) lives on it and is
    cleared by `reset`; `episode_note` reports it with the episode.
    """

    name: ClassVar[str] = ""
    requires: ClassVar[tuple[str, ...]] = ()
    Options: ClassVar[type] = NoOptions

    def __init__(self, options=None):
        self.options = options if options is not None else self.Options()
        self.reset()

    def reset(self) -> None:  # noqa: B027 (a filter without per-episode memory has nothing to reset)
        """Start an episode."""

    @abstractmethod
    def __call__(self, proposal: Proposal, context: FilterContext) -> FilterResult:
        """The proposal after this filter, and a note of what it did."""

    def episode_note(self) -> dict[str, Any]:
        """What it did over the episode (JSON values), e.g. {"steps": 3}; {} when nothing worth recording."""
        return {}


class UnknownChunkFilterError(SettingsError):
    """No chunk filter is registered under that name."""


def _check_filter(name: str, prototype) -> None:
    if not isinstance(prototype, ChunkFilter):
        raise TypeError(f"chunk filter {name!r} must be a ChunkFilter subclass, got {type(prototype).__name__}")
    if type(prototype).name != name:
        raise TypeError(f"chunk filter class {type(prototype).__name__} is named {type(prototype).name!r}")
    if not dataclasses.is_dataclass(type(prototype).Options):
        raise TypeError(f"{type(prototype).__name__}.Options must be a dataclass")


# name -> an instance with default options (the registry keeps instances; `build_filters` makes fresh ones)
_FILTERS: Registry[ChunkFilter] = Registry(
    "chunk filter", UnknownChunkFilterError, ("__call__", "reset"), "lano3dp.guidance.execution.ChunkFilter",
    check=_check_filter, hint=" (one from outside needs its module imported: register_chunk_filter)",
    field="guidance.execution.filters entry")


def register_chunk_filter(cls: type[ChunkFilter], *, replace: bool = False) -> type[ChunkFilter]:
    """Make a ChunkFilter subclass available under its `name` in `ExecutionSettings.filters`."""
    _FILTERS.register(cls.name, cls, replace=replace)
    return cls


def chunk_filter_names() -> list[str]:
    return list(_FILTERS.names())


def filters_for_workers(names: Sequence[str]) -> dict[str, bytes]:
    """{name: pickled filter} for the filters in `names` registered from outside, which spawned worker
    processes would not know."""
    return {k: v for name in names for k, v in _FILTERS.worker_payload(name).items()}


def register_worker_filters(payload: Mapping[str, bytes]) -> None:
    import pickle

    for name, data in payload.items():
        _FILTERS.register(name, pickle.loads(data), replace=True)


def check_filters(execution: ExecutionSettings) -> None:
    """Refuse filter lists that cannot work: an unknown name or option, or a filter before one it requires."""
    build_filters(execution)


def build_filters(execution: ExecutionSettings) -> list[ChunkFilter]:
    """One instance of each listed filter, in order, with its options."""
    built: list[ChunkFilter] = []
    for position, name in enumerate(execution.filters):
        cls = type(_FILTERS.get(name))
        for needed in cls.requires:
            if needed not in execution.filters[:position]:
                raise SettingsError(f"guidance.execution.filters: {name} acts on what {needed} decided, so it "
                                    f"needs {needed} earlier in the list: {list(execution.filters)}")
        given = execution.options.get(name, {})
        known = [field.name for field in dataclasses.fields(cls.Options)]
        if unknown := sorted(set(given) - set(known)):  # a filter's own Options need not forbid extra keys
            raise SettingsError(f"guidance.execution.options.{name}.{unknown[0]}: no such setting (settings here: "
                                f"{', '.join(known) or 'none'})")
        options = from_dict(cls.Options, given, where=f"guidance.execution.options.{name}")
        built.append(cls(options))
    return built


def run_filters(filters: Sequence[ChunkFilter], proposal: Proposal,
                context: FilterContext) -> tuple[Proposal, dict[str, Mapping[str, Any]]]:
    """The proposal through every filter in order, and each filter's note (by name, non-empty ones)."""
    notes: dict[str, Mapping[str, Any]] = {}
    for chunk_filter in filters:
        proposal, note = chunk_filter(proposal, context)
        if note:
            notes[chunk_filter.name] = note
    return proposal, notes
