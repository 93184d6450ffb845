"""hold: execute only the start of a guided chunk predicted to keep half the margin; hold still when none does.

The repair cannot always clear a chunk that guidance left on course for an obstacle. Running only its clear start
(`costs.clear_prefix` along the executed-path cost; the last kept action may be moved part of the way to its
waypoint) and re-planning from there is safer than running it whole (beyond the paper, which executes every
chunk whole).
"""

from __future__ import annotations

import numpy as np
import torch

from lano3dp.guidance.costs import PositionCost, clear_prefix
from lano3dp.guidance.execution.base import ChunkFilter, FilterContext, FilterResult, Proposal, register_chunk_filter


def cut_to_clear(actions: torch.Tensor, state: np.ndarray, cost: PositionCost, required: float) -> torch.Tensor:
    """The start of `actions` (B, T, 10) whose executed path keeps `required` metres from every obstacle."""
    start = torch.as_tensor(np.asarray(state[:3], dtype=np.float64))[None]
    kept = clear_prefix(cost, actions[:, :, :3].double(), start, clearance=required)
    if kept.shape[1] == actions.shape[1]:
        return actions
    cut = actions[:, :kept.shape[1]].clone()
    cut[:, :, :3] = kept.to(cut.dtype)
    return cut


def cut_proposal(proposal: Proposal, context: FilterContext, required: float) -> Proposal:
    """The planned actions cut to what keeps `required` metres clear, or a hold of the present pose."""
    actions = cut_to_clear(context.planned(proposal), context.state, context.path, required)
    executed = actions.shape[1] if actions.shape[1] < context.n_action_steps else None
    if actions.shape[1] == 0:
        return proposal._replace(actions=context.hold_here(proposal), executed=0, held=True)
    return proposal._replace(actions=actions, executed=executed, held=False)


class Hold(ChunkFilter):
    name = "hold"

    def __call__(self, proposal: Proposal, context: FilterContext) -> FilterResult:
        return FilterResult(cut_proposal(proposal, context, context.margin / 2), {})


register_chunk_filter(Hold)
