"""A full disk under every writer: the command fails in one line naming the file and the cause, no temporary file
is left, and what was there before is unchanged.

The disk is made full for one file by pointing the writer's temporary file at /dev/full (ffmpeg, Python's own
writes), or, where a library picks its own temporary name (safetensors, zarr), by a patched writer that fails
with the error that library raises on a full disk.
"""

from __future__ import annotations

import errno
import json
import os

import numpy as np
import pytest
from typer.testing import CliRunner

from faults_common import EXAMPLE_ENV, assert_one_line, full_disk_under
from lano3dp.cli import app
from lano3dp.errors import StorageError
from lano3dp.jsonio import write_json

NO_SPACE = "No space left on device"


def test_a_video_on_a_full_disk_is_one_line_and_keeps_the_old_video(tmp_path):
    """`lano3dp video` used to exit 0 with success=True over a 96-byte file (ffmpeg could not write its trailer)."""
    out = tmp_path / "expert.mp4"
    out.write_bytes(b"an older video")
    full_disk_under(tmp_path / f".expert.tmp-{os.getpid()}.mp4")
    result = CliRunner().invoke(app, ["video", "--task", "open_drawer", "--out", str(out), "--image-size", "32"])
    assert_one_line(result, 1, f"cannot write {out}: ffmpeg exited with status", NO_SPACE)
    assert out.read_bytes() == b"an older video"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["expert.mp4"]  # no temporary left, nor its link


def test_a_gif_on_a_full_disk_is_refused_and_leaves_nothing(tmp_path):
    from lano3dp.video import write_video

    out = tmp_path / "episode.gif"
    full_disk_under(tmp_path / f".episode.tmp-{os.getpid()}.gif")
    with pytest.raises(StorageError, match=f"cannot write {out}: {NO_SPACE}"):
        write_video(out, [np.full((8, 8, 3), value, np.uint8) for value in (0, 255)])
    assert list(tmp_path.iterdir()) == []


def test_a_results_json_on_a_full_disk_keeps_the_old_file_and_leaves_no_tmp(tmp_path):
    """A full disk during `run` left a .tmp file beside run.json."""
    path = tmp_path / "run.json"
    write_json(path, {"episodes": 1})
    before = path.read_bytes()
    full_disk_under(tmp_path / "run.json.tmp")
    with pytest.raises(StorageError, match=f"cannot write {path}: {NO_SPACE}"):
        write_json(path, {"episodes": 2})
    assert path.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["run.json"]


def test_a_figure_on_a_full_disk_keeps_the_old_one(tmp_path):
    from lano3dp.report import plot_rates

    path = tmp_path / "rates.png"
    summary = {"success_rate": 0.5, "collision_rate": 0.1, "safe_success_rate": 0.4}
    plot_rates(path, [("clean", summary)])
    before = path.read_bytes()
    full_disk_under(tmp_path / f".rates.tmp-{os.getpid()}.png")
    with pytest.raises(StorageError, match=f"cannot write {path}: {NO_SPACE}"):
        plot_rates(path, [("clean", summary), ("obstacle", summary)])
    assert path.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["rates.png"]


def safetensors_full_disk(monkeypatch, *, after: int) -> list[str]:
    """safetensors' save_file fails as it does on a full disk (SafetensorError, not an OSError) from its
    `after`+1-th call on; returns the paths it was asked to write."""
    import safetensors.torch
    from safetensors import SafetensorError

    real, calls = safetensors.torch.save_file, []

    def save_file(tensors, filename, metadata=None):
        calls.append(str(filename))
        if len(calls) > after:
            raise SafetensorError(f"Error while serializing: I/O error: {NO_SPACE} (os error 28) at path "
                                  f"\"{filename}\"")
        return real(tensors, filename, metadata=metadata)

    monkeypatch.setattr(safetensors.torch, "save_file", save_file)
    return calls


def test_a_full_disk_while_training_writes_a_checkpoint_is_one_line_and_the_run_resumes(reach_data, tmp_path,
                                                                                       monkeypatch):
    """The safetensors error went straight through the CLI's boundary as a traceback."""
    run = tmp_path / "run"
    args = ["train", "--data", str(reach_data), "--out", str(run), "--steps", "4", "--ckpt-every", "2",
            "--batch-size", "4", "--val-ratio", "0", "--warmup-steps", "1", "--no-progress"]
    calls = safetensors_full_disk(monkeypatch, after=2)  # step 2's policy and training state, then the disk fills
    result = CliRunner().invoke(app, args)
    assert_one_line(result, 1, f"cannot write {run / 'checkpoints' / 'step_0000004' / 'model.safetensors'}: "
                               f"{NO_SPACE}")
    assert len(calls) == 3
    checkpoints = run / "checkpoints"
    assert sorted(p.name for p in checkpoints.iterdir()) == ["last", "step_0000002"]  # nothing half-written
    assert (checkpoints / "last").resolve().name == "step_0000002"
    monkeypatch.undo()  # space again: the run resumes from step 2 and finishes
    resumed = CliRunner().invoke(app, args)
    assert resumed.exit_code == 0, resumed.output
    assert (checkpoints / "last").resolve().name == "step_0000004"


def test_a_full_disk_while_collecting_keeps_every_complete_episode_and_resumes_to_the_same_data(tmp_path,
                                                                                            monkeypatch):
    from lano3dp.collect import collect_from_env
    from lano3dp.data.store import EpisodeStore

    expert = tmp_path / "experts.py"
    expert.write_text(REACH_EXPERT)
    options = dict(slots=["block"], image_size=48, follow_through_s=0.0, progress=False)
    env, reach = f"{EXAMPLE_ENV}:make_env", f"{expert}:reach"
    collect_from_env(env, reach, 1, tmp_path / "d.zarr", **options)
    first = EpisodeStore.open(tmp_path / "d.zarr").get_episode(0)

    real = EpisodeStore._write_rows

    def write_rows_then_fill(self, episode, existing, start, length):  # one key's chunks land, then ENOSPC
        first = dict(list(episode.items())[:1])
        real(self, first, existing, start, length)
        raise OSError(errno.ENOSPC, NO_SPACE, str(self.path / "data" / "state" / "c" / "1" / "0"))

    monkeypatch.setattr(EpisodeStore, "_write_rows", write_rows_then_fill)
    with pytest.raises(StorageError, match=rf"cannot write {tmp_path / 'd.zarr'}: adding episode 1 failed "
                                           rf"\({NO_SPACE}\); the dataset still holds its 1 complete episodes"):
        collect_from_env(env, reach, 3, tmp_path / "d.zarr", **options)
    store = EpisodeStore.open(tmp_path / "d.zarr")
    assert store.n_episodes == 1 and all(np.array_equal(store.get_episode(0)[k], v) for k, v in first.items())
    monkeypatch.undo()
    collect_from_env(env, reach, 3, tmp_path / "d.zarr", **options)
    collect_from_env(env, reach, 3, tmp_path / "unbroken.zarr", **options)
    resumed, unbroken = EpisodeStore.open(tmp_path / "d.zarr"), EpisodeStore.open(tmp_path / "unbroken.zarr")
    for index in range(3):
        for key, value in unbroken.get_episode(index).items():
            np.testing.assert_array_equal(resumed.get_episode(index)[key], value)


REACH_EXPERT = '''
import numpy as np

ROT6D = np.array([1, 0, 0, 0, 1, 0], np.float32)


def reach(env, obs, info):
    """Straight to 2 cm above the block's top: the example env's task."""
    block = env.scene.boxes[0]
    return np.r_[block.center_xy, block.size[2] + 0.02, ROT6D, 0.0].astype(np.float32)
'''


def test_a_results_file_that_a_full_disk_left_empty_is_named_when_read(tmp_path):
    from lano3dp.errors import CorruptFileError
    from lano3dp.jsonio import read_json

    (tmp_path / "train_config.json").write_text("")
    with pytest.raises(CorruptFileError, match=rf"{tmp_path / 'train_config.json'}: the file is empty"):
        read_json(tmp_path / "train_config.json")
    (tmp_path / "train_config.json").write_text('{"steps": 3')
    with pytest.raises(CorruptFileError, match="train_config.json: not valid JSON"):
        read_json(tmp_path / "train_config.json")
    assert json.loads(write_json(tmp_path / "ok.json", {"a": 1}).read_text()) == {"a": 1}
