"""The protocol benchmark's table: runs missing from the work folder are shown as not run, never dropped."""


import pytest

import bench_loader


def load_bench():
    return bench_loader.load_bench("bench_protocol")


def summary(successes: int, episodes: int = 20, **extra) -> dict:
    return {"episodes": episodes, "episodes_with_obstacles": extra.pop("placed", None), "successes": successes,
            "success_rate": successes / episodes, "collision_rate": extra.pop("collision", 0.0),
            "mean_collision_steps": extra.pop("contact", 0.0), "safe_success_rate": successes / episodes,
            "mean_min_clearance": extra.pop("clearance", None), "error_rate": 0.0, "latency_mean_s": 0.1}


def test_report_marks_missing_runs_and_evaluations_as_not_run():
    bench = load_bench()
    args = bench.parse_args(["--tasks", "open_drawer", "--variations", "clutter,camera", "--rho-sweep", "0.01",
                             "--report-only"])
    trained = {"method": bench.METHODS["objects"], "seed": 0, "parameters": 5_400_000, "steps": 2000,
               "curve": [{"step": 1000, **summary(8)}, {"step": 2000, **summary(12)}],
               "paper_best_k": 0.5, "best_k_used": 2, "final": {"step": 2000, **summary(12)},
               "variations": {"clutter": summary(10), "camera": None},
               "obstacle": {"no_guidance": summary(13, placed=18, collision=0.9, contact=19.8, clearance=-0.031),
                            "guidance": summary(5, placed=18, collision=0.65, contact=0.95, clearance=-0.001)},
               "obstacle_sweep": {"0.01": None}}
    missing = {"method": bench.METHODS["scene"], "seed": 0, "not_run": True}
    results = {"command": "python bench/bench_protocol.py --report-only", "machine": {"platform": "x", "note": "y"},
               "tasks": {"open_drawer": {"objects/seed0": trained, "scene/seed0": missing}}}
    text = bench.markdown_report(results, args)
    assert "| Lan-o3dp (object clouds) | 0 | 5.40 M | 2000 | 50% (best 2) | 60% (39%–78%) | 50% | not run |" in text
    assert "| DP3 (scene cloud) | 0 | – | – | not run | not run | not run | not run |" in text
    assert "| guidance A_0\\|k, rho 0.01 | not run |" in text
    assert "| no guidance | 20 | 18 | 65% | 90% | 19.8 | 65% | -3.1 cm |" in text
    assert "Assembled by --report-only" in text


def test_a_task_run_only_for_the_obstacle_test_has_no_variation_cells():
    bench = load_bench()
    args = bench.parse_args(["--tasks", "open_drawer", "--obstacle-tasks", "put_item_in_drawer",
                             "--variations", "clutter", "--report-only"])
    assert args.obstacle_tasks == "put_item_in_drawer"
    obstacle_only = {"method": bench.METHODS["objects"], "seed": 0, "not_run": True, "obstacle_only": True}
    results = {"command": "c", "machine": {"platform": "x", "note": "y"},
               "tasks": {"put_item_in_drawer": {"objects/seed0": obstacle_only}}}
    assert "| Lan-o3dp (object clouds) | 0 | – | – | not run | not run | – |" in bench.markdown_report(results, args)


def entry(bench, method: str, seed: int, final: int, **variations: int | None) -> dict:
    """A trained run with `final` successes of 20 and, per variation axis, its successes (None: not run)."""
    return {"method": bench.METHODS[method], "seed": seed, "parameters": 5_400_000, "steps": 2000,
            "curve": [{"step": 2000, **summary(final)}], "paper_best_k": final / 20, "best_k_used": 1,
            "final": {"step": 2000, **summary(final)},
            "variations": {axis: None if count is None else summary(count) for axis, count in variations.items()}}


def test_the_report_plots_success_with_intervals_and_the_generalisation_drops_and_links_both(tmp_path):
    import matplotlib.image

    bench = load_bench()
    args = bench.parse_args(["--tasks", "open_drawer,close_microwave", "--variations", "clutter,camera",
                             "--seeds", "0,1", "--results", str(tmp_path), "--tag", "_synthetic", "--report-only"])
    results = {"command": "c", "machine": {"platform": "x", "note": "y"}, "tasks": {
        "open_drawer": {"objects/seed0": entry(bench, "objects", 0, 16, clutter=12, camera=14),
                        "objects/seed1": entry(bench, "objects", 1, 18, clutter=15, camera=18),
                        "scene/seed0": entry(bench, "scene", 0, 10, clutter=4, camera=10),
                        "scene/seed1": {"method": bench.METHODS["scene"], "seed": 1, "not_run": True}},
        "close_microwave": {"objects/seed0": entry(bench, "objects", 0, 20, clutter=20, camera=19),
                            "objects/seed1": entry(bench, "objects", 1, 19, clutter=17, camera=None)}}}

    assert bench.success_cells(results) == {("open_drawer", bench.METHODS["objects"]): [(16, 20), (18, 20)],
                                            ("open_drawer", bench.METHODS["scene"]): [(10, 20)],
                                            ("close_microwave", bench.METHODS["objects"]): [(20, 20), (19, 20)]}
    drops = bench.variation_drops(results)
    assert drops[bench.METHODS["objects"]]["clutter"] == pytest.approx([0.2, 0.15, 0.0, 0.1])
    assert drops[bench.METHODS["objects"]]["camera"] == pytest.approx([0.1, 0.0, 0.05])  # one camera not run
    assert drops[bench.METHODS["scene"]] == {"clutter": pytest.approx([0.3]), "camera": [0.0]}

    out_json, out_md = bench.write_report(results, args)
    text = out_md.read_text()
    assert "![final clean success per task and method, 95% Wilson intervals](protocol_synthetic_success.png)" in text
    assert "![success lost under each scene change, per method](protocol_synthetic_drops.png)" in text
    assert "| Lan-o3dp (object clouds) | +11 (4) | +5 (3) |" in text  # mean clean - varied, in points
    assert "| DP3 (scene cloud) | +30 (1) | +0 (1) |" in text
    for name in ("protocol_synthetic_success.png", "protocol_synthetic_drops.png"):
        height, width, _ = matplotlib.image.imread(tmp_path / name).shape
        assert width > 500 and height > 300
    assert out_json == tmp_path / "protocol_synthetic.json"
