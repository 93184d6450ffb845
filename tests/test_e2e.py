"""End to end on the real simulator: collect -> train -> `lano3dp eval` -> results JSON.

Sized for CI on one CPU thread: 2 demonstrations at 64x64, a tiny policy trained 30 steps, one
evaluation episode cut at 24 steps (3 chunks) in a scene with a novel obstacle and guidance on. A
policy trained this little does not solve the task, so success is not asserted; the test checks
that every stage connects and that the JSON holds the documented fields with sane values.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from lano3dp.cli import app
from lano3dp.evaluation.results import SUMMARY_FIELDS

pytestmark = pytest.mark.slow

EPISODE_FIELDS = ("seed", "success", "steps", "collided", "n_collision_steps", "min_clearance", "path_length",
                  "chunk_latency_s", "chunk_tries", "chunk_predicted_clearance", "obstacles", "held_radius", "error")


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    from lano3dp.collect import collect
    from lano3dp.train import TrainConfig, policy_config_for_dataset, train

    root = tmp_path_factory.mktemp("e2e")
    data = root / "bowl_pour.zarr"
    collect("bowl_pour", 2, data, image_size=64, n_points=64, progress=False)
    policy = policy_config_for_dataset(data, down_dims=(32, 64), point_hidden_dims=(32, 64), encoder_out=32,
                                       state_feature_dim=32, diffusion_step_embed_dim=32)
    checkpoint = train(TrainConfig(data=str(data), out=str(root / "run"), policy=policy, steps=30, batch_size=16,
                                   lr=1e-3, warmup_steps=5, val_ratio=0.0, ckpt_every=30, val_every=30,
                                   progress=False))
    return root, checkpoint


def test_eval_cli_writes_results_with_the_documented_fields(trained):
    root, checkpoint = trained
    out = root / "results.json"
    result = CliRunner().invoke(app, [
        "eval", "--checkpoint", str(root / "run"), "--variation", "obstacle", "--episodes", "1", "--max-steps", "24",
        "--guidance-preset", "recommended", "--set", "guidance.sampler.rho=0.5", "--video-dir", str(root / "videos"),
        "--out", str(out)])
    assert result.exit_code == 0, result.output + repr(result.exception)
    data = json.loads(out.read_text())

    provenance = data["provenance"]
    assert provenance["command"].startswith(f"lano3dp eval --checkpoint {root / 'run'} --variation obstacle "
                                            "--episodes 1 ")
    assert "--guidance-preset recommended" in provenance["command"] and "--overwrite" not in provenance["command"]
    assert provenance["behaviour_version"] >= 1 and provenance["versions"]["torch"]
    assert provenance["machine"]["cpu_count"] >= 1 and provenance["config"] == data["config"]
    assert len(provenance["commit"]) == 40 and isinstance(provenance["dirty"], bool)  # a git checkout here
    assert data["schema"] == "lano3dp-results/1" and data["kind"] == "eval"
    assert data["config"]["task"] is None and data["config"]["guidance"] == {
        "preset": "recommended", "overrides": {"sampler.rho": 0.5}}
    assert data["guidance"]["sampler"]["rho"] == 0.5 and data["guidance"]["sampler"]["mode"] == "clean"
    assert data["checkpoint"] == str(checkpoint.resolve())
    assert data["policy"]["object_names"] == ["bowl", "pan"]
    assert set(SUMMARY_FIELDS) <= set(data["summary"])
    assert data["summary"]["episodes"] == 1
    (episode,) = data["episodes"]
    assert set(EPISODE_FIELDS) <= set(episode)
    assert episode["error"] is None
    assert episode["seed"] == 1_000_000
    assert episode["steps"] == 24 or episode["success"]
    assert len(episode["chunk_latency_s"]) == 3  # 8 actions per chunk
    assert all(0 < t < 30 for t in episode["chunk_latency_s"])
    path = np.asarray(episode["ee_path"])
    assert path.shape == (episode["steps"] + 1, 3)
    assert episode["path_length"] == pytest.approx(np.linalg.norm(np.diff(path, axis=0), axis=1).sum(), rel=1e-4)
    # the scene's obstacle was segmented and fitted: a cylinder of a few cm, bare (the swept body carries the
    # hand and held object, reaching at least the hand's half span from the EE)
    (obstacle,) = episode["obstacles"]
    assert obstacle["shape"] == "Cylinder" and 0.01 < obstacle["radius"] < 0.08
    assert obstacle["safety_distance"] == pytest.approx(obstacle["radius"] + 0.02, abs=1e-4)
    assert episode["held_radius"] >= 0.065 - 1e-6
    assert episode["min_clearance"] is not None and np.isfinite(episode["min_clearance"])
    assert episode["collided"] == (episode["n_collision_steps"] > 0)
    assert all(c is not None for c in episode["chunk_predicted_clearance"])
    assert (root / "videos" / "episode_1000000.mp4").stat().st_size > 1000


def test_run_cli_plans_acts_and_writes_video_and_top_view(trained):
    root, _ = trained
    out = root / "run_out"
    result = CliRunner().invoke(app, [
        "run", "pour the bowl into the pan and keep clear of the mug", "--checkpoint", str(root / "run"),
        "--max-steps", "16", "--scenes", "2", "--compare", "--out", str(out)])
    assert result.exit_code == 0, result.output + repr(result.exception)
    assert "plan: bowl_pour(bowl, pan); avoid mug" in result.output
    assert "guided over 2 scene(s): success" in result.output and "unguided over 2 scene(s)" in result.output
    record = json.loads((out / "run.json").read_text())
    assert record["plan"]["skill"] == "bowl_pour" and record["variation"] == "obstacle"
    # the simulator has no mug: its obstacle stands in, and the user is told so
    assert [scene["obstacles"] for scene in record["scenes"]] == [["obstacle_0"]] * 2
    assert any("'mug' not in the simulated scene" in note for note in record["notes"])
    assert set(record["episodes"]) == {"guided", "unguided"} and set(record["summary"]) == {"guided", "unguided"}
    for name, episodes in record["episodes"].items():
        assert [e["seed"] for e in episodes] == [scene["seed"] for scene in record["scenes"]]
        for episode in episodes:
            assert episode["steps"] == 16 or episode["success"], name
            assert set(episode["targets"]) == {"bowl", "pan"}
        assert (out / f"video_{name}.mp4").stat().st_size > 1000  # the first scene's
        assert record["summary"][name]["episodes"] == 2
    assert (out / "top_view.png").read_bytes()[:4] == b"\x89PNG"


def test_a_training_budget_stops_the_run_checkpointed_and_a_rerun_skips_it(trained):
    from lano3dp.pipeline import train_stage
    from lano3dp.policy import DiffusionPolicy
    from lano3dp.train import policy_config_for_dataset

    root, _ = trained
    data = root / "bowl_pour.zarr"
    policy = policy_config_for_dataset(data, down_dims=(32, 64), point_hidden_dims=(32,), encoder_out=16,
                                       state_feature_dim=16, diffusion_step_embed_dim=16)
    run = root / "budget_run"
    # a CPU budget of ~0 s: the planned steps (at least 50) are cut after the first one, which is checkpointed
    final = train_stage(data, run, policy_config=policy, minutes=1e-6, batch_size=8, progress=False, val_ratio=0.0)
    assert final.name == "step_0000001"
    assert DiffusionPolicy.from_pretrained(run).config.down_dims == (32, 64)
    saved = json.loads((run / "train_config.json").read_text())
    assert saved["steps"] >= 50 and saved["extra"]["stopped_by_budget_at"] == 1 and saved["cpu_minutes"] == 1e-6
    messages = []
    assert train_stage(data, run, policy_config=policy, minutes=1e-6, batch_size=8, log=messages.append) == final
    assert messages == [f"train: {run} is complete (1 steps); skipping"]


def test_the_training_budget_counts_cpu_time_so_a_sleeping_machine_does_not_shorten_it(trained, monkeypatch):
    """Wall time spent off the CPU (another job holding the core, here a sleep) does not count."""
    import time as time_module

    from lano3dp.train import TrainConfig, Trainer, policy_config_for_dataset

    root, _ = trained
    data = root / "bowl_pour.zarr"
    policy = policy_config_for_dataset(data, down_dims=(32, 64), point_hidden_dims=(32,), encoder_out=16,
                                       state_feature_dim=16, diffusion_step_embed_dim=16)
    config = TrainConfig(data=str(data), out=str(root / "cpu_budget_run"), policy=policy, steps=6, batch_size=8,
                         val_ratio=0.0, progress=False, cpu_minutes=1.5 / 60, warmup_steps=1)
    trainer = Trainer(config)
    subsample = trainer._subsample

    def slow_batch(*args, **kwargs):
        time_module.sleep(0.5)  # 3 s of wall time in all, twice the budget, but no CPU
        return subsample(*args, **kwargs)

    monkeypatch.setattr(trainer, "_subsample", slow_batch)
    trainer.run()
    assert trainer.step == 6 and not trainer.stopped_by_budget
    assert trainer.cpu_seconds < 1.5
