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
          "GuidanceSettings", "GuidanceChoice", "guidance_preset", "register_guidance_preset", "PerceptionSettings")


def readme_python_block(section: str = "## Use it from Python") -> str:
    text = README.read_text()
    start = text.index(section)
    return re.search(r"```python\n(.*?)```", text[start:], re.S).group(1)


def test_import_lano3dp_loads_neither_torch_nor_mujoco():
    probe = "import sys, lano3dp; print(sorted(m for m in ('torch', 'mujoco', 'lano3dp.sim') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_every_public_name_resolves_to_the_object_its_module_defines():
    from lano3dp.evaluation import evaluate
    from lano3dp.policy.modeling import DiffusionPolicy
    from lano3dp.sim.protocol import SimulatorProtocol

    assert set(PUBLIC) <= set(lano3dp.__all__) and set(lano3dp.__all__) == {"__version__", *lano3dp._EXPORTS}
    for name in PUBLIC:
        assert getattr(lano3dp, name) is not None
    assert lano3dp.DiffusionPolicy is DiffusionPolicy
    assert lano3dp.evaluate is evaluate
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
    from lano3dp.sim.tasks.put_item_in_drawer import PutItemInDrawer

    write_tiny_packaged_policy(tmp_path)
    monkeypatch.setattr(pretrained, "PACKAGED_ROOT", tmp_path / "checkpoints")
    # the block sets no step limit (the task's 130 steps); an untrained stand-in never succeeds, so its episodes
    # are cut to 25 steps here to keep the test quick
    monkeypatch.setattr(PutItemInDrawer, "max_steps", 25)
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    exec(compile(readme_python_block(), str(README), "exec"), namespace)
    printed = capsys.readouterr().out
    assert "put_item_in_drawer ('block', 'drawer') ['mug']" in printed
    run, report = namespace["run"], namespace["report"]
    # the run: the main command's five obstacle scenes, guided as the policy was tuned (this one has no tuning)
    saved = json.loads((tmp_path / "outputs" / "run" / "python" / "run.json").read_text())
    assert saved["plan"]["skill"] == "put_item_in_drawer" and saved["guidance"] == report["guidance"]
    assert [scene["seed"] for scene in run["scenes"]] == [scene["seed"] for scene in saved["scenes"]]
    guided = run["episodes"]["guided"]
    assert list(run["episodes"]) == ["guided"] and len(guided) == len(run["scenes"]) == 5
    assert all(isinstance(episode["success"], bool) and episode["steps"] <= 25 for episode in guided)
    assert run["summary"]["guided"]["episodes"] == 5
    assert all(scene["obstacles"] for scene in run["scenes"])  # the mug's stand-in: guidance has a cost everywhere
    assert f"guided successes: {[episode['success'] for episode in guided]}" in printed
    # the evaluation: the same policy over five obstacle scenes, batched, with the tree that ran and its provenance
    assert report["summary"]["episodes"] == 5 and report["config"]["guidance"]["preset"] == "tuned"
    assert report["config"]["batch"] == 5 and report["config"]["obstacle_scenes_only"]
    assert report["guidance"]["sampler"]["mode"] == "clean"  # tuned without a guidance.json: recommended
    assert report["guidance"]["execution"]["filters"] == ["repair", "hold", "escape", "follow"]
    assert {"commit", "behaviour_version", "versions", "config"} <= set(report["provenance"])
    assert f"success rate: {report['summary']['success_rate']}" in printed
