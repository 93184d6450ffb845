"""The README's paragraph on the paper's three claims, from results/protocol.json and results/obstacles.json.

Each claim is one comparison of pooled success (or touch) counts with 95% Wilson intervals: it "holds" when the
intervals separate in the claimed direction, "does not hold" when they separate the other way, and is "not
separated" otherwise. Only cells measured on the same task and training seed for every method enter a comparison, so
a method is never credited with a task or seed the others were not run on. docs/gen_benchmarks.py writes the
paragraph between the README's claims markers.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from lano3dp.report import wilson_interval

OURS, BASELINES = "objects", ("scene", "image")
NAMES = {"objects": "Lan-o3dp", "scene": "DP3", "image": "Diffusion Policy"}
ROBUST_SEGMENTER = "error-model"  # Lan-o3dp's scene-change rows with perception that can fail


class Count:
    """Pooled successes over episodes, with its 95% interval."""

    def __init__(self, successes: int = 0, episodes: int = 0):
        self.successes, self.episodes = successes, episodes

    def add(self, result: Mapping[str, Any]) -> None:
        self.successes += int(result["successes"])
        self.episodes += int(result["episodes"])

    @property
    def interval(self) -> tuple[float, float]:
        return wilson_interval(self.successes, self.episodes)

    def __str__(self) -> str:
        if not self.episodes:
            return "no episodes"
        low, high = self.interval
        return f"{self.successes}/{self.episodes} ({100 * low:.0f}–{100 * high:.0f}%)"


def verdict(ours: Count, others: Iterable[Count], *, higher_is_better: bool = True) -> str:
    """Whether `ours` beats every count in `others` at 95% ("holds"), loses to one ("does not hold"), or neither."""
    others = list(others)
    if not ours.episodes or not all(other.episodes for other in others):
        return "not measured yet"
    sign = 1 if higher_is_better else -1
    low, high = (v * sign for v in ours.interval)
    low, high = min(low, high), max(low, high)
    bounds = [sorted(v * sign for v in other.interval) for other in others]
    if all(low > other_high for _, other_high in bounds):
        return "holds"
    if any(high < other_low for other_low, _ in bounds):
        return "does not hold"
    return "not separated at 95%"


def _cells(protocol: Mapping[str, Any]) -> dict[str, dict[str, list[dict]]]:
    """{task: {method: [seed entries]}} of the committed cells, keeping only the training seeds every method has
    for that task (a task without all three methods keeps none)."""
    out = {}
    for task, methods in protocol.get("tasks", {}).items():
        seeds = [set(methods[m]["seeds"]) if m in methods else set() for m in (OURS, *BASELINES)]
        shared = sorted(set.intersection(*seeds))
        out[task] = {method: [entry["seeds"][seed] for seed in shared] for method, entry in methods.items()}
    return out


def success_claim(protocol: Mapping[str, Any]) -> str:
    cells = _cells(protocol)
    shared = [task for task, methods in cells.items() if all(methods.get(m) for m in (OURS, *BASELINES))]
    counts = {method: Count() for method in (OURS, *BASELINES)}
    for task in shared:
        for method, count in counts.items():
            for seed in cells[task][method]:
                count.add(seed["final"])
    numbers = ", ".join(f"{NAMES[m]} {counts[m]}" for m in counts)
    where = f"on the {len(shared)} task(s) with all three methods measured, on the same training seeds " \
            f"({', '.join(shared)}): {numbers}" \
        if shared else "no task has all three methods measured yet"
    return f"**Higher success than DP3 and Diffusion Policy** (clean scenes, final checkpoints): " \
           f"{verdict(counts[OURS], [counts[m] for m in BASELINES])}; {where}."


def robustness_claim(protocol: Mapping[str, Any]) -> str:
    cells = _cells(protocol)
    counts = {method: Count() for method in (OURS, *BASELINES)}
    oracle = Count()
    shared = []
    for task, methods in cells.items():
        if not all(methods.get(m) for m in (OURS, *BASELINES)):
            continue
        changes = {name.rsplit("_", 1)[0] for seed in methods[OURS] for name in seed["variations"]
                   if name.endswith(f"_{ROBUST_SEGMENTER}")}
        if not changes:
            continue
        shared.append(task)
        for method in counts:
            segmenter = ROBUST_SEGMENTER if method == OURS else "sim"
            for seed in methods[method]:
                for change in changes:
                    if (result := seed["variations"].get(f"{change}_{segmenter}")) is not None:
                        counts[method].add(result)
        for seed in methods[OURS]:
            for change in changes:
                if (result := seed["variations"].get(f"{change}_sim")) is not None:
                    oracle.add(result)
    if not shared:
        return ("**Robustness to scene changes** (clutter, look-alikes, new instances, camera, background): "
                "not measured yet; no task has all three methods with Lan-o3dp's perception-error rows.")
    numbers = ", ".join(f"{NAMES[m]} {counts[m]}" for m in counts)
    return (f"**Robustness to scene changes** (clutter, look-alikes, new instances, camera, background; Lan-o3dp "
            f"with perception that can fail): {verdict(counts[OURS], [counts[m] for m in BASELINES])}; pooled over "
            f"{', '.join(shared)}: {numbers} (Lan-o3dp with ground-truth masks: {oracle}).")


def avoidance_claim(obstacles: Mapping[str, Any]) -> str:
    touched = {"none": Count(), "default": Count()}
    succeeded = {"none": Count(), "default": Count()}
    for entry in obstacles.get("tasks", {}).values():
        for name, row in entry["rows"].items():
            sampler = name.rsplit("/", 1)[1]
            if sampler in touched:
                episodes = int(row["episodes"])  # every benchmark episode has an obstacle (obstacle scenes only)
                touched[sampler].add({"successes": round(row["touch_rate"] * episodes), "episodes": episodes})
                succeeded[sampler].add({"successes": round(row["success_rate"] * episodes), "episodes": episodes})
    return (f"**Training-free obstacle avoidance** (an obstacle no demonstration had, on the demonstrated path of "
            f"{len(obstacles.get('tasks', {}))} tasks): "
            f"{verdict(touched['default'], [touched['none']], higher_is_better=False)}; episodes that touched it "
            f"guided {touched['default']}, unguided {touched['none']}; success guided {succeeded['default']}, "
            f"unguided {succeeded['none']}.")


def claims(protocol: Mapping[str, Any] | None, obstacles: Mapping[str, Any]) -> str:
    """The paragraph, one bullet per claim."""
    protocol = protocol or {}
    committed = f"{protocol.get('cells', 0)} of {protocol.get('cells_planned', 63)}"
    return "\n".join([
        f"Whether the paper's three claims hold here, from the protocol's committed cells ({committed}; "
        "[protocol](docs/benchmarks/protocol.md)) and the obstacle benchmark "
        "([obstacles](docs/benchmarks/obstacles.md)):", "",
        f"- {success_claim(protocol)}",
        f"- {robustness_claim(protocol)}",
        f"- {avoidance_claim(obstacles)}"])
