"""An episode recorded for the Rerun viewer holds, on one timeline, what the policy saw and did: read back with
rerun's own .rrd reader."""

import sys

import numpy as np
import pytest

from lano3dp.geometry.camera import PinholeCamera
from lano3dp.recording import EpisodeRecording, RecordingUnavailableError


def rows_by_entity(path) -> dict[str, list]:
    """{entity path: [record batch row as a dict, ...]} of every chunk on the "step" timeline, by step."""
    rr = pytest.importorskip("rerun")
    rows: dict[str, list] = {}
    for chunk in rr.chunk.RrdReader(path).stream().to_chunks():
        if chunk.is_static:
            continue
        assert chunk.timeline_names == ["step"], chunk.entity_path
        rows.setdefault(chunk.entity_path, []).extend(chunk.to_record_batch().to_pylist())
    return {entity: sorted(found, key=lambda row: row["step"]) for entity, found in rows.items()}


def test_a_recording_holds_images_clouds_hand_obstacles_chunks_and_path_on_one_timeline(tmp_path):
    pytest.importorskip("rerun")
    camera = PinholeCamera.from_fovy(32, 24, 50.0, np.eye(4))
    bowl = np.random.default_rng(0).uniform(-0.1, 0.1, (64, 3)).astype(np.float32)
    path = np.linspace([0.3, 0.0, 0.3], [0.5, 0.1, 0.1], 3).astype(np.float32)
    cylinder = {"center": [0.4, 0.0], "radius": 0.03, "safety_distance": 0.07}
    box = {"corners": [[0.0, 0.0], [0.1, 0.0], [0.1, 0.2], [0.0, 0.2]]}
    with EpisodeRecording(tmp_path / "episode.rrd") as recording:
        for step in range(3):
            recording.log_frame(step, np.full((24, 32, 3), step, np.uint8), np.ones((24, 32), np.float32), camera)
            recording.log_clouds(step, {"blue bowl": bowl + step, "pan": bowl[:10]})
            recording.log_hand(step, path[step], body_balls=path[step][None], body_radii=0.04)
            recording.log_obstacles(step, [cylinder, box] if step < 2 else [cylinder], margin=0.02)
            unguided = np.ones((16, 3)) if step == 0 else None
            recording.log_chunk(step, np.zeros((16, 3)), np.zeros((8, 3)) + step, unguided)
        recording.log_path(path)
    rows = rows_by_entity(tmp_path / "episode.rrd")

    for entity in ("/world/camera", "/world/camera/rgb", "/world/camera/depth", "/world/clouds/blue_bowl",
                   "/world/clouds/pan", "/world/hand", "/world/hand/body", "/world/obstacles/0/body",
                   "/world/obstacles/0/safety", "/world/chunk/sampled", "/world/chunk/executed"):
        assert sorted({row["step"] for row in rows[entity]}) == [0, 1, 2], entity
    # the clouds as the policy received them, point for point
    logged = np.array(rows["/world/clouds/blue_bowl"][1]["Points3D:positions"], dtype=np.float32)
    np.testing.assert_allclose(logged, bowl + 1)
    assert len(rows["/world/clouds/pan"][0]["Points3D:positions"]) == 10
    np.testing.assert_allclose(rows["/world/hand"][2]["Points3D:positions"], path[2:3])
    # the cylinder's safety outline is its Q* (7 cm) round the axis, at the table and at the outline height
    rings = [np.array(strip) for strip in rows["/world/obstacles/0/safety"][0]["LineStrips3D:strips"]]
    assert sorted(ring[0, 2] for ring in rings) == pytest.approx([0.0, 0.4])
    np.testing.assert_allclose(np.linalg.norm(rings[0][:, :2] - [0.4, 0.0], axis=1), 0.07, atol=1e-6)
    # the box grows by the 2 cm margin on every side; it is cleared once no longer fitted
    grown = np.array(rows["/world/obstacles/1/safety"][0]["LineStrips3D:strips"][0])[:, :2]
    np.testing.assert_allclose(grown.min(0), [-0.02, -0.02], atol=1e-6)
    np.testing.assert_allclose(grown.max(0), [0.12, 0.22], atol=1e-6)
    assert any(row["step"] == 2 and row.get("Clear:is_recursive") for row in rows["/world/obstacles/1"])
    # the unguided sample only where the runner drew it; the executed path at its last step
    drawn = [row["step"] for row in rows["/world/chunk/before_guidance"] if row.get("LineStrips3D:strips")]
    assert drawn == [0]
    (path_row,) = rows["/world/path"]
    assert path_row["step"] == 2
    np.testing.assert_allclose(path_row["LineStrips3D:strips"][0], path)
    assert [row["step"] for row in rows["/world/camera/rgb"]] == [0, 1, 2]


def test_without_rerun_the_recorder_says_how_to_install_it(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "rerun", None)  # `import rerun` now raises ImportError
    with pytest.raises(RecordingUnavailableError, match=r"install lano3dp\[viewer\]"):
        EpisodeRecording(tmp_path / "episode.rrd")
    assert not (tmp_path / "episode.rrd").exists()


@pytest.mark.slow
def test_eval_records_each_episode_with_frames_target_clouds_obstacles_chunks_and_path(tmp_path):
    pytest.importorskip("rerun")
    from lano3dp.evaluation import EvalConfig, GuidanceChoice, evaluate

    report = evaluate(EvalConfig(task="put_item_in_drawer", variation="obstacle", obstacle_scenes_only=True,
                                 episodes=1, max_steps=12, guidance=GuidanceChoice("tuned"),
                                 rerun_dir=str(tmp_path / "rrd")))
    episode = report["episodes"][0]
    rows = rows_by_entity(episode["rerun"])
    frames = sorted({row["step"] for row in rows["/world/camera/rgb"]})
    assert frames == list(range(episode["steps"] + 1))  # the first frame and one after every step
    assert any(entity.startswith("/world/clouds/") for entity in rows)
    assert "/world/obstacles/0/safety" in rows  # the fitted obstacle with its safety outline
    assert len(rows["/world/chunk/executed"]) == len(episode["chunk_executed"]) >= 2  # every chunk planned
    path = rows["/world/path"][-1]
    assert path["step"] == episode["steps"]
