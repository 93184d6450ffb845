"""The protocol benchmark: cells in a fixed order, current only at this behaviour version and configuration, and a
report made from the committed cells alone."""

from __future__ import annotations

import json

import bench_loader
from lano3dp import provenance


def load_bench():
    return bench_loader.load_bench("bench_protocol")


def test_cells_cover_tasks_methods_and_seeds_seed_by_seed():
    bench = load_bench()
    args = bench.parse_args(["--tasks", "open_drawer,put_item_in_drawer", "--methods", "objects,image",
                             "--train-seeds", "0,1"])
    names = [spec.name for spec in bench.cell_specs(args)]
    assert names == ["open_drawer-objects-seed0", "open_drawer-image-seed0", "put_item_in_drawer-objects-seed0",
                     "put_item_in_drawer-image-seed0", "open_drawer-objects-seed1", "open_drawer-image-seed1",
                     "put_item_in_drawer-objects-seed1", "put_item_in_drawer-image-seed1"]
    objects, image = bench.cell_specs(args)[2:4]
    assert bench.cell_config(objects, args)["segmenters"] == ["sim", "error-model"]  # perception that can fail beside
    assert bench.cell_config(image, args)["segmenters"] == ["sim"]  # an image policy segments nothing
    assert bench.cell_config(objects, args)["obstacle_rows"] and bench.cell_config(objects, args)["cpu_minutes"] == 10
    default = bench.parse_args([])
    assert len(bench.cell_specs(default)) == 7 * 3 * 3  # the paper's seven tasks, three methods, three seeds


def test_a_cell_is_current_only_at_this_behaviour_version_and_configuration(tmp_path, monkeypatch):
    bench = load_bench()
    args = bench.parse_args(["--tasks", "open_drawer", "--methods", "scene", "--train-seeds", "0",
                             "--out-dir", str(tmp_path)])
    (spec,) = bench.cell_specs(args)
    path = bench.cell_path(spec, args)
    assert not bench.is_current(spec, args)
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps({"provenance": {"behaviour_version": provenance.BEHAVIOUR_VERSION},
                                "config": bench.cell_config(spec, args)}))
    assert bench.is_current(spec, args)
    longer = bench.parse_args(["--tasks", "open_drawer", "--methods", "scene", "--train-seeds", "0",
                               "--out-dir", str(tmp_path), "--minutes", "15"])
    assert not bench.is_current(spec, longer)  # another budget: run again
    monkeypatch.setattr(provenance, "BEHAVIOUR_VERSION", provenance.BEHAVIOUR_VERSION + 1)
    assert not bench.is_current(spec, args)  # code that behaves otherwise: run again


def cell_record(task, method, seed, finals, variations=None) -> dict:
    successes, episodes = finals
    final = {"step": 4000, "episodes": episodes, "successes": successes, "success_rate": successes / episodes,
             "interval95": [0.1, 0.9], "collision_rate": 0.0, "episodes_with_obstacles": 0, "stage_rates": {}}
    evaluations = {"curve_step1000": {**final, "step": 1000, "successes": 0, "success_rate": 0.0}, "final": final,
                   **(variations or {})}
    return {"schema": "lano3dp-results/1", "kind": "protocol_cell", "cell": f"{task}-{method}-seed{seed}",
            "provenance": {"behaviour_version": provenance.BEHAVIOUR_VERSION, "command": "x"},
            "config": {"task": task, "method": method, "train_seed": seed},
            "training": {"cpu_minutes_budget": 10, "steps_reached": 4000, "cell_cpu_s_this_session": 900.0},
            "evaluations": evaluations}


def test_the_report_is_made_from_committed_cells_with_seeds_spread_and_segmenters_side_by_side(tmp_path,
                                                                                                  monkeypatch):
    bench = load_bench()
    clutter = {"clutter_sim": {"episodes": 20, "successes": 18, "success_rate": 0.9, "collision_rate": 0.0},
               "clutter_error-model": {"episodes": 20, "successes": 12, "success_rate": 0.6, "collision_rate": 0.0}}
    records = [cell_record("open_drawer", "objects", 0, (45, 50), clutter),
               cell_record("open_drawer", "objects", 1, (40, 50), clutter),
               cell_record("open_drawer", "image", 0, (20, 50))]
    monkeypatch.setattr(bench, "committed_cells", lambda args: records)
    args = bench.parse_args(["--tasks", "open_drawer", "--methods", "objects,image", "--train-seeds", "0,1",
                             "--out-dir", str(tmp_path), "--report-only"])
    out = bench.write_report(args)
    written = json.loads(out.read_text())
    objects = written["tasks"]["open_drawer"]["objects"]
    assert abs(objects["mean_final"] - 0.85) < 1e-9 and abs(objects["spread_final"] - 0.05) < 1e-9
    assert written["cells"] == 3 and written["cells_planned"] == 4 and written["cpu_hours"] == 0.75
    page = out.with_suffix(".md").read_text()
    assert "3 of 4 cells committed" in page
    assert "Cells run by `x`: open_drawer-objects-seed0, open_drawer-objects-seed1, open_drawer-image-seed0." in page
    assert "| open_drawer | Lan-o3dp (object clouds) | clutter_error-model | 60% (" in page  # both seeds pooled: 24/40
    assert "| open_drawer | Lan-o3dp (object clouds) | clutter_sim | 90% (" in page
    assert (tmp_path / "protocol_success.png").stat().st_size > 0
