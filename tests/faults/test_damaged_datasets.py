"""A dataset with a deleted chunk, arrays shorter than its episode index, or NaN rows is refused before training,
in one line naming the key, the episode (and step), and the dataset is left as it was."""

from __future__ import annotations

import numpy as np
import pytest
import zarr
from typer.testing import CliRunner

from faults_common import assert_one_line, tree_digest
from lano3dp.cli import app
from lano3dp.data import EpisodeStore
from lano3dp.data.sequence import NonFiniteDataError
from lano3dp.errors import CorruptFileError
from lano3dp.train import Trainer
from test_train import micro_config, write_reach_store


def train_args(data, out) -> list[str]:
    return ["train", "--data", str(data), "--out", str(out), "--steps", "1", "--batch-size", "4", "--no-progress"]


def test_a_missing_chunk_file_is_refused_naming_key_and_episode(tmp_path):
    data = write_reach_store(tmp_path / "d.zarr", episodes=3)
    (data / "data" / "action" / "c" / "0" / "0").unlink()
    with pytest.raises(CorruptFileError, match=r"d\.zarr: data/action is missing chunk 0/0 \(rows 0-29, episode 0\)"):
        EpisodeStore.open(data)
    before = tree_digest(data)
    result = CliRunner().invoke(app, train_args(data, tmp_path / "run"))
    assert_one_line(result, 1, "data/action is missing chunk 0/0 (rows 0-29, episode 0)")
    assert tree_digest(data) == before and not (tmp_path / "run" / "checkpoints").exists()


def test_arrays_shorter_than_episode_ends_are_refused_naming_the_episode(tmp_path):
    data = write_reach_store(tmp_path / "d.zarr", episodes=3, length=10)
    zarr.open_group(str(data), mode="r+")["data/state"].resize((25, 11))
    with pytest.raises(CorruptFileError, match=r"data/state has 25 rows, but meta/episode_ends says episode 2 ends "
                                               r"at row 30"):
        EpisodeStore.open(data)


def test_an_all_zero_episode_is_stored_and_reads_back(tmp_path):
    store = EpisodeStore.create(tmp_path / "z.zarr")
    store.append_episode({"action": np.zeros((5, 2), np.float32)})  # every chunk is written, even a zero one
    assert EpisodeStore.open(tmp_path / "z.zarr").get_episode(0)["action"].shape == (5, 2)


def test_nan_rows_are_refused_before_training_naming_key_episode_and_step(tmp_path):
    data = write_reach_store(tmp_path / "d.zarr", episodes=4)
    state = zarr.open_group(str(data), mode="r+")["data/state"]
    state[33, 2] = np.nan  # episode 3, step 3: a validation episode with val_ratio 0.25
    before = tree_digest(data)
    with pytest.raises(NonFiniteDataError, match=r"data/state holds NaN or inf in episode 3 \(step 3"):
        Trainer(micro_config(data, tmp_path / "run", val_ratio=0.25))
    result = CliRunner().invoke(app, train_args(data, tmp_path / "run2"))
    assert_one_line(result, 1, "data/state holds NaN or inf in episode 3 (step 3")
    assert tree_digest(data) == before and not (tmp_path / "run" / "checkpoints" / "last").exists()
