"""Expert episode videos are written as MP4 and GIF with one frame per control step."""

import imageio.v2 as imageio
import numpy as np
import pytest

from lano3dp.sim.video import record_expert_video, write_video


def test_expert_video_mp4(tmp_path):
    summary = record_expert_video("bottle_upright", tmp_path / "episode.mp4", seed=0, image_size=64)
    assert summary["success"]
    frames = imageio.mimread(tmp_path / "episode.mp4", memtest=False)
    assert len(frames) == summary["steps"] + 1 and frames[0].shape == (64, 64, 3)


def test_gif_and_bad_suffix(tmp_path):
    frames = [np.full((8, 8, 3), i * 20, np.uint8) for i in range(5)]
    write_video(tmp_path / "a.gif", frames)
    assert len(imageio.mimread(tmp_path / "a.gif")) == 5
    with pytest.raises(ValueError, match=".avi"):
        write_video(tmp_path / "a.avi", frames)
    with pytest.raises(ValueError, match="no frames"):
        write_video(tmp_path / "b.mp4", [])
