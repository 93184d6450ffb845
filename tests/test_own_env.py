"""A user's own environment plugs into `lano3dp eval` and `lano3dp run` by name, with no glue in lano3dp.

The environment is examples/own_env.py (numpy and lano3dp.geometry/perception helpers, no lano3dp.sim); the
policy is an untrained tiny one for its "reach_block" skill: evaluation needs a checkpoint, not a good one.
"""

from __future__ import annotations

import ast
import json
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from lano3dp import EvalConfig, RunConfig, evaluate, run_instruction
from lano3dp.cli import app
from lano3dp.env_factory import EnvContractError, EnvFactoryError, load_factory, make_env
from lano3dp.language import SkillRegistry, SkillSpec, Slot
from lano3dp.policy import DiffusionPolicy, PolicyConfig
from test_policy import TINY, stats_for

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "own_env.py"
SPEC = f"{EXAMPLE}:make_env"


@pytest.fixture(scope="module")
def reach_checkpoint(tmp_path_factory) -> Path:
    torch.manual_seed(0)
    config = PolicyConfig(**({"object_names": ("block",), "extra": {
        "skill": "reach_block", "task": "reach_block",
        "observation": {"image_size": 48, "n_points": 32, "crop_low": [-0.5, -0.5, 0.005],
                        "crop_high": [0.5, 0.5, 0.6]}}} | TINY))
    policy = DiffusionPolicy(config)
    policy.set_normalizer(stats_for(policy.config))
    return policy.save_pretrained(tmp_path_factory.mktemp("reach") / "policy")


def error_lines(result) -> list[str]:
    return [line for line in result.stderr.splitlines() if line.startswith("error: ")]


def test_eval_runs_the_example_env_from_its_file_and_reports_its_own_success(reach_checkpoint, tmp_path,
                                                                             monkeypatch):
    monkeypatch.chdir(ROOT)  # the command as the README gives it
    out = tmp_path / "own.json"
    result = CliRunner().invoke(app, ["eval", "--env", "examples/own_env.py:make_env", "--checkpoint",
                                      str(reach_checkpoint), "--episodes", "2", "--max-steps", "6",
                                      "--guidance-preset", "recommended", "--out", str(out)])
    assert result.exit_code == 0, (result.output, result.exception)
    data = json.loads(out.read_text())
    assert data["env"] == "examples/own_env.py:make_env" and data["config"]["env"] == data["env"]
    assert data["notes"] == []
    episodes = data["episodes"]
    assert [e["seed"] for e in episodes] == [1_000_000, 1_000_001]
    for episode in episodes:
        assert episode["success_reported"] is True and episode["error"] is None
        assert 1 <= episode["steps"] <= 6
        assert set(episode["targets"]) == {"block"}  # the block's cloud fed the policy's one slot
        # the post, marked role "obstacle" by the env, became the guidance's cylinder; the env measured clearance
        assert [o["shape"] for o in episode["obstacles"]] == ["Cylinder"]
        assert episode["min_clearance"] is not None and episode["min_clearance"] > 0
        assert episode["stages"] == {}  # the env reports none: the summary has no stage breakdown
    assert data["summary"]["episodes"] == 2 and data["summary"]["stage_rates"] == {}
    assert data["summary"]["success_rate"] in (0.0, 0.5, 1.0)
    assert "success " in result.stderr and "results:" in result.stderr


def test_the_python_form_takes_the_factory_itself_and_saves_its_name(reach_checkpoint):
    factory = load_factory(SPEC)
    config = EvalConfig(checkpoint=str(reach_checkpoint), env=factory, episodes=1, max_steps=3)
    assert config.env == f"{EXAMPLE}:make_env"  # JSON-able, and what a worker process re-imports
    report = evaluate(config)
    assert report["episodes"][0]["steps"] == 3 and report["env"] == config.env


def test_a_factory_gets_only_the_options_it_names():
    seen = {}

    def factory(task, image_size):
        seen.update(task=task, image_size=image_size)
        return load_factory(SPEC)(image_size=image_size)

    env = make_env(factory, task="reach_block", seed=1, variation="clean", image_size=40, render_rgb=False,
                   max_steps=None)
    assert seen == {"task": "reach_block", "image_size": 40}
    obs, info = env.reset(seed=0)
    assert obs["frame"].depth.shape == (40, 40) and env.max_steps == 30 and env.reports_success


SILENT_ENV = '''
import sys
sys.path.insert(0, {examples!r})
from own_env import make_env as make_reach_env


class Silent:
    """The example env without info["success"], as a robot that cannot tell."""

    def __init__(self, env):
        self.env, self.max_steps = env, env.max_steps

    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed)
        return obs, {{k: v for k, v in info.items() if k != "success"}}

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, False, truncated, {{k: v for k, v in info.items() if k != "success"}}


def make_env(**options):
    return Silent(make_reach_env(**options))
'''


def test_an_env_without_success_is_said_to_measure_none(reach_checkpoint, tmp_path, monkeypatch):
    (tmp_path / "silent_env.py").write_text(SILENT_ENV.format(examples=str(EXAMPLE.parent)))
    monkeypatch.syspath_prepend(str(tmp_path))  # the module form: 'silent_env:make_env'
    out = tmp_path / "silent.json"
    result = CliRunner().invoke(app, ["eval", "--env", "silent_env:make_env", "--checkpoint", str(reach_checkpoint),
                                      "--episodes", "1", "--max-steps", "2", "--out", str(out)])
    assert result.exit_code == 0, (result.output, result.exception)
    data = json.loads(out.read_text())
    assert data["episodes"][0]["success_reported"] is False
    assert data["summary"]["success_rate"] is None and data["summary"]["safe_success_rate"] is None
    assert data["notes"] == ["the environment reports no info['success']: success is not measured"]
    assert "success not reported by the env" in result.stderr
    sys.modules.pop("silent_env", None)
    sys.modules.pop("own_env", None)


BAD_ENVS = '''
import numpy as np

answer = 42


def not_an_env(**options):
    return {"reset": "no"}


class NoState:
    max_steps = 5

    def reset(self, *, seed=None, options=None):
        return {"rgb": np.zeros((4, 4, 3), np.uint8)}, {}

    def step(self, action):
        raise AssertionError("never reached")


def no_state(**options):
    return NoState()


def broken(task, **options):
    raise RuntimeError("robot not connected")
'''


def test_a_bad_env_is_one_line_naming_what_is_wrong(reach_checkpoint, tmp_path):
    bad = tmp_path / "bad_envs.py"
    bad.write_text(BAD_ENVS)
    cases = [
        ("no_such_module:make_env", 2, "no module named 'no_such_module'"),
        (f"{tmp_path / 'missing.py'}:make_env", 2, "no file"),
        (f"{EXAMPLE}:make_envv", 2, "has no attribute 'make_envv' (it defines: ReachBlockEnv, ReachBlockScene, "
                                    "make_env)"),
        (str(EXAMPLE), 2, "give module:factory or path/to/file.py:factory"),
        (f"{bad}:answer", 2, "answer is an int, not a callable factory"),
        (f"{bad}:not_an_env", 1, "the factory returned a dict, which has no reset() and no step()"),
        (f"{bad}:no_state", 1, "reset()'s observation has no 'state' (11,"),
        (f"{bad}:broken", 1, "raised RuntimeError: robot not connected"),
    ]
    runner = CliRunner()
    for spec, code, text in cases:
        result = runner.invoke(app, ["eval", "--env", spec, "--checkpoint", str(reach_checkpoint), "--episodes",
                                     "1", "--out", str(tmp_path / "r.json")])
        errors = error_lines(result)
        assert result.exit_code == code, (spec, result.output, result.exception)
        assert len(errors) == 1 and text in errors[0], (spec, result.stderr)
        assert "Traceback" not in result.output
    with pytest.raises(EnvFactoryError, match="no importable name"):
        EvalConfig(checkpoint=str(reach_checkpoint), env=lambda **options: None)
    with pytest.raises(EnvContractError, match="reset\\(\\) must return \\(obs, info\\), got a dict"):
        env = make_env(f"{bad}:no_state", task="t")
        env.env.reset = lambda **kwargs: {"state": np.zeros(11)}
        env.reset(seed=0)


def test_run_acts_an_instruction_in_the_example_env(reach_checkpoint, tmp_path):
    registry = tmp_path / "skills.json"
    registry.write_text(SkillRegistry([SkillSpec(
        name="reach_block", description="move the hand to the block", verbs=("reach", "touch"),
        slots=(Slot(word="block", synonyms=("block", "cube")),), checkpoint=reach_checkpoint)]).to_json())
    result = run_instruction(RunConfig("touch the red block and keep clear of the post", registry=str(registry),
                                       env=SPEC, max_steps=4, out=str(tmp_path / "run")))
    assert result["plan"]["skill"] == "reach_block" and result["scenes"][0]["obstacles"] == ["post"]
    (guided,) = result["episodes"]["guided"]
    assert guided["steps"] <= 4 and guided["success_reported"] is True
    assert [o["shape"] for o in guided["obstacles"]] == ["Cylinder"]
    assert (tmp_path / "run" / "run.json").exists() and (tmp_path / "run" / "top_view.png").exists()


def test_the_example_needs_at_most_30_lines_of_glue_and_no_simulator():
    source = EXAMPLE.read_text()
    glue = source.split("# ---- GLUE", 1)[1].splitlines()[1:]
    code = [line for line in glue if line.strip() and not line.strip().startswith(("#", '"""'))]
    assert len(code) == 21  # the README's count; the acceptance is at most 30
    imported = {node.module for node in ast.walk(ast.parse(source)) if isinstance(node, ast.ImportFrom)}
    assert imported == {"__future__", "lano3dp.geometry", "lano3dp.geometry.rotations",
                        "lano3dp.perception.synthetic"}  # no lano3dp.sim
