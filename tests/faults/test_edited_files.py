"""A checkpoint is verified as a whole: every file that shapes what the policy does is sealed by manifest.json; an
edit, an added or a deleted file is refused naming the file, until `lano3dp checkpoint seal` accepts it. The
weights keep their own checksum, which sealing cannot override."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from faults_common import assert_one_line, tree_digest
from lano3dp.cli import app
from lano3dp.errors import CorruptFileError
from lano3dp.evaluation import PolicyBundle, PolicyTaskMismatchError
from lano3dp.guidance import load_guidance_tuning, save_guidance_tuning
from lano3dp.policy import DiffusionPolicy
from lano3dp.policy.integrity import MANIFEST_NAME, SEALED_FILES, CheckpointSealError, verify_checkpoint
from lano3dp.policy.pretrained import packaged_checkpoint, packaged_checkpoints
from test_policy import make_policy


def edit_json(path: Path, **changes) -> None:
    data = json.loads(path.read_text())
    data.update(changes)
    path.write_text(json.dumps(data, indent=2))


@pytest.fixture
def packaged_copy(tmp_path) -> Path:
    """A copy of the packaged open_drawer policy, as a user would make one to experiment with."""
    folder = tmp_path / "open_drawer"
    shutil.copytree(packaged_checkpoint("open_drawer"), folder)
    return folder


def test_every_packaged_policy_is_sealed_and_matches_its_manifest():
    packaged = packaged_checkpoints()
    assert len(packaged) == 10
    for folder in packaged.values():
        sealed = verify_checkpoint(folder)
        assert set(sealed) == {name for name in SEALED_FILES if (folder / name).exists()}
    assert "guidance.json" in verify_checkpoint(packaged["bowl_pour"])


def test_n_points_edited_in_a_copy_of_a_packaged_policy_is_refused_naming_config_json(packaged_copy, tmp_path):
    """It used to evaluate, without a word, on clouds the policy was not trained on."""
    edit_json(packaged_copy / "config.json", n_points=128)
    out = tmp_path / "r.json"
    result = CliRunner().invoke(app, ["eval", "--checkpoint", str(packaged_copy), "--task", "open_drawer",
                                      "--episodes", "1", "--max-steps", "2", "--out", str(out)])
    assert_one_line(result, 1, f"{packaged_copy / 'config.json'}: changed since the checkpoint was sealed",
                    f"lano3dp checkpoint seal {packaged_copy}")
    assert not out.exists()


def test_a_change_made_on_purpose_is_accepted_once_sealed(packaged_copy):
    edit_json(packaged_copy / "config.json", n_points=128)
    result = CliRunner().invoke(app, ["checkpoint", "seal", str(packaged_copy)])
    assert result.exit_code == 0, result.output
    assert result.stdout.startswith(f"sealed {packaged_copy}: config.json ")
    assert DiffusionPolicy.from_pretrained(packaged_copy).config.n_points == 128
    verified = CliRunner().invoke(app, ["checkpoint", "verify", str(packaged_copy)])
    assert verified.exit_code == 0 and "every sealed file matches" in verified.stdout


@pytest.mark.parametrize("fault, file, reason", [
    ("edit normalizer.json", "normalizer.json", "changed since the checkpoint was sealed"),
    ("edit guidance.json", "guidance.json", "changed since the checkpoint was sealed"),
    ("add guidance.json", "guidance.json", "added after the checkpoint was sealed (not in manifest.json)"),
    ("delete normalizer.json", "normalizer.json", "listed in manifest.json but missing"),
    ("delete manifest.json", "manifest.json", "missing: this checkpoint was saved before lano3dp sealed"),
])
def test_every_sealed_file_is_checked_on_load(tmp_path, fault, file, reason):
    folder = make_policy().save_pretrained(tmp_path / "policy")
    if fault != "add guidance.json":
        save_guidance_tuning(folder, {"sampler.rho": 0.02}, measured="test")  # through the library: stays sealed
    DiffusionPolicy.from_pretrained(folder)
    action, name = fault.split(" ", 1)
    if action == "delete":
        (folder / name).unlink()
    elif name == "normalizer.json":
        stats = json.loads((folder / name).read_text())
        stats["action"]["max"][0] += 0.5
        (folder / name).write_text(json.dumps(stats))
    else:
        (folder / name).write_text(json.dumps({"format": "lano3dp-guidance-tuning", "version": 2,
                                               "preset": "recommended", "overrides": {"sampler.rho": 0.5},
                                               "measured": "by hand"}))
    with pytest.raises(CheckpointSealError, match=re.escape(f"{folder / file}: {reason}")):
        DiffusionPolicy.from_pretrained(folder)


def test_a_library_write_updates_the_manifest_but_never_seals_a_hand_edit(tmp_path):
    folder = make_policy().save_pretrained(tmp_path / "policy")
    save_guidance_tuning(folder, {"sampler.rho": 0.02}, measured="test")
    assert load_guidance_tuning(folder).overrides == {"sampler.rho": 0.02}
    assert "guidance.json" in verify_checkpoint(folder)
    make_policy(seed=3).save_pretrained(folder)  # re-saved in place: weights and config change, sealed again
    DiffusionPolicy.from_pretrained(folder)
    edit_json(folder / "config.json", n_points=64)
    before = (folder / MANIFEST_NAME).read_bytes()
    with pytest.raises(CheckpointSealError, match=r"config\.json: changed since the checkpoint was sealed"):
        save_guidance_tuning(folder, {"sampler.rho": 0.03}, measured="test")
    assert (folder / MANIFEST_NAME).read_bytes() == before


def test_sealing_refuses_a_checkpoint_that_does_not_load(packaged_copy):
    before = tree_digest(packaged_copy)
    (packaged_copy / "config.json").write_text('{"obs_type": "objects", "horiz')
    result = CliRunner().invoke(app, ["checkpoint", "seal", str(packaged_copy)])
    assert_one_line(result, 1, f"{packaged_copy / 'config.json'}: not a valid policy config")
    manifest_before = json.loads((packaged_checkpoint("open_drawer") / MANIFEST_NAME).read_text())
    assert json.loads((packaged_copy / MANIFEST_NAME).read_text()) == manifest_before
    assert tree_digest(packaged_copy) != before  # (the edit itself is still there for the user to fix)


# ---- the weights' own checksum (issue 13), which sealing cannot override -----------------------------------
def _flip_weight_bytes(path: Path) -> None:
    raw = bytearray(path.read_bytes())
    raw[-64:-56] = b"\xff" * 8  # inside the tensor data: the header still parses
    path.write_bytes(bytes(raw))


def test_overwritten_weight_bytes_are_refused_naming_the_file_even_after_sealing(tmp_path):
    folder = make_policy().save_pretrained(tmp_path / "ckpt")
    _flip_weight_bytes(folder / "model.safetensors")
    with pytest.raises(CorruptFileError, match=r"ckpt/model\.safetensors: the weights do not match the checksum"):
        DiffusionPolicy.from_pretrained(folder)
    result = CliRunner().invoke(app, ["checkpoint", "seal", str(folder)])
    assert_one_line(result, 1, "model.safetensors: the weights do not match the checksum")


def test_an_fp16_export_is_sealed_loads_and_its_damage_is_named(tmp_path):
    from lano3dp.policy.pretrained import export_fp16

    folder = make_policy(extra={"observation": {"image_size": 128}}).save_pretrained(tmp_path / "ckpt")
    exported = export_fp16(folder, tmp_path / "fp16")
    assert set(verify_checkpoint(exported)) == {"config.json", "model.safetensors", "normalizer.json"}
    loaded = DiffusionPolicy.from_pretrained(exported)
    original = DiffusionPolicy.from_pretrained(folder)
    weight = "unet.final_conv.1.weight"
    assert torch.allclose(loaded.state_dict()[weight], original.state_dict()[weight], atol=1e-3)
    _flip_weight_bytes(exported / "model.safetensors")
    with pytest.raises(CorruptFileError, match=r"fp16/model\.safetensors: the weights do not match the checksum"):
        DiffusionPolicy.from_pretrained(exported)


def test_a_checkpoint_refuses_a_task_of_another_skill_and_accepts_its_own(tiny_checkpoint):
    bundle = PolicyBundle.load(tiny_checkpoint)
    bundle.check_task("open_drawer", env=None)
    with pytest.raises(PolicyTaskMismatchError, match="trained for skill 'open_drawer'.*not 'close_microwave'"):
        bundle.check_task("close_microwave", env=None)
