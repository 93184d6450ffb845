"""The grasp-error benchmark compares where a policy first closes the gripper with where the expert does."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bench_loader import load_bench
from lano3dp.geometry.rotations import matrix_to_rot6d


def _bench():
    return load_bench("bench_grasp_error")


def _top_down_action(yaw: float, grip: float = 1.0) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ np.diag([1.0, -1.0, -1.0])
    return np.concatenate([[0.4, 0.0, 0.02], np.asarray(matrix_to_rot6d(rotation)), [grip]])


@pytest.mark.parametrize("yaw, other, expected", [(0.3, 0.1, 11.5), (0.1, 0.1 + np.pi, 0.0), (1.5, -1.5, -8.1)])
def test_yaw_errors_fold_a_half_turn_into_the_same_grasp(yaw, other, expected):
    bench = _bench()
    difference = bench.yaw_of(_top_down_action(yaw)) - bench.yaw_of(_top_down_action(other))
    assert bench.folded_degrees(difference) == pytest.approx(expected, abs=0.1)


def test_the_first_closing_step_is_where_the_command_passes_half():
    bench = _bench()
    actions = np.stack([_top_down_action(0.0, grip) for grip in (0.0, 0.2, 0.4, 0.6, 1.0)])
    assert bench.first_closing(actions) == 3
    assert bench.first_closing(actions[:3]) is None


@pytest.mark.slow
def test_the_packaged_policy_is_measured_against_the_expert(tmp_path):
    _bench().main(["--tasks", "phone_on_base", "--episodes", "1", "--out-dir", str(tmp_path)])
    record = json.loads((tmp_path / "grasp_error.json").read_text())
    entry = record["entries"]["phone_on_base/packaged"]
    assert entry["summary"]["episodes"] == 1 and entry["episodes"][0]["seed"] == 1_000_000
    assert record["kind"] == "grasp_error" and record["provenance"]["command"].startswith(
        "python bench/bench_grasp_error.py --tasks phone_on_base")
    if entry["summary"]["closed"]:
        assert -90 <= entry["episodes"][0]["yaw_error_deg"] < 90
