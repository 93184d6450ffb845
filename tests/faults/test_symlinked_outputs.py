"""Output folders reached through symlinks are judged where they are: written into the link's target, locked as
one output however they are spelled, and refused when the target lies inside another dataset."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from faults_common import EXAMPLE_ENV, assert_one_line
from lano3dp.cli import app
from lano3dp.data import EpisodeStore
from lano3dp.locking import LockedError, WriteLock, lock_path
from test_kill_resume import SLOW_EXPERT


def collect_args(tmp_path, out, episodes: int = 1) -> list[str]:
    (tmp_path / "experts.py").write_text(SLOW_EXPERT)
    return ["collect", "--env", f"{EXAMPLE_ENV}:make_env", "--expert", f"{tmp_path / 'experts.py'}:reach",
            "--slots", "block", "--episodes", str(episodes), "--image-size", "48", "--follow-through", "0",
            "--no-progress", "--out", str(out)]


def test_a_dataset_collected_through_a_symlinked_folder_lands_in_its_target_and_resumes_by_either_name(tmp_path):
    (tmp_path / "disk").mkdir()
    (tmp_path / "data").symlink_to(tmp_path / "disk")
    result = CliRunner().invoke(app, collect_args(tmp_path, tmp_path / "data" / "d.zarr"))
    assert result.exit_code == 0, result.output
    assert EpisodeStore.open(tmp_path / "disk" / "d.zarr").n_episodes == 1
    again = CliRunner().invoke(app, collect_args(tmp_path, tmp_path / "disk" / "d.zarr", episodes=2))
    assert again.exit_code == 0 and "added 1 episodes" in again.stdout  # the same dataset, resumed


def test_a_lock_taken_through_a_link_refuses_the_target_and_the_other_way_round(tmp_path):
    (tmp_path / "run").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "run")
    assert lock_path(tmp_path / "link") == lock_path(tmp_path / "run") == tmp_path / "run.lock"
    with WriteLock(tmp_path / "link"):
        with pytest.raises(LockedError, match="is being written by process"):
            WriteLock(tmp_path / "run").acquire()
    with WriteLock(tmp_path / "run" / "r.json"):
        with pytest.raises(LockedError):
            WriteLock(tmp_path / "link" / "r.json").acquire()


def test_a_link_into_another_dataset_is_refused_before_anything_is_written(tmp_path):
    store = EpisodeStore.create(tmp_path / "other.zarr", {"skill": "s"})
    (tmp_path / "shortcut").symlink_to(store.path)
    out = tmp_path / "shortcut" / "nested.zarr"
    result = CliRunner().invoke(app, collect_args(tmp_path, out))
    assert_one_line(result, 2, f"{out} (= {tmp_path / 'other.zarr' / 'nested.zarr'}) is inside the dataset "
                               f"{tmp_path / 'other.zarr'}; give a folder outside it")
    assert sorted(p.name for p in (tmp_path / "other.zarr").iterdir()) == ["data", "meta", "zarr.json"]


def test_a_run_resumed_through_a_symlink_continues_the_same_run(reach_data, tmp_path):
    from lano3dp.train import train
    from test_train import micro_config

    (tmp_path / "runs").mkdir()
    (tmp_path / "latest").symlink_to(tmp_path / "runs")
    train(micro_config(reach_data, tmp_path / "runs" / "a", steps=1, ckpt_every=1, val_ratio=0.0))
    final = train(micro_config(reach_data, tmp_path / "latest" / "a", steps=2, ckpt_every=1, val_ratio=0.0))
    assert final.resolve() == tmp_path / "runs" / "a" / "checkpoints" / "step_0000002"
    assert sorted(p.name for p in (tmp_path / "runs" / "a" / "checkpoints").iterdir()) == \
        ["last", "step_0000001", "step_0000002"]
