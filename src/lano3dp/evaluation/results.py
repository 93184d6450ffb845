"""What an evaluation writes: per-episode records as they finish (the episode log), and the results file with its
summary and provenance.

    EpisodeLog      finished episodes, one JSON line each, appended and fsync'ed: a killed evaluation resumes
    summarize       rates and means over episode records
    results_file    {"schema", "kind", "provenance", "config", "guidance", ...}: the shape of every results JSON
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from lano3dp.errors import CorruptFileError
from lano3dp.jsonio import to_jsonable, write_text_atomic
from lano3dp.provenance import RESULTS_SCHEMA, provenance

EPISODE_LOG_FORMAT = "lano3dp-eval-episodes/2"
SUMMARY_FIELDS = ("episodes", "success_rate", "collision_rate", "safe_success_rate", "error_rate",
                  "mean_min_clearance", "mean_path_length", "mean_steps", "latency_mean_s", "latency_p95_s")


def stage_breakdown(episodes: Sequence[Mapping[str, Any]]) -> tuple[dict[str, float], dict[str, int]]:
    """Where episodes fail: (stage -> fraction of episodes that reached it, furthest stage -> episodes that got
    that far and no further, with "none" for those that reached no stage), both in the task's order; both empty
    when no record holds stages (an env that reports none)."""
    order = next((list(e["stages"]) for e in episodes if e.get("stages")), [])
    if not order:
        return {}, {}
    n = len(episodes)
    rates = {stage: round(sum(bool((e.get("stages") or {}).get(stage)) for e in episodes) / n, 4)
             for stage in order}
    furthest = {stage: 0 for stage in ["none", *order]}
    for e in episodes:
        key = e.get("stage") or "none"
        furthest[key] = furthest.get(key, 0) + 1
    return rates, furthest


def summarize(episodes: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Aggregate per-episode records into rates and means (clearance only over episodes that measured one)."""
    n = len(episodes)
    latencies = np.array([t for e in episodes for t in e["chunk_latency_s"]], dtype=np.float64)
    clearances = [e["min_clearance"] for e in episodes if e["min_clearance"] is not None]

    def rate(flag: Callable[[Mapping], bool]) -> float:
        return round(sum(bool(flag(e)) for e in episodes) / n, 4) if n else float("nan")

    def mean(values) -> float | None:
        values = list(values)
        return round(float(np.mean(values)), 5) if values else None

    stage_rates, furthest_stages = stage_breakdown(episodes)
    summary = {
        "episodes": n,
        "successes": sum(bool(e["success"]) for e in episodes),
        # an obstacle variation without obstacle_scenes_only skips the obstacle where a layout leaves no room:
        # a collision rate is read against the episodes that really had one
        "episodes_with_obstacles": sum(bool(e.get("obstacles")) for e in episodes),
        "success_rate": rate(lambda e: e["success"]),
        "collision_rate": rate(lambda e: e["collided"]),
        "mean_collision_steps": mean(e["n_collision_steps"] for e in episodes),
        "safe_success_rate": rate(lambda e: e["success"] and not e["collided"]),
        "error_rate": rate(lambda e: e["error"] is not None),
        "mean_min_clearance": mean(clearances),
        "worst_min_clearance": round(min(clearances), 5) if clearances else None,
        "mean_path_length": mean(e["path_length"] for e in episodes),
        "mean_steps": mean(e["steps"] for e in episodes),
        "chunks": int(latencies.size),
        "latency_mean_s": round(float(latencies.mean()), 5) if latencies.size else None,
        "latency_p95_s": round(float(np.quantile(latencies, 0.95)), 5) if latencies.size else None,
        "mean_tries": mean(t for e in episodes for t in e["chunk_tries"]),
        "errors": sorted({e["error"].split(":")[0] for e in episodes if e["error"]}),
        "stage_rates": stage_rates,
        "furthest_stages": furthest_stages,
    }
    if episodes and not any(e.get("success_reported", True) for e in episodes):
        # an env without info["success"]: a success rate of 0 would read as a measurement
        summary.update(success_rate=None, safe_success_rate=None, successes=None)
    return summary


def episode_log_path(out: str | Path) -> Path:
    """The JSONL log beside a results JSON: results.json -> results.episodes.jsonl."""
    out = Path(out)
    return out.with_name((out.stem if out.suffix == ".json" else out.name) + ".episodes.jsonl")


class EpisodeLog:
    """Finished episodes of one evaluation, one JSON line each, appended (and fsync'ed) as they finish.

    The first line says which evaluation the log belongs to (`identity`: what makes two evaluations give the same
    episodes); a log of another evaluation is started afresh. A last line cut short by a kill is dropped; every
    complete line is an episode that is not run again.
    """

    def __init__(self, path: str | Path, identity: dict[str, Any]):
        self.path = Path(path)
        self.identity = json.loads(json.dumps(to_jsonable(identity)))
        self.records: dict[int, dict[str, Any]] = {}
        self._load()

    def _load(self) -> None:
        if not self.path.exists():
            self._start()
            return
        raw = self.path.read_bytes()
        lines = raw.split(b"\n")
        complete, tail = lines[:-1], lines[-1]  # `tail` is what a kill mid-line left (b"" when none)
        try:
            header = json.loads(complete[0]) if complete else None
        except ValueError:
            header = None
        if not isinstance(header, dict) or header.get("format") != EPISODE_LOG_FORMAT \
                or header.get("evaluation") != self.identity:
            self._start()  # another evaluation's log (or an empty one): this evaluation starts from nothing
            return
        for number, line in enumerate(complete[1:], 2):
            try:
                entry = json.loads(line)
                self.records[int(entry["index"])] = entry["episode"]
            except (ValueError, KeyError, TypeError) as error:
                raise CorruptFileError(self.path, f"line {number} is not an episode record ({error}); delete the "
                                                  "file to evaluate every episode again") from error
        if tail:
            with open(self.path, "r+b") as handle:
                handle.truncate(len(raw) - len(tail))

    def _start(self) -> None:
        write_text_atomic(self.path, json.dumps({"format": EPISODE_LOG_FORMAT, "evaluation": self.identity}) + "\n")
        self.records = {}

    def append(self, index: int, record: dict[str, Any]) -> dict[str, Any]:
        """Write one finished episode; returns it as read back (JSON types), as every summary sees it."""
        record = json.loads(json.dumps(to_jsonable(record)))
        with open(self.path, "a") as handle:
            handle.write(json.dumps({"index": index, "episode": record}) + "\n")
            handle.flush()
            os.fsync(handle.fileno())
        self.records[index] = record
        return record


def results_file(kind: str, config: Mapping[str, Any], body: Mapping[str, Any], *,
                 command: str | None = None) -> dict[str, Any]:
    """A results JSON: the schema, what kind of result, its provenance (command, commit, behaviour version,
    versions, machine, config), then `body`."""
    return {"schema": RESULTS_SCHEMA, "kind": kind, "provenance": provenance(command, config), "config": dict(config),
            **body}
