"""One settings tree: presets, dotted changes, combinations refused, and the command line and config files on top."""

from __future__ import annotations

import json

import pytest
import yaml
from typer.testing import CliRunner

from lano3dp.cli import app
from lano3dp.config_tree import SettingsError, parse_assignment
from lano3dp.errors import CorruptFileError
from lano3dp.evaluation import EvalConfig, GuidanceChoice, PerceptionSettings, RunConfig, with_assignments
from lano3dp.guidance.settings import (
    GuidanceSettings,
    guidance_preset,
    load_guidance_tuning,
    preset_names,
    register_guidance_preset,
    resolve_guidance,
    save_guidance_tuning,
)

RECOMMENDED = guidance_preset("recommended")


def test_the_dataclass_defaults_are_the_recommended_preset_and_the_presets_say_what_they_are():
    assert RECOMMENDED == GuidanceSettings()
    assert RECOMMENDED.execution.filters == ("repair", "hold", "escape", "follow")
    paper = guidance_preset("paper")  # the paper's Algorithm 1 as published, sampler and body included
    assert (paper.sampler.mode, paper.sampler.rho, paper.sampler.last_steps, paper.sampler.scheduler,
            paper.sampler.steps) == ("clean", 4.0, 10, "ddpm", 100)
    assert (paper.cost.metric_push, paper.cost.densify, paper.cost.anchored) == (False, 1, False)
    assert paper.obstacles.body == "sphere" and paper.execution.filters == ()
    a_k = guidance_preset("a_k")
    assert a_k.sampler.mode == "noisy" and not a_k.cost.anchored and a_k.execution.filters == ()
    assert not guidance_preset("none").guided and guidance_preset("none").execution.filters == ()
    assert set(preset_names()) >= {"none", "a_k", "paper", "recommended", "tuned"}


# each combination that cannot work, and the two settings its one-line refusal must name
INVALID = [
    ("none", {"execution.filters": ["hold"]}, ("execution.filters", "sampler.mode")),
    ("none", {"sampler.strategy": "when_needed"}, ("sampler.strategy", "sampler.mode")),
    ("recommended", {"sampler.rho": 0.0}, ("sampler.rho", "sampler.mode")),
    ("recommended", {"sampler.on_unclear": "stop"}, ("sampler.on_unclear", "sampler.strategy")),
    ("recommended", {"cost.anchored": False, "cost.push_turn": 30.0}, ("cost.push_turn", "cost.anchored")),
    ("recommended", {"execution.filters": ["repair", "escape"]}, ("escape", "hold")),
    ("recommended", {"execution.filters": ["follow", "hold"]}, ("follow", "hold")),
    ("recommended", {"obstacles.held_radius": 0.05}, ("held_radius", "obstacles.body")),
    ("recommended", {"execution.options": {"hold": {"x": 1}}, "execution.filters": ["repair"]},
     ("options", "filters")),
]


@pytest.mark.parametrize(("preset", "changes", "named"), INVALID)
def test_combinations_that_cannot_work_are_refused_naming_both_settings(preset, changes, named):
    with pytest.raises(ValueError) as refused:
        resolve_guidance(preset, changes)
    message = str(refused.value)
    assert "\n" not in message and all(name in message for name in named), message


def test_a_setting_changes_by_its_dotted_path_and_unknown_paths_are_refused_with_the_choices():
    changed = RECOMMENDED.with_changes({"sampler.rho": 0.02, "execution.options.repair.steps": 5})
    assert changed.sampler.rho == 0.02 and changed.execution.options == {"repair": {"steps": 5}}
    assert changed.cost == RECOMMENDED.cost  # nothing else moved
    with pytest.raises(SettingsError, match=r"guidance.sampler.rhoo: no such setting \(here: .*rho"):
        RECOMMENDED.with_changes({"sampler.rhoo": 1})
    with pytest.raises(SettingsError, match="guidance.sampler.rho: Input should be a valid number"):
        RECOMMENDED.with_changes({"sampler.rho": "fast"})
    with pytest.raises(SettingsError, match="repair steps must be >= 1"):
        resolve_guidance("recommended", {"execution.options.repair.steps": 0})
    assert parse_assignment("guidance.execution.filters=[repair, hold]") == \
        ("guidance.execution.filters", ["repair", "hold"])
    assert parse_assignment("max_steps=200") == ("max_steps", 200)
    with pytest.raises(SettingsError, match="section.field=value"):
        parse_assignment("rho 0.02")


def test_a_checkpoints_tuning_is_a_preset_plus_overrides_and_the_users_changes_go_on_top(tmp_path):
    save_guidance_tuning(tmp_path, {"cost.push_turn": 60.0, "obstacles.bridge_gaps": False}, measured="a test")
    tuning = load_guidance_tuning(tmp_path)
    tuned = resolve_guidance("tuned", None, tuning)
    assert tuned.cost.push_turn == 60.0 and not tuned.obstacles.bridge_gaps
    assert tuned.sampler == RECOMMENDED.sampler
    mine = resolve_guidance("tuned", {"cost.push_turn": 0.0}, tuning)
    assert mine.cost.push_turn == 0.0 and not mine.obstacles.bridge_gaps
    assert resolve_guidance("tuned", None, None) == RECOMMENDED  # a policy without one
    assert resolve_guidance("paper", None, tuning) == guidance_preset("paper")  # a named preset is what it says
    (tmp_path / "guidance.json").write_text(json.dumps({"format": "lano3dp-guidance-tuning", "settings": {}}))
    with pytest.raises(CorruptFileError, match="lano3dp migrate"):
        load_guidance_tuning(tmp_path)


def test_a_preset_registered_from_outside_is_named_like_the_built_in_ones(tmp_path):
    cautious = RECOMMENDED.with_changes({"obstacles.margin": 0.04, "sampler.rho": 0.06})
    register_guidance_preset("cautious_test", cautious)
    assert "cautious_test" in preset_names()
    assert EvalConfig(task="bowl_pour", guidance=GuidanceChoice("cautious_test")).guidance.resolve(None) == cautious
    with pytest.raises(SettingsError, match="exists already"):
        register_guidance_preset("cautious_test", RECOMMENDED)
    with pytest.raises(ValueError, match="unknown guidance preset 'fast'"):
        GuidanceChoice("fast")


@pytest.fixture
def captured(monkeypatch):
    """Replace evaluate and run_instruction by recorders of the config the command line built."""
    import lano3dp.evaluation as evaluation

    configs = []

    def record(config, *args, **kwargs):
        configs.append(config)
        return {"summary": {"success_rate": 0.0, "successes": 0, "episodes": 0, "collision_rate": 0.0,
                            "mean_min_clearance": None, "mean_path_length": 0.0, "latency_mean_s": None,
                            "errors": []}, "timing": {"resumed_episodes": 0}, "notes": [], "scenes": [{"seed": 0}]}

    monkeypatch.setattr(evaluation, "evaluate", record)
    monkeypatch.setattr(evaluation, "run_instruction", record)
    return configs


def test_options_and_set_map_onto_the_config_tree(captured, tmp_path):
    runner = CliRunner()
    sets = ["--set", "guidance.sampler.rho=0.02", "--set", "guidance.execution.filters=[repair, hold]",
            "--set", "max_steps=90", "--set", "perception.image_size=96"]
    result = runner.invoke(app, ["eval", "--task", "bowl_pour", "--episodes", "3", "--guidance-preset", "recommended",
                                 "--out", str(tmp_path / "r.json"), *sets])
    assert result.exit_code == 0, result.output
    (config,) = captured
    assert (config.task, config.episodes, config.max_steps) == ("bowl_pour", 3, 90)
    assert config.guidance == GuidanceChoice("recommended", {"sampler.rho": 0.02,
                                                             "execution.filters": ["repair", "hold"]})
    assert config.perception == PerceptionSettings(image_size=96)
    resolved = config.guidance.resolve(None)
    assert resolved.sampler.rho == 0.02 and resolved.execution.filters == ("repair", "hold")
    result = runner.invoke(app, ["run", "pour the bowl into the pan", "--out", str(tmp_path / "run"), *sets[:4]])
    assert result.exit_code == 0, result.output
    run = captured[1]
    assert isinstance(run, RunConfig) and run.guidance.preset == "tuned" and run.guidance.overrides["sampler.rho"]


def test_a_config_file_and_a_results_file_set_what_options_and_set_then_change(captured, tmp_path):
    config_file = tmp_path / "eval.yaml"
    config_file.write_text(yaml.safe_dump({"task": "bowl_pour", "episodes": 7, "variation": "obstacle",
                                           "guidance": {"preset": "paper", "overrides": {"sampler": {"rho": 3.0}}}}))
    runner = CliRunner()
    result = runner.invoke(app, ["eval", "--config", str(config_file), "--episodes", "5",
                                 "--set", "guidance.sampler.last_steps=5", "--out", str(tmp_path / "a.json")])
    assert result.exit_code == 0, result.output
    config = captured[-1]
    assert (config.task, config.episodes, config.variation) == ("bowl_pour", 5, "obstacle")  # the option wins
    assert config.guidance == GuidanceChoice("paper", {"sampler.rho": 3.0, "sampler.last_steps": 5})
    # a results file re-runs what made it
    saved = tmp_path / "results.json"
    saved.write_text(json.dumps({"schema": "lano3dp-results/1", "provenance": {}, "config": config.to_dict()}))
    result = runner.invoke(app, ["eval", "--config", str(saved), "--out", str(tmp_path / "b.json")])
    assert result.exit_code == 0, result.output
    assert captured[-1].replace(out=None) == config.replace(out=None)


def test_bad_settings_are_one_usage_line_naming_the_setting(tmp_path):
    runner = CliRunner()
    result = runner.invoke(app, ["eval", "--task", "bowl_pour", "--set", "guidance.sampler.rho=-1"])
    assert result.exit_code == 2 and "rho" in result.output
    result = runner.invoke(app, ["eval", "--task", "bowl_pour", "--guidance-preset", "fast"])
    assert result.exit_code == 2 and "unknown guidance preset 'fast'" in result.output
    result = runner.invoke(app, ["eval", "--task", "bowl_pour", "--guidance-preset", "none",
                                 "--set", "guidance.execution.filters=[hold]"])
    assert result.exit_code == 2 and "sampler.mode" in result.output
    result = runner.invoke(app, ["eval", "--task", "bowl_pour", "--set", "episodez=3"])
    assert result.exit_code == 2 and "episodez" in result.output


def test_eval_help_shows_the_basic_options_on_one_screen():
    result = CliRunner().invoke(app, ["eval", "--help"], terminal_width=100)
    lines = result.output.splitlines()
    start = next(i for i, line in enumerate(lines) if "Options" in line)
    end = next(i for i in range(start + 1, len(lines)) if lines[i].startswith("╰"))
    assert end - start <= 40
    for panel in ("Settings", "Perception", "Advanced"):
        assert any(panel in line for line in lines[end:])


def test_set_assignments_apply_to_a_config_dict_in_order():
    data = with_assignments({"task": "bowl_pour", "guidance": {"preset": "recommended"}},
                            ["guidance.cost.push_turn=30", "guidance.preset=paper", "episodes=4"])
    assert data == {"task": "bowl_pour", "episodes": 4,
                    "guidance": {"preset": "paper", "overrides": {"cost.push_turn": 30}}}
