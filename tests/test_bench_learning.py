"""The learning benchmark's report and packaging: curves from the work folder, a shipped policy with its record."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import bench_loader
from lano3dp.policy import DiffusionPolicy, pretrained

ROOT = Path(__file__).resolve().parent.parent
pytestmark = pytest.mark.slow


def load_bench():
    return bench_loader.load_bench("bench_learning")


def fake_eval(path: Path, successes: int, episodes: int) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"summary": {"episodes": episodes, "success_rate": successes / episodes,
                                            "stage_rates": {"reached_bowl": 1.0, "poured": successes / episodes}}}))


def test_the_report_reads_curves_and_packaging_ships_the_final_checkpoint(tmp_path, monkeypatch):
    from lano3dp.collect import collect
    from lano3dp.pipeline import train_stage
    from lano3dp.train import policy_config_for_dataset

    bench = load_bench()
    work = tmp_path / "work"
    data = collect("bowl_pour", 2, work / "data" / "bowl_pour_32pts.zarr", image_size=32, n_points=32,
                   progress=False).path
    policy = policy_config_for_dataset(data, down_dims=(16, 32), point_hidden_dims=(16,), encoder_out=16,
                                       state_feature_dim=16, diffusion_step_embed_dim=16, n_groups=4)
    run = work / "runs" / "bowl_pour_compact_seed0"
    train_stage(data, run, policy_config=policy, steps=4, n_checkpoints=2, batch_size=8, val_ratio=0.0,
                progress=False)
    fake_eval(work / "eval" / f"{run.name}_step2.json", 3, 10)
    fake_eval(work / "eval" / f"{run.name}_step4.json", 9, 10)

    args = bench.parse_args(["--tasks", "bowl_pour", "--recipes", "compact", "--work", str(work), "--report-only"])
    report = {"provenance": {"command": "python bench/bench_learning.py ...", "created_utc": "now"},
              "setup": {"demos": 2, "final_episodes": 10, "curve_episodes": 10, "evaluation": "clean"},
              **bench.collect_report(args, ["bowl_pour"], ["compact"], [0])}
    (cell,) = report["cells"]
    assert [p["step"] for p in cell["curve"]] == [2, 4] and cell["final"]["successes"] == 9
    assert cell["final"]["stages"]["poured"] == 0.9 and cell["final"]["ci95"][0] < 0.9 < cell["final"]["ci95"][1]
    assert "| `bowl_pour` | compact | 0 | **90%** (9/10; " in bench.markdown(report)

    monkeypatch.setattr(pretrained, "PACKAGED_ROOT", tmp_path / "shipped")
    folder = bench.package(args, cell, report)
    record = json.loads((folder / "record.json").read_text())
    assert record["success_rate"] == 0.9 and record["steps"] == 4
    assert "--tasks bowl_pour --recipes compact --train-seeds 0" in record["made_by"]
    assert "--seed 1000000" in record["made_by"] and record["packaged_by"] == "python bench/bench_learning.py ..."
    assert DiffusionPolicy.from_pretrained(pretrained.packaged_checkpoint("bowl_pour")).config.extra["task"] == \
        "bowl_pour"
