"""`--segmenter sim|open-vocab`: evaluation and `run` get their segmenter from perception.factory.build_segmenter."""

from __future__ import annotations

import json
from dataclasses import asdict

import pytest
from typer.testing import CliRunner

from lano3dp.cli import app
from lano3dp.evaluate import EpisodeRunner, EvalConfig, PerceptionSettings, RunConfig, run_instruction
from lano3dp.perception import SimOracleSegmenter, factory
from lano3dp.pipeline import cached_eval
from test_public_api import write_tiny_packaged_policy


class CountingSegmenter:
    """A test-local segmenter: the simulator's masks, counting the phrases it was asked for."""

    def __init__(self):
        self.inner, self.phrases = SimOracleSegmenter(), []

    def segment(self, frame, phrases):
        self.phrases += list(phrases)
        return self.inner.segment(frame, phrases)

    def segment_instances(self, frame, phrase):
        self.phrases.append(phrase)
        return self.inner.segment_instances(frame, phrase)

    def reset(self):
        self.inner.reset()


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    return write_tiny_packaged_policy(tmp_path_factory.mktemp("segmenter"))


@pytest.fixture
def built(monkeypatch):
    """Replace the factory's build_segmenter: record each SegmenterConfig, hand out a CountingSegmenter."""
    configs, segmenters = [], []

    def build(config):
        configs.append(config)
        segmenters.append(CountingSegmenter())
        return segmenters[-1]

    monkeypatch.setattr(factory, "build_segmenter", build)
    return configs, segmenters


def test_evaluation_segments_with_what_the_factory_builds_for_open_vocab(checkpoint, built, tmp_path):
    configs, segmenters = built
    perception = PerceptionSettings(segmenter="open-vocab", detector="owlv2", detector_dir=tmp_path / "owlv2",
                                    sam_dir=str(tmp_path / "sam"))
    runner = EpisodeRunner(EvalConfig(checkpoint=str(checkpoint), perception=perception, episodes=1, max_steps=2))
    assert [(c.kind, c.detector, c.detector_dir.name, c.sam_dir.name) for c in configs] == \
        [("open_vocab", "owlv2", "owlv2", "sam")]
    assert runner.observer.segmenter is segmenters[0]
    record = runner.run(seed=0)
    assert record["steps"] == 2 and {"block", "drawer"} <= set(segmenters[0].phrases)


def test_the_default_is_the_simulators_ground_truth_through_the_factory(checkpoint, monkeypatch):
    kinds, build = [], factory.build_segmenter
    monkeypatch.setattr(factory, "build_segmenter", lambda config: kinds.append(config.kind) or build(config))
    runner = EpisodeRunner(EvalConfig(checkpoint=str(checkpoint), episodes=1, max_steps=1))
    assert kinds == ["oracle"] and isinstance(runner.observer.segmenter, SimOracleSegmenter)


def test_run_perceives_targets_and_obstacles_with_the_chosen_segmenter(checkpoint, built, tmp_path):
    configs, segmenters = built
    run_instruction(RunConfig("put the block in the drawer and keep clear of the mug", checkpoint=str(checkpoint),
                              perception={"segmenter": "open-vocab", "detector_dir": str(tmp_path),
                                          "sam_dir": str(tmp_path)},
                              max_steps=2, out=str(tmp_path / "run")), log=lambda line: None)
    assert [c.kind for c in configs] == ["open_vocab"]
    assert {"block", "drawer", "obstacle_0"} <= set(segmenters[0].phrases)  # the mug's stand-in in the sim


def test_cli_open_vocab_without_weight_folders_is_a_usage_error_naming_both(checkpoint, tmp_path):
    for command in (["eval", "--checkpoint", str(checkpoint), "--out", str(tmp_path / "r.json")],
                    ["run", "put the block in the drawer", "--checkpoint", str(checkpoint)]):
        result = CliRunner().invoke(app, [*command, "--segmenter", "open-vocab"])
        assert result.exit_code == 2 and "--detector-dir and --sam-dir" in result.output


def test_cli_open_vocab_reaches_the_factory_which_refuses_empty_weight_folders(checkpoint, tmp_path):
    (tmp_path / "dino").mkdir(), (tmp_path / "sam").mkdir()
    result = CliRunner().invoke(app, ["eval", "--checkpoint", str(checkpoint), "--episodes", "1",
                                      "--segmenter", "open-vocab", "--detector-dir", str(tmp_path / "dino"),
                                      "--sam-dir", str(tmp_path / "sam"), "--out", str(tmp_path / "r.json")])
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert "GroundingDINO weights" in result.output  # MissingWeightsError from the factory, nothing downloaded


def test_an_unknown_segmenter_is_refused_by_name():
    with pytest.raises(ValueError, match="segmenter must be one of sim, open-vocab, got 'sam'"):
        EvalConfig(checkpoint="x", perception=PerceptionSettings(segmenter="sam"))
    result = CliRunner().invoke(app, ["eval", "--task", "bowl_pour", "--segmenter", "sam"])
    assert result.exit_code == 2 and "'sam' is not one of sim, open-vocab" in result.output


def test_results_cached_before_the_segmenter_option_still_count_as_up_to_date(tmp_path):
    config = EvalConfig(checkpoint="run", task="bowl_pour", episodes=2, out=str(tmp_path / "r.json"))
    old = {"checkpoint": "run", "task": "bowl_pour", "variation": "clean", "episodes": 2, "seed": 1_000_000,
           "obstacles": None, "guidance": "none", "rho": 0.04, "last_steps": 100, "per_train_step": False,
           "metric_gradient": True, "densify": 4, "scheduler": None, "steps": None, "checked": False, "margin": 0.02,
           "held_radius": None, "n_action_steps": None, "max_steps": None, "image_size": None, "workers": 1,
           "video_dir": None, "n_videos": 2, "out": config.out, "body": "swept"}  # flat, as saved then
    (tmp_path / "r.json").write_text(json.dumps({"config": old, "summary": {"episodes": 2}}))
    assert cached_eval(config) == {"config": old, "summary": {"episodes": 2}}
    other = EvalConfig(checkpoint="run", task="bowl_pour", episodes=2, out=str(tmp_path / "r.json"),
                       perception=PerceptionSettings(segmenter="open-vocab", detector_dir="d", sam_dir="s"))
    assert cached_eval(other) is None  # made with the simulator's masks, not open-vocab: re-run


def test_results_older_than_the_checkpoint_weights_are_not_reused(tmp_path):
    """A policy re-written in place (a re-packaged task keeps its folder) must be evaluated again."""
    import os

    checkpoint = tmp_path / "policy"
    checkpoint.mkdir()
    (checkpoint / "config.json").write_text("{}")
    (checkpoint / "model.safetensors").write_bytes(b"old weights")
    config = EvalConfig(checkpoint=str(checkpoint), task="bowl_pour", episodes=2, out=str(tmp_path / "r.json"))
    saved = {"config": json.loads(json.dumps(asdict(config))), "summary": {"episodes": 2}}
    (tmp_path / "r.json").write_text(json.dumps(saved))
    os.utime(checkpoint / "model.safetensors", (1_000_000, 1_000_000))
    assert cached_eval(config) == saved
    os.utime(checkpoint / "model.safetensors")  # written again now, after the results
    os.utime(tmp_path / "r.json", (1_000_000, 1_000_000))
    assert cached_eval(config) is None
