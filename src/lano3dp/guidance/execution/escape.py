"""escape: a hand already inside half the margin moves where it gets no closer, or steps straight out.

A moving obstacle can come at a hand the hold keeps still; holding there lets it walk into the hand. So when the
hand is already closer than half the margin, the chunk's start is cut to what keeps its present clearance instead
of half the margin (it may move away, never closer); when every chunk's first step leads deeper, the hand steps
straight out along the executed-path cost, a few 1 cm steps of plain descent (a moving obstacle traced on a table
scene held a hand 3 cm inside it for 48 chunks). Needs hold earlier in the filters.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from lano3dp.guidance.costs import ExecutedPath, push_clear
from lano3dp.guidance.execution.base import ChunkFilter, FilterContext, FilterResult, Proposal, register_chunk_filter
from lano3dp.guidance.execution.hold import cut_proposal

MAX_STEPS = 5  # 1 cm steps at most: the arm's step limit; the next chunk re-plans


def retreat(state: np.ndarray, cost: ExecutedPath, required: float) -> torch.Tensor:
    """(3,) where a hand closer than `required` to an obstacle steps to: straight out along `cost`; its present
    position when it is not that close (an ordinary hold)."""
    here = torch.as_tensor(np.asarray(state[:3], dtype=np.float64))
    deficit = required - cost.present_clearance()
    if deficit <= 0:
        return here
    steps = min(math.ceil(deficit / 0.01) + 1, MAX_STEPS)
    moved, _ = push_clear(cost, here[None, None], clearance=required, iterations=steps)
    return moved[0, 0]


class Escape(ChunkFilter):
    name = "escape"
    requires = ("hold",)

    def __call__(self, proposal: Proposal, context: FilterContext) -> FilterResult:
        required = context.margin / 2
        present = context.path.present_clearance()
        if present >= required:
            return FilterResult(proposal, {})
        proposal = cut_proposal(proposal, context, min(required, present))
        if not proposal.held:
            return FilterResult(proposal, {"inside": True})
        actions = proposal.actions.clone()
        actions[0, 0, :3] = retreat(context.state, context.path, required).to(actions.dtype)
        return FilterResult(proposal._replace(actions=actions), {"inside": True, "stepped_out": True})


register_chunk_filter(Escape)
