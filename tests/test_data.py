"""Episode store (zarr) and the windowed sequence sampler."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from lano3dp.data import EpisodeStore, SequenceDataset, split_episodes
from lano3dp.data.sequence import window_indices
from lano3dp.data.store import DatasetSchemaError, ZarrVersionError
from lano3dp.errors import CorruptFileError


def make_episode(index: int, length: int) -> dict:
    """Values encode (episode, step) so any mix-up is visible."""
    steps = np.arange(length, dtype=np.float32)
    return {
        "action": np.stack([np.full(length, index, np.float32), steps], -1),
        "object_clouds": np.full((length, 2, 8, 3), index, np.float32),
    }


def test_episodes_round_trip_with_attributes(tmp_path):
    store = EpisodeStore.create(tmp_path / "d.zarr", {"skill": "bowl_pour", "object_names": ["bowl", "pan"]})
    for index, length in enumerate([3, 5, 4]):
        store.append_episode(make_episode(index, length))
    reopened = EpisodeStore.open(tmp_path / "d.zarr")
    assert reopened.n_episodes == 3 and reopened.n_steps == 12
    assert reopened.episode_ends.tolist() == [3, 8, 12]
    assert reopened.attrs["object_names"] == ["bowl", "pan"]
    assert "zarr" in reopened.attrs["versions"]
    episode = reopened.get_episode(1)
    assert np.array_equal(episode["action"], make_episode(1, 5)["action"])
    assert episode["object_clouds"].shape == (5, 2, 8, 3)


def test_inconsistent_episodes_are_rejected(tmp_path):
    store = EpisodeStore.create(tmp_path / "d.zarr")
    store.append_episode(make_episode(0, 3))
    with pytest.raises(DatasetSchemaError, match="keys"):
        store.append_episode({"action": np.zeros((3, 2), np.float32)})
    bad = make_episode(1, 3)
    bad["object_clouds"] = np.zeros((3, 3, 8, 3), np.float32)
    with pytest.raises(DatasetSchemaError, match="per-step shape"):
        store.append_episode(bad)
    bad = make_episode(1, 3)
    bad["action"] = bad["action"][:2]
    with pytest.raises(DatasetSchemaError, match="share"):
        store.append_episode(bad)
    assert EpisodeStore.open(tmp_path / "d.zarr").n_episodes == 1


def test_open_or_create_refuses_a_different_skill(tmp_path):
    EpisodeStore.create(tmp_path / "d.zarr", {"skill": "bowl_pour", "object_names": ["bowl", "pan"]})
    with pytest.raises(DatasetSchemaError, match="skill"):
        EpisodeStore.open_or_create(tmp_path / "d.zarr", {"skill": "open_drawer"})


_WRITER = """
import sys, numpy as np
from lano3dp.data import EpisodeStore
store = EpisodeStore.open_or_create(sys.argv[1], {"skill": "s"})
index = store.n_episodes
while True:
    length = 400
    steps = np.arange(length, dtype=np.float32)
    store.append_episode({"action": np.stack([np.full(length, index, np.float32), steps], -1),
                          "object_clouds": np.full((length, 4, 256, 3), index, np.float32)})
    print(index, flush=True)
    index += 1
"""


def test_a_writer_killed_mid_append_leaves_earlier_episodes_readable(tmp_path):
    path = tmp_path / "d.zarr"
    writer = subprocess.Popen([sys.executable, "-c", _WRITER, str(path)], stdout=subprocess.PIPE, text=True)
    try:
        for _ in range(3):  # let three episodes commit, then kill during a later append
            assert writer.stdout.readline(), "writer died early"
        time.sleep(0.05)
        writer.send_signal(signal.SIGKILL)
    finally:
        writer.wait(timeout=30)
    store = EpisodeStore.open(path, mode="r+")
    assert store.n_episodes >= 3
    for index in range(store.n_episodes):
        action = store.get_episode(index)["action"]
        assert action.shape == (400, 2) and np.all(action[:, 0] == index)
    committed = store.n_episodes
    store.append_episode({"action": np.zeros((2, 2), np.float32),
                          "object_clouds": np.zeros((2, 4, 256, 3), np.float32)})
    assert EpisodeStore.open(path).n_steps == committed * 400 + 2


def test_an_end_entry_grown_but_never_written_is_not_an_episode(tmp_path):
    """The torn state a kill between growing meta/episode_ends and writing its value leaves."""
    import zarr

    path = tmp_path / "d.zarr"
    store = EpisodeStore.create(path)
    store.append_episode(make_episode(0, 3))
    zarr.open_group(str(path), mode="r+")["meta/episode_ends"].resize((2,))
    store = EpisodeStore.open(path, mode="r+")
    assert store.n_episodes == 1 and store.n_steps == 3
    store.append_episode(make_episode(1, 4))
    assert EpisodeStore.open(path).episode_ends.tolist() == [3, 7]


def test_a_damaged_store_names_the_file(tmp_path):
    path = tmp_path / "d.zarr"
    store = EpisodeStore.create(path)
    store.append_episode(make_episode(0, 3))
    (path / "zarr.json").write_text("{ not json")
    with pytest.raises(CorruptFileError, match="d.zarr"):
        EpisodeStore.open(path)
    other = tmp_path / "e.zarr"
    EpisodeStore.create(other).append_episode(make_episode(0, 3))
    ends = other / "meta" / "episode_ends" / "zarr.json"
    meta = json.loads(ends.read_text())
    meta["shape"] = [5]  # claims episodes whose data is missing
    ends.write_text(json.dumps(meta))
    with pytest.raises(CorruptFileError, match="e.zarr"):
        EpisodeStore.open(other)
    with pytest.raises(FileNotFoundError, match="nowhere.zarr"):
        EpisodeStore.open(tmp_path / "nowhere.zarr")


def test_a_zarr_too_old_for_the_store_is_refused_before_a_file_is_written(tmp_path, monkeypatch):
    import zarr

    EpisodeStore.create(tmp_path / "old.zarr").append_episode(make_episode(0, 3))
    monkeypatch.setattr(zarr, "__version__", "2.18.7")
    with pytest.raises(ZarrVersionError, match=r"new.zarr: episode stores need zarr >= 3\.0\.8, but zarr 2\.18\.7 is "
                                               r"installed; pip install 'zarr>=3\.0\.8'"):
        EpisodeStore.open_or_create(tmp_path / "new.zarr", {"skill": "reach"})
    assert not (tmp_path / "new.zarr").exists()  # nothing left behind to be called corrupt later
    with pytest.raises(ZarrVersionError, match="old.zarr: episode stores need zarr"):
        EpisodeStore.open(tmp_path / "old.zarr")


def test_windows_are_edge_padded_like_diffusion_policy(tmp_path):
    store = EpisodeStore.create(tmp_path / "d.zarr")
    store.append_episode(make_episode(0, 6))
    store.append_episode(make_episode(1, 4))
    dataset = SequenceDataset(store, ["object_clouds"], n_obs_steps=2, horizon=4, n_action_steps=2)
    # Starts from -(To-1) to length - horizon + (Ta-1): 6 - 4 + 1 + 1 + 1 = 5 windows, then 3.
    assert len(dataset) == 5 + 3
    first = dataset[0]
    assert first["action"][:, 1].tolist() == [0, 0, 1, 2]  # step 0 repeated before the episode
    assert first["obs"]["object_clouds"].shape == (2, 2, 8, 3)
    last_of_first_episode = dataset[4]
    assert last_of_first_episode["action"][:, 1].tolist() == [3, 4, 5, 5]  # last step repeated after it
    assert np.all(dataset[5]["action"][:, 0] == 1)  # windows never mix episodes


def test_window_index_count_matches_the_formula():
    ends = np.array([10, 25])
    rows = window_indices(ends, [0, 1], horizon=16, pad_before=1, pad_after=7)
    assert len(rows) == (10 - 16 + 7 + 1 + 1) + (15 - 16 + 7 + 1 + 1)


def test_split_keeps_episodes_whole_and_disjoint():
    train, val = split_episodes(20, 0.1, seed=0)
    assert len(val) == 2 and len(train) == 18
    assert set(train).isdisjoint(val) and set(train) | set(val) == set(range(20))
    train, val = split_episodes(3, 0.01)
    assert len(val) == 1  # a requested validation split is never empty
    assert split_episodes(5, 0.0)[1].size == 0


def test_dataset_restricted_to_episodes_sees_only_them(tmp_path):
    store = EpisodeStore.create(tmp_path / "d.zarr")
    for index in range(4):
        store.append_episode(make_episode(index, 5))
    dataset = SequenceDataset(store, ["object_clouds"], n_obs_steps=2, horizon=4, n_action_steps=2, episodes=[1, 3])
    seen = {int(dataset[i]["action"][0, 0]) for i in range(len(dataset))}
    assert seen == {1, 3}
    assert dataset.all_actions().shape == (10, 2)


def test_store_path_errors_are_explicit(tmp_path):
    os.makedirs(tmp_path / "plain")
    with pytest.raises(CorruptFileError, match="plain"):
        EpisodeStore.open(Path(tmp_path / "plain"))
