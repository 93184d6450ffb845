"""Plots and Markdown for evaluation results (matplotlib, Agg backend: no display needed).

    plot_top_view    executed EE paths seen from above, with the fitted obstacles (radius and Q*)
    plot_rates       success / collision rates of several conditions side by side
    plot_success_intervals   success per group and series (task, method) with 95% Wilson intervals
    plot_variation_drops     success lost under each scene change, per series (method)
    markdown_table   a GitHub table from rows of cells
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:pink", "tab:olive", "tab:cyan")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_top_view(path: str | Path, runs: Sequence[tuple[str, np.ndarray]], *,
                  obstacles: Sequence[Mapping[str, Any]] = (), objects: Mapping[str, Sequence[float]] | None = None,
                  title: str = "executed end-effector path (top view)") -> Path:
    """Top view (x, y) of executed EE paths.

    Args:
        path: PNG to write.
        runs: (label, (T, 3) EE positions in metres) per path; the start is a dot, the end a cross.
        obstacles: `runtime.describe_obstacle` dicts, each drawn by its registered shape
            (`guidance.shapes.draw_obstacle`): a cylinder filled (its fitted radius) with a dashed circle at its
            safety distance Q* (held-object extent and margin included), a box as its footprint.
        objects: name -> (x, y[, z]) of labelled objects (e.g. target centroids).
    """
    from lano3dp.guidance.shapes import draw_obstacle

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 5.0), dpi=120)
    for index, obstacle in enumerate(obstacles):
        draw_obstacle(ax, obstacle, label="obstacle (fitted)" if index == 0 else None)
    for index, (label, positions) in enumerate(runs):
        positions = np.asarray(positions, dtype=np.float64)
        if positions.ndim != 2 or len(positions) == 0:
            continue
        color = _COLORS[index % len(_COLORS)]
        ax.plot(positions[:, 0], positions[:, 1], "-", color=color, lw=1.6, label=label)
        ax.plot(*positions[0, :2], "o", color=color, ms=5)
        ax.plot(*positions[-1, :2], "x", color=color, ms=7, mew=2)
    for name, xy in (objects or {}).items():
        ax.plot(xy[0], xy[1], "s", color="black", ms=5)
        ax.annotate(name, (xy[0], xy[1]), textcoords="offset points", xytext=(5, 5), fontsize=8)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    return _save_figure(plt, fig, path)


def _save_figure(plt, fig, path: str | Path) -> Path:
    """Save through a temporary file, renamed into place once it reads back as an image of the figure's size; a
    failure (a full disk) removes it, keeps an older figure and raises StorageError naming `path`."""
    import os

    from lano3dp.errors import StorageError, describe_os_error
    from lano3dp.jsonio import discard

    fig.tight_layout()
    path = Path(path)
    temporary = path.with_name(f".{path.stem}.tmp-{os.getpid()}{path.suffix}")  # the suffix tells the format
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(temporary)
        _check_image(temporary)
        os.replace(temporary, path)
    except OSError as error:
        discard(temporary)
        raise StorageError(path, error.cause if isinstance(error, StorageError) else describe_os_error(error)) \
            from error
    except BaseException:
        discard(temporary)
        raise
    finally:
        plt.close(fig)
    return path


def _check_image(path: Path) -> None:
    """A raster image reads back whole (Pillow decodes it); other formats (SVG, PDF) must not be empty."""
    from lano3dp.errors import StorageError

    if path.stat().st_size == 0:
        raise StorageError(path, "0 bytes written")
    if path.suffix.lower() in (".png", ".jpg", ".jpeg"):
        from PIL import Image

        try:
            with Image.open(path) as image:
                image.load()
        except (OSError, ValueError, SyntaxError) as error:
            raise StorageError(path, f"the image does not read back ({error})") from None

def plot_rates(path: str | Path, conditions: Sequence[tuple[str, Mapping[str, Any]]], *,
               title: str = "closed-loop evaluation") -> Path:
    """Grouped bars of success, collision and safe-success rates, one group per (name, summary)."""
    plt = _pyplot()
    metrics = (("success_rate", "success", "tab:green"), ("collision_rate", "collision", "tab:red"),
               ("safe_success_rate", "success without collision", "tab:blue"))
    fig, ax = plt.subplots(figsize=(max(5.0, 1.6 * len(conditions) + 2), 3.6), dpi=120)
    x = np.arange(len(conditions))
    width = 0.8 / len(metrics)
    for offset, (key, label, color) in enumerate(metrics):
        values = [float(summary.get(key) or 0.0) for _, summary in conditions]
        bars = ax.bar(x + (offset - 1) * width, values, width, label=label, color=color)
        for bar, value in zip(bars, values, strict=True):
            ax.annotate(f"{value:.0%}", (bar.get_x() + bar.get_width() / 2, value), ha="center", va="bottom",
                        fontsize=7)
    ax.set_xticks(x, [name for name, _ in conditions], fontsize=8)
    ax.set_ylim(0, 1.15)
    ax.set_ylabel("rate over episodes")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=7, ncols=3, loc="upper center")
    return _save_figure(plt, fig, path)


def plot_success_intervals(path: str | Path, cells: Mapping[tuple[str, str], Sequence[tuple[int, int]]], *,
                           title: str = "success per task and method") -> Path:
    """Grouped bars of success rate with 95% Wilson intervals, one group per task, one bar per method.

    Args:
        path: PNG to write.
        cells: (group, series) -> the (successes, episodes) of each seed, in the order groups and series are
            drawn. A bar is the rate pooled over its seeds (its interval from the pooled counts); each seed is a
            dot on it. An empty sequence draws no bar (a run not made).
    """
    plt = _pyplot()
    groups = list(dict.fromkeys(group for group, _ in cells))
    series = list(dict.fromkeys(name for _, name in cells))
    fig, ax = plt.subplots(figsize=(max(5.0, 0.7 * len(groups) * max(1, len(series)) + 2.5), 3.8), dpi=120)
    x = np.arange(len(groups))
    width = 0.8 / max(1, len(series))
    for index, name in enumerate(series):
        color = _COLORS[index % len(_COLORS)]
        offset = (index - (len(series) - 1) / 2) * width
        labelled = False
        for position, group in zip(x + offset, groups, strict=True):
            seeds = cells.get((group, name)) or ()
            trials = sum(episodes for _, episodes in seeds)
            if trials == 0:
                continue
            successes = sum(count for count, _ in seeds)
            rate = successes / trials
            low, high = wilson_interval(successes, trials)
            ax.bar(position, rate, width, color=color, alpha=0.85, label=None if labelled else name)
            labelled = True
            # clamped: at 100/100 the Wilson bound computes a hair under the rate, which matplotlib refuses
            ax.errorbar(position, rate, yerr=[[max(0.0, rate - low)], [max(0.0, high - rate)]], color="black",
                        capsize=3, lw=1)
            if len(seeds) > 1:
                ax.plot([position] * len(seeds), [c / e for c, e in seeds if e], ".", color="black", ms=4)
            ax.annotate(f"{rate:.0%}", (position, high), textcoords="offset points", xytext=(0, 2), ha="center",
                        fontsize=7)
    ax.set_xticks(x, groups, fontsize=8, rotation=15 if len(groups) > 4 else 0)
    ax.set_ylim(0, 1.1)
    ax.set_ylabel("success rate (95% Wilson interval)")
    ax.set_title(title, fontsize=10)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=7, ncols=min(4, max(1, len(series))), loc="upper center", bbox_to_anchor=(0.5, -0.12))
    return _save_figure(plt, fig, path)


def plot_variation_drops(path: str | Path, drops: Mapping[str, Mapping[str, Sequence[float]]], *,
                         title: str = "generalisation: success lost under each scene change") -> Path:
    """Bars of the mean drop in success (clean minus varied, percentage points), per variation and method.

    Args:
        path: PNG to write.
        drops: series (method) -> variation axis -> the drops (fractions, clean - varied) of its runs (tasks
            and seeds); each is a dot, the bar their mean. Positive: the change costs success.
    """
    plt = _pyplot()
    series = list(drops)
    axes = list(dict.fromkeys(axis for by_axis in drops.values() for axis in by_axis))
    fig, ax = plt.subplots(figsize=(max(5.0, 1.3 * len(axes) + 2.5), 3.6), dpi=120)
    x = np.arange(len(axes))
    width = 0.8 / max(1, len(series))
    for index, name in enumerate(series):
        color = _COLORS[index % len(_COLORS)]
        offset = (index - (len(series) - 1) / 2) * width
        labelled = False
        for position, axis in zip(x + offset, axes, strict=True):
            values = [100 * value for value in drops[name].get(axis, ())]
            if not values:
                continue
            mean = float(np.mean(values))
            ax.bar(position, mean, width, color=color, alpha=0.85, label=None if labelled else name)
            labelled = True
            ax.plot([position] * len(values), values, ".", color="black", ms=4)
            ax.annotate(f"{mean:+.0f}", (position, max(mean, 0)), textcoords="offset points", xytext=(0, 2),
                        ha="center", fontsize=7)
    ax.axhline(0, color="black", lw=0.8)
    ax.set_xticks(x, axes, fontsize=8)
    ax.set_ylabel("clean - varied success (points)")
    ax.set_title(title, fontsize=10)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=7, ncols=min(4, max(1, len(series))), loc="upper center", bbox_to_anchor=(0.5, -0.12))
    return _save_figure(plt, fig, path)


def markdown_table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """A GitHub-flavoured Markdown table; None cells print as a dash."""
    def cell(value: Any) -> str:
        if value is None:
            return "–"
        if isinstance(value, float):
            return f"{value:.3g}"
        return str(value).replace("|", "\\|")

    lines = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in rows]
    return "\n".join(lines)


def percent(value: float | None) -> str:
    return "–" if value is None else f"{100 * value:.0f}%"


def centimetres(value: float | None) -> str:
    return "–" if value is None else f"{100 * value:.1f} cm"


def wilson_interval(successes: int, trials: int, z: float = 1.96) -> tuple[float | None, float | None]:
    """95% Wilson score interval of a success rate (sound at small n and at 0 or n successes)."""
    if trials <= 0:
        return None, None
    p = successes / trials
    denominator = 1 + z * z / trials
    centre = (p + z * z / (2 * trials)) / denominator
    half = z * ((p * (1 - p) / trials + z * z / (4 * trials * trials)) ** 0.5) / denominator
    return max(0.0, centre - half), min(1.0, centre + half)
