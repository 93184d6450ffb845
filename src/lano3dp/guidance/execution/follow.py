"""follow: a hand held still for several chunks in a row follows the nearest obstacle's boundary (beyond the paper).

Two obstacles, or the wall across their gap, can stand between the hand and its target while the network keeps
aiming through: the hold then keeps the hand still for the rest of the episode. This is the Bug algorithm's
boundary following: after `after_holds` held chunks in a row, the hand steps `step_m` at a time along the nearest
obstacle, on the side of the chunk's end, keeping `keep` of the margin, until a chunk's start runs again and the
straight way from the hand to the chunk's end keeps half the margin (at most `max_steps` steps at a time).
Needs hold earlier in the filters.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from lano3dp.guidance.execution.base import ChunkFilter, FilterContext, FilterResult, Proposal, register_chunk_filter


class Follow(ChunkFilter):
    name = "follow"
    requires = ("hold",)

    @dataclass(frozen=True)
    class Options:
        """after_holds: held chunks in a row before following; step_m: metres per step along the boundary;
        max_steps: steps before the policy is given the way again; keep: share of the margin a step keeps
        (headroom above the hold's half)."""

        after_holds: int = 5
        step_m: float = 0.03
        max_steps: int = 40
        keep: float = 0.75

        def __post_init__(self):
            if self.after_holds < 1 or self.max_steps < 1 or self.step_m <= 0 or not 0.5 <= self.keep <= 1:
                raise ValueError("need after_holds >= 1, max_steps >= 1, step_m > 0 and keep in [0.5, 1]")

    def reset(self) -> None:
        self.held_in_a_row = 0
        self.following: tuple[float | None, int] | None = None  # (side, steps) while following a boundary
        self.steps = 0  # steps taken along obstacle boundaries this episode

    def episode_note(self):
        return {"steps": self.steps} if self.steps else {}

    def __call__(self, proposal: Proposal, context: FilterContext) -> FilterResult:
        self.held_in_a_row = self.held_in_a_row + 1 if proposal.held else 0
        step = self._step(context, proposal)
        if step is None:
            return FilterResult(proposal, {})
        moved = proposal.trajectory[:, context.start:context.start + 1].clone()
        moved[0, 0, :9] = torch.as_tensor(np.asarray(context.state[:9]), dtype=moved.dtype)
        moved[0, 0, :2] += torch.as_tensor(step, dtype=moved.dtype, device=moved.device)
        return FilterResult(proposal._replace(actions=moved), {"step_m": [round(float(v), 5) for v in step]})

    def _step(self, context: FilterContext, proposal: Proposal) -> np.ndarray | None:
        """(2,) the xy step along the boundary, or None to let the proposal run."""
        options, cost, state = self.options, context.path, context.state
        margin = context.margin
        goal = proposal.trajectory[0, -1, :3].detach().cpu().numpy()
        if self.following is None:
            if self.held_in_a_row < options.after_holds or cost.present_clearance() < margin / 2:
                return None
            self.following = (None, 0)
        here = torch.as_tensor(np.asarray(state[:3], dtype=np.float64))
        # the straight way to the chunk's end, as waypoints the path cost can pose the body at
        fractions = torch.arange(1, len(cost.node_offsets), dtype=torch.float64)[:, None] / (len(cost.node_offsets) - 1)
        way = here + fractions * (torch.as_tensor(goal, dtype=torch.float64) - here)
        with torch.no_grad():
            way_clear = float(cost.clearance(way[None]).min()) >= margin / 2
        if (way_clear and self.held_in_a_row == 0) or self.following[1] >= options.max_steps:
            self.following = None
            return None

        def clearance_at(offset_xy: np.ndarray) -> float:
            target = here.clone()
            target[:2] += torch.as_tensor(offset_xy)
            with torch.no_grad():
                return float(cost.clearance(target[None, None]).min())

        # away from the nearest obstacle: the clearance's gradient, by central differences over 5 mm
        probe = 0.005
        away = np.array([clearance_at(np.array([probe, 0.0])) - clearance_at(np.array([-probe, 0.0])),
                         clearance_at(np.array([0.0, probe])) - clearance_at(np.array([0.0, -probe]))])
        if np.linalg.norm(away) < 1e-9:
            self.following = None
            return None
        away /= np.linalg.norm(away)
        tangent = np.array([-away[1], away[0]])
        side = self.following[0]
        if side is None:
            side = 1.0 if tangent @ (np.asarray(goal[:2]) - here[:2].numpy()) >= 0 else -1.0
        # hug the boundary at the margin: drift out when closer, in when farther; bend out more round a tight curve
        drift = 0.3 if cost.present_clearance() < margin else -0.3
        for bend in (0.0, 0.5, 1.0):
            step = side * tangent + (drift + bend) * away
            step = options.step_m * step / np.linalg.norm(step)
            if clearance_at(step) >= options.keep * margin:
                break
        else:
            self.following = None
            return None
        self.following = (side, self.following[1] + 1)
        self.steps += 1
        return step


register_chunk_filter(Follow)
