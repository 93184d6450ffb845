"""`--segmenter sim|open-vocab`: evaluation and `run` get their segmenter from perception.factory.build_segmenter."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from lano3dp.cli import app
from lano3dp.evaluation import EvalConfig, PerceptionSettings, RunConfig, run_instruction
from lano3dp.evaluation.episodes import EpisodeRunner
from lano3dp.guidance.settings import guidance_preset
from lano3dp.perception import SimOracleSegmenter, factory
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
    runner = EpisodeRunner(EvalConfig(checkpoint=str(checkpoint), perception=perception, episodes=1, max_steps=2),
                           guidance_preset("none"))
    assert [(c.kind, c.detector, c.detector_dir.name, c.sam_dir.name) for c in configs] == \
        [("open_vocab", "owlv2", "owlv2", "sam")]
    assert runner.runner.observer.segmenter is segmenters[0]
    record = runner.run(seed=0)
    assert record["steps"] == 2 and {"block", "drawer"} <= set(segmenters[0].phrases)


def test_the_default_is_the_simulators_ground_truth_through_the_factory(checkpoint, monkeypatch):
    kinds, build = [], factory.build_segmenter
    monkeypatch.setattr(factory, "build_segmenter", lambda config: kinds.append(config.kind) or build(config))
    runner = EpisodeRunner(EvalConfig(checkpoint=str(checkpoint), episodes=1, max_steps=1), guidance_preset("none"))
    assert kinds == ["oracle"] and isinstance(runner.runner.observer.segmenter, SimOracleSegmenter)


def test_error_model_evaluation_draws_each_episodes_errors_from_its_seed(checkpoint, monkeypatch):
    from lano3dp.perception import ErrorModelSegmenter

    runner = EpisodeRunner(EvalConfig(checkpoint=str(checkpoint), episodes=1, max_steps=1,
                                      perception=PerceptionSettings(segmenter="error-model")), guidance_preset("none"))
    segmenter = runner.runner.observer.segmenter
    assert isinstance(segmenter, ErrorModelSegmenter)
    seeds = []
    start = segmenter.start_episode
    monkeypatch.setattr(segmenter, "start_episode", lambda seed: seeds.append(seed) or start(seed))
    runner.run(seed=17)
    runner.run(seed=18)
    assert seeds == [17, 18] and set(segmenter.groundings) == {"block", "drawer"}


def test_run_perceives_targets_and_obstacles_with_the_chosen_segmenter(checkpoint, built, tmp_path):
    configs, segmenters = built
    run_instruction(RunConfig("put the block in the drawer and keep clear of the mug", checkpoint=str(checkpoint),
                              perception=PerceptionSettings(segmenter="open-vocab", detector_dir=str(tmp_path),
                                                            sam_dir=str(tmp_path)),
                              max_steps=2, out=str(tmp_path / "run")), log=lambda line: None)
    assert [c.kind for c in configs] == ["open_vocab"]
    assert {"block", "drawer", "obstacle_0"} <= set(segmenters[0].phrases)  # the mug's stand-in in the sim


def test_cli_open_vocab_without_weight_folders_is_a_usage_error_naming_both(checkpoint, tmp_path):
    for command in (["eval", "--checkpoint", str(checkpoint), "--out", str(tmp_path / "r.json")],
                    ["run", "put the block in the drawer", "--checkpoint", str(checkpoint)]):
        result = CliRunner().invoke(app, [*command, "--segmenter", "open-vocab"])
        assert result.exit_code == 2 and "set detector_dir and sam_dir" in result.output


def test_cli_open_vocab_reaches_the_factory_which_refuses_empty_weight_folders(checkpoint, tmp_path):
    (tmp_path / "dino").mkdir(), (tmp_path / "sam").mkdir()
    result = CliRunner().invoke(app, ["eval", "--checkpoint", str(checkpoint), "--episodes", "1",
                                      "--segmenter", "open-vocab", "--detector-dir", str(tmp_path / "dino"),
                                      "--sam-dir", str(tmp_path / "sam"), "--out", str(tmp_path / "r.json")])
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert "GroundingDINO weights" in result.output  # MissingWeightsError from the factory, nothing downloaded


def test_an_unknown_segmenter_is_refused_by_name():
    with pytest.raises(ValueError, match="segmenter must be one of sim, error-model, open-vocab, got 'sam'"):
        EvalConfig(checkpoint="x", perception=PerceptionSettings(segmenter="sam"))
    result = CliRunner().invoke(app, ["eval", "--task", "bowl_pour", "--segmenter", "sam"])
    assert result.exit_code == 2 and "segmenter must be one of sim, error-model, open-vocab, got 'sam'" in result.output
