"""The public API: `import lano3dp` is light, exports what the README names, and the README's Python block runs."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

import lano3dp

README = Path(__file__).resolve().parents[1] / "README.md"
PUBLIC = ("DiffusionPolicy", "PolicyConfig", "TabletopEnv", "SimulatorProtocol", "OfflineDecomposer", "LLMDecomposer",
          "PolicyRunner", "rollout", "evaluate", "EvalConfig", "packaged_checkpoint", "run_instruction", "RunConfig",
          "GuidanceSettings", "GUIDANCE_PRESETS", "ObstacleSettings", "PerceptionSettings")


def readme_python_block(section: str = "## Use it from Python") -> str:
    text = README.read_text()
    start = text.index(section)
    return re.search(r"```python\n(.*?)```", text[start:], re.S).group(1)


def test_import_lano3dp_loads_neither_torch_nor_mujoco():
    probe = "import sys, lano3dp; print(sorted(m for m in ('torch', 'mujoco', 'lano3dp.sim') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_evaluate_is_callable_as_the_function_however_it_was_imported(monkeypatch):
    import lano3dp.evaluate as module
    from lano3dp import evaluate

    calls = []
    monkeypatch.setattr(module, "evaluate", lambda *args: calls.append(args) or {"summary": {}})
    assert evaluate("config") == {"summary": {}} and calls == [("config", None, None)]


def test_every_public_name_resolves_to_the_object_its_module_defines():
    from lano3dp.evaluate import evaluate
    from lano3dp.policy.modeling import DiffusionPolicy
    from lano3dp.sim.protocol import SimulatorProtocol

    assert set(PUBLIC) <= set(lano3dp.__all__) and set(lano3dp.__all__) == {"__version__", *lano3dp._EXPORTS}
    for name in PUBLIC:
        assert getattr(lano3dp, name) is not None
    assert lano3dp.DiffusionPolicy is DiffusionPolicy
    assert lano3dp.evaluate is evaluate or lano3dp.evaluate is sys.modules["lano3dp.evaluate"]
    assert lano3dp.SimulatorProtocol is SimulatorProtocol
    with pytest.raises(AttributeError, match="no attribute 'Nonesuch'"):
        lano3dp.Nonesuch  # noqa: B018


def write_tiny_packaged_policy(root: Path) -> Path:
    """An untrained put_item_in_drawer policy shipped the way packaged ones are (fp16, observation settings)."""
    from lano3dp.policy.pretrained import export_fp16

    torch.manual_seed(0)
    config = lano3dp.PolicyConfig(
        object_names=("block", "drawer"), n_points=32, down_dims=(16, 32), diffusion_step_embed_dim=16, n_groups=4,
        point_hidden_dims=(16,), encoder_out=16, state_feature_dim=16,
        extra={"skill": "put_item_in_drawer", "task": "put_item_in_drawer",
               "observation": {"image_size": 64, "n_points": 32, "crop_low": [-0.2, -0.6, 0.005],
                               "crop_high": [1.0, 0.6, 0.6]}})
    policy = lano3dp.DiffusionPolicy(config)
    rng = np.random.default_rng(0)
    policy.set_normalizer({"action": {"min": np.r_[0.3, -0.3, 0.0, -np.ones(6), 0.0] - 0.05 * rng.random(10),
                                      "max": np.r_[0.7, 0.3, 0.4, np.ones(6), 1.0]},
                           "state": {"min": -np.ones(11), "max": np.ones(11)},
                           "object_clouds": {"min": np.array([0.0, -0.5, 0.0]), "max": np.array([0.9, 0.5, 0.4])}})
    source = policy.save_pretrained(root / "trained")
    return export_fp16(source, root / "checkpoints" / "put_item_in_drawer")


@pytest.mark.slow
def test_the_readme_python_example_runs_on_a_packaged_policy(tmp_path, monkeypatch, capsys):
    from lano3dp.policy import pretrained

    write_tiny_packaged_policy(tmp_path)
    monkeypatch.setattr(pretrained, "PACKAGED_ROOT", tmp_path / "checkpoints")
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    exec(compile(readme_python_block(), str(README), "exec"), namespace)
    printed = capsys.readouterr().out
    assert "put_item_in_drawer ('block', 'drawer') ['mug']" in printed
    run, report = namespace["run"], namespace["report"]
    assert json.loads((tmp_path / "run_out" / "run.json").read_text())["plan"]["skill"] == "put_item_in_drawer"
    assert run["episodes"]["guided"]["steps"] <= 40 and isinstance(run["episodes"]["guided"]["success"], bool)
    assert run["obstacles"]  # the mug is not in the simulator: its obstacle stands in, and guidance has a cost
    assert report["summary"]["episodes"] == 3 and report["config"]["guidance"]["mode"] == "clean"
