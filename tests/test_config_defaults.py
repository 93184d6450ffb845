"""The defaults the README states are the ones the code uses, and the command line maps onto the nested settings.

The README's "Defaults" table (under "Command line") is parsed here: each row's option names a setting, and its
`recommended` and `paper` cells must equal the presets (`guidance.GUIDANCE_PRESETS`), the obstacle defaults,
the runner's own defaults (`RuntimeConfig`) and the paper sampler of bench/bench_obstacles.py.
"""

from __future__ import annotations

import re
from dataclasses import asdict, fields
from pathlib import Path

import pytest
from typer.testing import CliRunner

from bench_loader import load_bench
from lano3dp.cli import app
from lano3dp.evaluate import EvalConfig, PerceptionSettings, RunConfig
from lano3dp.guidance import GUIDANCE_PRESETS, SAFETY_MARGIN, CheckConfig, GuidanceSettings, ObstacleSettings
from lano3dp.policy.config import PolicyConfig
from lano3dp.runtime import ObstacleModel, RuntimeConfig

README = Path(__file__).resolve().parents[1] / "README.md"
RECOMMENDED, PAPER = GUIDANCE_PRESETS["recommended"], GUIDANCE_PRESETS["paper"]
# README option -> GuidanceSettings field
GUIDANCE_OPTIONS = {"--guidance": "mode", "--rho": "rho", "--last-steps": "last_steps",
                    "--metric-push/--paper-push": "metric_gradient", "--densify": "densify",
                    "--per-train-step": "per_train_step", "--guided-clip-range": "guided_clip_range",
                    "--push-weight": "push_weight", "--checked": "checked", "--guide-when-needed": "guide_when_needed",
                    "--anchored/--no-anchored": "anchored", "--repair-steps": "repair_steps",
                    "--hold-unclear/--no-hold-unclear": "hold_unclear", "--push-turn": "push_turn",
                    "--bridge-gaps/--no-bridge-gaps": "bridge_gaps",
                    "--escape-inside/--no-escape-inside": "escape_when_inside",
                    "--follow-obstacles/--no-follow-obstacles": "follow_when_stuck",
                    "--checkpoint-guidance/--no-checkpoint-guidance": "tuned"}


def _value(text: str):
    if text in ("on", "off"):
        return text == "on"
    if text == "none":
        return None
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def readme_defaults() -> dict[str, tuple[list, list]]:
    """{option: (recommended values, paper values)} from the README's Defaults table (backticked values)."""
    lines = README.read_text().splitlines()
    start = lines.index("| setting | option | recommended | paper |")
    rows = {}
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        cells = [cell.strip() for cell in re.split(r"(?<!\\)\|", line)[1:-1]]
        option = re.findall(r"`([^`]+)`", cells[1])[0]
        rows[option] = tuple([_value(v) for v in re.findall(r"`([^`]+)`", cell)] for cell in cells[2:4])
    return rows


def test_the_readme_table_states_every_guidance_setting():
    assert set(GUIDANCE_OPTIONS) <= set(readme_defaults())
    # `keep` is no setting: the command line fills it with the options given
    assert set(GUIDANCE_OPTIONS.values()) == {f.name for f in fields(GuidanceSettings)} - {"keep"}


def test_the_readme_guidance_defaults_are_the_presets():
    rows = readme_defaults()
    for option, name in GUIDANCE_OPTIONS.items():
        recommended, paper = rows[option]
        assert recommended == [getattr(RECOMMENDED, name)], option
        assert paper == [getattr(PAPER, name)], option
    assert RECOMMENDED == GuidanceSettings()  # the class's defaults are the recommended preset


def test_the_readme_obstacle_and_sampler_defaults_are_the_codes():
    rows = readme_defaults()
    paper_sampler = load_bench("bench_obstacles").SAMPLERS["paper"]
    assert paper_sampler["guidance"] == asdict(PAPER)  # the bench's paper row is the paper preset
    assert rows["--scheduler"] == ([PolicyConfig.inference_scheduler, PolicyConfig.num_inference_steps],
                                   [paper_sampler["scheduler"], paper_sampler["steps"]])
    assert EvalConfig(checkpoint="c").scheduler is None  # the policy's
    assert rows["--body"] == ([ObstacleSettings().body], [paper_sampler["obstacle"]["body"]])
    assert rows["--margin"] == ([SAFETY_MARGIN], [SAFETY_MARGIN])
    assert rows["--obstacle-shape"] == ([ObstacleSettings().shape], [ObstacleSettings().shape])


def test_the_runners_own_defaults_are_the_recommended_presets():
    runtime, model, settings = RuntimeConfig(), ObstacleModel(), ObstacleSettings()
    assert (runtime.metric_gradient, runtime.densify, runtime.guide_when_needed, runtime.anchored,
            runtime.repair_steps, runtime.hold_unclear, runtime.push_turn) == (
        RECOMMENDED.metric_gradient, RECOMMENDED.densify, RECOMMENDED.guide_when_needed, RECOMMENDED.anchored,
        RECOMMENDED.repair_steps, RECOMMENDED.hold_unclear, RECOMMENDED.push_turn)
    assert CheckConfig().densify == RECOMMENDED.densify
    assert (model.shape, model.margin, model.body, model.held_radius, model.refit_every_chunk) == (
        settings.shape, settings.margin, settings.body, settings.held_radius, settings.refit)
    built = RuntimeConfig.from_settings(GuidanceSettings(), seed=3)
    assert built.guidance.scale == RECOMMENDED.rho and built.guidance.last_steps == RECOMMENDED.last_steps
    assert RuntimeConfig.from_settings(GuidanceSettings(push_turn=30.0)).push_turn == 30.0
    assert built.obstacle == model and built.checked is None and built.seed == 3
    assert RuntimeConfig.from_settings(GuidanceSettings(mode="none")).guidance is None


def test_a_mode_alone_is_the_recommended_preset_in_that_mode():
    assert EvalConfig(checkpoint="c").guidance == GuidanceSettings(mode="none")  # eval: unguided unless asked
    assert EvalConfig(checkpoint="c", guidance="clean").guidance == RECOMMENDED
    assert RunConfig("open the drawer").guidance == RECOMMENDED  # run: guided
    assert EvalConfig(checkpoint="c", guidance={"rho": 0.02}).guidance.densify == RECOMMENDED.densify
    with pytest.raises(ValueError, match="finite"):
        GuidanceSettings(guided_clip_range=float("inf"))  # the results JSON could not hold it


@pytest.fixture
def captured(monkeypatch):
    """Replace evaluate and run_instruction by recorders of the config the command line built."""
    import lano3dp.evaluate as evaluate_module

    configs = []

    def record(config, *args, **kwargs):
        configs.append(config)
        return {"summary": {}, "timing": {"resumed_episodes": 0}, "notes": [], "episodes": {}, "top_view": ""}

    monkeypatch.setattr(evaluate_module, "evaluate", record)
    monkeypatch.setattr(evaluate_module, "run_instruction", record)
    return configs


OPTIONS = ["--guidance", "clean", "--guidance-preset", "paper", "--rho", "2", "--guided-clip-range", "3",
           "--push-weight", "alpha_bar", "--checked", "--anchored", "--repair-steps", "5", "--hold-unclear",
           "--push-turn", "30", "--no-bridge-gaps", "--no-escape-inside", "--no-follow-obstacles",
           "--margin", "0.03", "--body", "sphere", "--held-radius", "0.05",
           "--refit-obstacles", "--obstacle-shape", "box", "--image-size", "96"]


def test_eval_and_run_options_map_onto_the_nested_settings(captured, tmp_path):
    runner = CliRunner()
    runner.invoke(app, ["eval", "--task", "bowl_pour", "--out", str(tmp_path / "r.json"), *OPTIONS])
    runner.invoke(app, ["run", "pour the bowl into the pan", "--out", str(tmp_path / "run"), *OPTIONS])
    assert [type(c) for c in captured] == [EvalConfig, RunConfig]
    for config in captured:
        # the paper preset, with the given options over it, kept over a checkpoint's tuning
        assert config.guidance == GuidanceSettings(mode="clean", rho=2.0, last_steps=10, metric_gradient=False,
                                                   densify=1, guided_clip_range=3.0, push_weight="alpha_bar",
                                                   checked=True, anchored=True, repair_steps=5, hold_unclear=True,
                                                   push_turn=30.0, bridge_gaps=False, escape_when_inside=False,
                                                   follow_when_stuck=False, tuned=False, keep=config.guidance.keep)
        assert set(config.guidance.keep) == {"rho", "guided_clip_range", "push_weight", "checked", "anchored",
                                             "repair_steps", "hold_unclear", "push_turn", "bridge_gaps",
                                             "escape_when_inside", "follow_when_stuck"}
        assert config.obstacle == ObstacleSettings(shape="box", margin=0.03, body="sphere", held_radius=0.05,
                                                   refit=True)
        assert config.perception == PerceptionSettings(image_size=96)


def test_eval_without_guidance_options_saves_the_recommended_preset(captured, tmp_path):
    CliRunner().invoke(app, ["eval", "--task", "bowl_pour", "--guidance", "clean", "--out", str(tmp_path / "r.json")])
    (config,) = captured
    assert config.guidance == RECOMMENDED and config.obstacle == ObstacleSettings()


def test_a_bad_guidance_value_is_a_usage_error():
    result = CliRunner().invoke(app, ["eval", "--task", "bowl_pour", "--guided-clip-range", "0"])
    assert result.exit_code == 2 and "guided_clip_range must be a finite number > 0" in result.output
    result = CliRunner().invoke(app, ["eval", "--task", "bowl_pour", "--guidance-preset", "fast"])
    assert result.exit_code == 2 and "'fast' is not one of recommended, paper" in result.output
