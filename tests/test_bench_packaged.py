"""The packaged-policy benchmark evaluates a shipped policy on held-out seeds beside its record."""

from __future__ import annotations

import json

import pytest

from bench_loader import load_bench

pytestmark = pytest.mark.slow


def test_a_shipped_policy_is_scored_on_held_out_seeds_beside_its_record(tmp_path):
    bench = load_bench("bench_packaged")
    bench.main(["--tasks", "close_microwave", "--episodes", "2", "--workers", "1", "--work", str(tmp_path / "work"),
                "--out-dir", str(tmp_path), "--tag", "_t"])
    report = json.loads((tmp_path / "packaged_t.json").read_text())
    (row,) = report["rows"]
    assert report["kind"] == "packaged" and report["provenance"]["behaviour_version"] >= 1
    assert report["seed"] == 2_000_000 and row["task"] == "close_microwave" and row["episodes"] == 2
    assert row["recorded_success"] is not None and row["recorded_within_interval"] in (True, False)
    low, high = row["ci95"]
    assert low <= row["success_rate"] <= high
    evaluated = json.loads((tmp_path / "work" / "close_microwave.json").read_text())
    assert evaluated["config"]["seed"] == 2_000_000  # held out from the record's 1000000 + i
    assert evaluated["provenance"]["command"] == report["provenance"]["command"]
    page = (tmp_path / "packaged_t.md").read_text()
    assert "[`packaged_t.json`](packaged_t.json), made by `python bench/bench_packaged.py --tasks close_microwave" \
        in page
    assert "packaged_t.json" in (tmp_path / "INDEX.md").read_text()
