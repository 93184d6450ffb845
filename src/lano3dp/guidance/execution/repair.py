"""repair: push the path the arm will take through a guided chunk clear of the margin (beyond the paper).

Guidance pushes a sample while the network pulls it back towards the demonstrations, so a guided chunk can end
inside the margin. At most `steps` 1 cm steps of plain cost descent (`costs.push_clear`) along the executed-path
cost move the chunk's executed waypoints until that path clears every obstacle by the margin.
"""

from __future__ import annotations

from dataclasses import dataclass

from lano3dp.guidance.costs import push_clear
from lano3dp.guidance.execution.base import ChunkFilter, FilterContext, FilterResult, Proposal, register_chunk_filter


class Repair(ChunkFilter):
    name = "repair"

    @dataclass(frozen=True)
    class Options:
        """steps: 1 cm descent steps at most."""

        steps: int = 20

        def __post_init__(self):
            if self.steps < 1:
                raise ValueError(f"repair steps must be >= 1 (leave repair out of the filters to turn it off), "
                                 f"got {self.steps}")

    def __call__(self, proposal: Proposal, context: FilterContext) -> FilterResult:
        trajectory = proposal.trajectory.detach().clone()
        executed = slice(context.start, context.start + len(context.path.node_offsets) - 1)
        moved, steps = push_clear(context.path, trajectory[:, executed, :3].double(), clearance=context.margin,
                                  iterations=self.options.steps)
        if steps == 0:
            return FilterResult(proposal, {})
        trajectory[:, executed, :3] = moved.to(trajectory.dtype)
        repaired = proposal._replace(trajectory=trajectory)
        return FilterResult(repaired._replace(actions=context.planned(repaired)), {"steps": steps})


register_chunk_filter(Repair)
