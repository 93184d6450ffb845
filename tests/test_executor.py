"""The cell graph and its executors: dependency order, skipping what the work folder holds, failures that name
their cell, the Ray extra's absence said in one line, and a small real graph whose episodes are the same whether
this process or a local Ray instance ran its cells.

Cheap cells ("touch": write a file listing the inputs' contents) test the graph; the real graph trains a tiny
policy for 4 steps on 2 demonstrations and evaluates 12-step episodes, about 10 s a run.
"""

from __future__ import annotations

import importlib.util
import json
import os
import sys
import time
from pathlib import Path

import pytest

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


def test_without_ray_the_ray_executor_says_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # as if the extra were not installed
    with pytest.raises(RayNotInstalledError, match=r"pip install 'lano3dp\[ray\]'"):
        make_executor("ray")


# ---- a small real graph (collect -> train -> evaluate), by every executor ---------------------------------
def real_graph(folder: Path) -> list[Cell]:
    """Two demonstrations, a tiny policy trained 4 steps, two 12-step evaluations of it: each built-in kind."""
    from lano3dp.evaluation import EvalConfig, GuidanceChoice
    from lano3dp.executor import collect_cell, eval_cell, train_cell

    data, run = folder / "data.zarr", folder / "run"
    policy = {"down_dims": [16, 32], "diffusion_step_embed_dim": 16, "n_groups": 4, "point_hidden_dims": [16],
              "encoder_out": 16, "state_feature_dim": 16}
    cells = [collect_cell("collect", "open_drawer", 2, data, image_size=64, n_points=32),
             train_cell("train", data, run, steps=4, policy=policy, inputs=["collect"], batch_size=8, val_ratio=0.0)]
    for variation in ("clean", "camera"):
        config = EvalConfig(checkpoint=str(run), task="open_drawer", variation=variation, episodes=1, max_steps=12,
                            guidance=GuidanceChoice("none", {"sampler.steps": 2}),
                            out=str(folder / f"{variation}.json"))
        cells.append(eval_cell(f"eval {variation}", config, inputs=["train"]))
    return cells


def path_lengths(folder: Path) -> dict[str, list[float]]:
    return {variation: [e["path_length"] for e in json.loads((folder / f"{variation}.json").read_text())["episodes"]]
            for variation in ("clean", "camera")}


@pytest.mark.slow
@pytest.mark.skipif(not HAVE_RAY, reason="ray not installed (pip install 'lano3dp[ray]')")
def test_a_real_graph_gives_the_same_episodes_locally_and_on_a_local_ray_instance(tmp_path):
    from lano3dp.executor import RayExecutor, start_ray

    local = LocalExecutor().run(real_graph(tmp_path / "local"))
    assert len(local.executed) == 4
    assert start_ray(num_cpus=2)  # the test's instance; the executor joins it and leaves it running
    import ray

    try:
        assert os.environ["RAY_USAGE_STATS_ENABLED"] == "0"
        assert ray.util.get_node_ip_address() == "127.0.0.1"
        assert ray.get_runtime_context().gcs_address.startswith("127.0.0.1:")
        on_ray = RayExecutor().run(real_graph(tmp_path / "ray"))
        assert len(on_ray.executed) == 4
        rerun = RayExecutor().run(real_graph(tmp_path / "ray"))
        assert rerun.executed == () and len(rerun.skipped) == 4
    finally:
        ray.shutdown()
    # the same training and the same episodes, cell by cell
    assert path_lengths(tmp_path / "ray") == path_lengths(tmp_path / "local")
    assert all(length > 0 for lengths in path_lengths(tmp_path / "local").values() for length in lengths)
