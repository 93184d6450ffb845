"""The cell graph and its executors: dependency order, skipping what the work folder holds, failures that name
their cell, the Ray extra's absence said in one line, and a reduced protocol whose report is the same whether
this process, a process pool or a local Ray instance ran its cells.

Cheap cells ("touch": write a file listing the inputs' contents) test the graph; the reduced protocol trains
a tiny policy for 4 steps on 2 demonstrations and evaluates 12-step episodes, about 10 s a run.
"""

from __future__ import annotations

import importlib.util
import json
import os
import sys
import time
from pathlib import Path

import pytest

import bench_loader
from lano3dp.executor import (
    Cell,
    CellFailedError,
    CellKind,
    GraphError,
    LocalExecutor,
    RayNotInstalledError,
    make_executor,
    ordered,
)

HAVE_RAY = importlib.util.find_spec("ray") is not None  # not imported here: lano3dp sets Ray's env first


# ---- cheap cells ---------------------------------------------------------------------------------------
def touch(cell: Cell) -> None:
    """Write the cell's name and its inputs' contents; append the name to the run log."""
    if cell.params.get("fail"):
        raise RuntimeError(f"{cell.name} was told to fail")
    parts = [Path(cell.params["folder"], f"{name}.txt").read_text() for name in cell.inputs]
    started = time.time()
    time.sleep(cell.params.get("sleep", 0.0))
    Path(cell.output).write_text(f"{cell.name}({','.join(parts)})")
    with open(Path(cell.params["folder"]) / "log.jsonl", "a") as log:
        log.write(json.dumps({"name": cell.name, "start": started, "end": time.time()}) + "\n")


def touched(cell: Cell) -> bool:
    return Path(cell.output).exists()


KINDS = {"touch": CellKind(touch, touched)}


def touch_cell(folder: Path, name: str, inputs=(), cpus: int = 1, **params) -> Cell:
    return Cell(name, "touch", {"folder": str(folder), **params}, output=str(folder / f"{name}.txt"),
                inputs=tuple(inputs), cpus=cpus)


def diamond(folder: Path, **params) -> list[Cell]:
    """d reads b and c, which both read a; listed readers first, so the executor must order them."""
    return [touch_cell(folder, "d", ["b", "c"]), touch_cell(folder, "b", ["a"]), touch_cell(folder, "c", ["a"]),
            touch_cell(folder, "a", **params)]


def run_log(folder: Path) -> list[dict]:
    path = folder / "log.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []


@pytest.mark.parametrize("workers", [1, 2])
def test_cells_run_after_their_inputs_and_a_rerun_executes_nothing(tmp_path, workers):
    cells = diamond(tmp_path)
    first = LocalExecutor(workers).run(cells, KINDS)
    assert sorted(first.executed) == ["a", "b", "c", "d"] and first.skipped == ()
    assert first.executed[0] == "a" and first.executed[-1] == "d"
    assert (tmp_path / "d.txt").read_text() == "d(b(a()),c(a()))"

    again = LocalExecutor(workers).run(cells, KINDS)
    assert again.executed == () and sorted(again.skipped) == ["a", "b", "c", "d"]
    assert len(run_log(tmp_path)) == 4

    (tmp_path / "b.txt").unlink()  # done-ness is per cell: only the missing output is made again
    assert LocalExecutor(workers).run(cells, KINDS).executed == ("b",)


def test_a_pool_never_runs_more_cores_worth_of_cells_than_it_has(tmp_path):
    cells = [touch_cell(tmp_path, name, sleep=0.3, cpus=2) for name in ("wide1", "wide2")]
    LocalExecutor(workers=2).run(cells, KINDS)
    first, second = sorted(run_log(tmp_path), key=lambda entry: entry["start"])
    assert second["start"] >= first["end"]  # each needs both cores: one at a time


def test_a_failing_cell_is_named_its_readers_do_not_run_and_what_was_done_is_kept(tmp_path):
    cells = [touch_cell(tmp_path, "a"), touch_cell(tmp_path, "b", ["a"], fail=True), touch_cell(tmp_path, "c", ["b"])]
    with pytest.raises(CellFailedError, match="cell 'b' failed") as caught:
        LocalExecutor().run(cells, KINDS)
    assert caught.value.name == "b" and "b was told to fail" in caught.value.details
    assert (tmp_path / "a.txt").exists() and not (tmp_path / "c.txt").exists()
    # a cell that failed in a pool process reaches the caller as the same error
    with pytest.raises(CellFailedError, match="cell 'b' failed"):
        LocalExecutor(workers=2).run(cells, KINDS)
    assert [entry["name"] for entry in run_log(tmp_path)] == ["a"]  # a was skipped the second time


def test_malformed_graphs_are_refused_with_what_is_wrong(tmp_path):
    with pytest.raises(GraphError, match=r"cycle: x -> y -> x"):
        ordered([touch_cell(tmp_path, "x", ["y"]), touch_cell(tmp_path, "y", ["x"])])
    with pytest.raises(GraphError, match=r"'x' reads \['nowhere'\]"):
        ordered([touch_cell(tmp_path, "x", ["nowhere"])])
    with pytest.raises(GraphError, match="two cells are named 'x'"):
        ordered([touch_cell(tmp_path, "x"), touch_cell(tmp_path, "x")])
    with pytest.raises(GraphError, match="kind 'touch'; known kinds: \\['collect', 'eval', 'train'\\]"):
        LocalExecutor().run([touch_cell(tmp_path, "x")])


def test_without_ray_the_ray_executor_says_how_to_install_it(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` now raises ImportError
    with pytest.raises(RayNotInstalledError, match=r"pip install 'lano3dp\[ray\]'"):
        make_executor("ray")
    bench = load_bench()
    with pytest.raises(SystemExit) as caught:
        bench.main(["--executor", "ray", "--tasks", "open_drawer", "--obstacle-tasks", ""])
    message = str(caught.value)
    assert message == "--executor ray: the Ray executor needs the optional extra: pip install 'lano3dp[ray]'"
    assert "\n" not in message and "Traceback" not in capsys.readouterr().err


# ---- the reduced protocol, by every executor ----------------------------------------------------------
def load_bench():
    return bench_loader.load_bench("bench_protocol")


# One clean task with a camera variation, one obstacle task: every kind of cell, 11 in all.
REDUCED = ["--tasks", "open_drawer", "--methods", "objects", "--demos", "2", "--points", "32", "--steps", "4",
           "--eval-every", "2", "--episodes", "1", "--batch-size", "8", "--variations", "camera",
           "--obstacle-tasks", "put_item_in_drawer", "--obstacle-episodes", "1", "--rho-sweep", "", "--tag", "_reduced"]


def reduced_overrides(bench):
    return bench.Overrides(
        collect={"image_size": 64},
        policy={"down_dims": [16, 32], "diffusion_step_embed_dim": 16, "n_groups": 4, "point_hidden_dims": [16],
                "encoder_out": 16, "state_feature_dim": 16},
        train={"val_ratio": 0.0}, eval={"max_steps": 12, "steps": 2})


def run_reduced(bench, folder: Path, *executor: str) -> dict:
    argv = [*REDUCED, "--work", str(folder / "work"), "--results", str(folder / "results"), *executor]
    assert bench.main(argv, reduced_overrides(bench)) == 0
    return json.loads((folder / "results" / "protocol_reduced.json").read_text())


def numbers(results: dict, folder: Path) -> dict:
    """The report's numbers: every entry, with the work folder's path and the timings taken out."""
    def strip(value):
        if isinstance(value, dict):
            return {key: strip(item) for key, item in value.items() if key != "latency_mean_s"}
        if isinstance(value, list):
            return [strip(item) for item in value]
        return value.replace(str(folder), "<folder>") if isinstance(value, str) else value

    return strip(results["tasks"])


def episode_paths(folder: Path) -> dict[str, list[float]]:
    """Evaluation JSON -> its episodes' end-effector path lengths (m): what the trained policies did."""
    evals = folder / "work" / "evals"
    return {str(path.relative_to(evals)): [episode["path_length"] for episode in json.loads(path.read_text())
                                            ["episodes"]] for path in sorted(evals.rglob("*.json"))}


@pytest.mark.slow
@pytest.mark.skipif(not HAVE_RAY, reason="ray not installed (pip install 'lano3dp[ray]')")
def test_the_reduced_protocol_reports_the_same_numbers_locally_and_on_a_local_ray_instance(tmp_path):
    from lano3dp.executor import RayExecutor, start_ray

    bench = load_bench()
    local = run_reduced(bench, tmp_path / "local")
    report = (tmp_path / "local" / "results" / "protocol_reduced.md").read_text()
    assert "![final clean success per task and method" in report and "| Lan-o3dp (object clouds) | +0 (1) |" in report
    assert (tmp_path / "local" / "results" / "protocol_reduced_success.png").stat().st_size > 0

    assert start_ray(num_cpus=2)  # the test's instance; the executor joins it and leaves it running
    import ray

    try:
        assert os.environ["RAY_USAGE_STATS_ENABLED"] == "0"
        assert ray.util.get_node_ip_address() == "127.0.0.1"
        assert ray.get_runtime_context().gcs_address.startswith("127.0.0.1:")
        assert ray.cluster_resources()["CPU"] == 2
        on_ray = run_reduced(bench, tmp_path / "ray", "--executor", "ray")
        assert ray.is_initialized()
    finally:
        ray.shutdown()

    assert numbers(on_ray, tmp_path / "ray") == numbers(local, tmp_path / "local")
    assert [entry["final"]["episodes"] for entry in on_ray["tasks"]["open_drawer"].values()] == [1]
    paths = episode_paths(tmp_path / "local")
    assert len(paths) == 7 and all(length > 0 for lengths in paths.values() for length in lengths)
    assert episode_paths(tmp_path / "ray") == paths  # the same training and the same episodes, cell by cell

    rerun = RayExecutor().run(bench.build_graph(bench.parse_args([*REDUCED, "--work", str(tmp_path / "ray" / "work")]),
                                                reduced_overrides(bench)))
    assert rerun.executed == () and len(rerun.skipped) == 11
