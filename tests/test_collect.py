"""`collect` writes a readable dataset of successful expert episodes and resumes without duplicates."""

import numpy as np
from typer.testing import CliRunner

from lano3dp.cli import app
from lano3dp.collect import collect
from lano3dp.data import EpisodeStore


def test_collect_writes_the_documented_keys_and_resumes(tmp_path):
    out = tmp_path / "bottle.zarr"
    first = collect("bottle_upright", 2, out, image_size=64, n_points=64, progress=False)
    assert (first.added, first.total) == (2, 2)
    store = EpisodeStore.open(out)
    attrs = store.attrs
    assert attrs["task"] == "bottle_upright" and attrs["skill"] == "bottle_upright"
    assert attrs["object_names"] == ["bottle"] and attrs["n_points"] == 64 and attrs["variation"] == "clean"
    assert attrs["control_hz"] == 10.0 and attrs["camera"]["width"] == 64
    assert attrs["episode_seeds"] == [0, 1]
    episode = store.get_episode(0)
    length = len(episode["action"])
    assert 30 < length < 150
    assert episode["action"].shape == (length, 10) and episode["state"].shape == (length, 11)
    assert episode["object_clouds"].shape == (length, 1, 64, 3)
    assert episode["scene_cloud"].shape == (length, 512, 3)
    assert episode["rgb"].shape == (length, 96, 96, 3) and episode["rgb"].dtype == np.uint8
    # The bottle cloud sits on the bottle at the start (lying: centre 2.5 cm above the table).
    assert abs(episode["object_clouds"][0, 0, :, 2].mean() - 0.025) < 0.02
    assert np.all(episode["scene_cloud"][:, :, 2] > 0.0)  # table removed

    # Resume: asking for 3 appends exactly one episode, seeded 2.
    result = CliRunner().invoke(app, ["collect", "--task", "bottle_upright", "--episodes", "3", "--out", str(out),
                                      "--image-size", "64", "--n-points", "64", "--no-progress"])
    assert result.exit_code == 0, result.output
    assert "added 1 episodes" in result.output
    store = EpisodeStore.open(out)
    assert store.n_episodes == 3 and store.attrs["episode_seeds"] == [0, 1, 2]
    np.testing.assert_array_equal(store.get_episode(0)["action"], episode["action"])


def test_failed_expert_episodes_are_never_stored(tmp_path):
    import pytest

    from lano3dp.collect import MAX_TRIES, CollectionError

    out = tmp_path / "short.zarr"
    # 5 steps are far too few for the expert: every seed fails, nothing is written.
    with pytest.raises(CollectionError, match=f"failed on {MAX_TRIES} seeds"):
        collect("bottle_upright", 1, out, image_size=32, n_points=32, progress=False, max_steps=5)
    assert not out.exists()  # a first collection that stored nothing leaves no store to block the re-run


def test_similar_scenes_record_the_colour_named_target(tmp_path):
    out = tmp_path / "similar.zarr"
    collect("bottle_upright", 1, out, variation="similar", image_size=64, n_points=32, progress=False)
    store = EpisodeStore.open(out)
    assert store.attrs["variation"] == "similar" and store.attrs["object_names"] == ["bottle"]
    clouds = store.get_episode(0)["object_clouds"]
    # The lying green target is 2.5 cm above the table; the standing look-alikes would average ~6 cm.
    assert abs(clouds[0, 0, :, 2].mean() - 0.025) < 0.015


def test_noise_injection_moves_the_robot_off_the_expert_path_but_records_the_expert(tmp_path):
    """DART: the states leave the expert's path by centimetres, every label is the expert's own action, and
    the hand is left alone at the grasp and the release."""
    from lano3dp.collect import DartNoise
    from lano3dp.sim import TabletopEnv

    out = tmp_path / "dart.zarr"
    collect("put_item_in_drawer", 1, out, image_size=64, n_points=16, dart_noise=0.03, progress=False)
    store = EpisodeStore.open(out)
    episode, seed = store.get_episode(0), store.attrs["episode_seeds"][0]
    assert store.attrs["dart_noise"] == 0.03
    env = TabletopEnv("put_item_in_drawer", image_size=64)
    try:
        env.reset(seed=seed)
        expert = env.expert_plan().actions()
    finally:
        env.close()
    length = len(episode["action"])
    np.testing.assert_allclose(episode["action"], expert[:length], atol=1e-6)  # labels: the expert's
    reached = episode["state"][1:, :3] - episode["action"][:-1, :3]
    assert np.abs(reached).max() > 0.02  # the executed positions were not

    weights = DartNoise(0.03, seed, expert).weights
    changes = np.flatnonzero(np.abs(np.diff(expert[:, 9])) > 1e-3)
    assert len(changes) >= 2  # a grasp and a release
    for change in changes:
        assert weights[max(change - DartNoise.QUIET_STEPS, 0): change + DartNoise.QUIET_STEPS + 1].max() == 0.0
    assert weights.max() == 1.0
    with __import__("pytest").raises(ValueError, match="dart_noise"):
        collect("put_item_in_drawer", 1, tmp_path / "bad.zarr", dart_noise=0.5, progress=False)


def test_episodes_go_on_past_the_first_success_while_it_holds(tmp_path):
    """The cap counts as off 3 cm up the neck; the expert pulls 5 cm. Cut at the first success frame, the data
    would end at 3 cm and teach a policy to stop there; with follow-through it shows the rest of the pull."""
    import pytest

    from lano3dp.collect import CollectionError
    from lano3dp.sim import TabletopEnv

    cut = collect("open_wine_bottle", 1, tmp_path / "cut.zarr", image_size=32, n_points=16, progress=False,
                  follow_through_s=0.0)
    full = collect("open_wine_bottle", 1, tmp_path / "full.zarr", image_size=32, n_points=16, progress=False)
    cut_actions = EpisodeStore.open(cut.path).get_episode(0)["action"]
    full_actions = EpisodeStore.open(full.path).get_episode(0)["action"]
    assert EpisodeStore.open(full.path).attrs["follow_through_s"] == 1.0
    assert len(full_actions) == len(cut_actions) + 10  # 1 s at 10 Hz
    np.testing.assert_array_equal(full_actions[:len(cut_actions)], cut_actions)
    assert full_actions[-1, 2] > cut_actions[-1, 2] + 0.01  # it pulled on
    # replaying the recorded actions ends in success: the tail kept only steps where success held
    env = TabletopEnv("open_wine_bottle", image_size=32)
    env.reset(seed=EpisodeStore.open(full.path).attrs["episode_seeds"][0])
    for action in full_actions:
        info = env.step(action)[-1]
    assert info["success"]
    env.close()
    with pytest.raises(CollectionError, match="follow_through_s=0.0"):  # a store made without it is not mixed
        collect("open_wine_bottle", 2, tmp_path / "cut.zarr", image_size=32, n_points=16, progress=False)
