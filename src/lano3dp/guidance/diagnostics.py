"""Figures that show what guidance does, after the paper's Fig. 5 and Fig. 6 (top view, x-y).

Fig. 5: the noisy sample A_k and the clean estimate A_0|k at several denoising steps k, with the
obstacle: A_k stays chaotic until the last steps, A_0|k is a trajectory early on, which is why the
paper costs A_0|k. Fig. 6: final trajectories for several guidance scales rho.

matplotlib runs on the Agg backend (no display needed); figures are written as PNG.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from lano3dp.guidance.costs import Cylinder, ObstacleSet, OrientedBox, PointCloudObstacle, PositionCost, Sphere
from lano3dp.guidance.sampler import DenoiseStep


@dataclass(frozen=True)
class RecordedStep:
    """One denoising step in metric units: A_k and A_0|k positions (B, H, 3), m."""

    timestep: int
    sample: np.ndarray
    clean_estimate: np.ndarray
    guided: bool


class DenoiseRecorder:
    """An `on_step` callback that keeps A_k and A_0|k as metric positions.

    Args:
        to_metric: normalised trajectory (B, H, D) -> metric positions (B, H, 3); for a policy,
            `lambda a: policy.normalizer.unnormalize("action", a)[..., :3]`. None: the first 3 dims as is.
        timesteps: keep only these scheduler timesteps (None: all).
    """

    def __init__(self, to_metric: Callable[[torch.Tensor], torch.Tensor] | None = None,
                 timesteps: Iterable[int] | None = None):
        self.to_metric = to_metric or (lambda a: a[..., :3])
        self.timesteps = None if timesteps is None else set(int(t) for t in timesteps)
        self.steps: list[RecordedStep] = []

    def __call__(self, step: DenoiseStep) -> None:
        if self.timesteps is not None and step.timestep not in self.timesteps:
            return
        with torch.no_grad():
            sample = self.to_metric(step.sample).detach().cpu().numpy()
            estimate = self.to_metric(step.clean_estimate).detach().cpu().numpy()
        self.steps.append(RecordedStep(step.timestep, sample, estimate, step.guided))


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _obstacle_list(obstacles) -> list:
    if obstacles is None:
        return []
    if isinstance(obstacles, ObstacleSet):
        return list(obstacles)
    if isinstance(obstacles, (list, tuple)):
        return [o for item in obstacles for o in _obstacle_list(item)]
    return [obstacles]


def draw_obstacles(ax, obstacles) -> None:
    """Draw obstacles top-down: the body in red, the held-object contact line dashed, Q* dotted."""
    from matplotlib.patches import Circle, Polygon

    for obstacle in _obstacle_list(obstacles):
        base = getattr(obstacle, "cost", obstacle)  # unwrap Densified
        if isinstance(base, (Cylinder, Sphere)):
            center = base.center[:2].tolist()
            ax.add_patch(Circle(center, base.radius, color="tab:red", alpha=0.35, lw=0))
            ax.add_patch(Circle(center, base.radius + base.held_radius, fill=False, ec="tab:red", ls="--", lw=1))
            ax.add_patch(Circle(center, base.safety_distance, fill=False, ec="tab:red", ls=":", lw=0.8))
        elif isinstance(base, OrientedBox):
            ax.add_patch(Polygon(base.corners_xy(), closed=True, color="tab:red", alpha=0.35, lw=0))
        elif isinstance(base, PointCloudObstacle):
            points = base.points.numpy()
            ax.scatter(points[:, 0], points[:, 1], s=2, c="tab:red", alpha=0.5)


def _view_limits(arrays: Sequence[np.ndarray], obstacles, pad: float = 0.05,
                 quantile: float = 0.0) -> tuple[tuple, tuple]:
    """A square x-y view around the obstacles and the waypoints (all of them, or those within the
    [quantile, 1 - quantile] range per axis, so that one runaway sample does not shrink the rest)."""
    xy = []
    for a in arrays:
        points = a.reshape(-1, 3)[:, :2]
        if quantile > 0:
            low, high = np.quantile(points, [quantile, 1 - quantile], axis=0)
            points = np.array([low, high])
        xy.append(points)
    for obstacle in _obstacle_list(obstacles):
        base = getattr(obstacle, "cost", obstacle)
        if isinstance(base, (Cylinder, Sphere)):
            c, r = base.center[:2].numpy(), base.safety_distance
            xy.append(np.array([c - r, c + r]))
        elif isinstance(base, OrientedBox):
            xy.append(base.corners_xy())
    xy = np.concatenate(xy)
    low, high = xy.min(0) - pad, xy.max(0) + pad
    center, half = (low + high) / 2, (high - low).max() / 2
    return (center[0] - half, center[0] + half), (center[1] - half, center[1] + half)


def plot_denoising(steps: Sequence[RecordedStep], obstacles, path: str | Path, *, sample_index: int | None = None,
                   title: str = "") -> Path:
    """Fig. 5: A_k (top row) and A_0|k (bottom row) at the recorded steps, x-y top view.

    The view is fixed by the final trajectory and the obstacle, so early, chaotic A_k fall partly
    outside it; each panel says how many waypoints are out of view.
    """
    plt = _pyplot()
    if not steps:
        raise ValueError("no recorded denoising steps to plot")
    pick = slice(None) if sample_index is None else slice(sample_index, sample_index + 1)
    final = steps[-1].clean_estimate[pick]
    xlim, ylim = _view_limits([final], obstacles)
    fig, axes = plt.subplots(2, len(steps), figsize=(2.6 * len(steps), 5.4), squeeze=False)
    for column, step in enumerate(steps):
        for row, (name, data) in enumerate((("A_k", step.sample[pick]), ("A_0|k", step.clean_estimate[pick]))):
            ax = axes[row, column]
            draw_obstacles(ax, obstacles)
            for trajectory in data:
                ax.plot(trajectory[:, 0], trajectory[:, 1], "-", color="tab:blue", lw=0.6, alpha=0.5)
                ax.plot(trajectory[:, 0], trajectory[:, 1], ".", color="tab:blue", ms=3)
            xy = data.reshape(-1, 3)[:, :2]
            outside = int(((xy[:, 0] < xlim[0]) | (xy[:, 0] > xlim[1]) | (xy[:, 1] < ylim[0])
                           | (xy[:, 1] > ylim[1])).sum())
            label = f"{name}, k={step.timestep + 1}" + (" (guided)" if step.guided else "")
            ax.set_title(label + (f"\n{outside} pts out of view" if outside else "\n"), fontsize=8)
            _top_view_axes(ax, xlim, ylim)
    return _save_figure(fig, path, title)


def plot_trajectories_by_scale(trajectories: Mapping[float | str, np.ndarray], obstacles, path: str | Path, *,
                               cost: PositionCost | None = None, title: str = "") -> Path:
    """Fig. 6: final trajectories (B, H, 3) for each rho, x-y top view; waypoints inside an obstacle in red.

    Args:
        trajectories: rho (or a label) -> (B, H, 3) metric positions.
        cost: what decides that a trajectory collides (drawn as a red line); default the obstacles at the
            waypoints; pass e.g. Densified(obstacle, 8) to count segments too.
    """
    plt = _pyplot()
    if not trajectories:
        raise ValueError("no trajectories to plot")
    listed = _obstacle_list(obstacles)
    waypoint_cost = ObstacleSet(listed) if listed else None
    cost = cost or waypoint_cost
    xlim, ylim = _view_limits(list(trajectories.values()), obstacles, quantile=0.01)
    fig, axes = plt.subplots(1, len(trajectories), figsize=(3.0 * len(trajectories), 3.4), squeeze=False)
    for ax, (scale, batch) in zip(axes[0], trajectories.items(), strict=True):
        draw_obstacles(ax, obstacles)
        batch = np.asarray(batch)
        positions = torch.as_tensor(batch, dtype=torch.float64)
        hits = np.zeros(batch.shape[:2], dtype=bool)  # waypoints inside
        colliding = np.zeros(len(batch), dtype=bool)  # trajectories that collide anywhere `cost` looks
        if waypoint_cost is not None:
            hits = (waypoint_cost.clearance(positions) < 0).numpy()
        if cost is not None:
            colliding = (cost.clearance(positions).min(-1).values < 0).numpy()
        for trajectory, inside, bad in zip(batch, hits, colliding, strict=True):
            ax.plot(trajectory[:, 0], trajectory[:, 1], "-", color="tab:red" if bad else "tab:blue", lw=0.6, alpha=0.6)
            ax.plot(trajectory[~inside, 0], trajectory[~inside, 1], ".", color="tab:blue", ms=3)
            ax.plot(trajectory[inside, 0], trajectory[inside, 1], ".", color="tab:red", ms=4)
        rate = colliding.mean()
        xy = batch.reshape(-1, 3)[:, :2]
        outside = int(((xy[:, 0] < xlim[0]) | (xy[:, 0] > xlim[1]) | (xy[:, 1] < ylim[0]) | (xy[:, 1] > ylim[1])).sum())
        name = f"rho = {scale:g}" if isinstance(scale, (int, float)) else str(scale)
        ax.set_title(f"{name}\ncolliding: {rate:.0%} of {len(batch)}" + (f", {outside} pts out of view" if outside
                                                                         else ""), fontsize=8)
        _top_view_axes(ax, xlim, ylim)
    return _save_figure(fig, path, title)


def _top_view_axes(ax, xlim, ylim) -> None:
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal")
    ax.tick_params(labelsize=6)


def _save_figure(fig, path: str | Path, title: str) -> Path:
    import matplotlib.pyplot as plt

    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def evenly_spaced_timesteps(timesteps: Sequence[int], count: int) -> list[int]:
    """`count` timesteps spread over a scheduler's schedule, always including the first and the last."""
    timesteps = [int(t) for t in timesteps]
    if count >= len(timesteps):
        return timesteps
    picks = np.linspace(0, len(timesteps) - 1, count).round().astype(int)
    return [timesteps[i] for i in picks]
