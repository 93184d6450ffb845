"""Training-checkpoint pieces: EMA schedule, optimizer state without pickle, atomic folders, `last` pointer."""

import json

import pytest
import torch

from lano3dp.errors import CorruptFileError
from lano3dp.policy.checkpoint import (
    EMA,
    atomic_directory,
    flatten_optimizer_state,
    latest_resumable,
    list_checkpoints,
    load_training_state,
    prune_training_states,
    remove_stale_temporaries,
    save_training_state,
    unflatten_optimizer_state,
    update_last_pointer,
)


def test_ema_decay_follows_diffusion_policys_power_schedule():
    ema = EMA(torch.nn.Linear(2, 2), inv_gamma=1.0, power=0.75, max_value=0.9999)
    assert ema.decay(0) == 0.0
    assert ema.decay(1) == pytest.approx(1 - 2**-0.75)
    assert ema.decay(1000) == pytest.approx(1 - 1001**-0.75)
    assert ema.decay(10**9) == 0.9999


def test_ema_starts_as_a_copy_then_averages():
    model = torch.nn.Linear(1, 1, bias=False)
    with torch.no_grad():
        model.weight.fill_(1.0)
    ema = EMA(model)
    with torch.no_grad():
        model.weight.fill_(3.0)
    ema.update(model)  # step 0: decay 0, the average becomes the model
    assert ema.model.weight.item() == 3.0
    with torch.no_grad():
        model.weight.fill_(5.0)
    ema.update(model)  # step 1: decay d = 1 - 2^-0.75
    d = 1 - 2**-0.75
    assert ema.model.weight.item() == pytest.approx(d * 3.0 + (1 - d) * 5.0)
    assert ema.optimization_step == 2 and not ema.model.weight.requires_grad


def _trained_adamw() -> tuple[torch.nn.Module, torch.optim.Optimizer]:
    torch.manual_seed(0)
    model = torch.nn.Sequential(torch.nn.Linear(3, 4), torch.nn.Linear(4, 1))
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-2, betas=(0.95, 0.999), weight_decay=1e-6, fused=True)
    for _ in range(3):
        optimizer.zero_grad()
        model(torch.randn(8, 3)).pow(2).mean().backward()
        optimizer.step()
    return model, optimizer


def test_optimizer_state_round_trips_through_tensors_and_json():
    _, optimizer = _trained_adamw()
    tensors, meta = flatten_optimizer_state(optimizer.state_dict())
    assert set(tensors) >= {"optimizer.0.exp_avg", "optimizer.0.exp_avg_sq", "optimizer.3.step"}
    meta = json.loads(json.dumps(meta))  # must survive JSON
    restored = unflatten_optimizer_state(tensors, meta)
    original = optimizer.state_dict()
    assert restored["param_groups"][0]["betas"] == (0.95, 0.999)
    assert restored["param_groups"] == original["param_groups"]
    for index, entries in original["state"].items():
        for name, value in entries.items():
            assert torch.equal(restored["state"][index][name], value)


def test_training_state_saves_and_loads_without_pickle(tmp_path):
    model, optimizer = _trained_adamw()
    scheduler = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda step: 0.5)
    save_training_state(tmp_path, step=3, model=model, optimizer=optimizer, lr_scheduler=scheduler, ema=None,
                        extra={"seed": 7})
    state = load_training_state(tmp_path)
    assert state.step == 3 and state.extra == {"seed": 7}
    assert all(torch.equal(state.model[k], v) for k, v in model.state_dict().items())
    fresh_model, _ = _trained_adamw()
    fresh = torch.optim.AdamW(fresh_model.parameters(), lr=1.0, fused=True)
    fresh.load_state_dict(state.optimizer)
    assert torch.equal(fresh.state_dict()["state"][0]["exp_avg"], optimizer.state_dict()["state"][0]["exp_avg"])
    assert fresh.param_groups[0]["lr"] == optimizer.param_groups[0]["lr"]


def test_damaged_training_state_names_the_file(tmp_path):
    model, optimizer = _trained_adamw()
    scheduler = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda step: 1.0)
    save_training_state(tmp_path, step=3, model=model, optimizer=optimizer, lr_scheduler=scheduler, ema=None)
    tensors = tmp_path / "training_state.safetensors"
    tensors.write_bytes(tensors.read_bytes()[:100])
    with pytest.raises(CorruptFileError, match="training_state.safetensors"):
        load_training_state(tmp_path)
    (tmp_path / "training_state.json").write_text("{not json")
    with pytest.raises(CorruptFileError, match="training_state.json"):
        load_training_state(tmp_path)


def test_atomic_directory_publishes_all_or_nothing(tmp_path):
    final = tmp_path / "checkpoints" / "step_0000010"
    with pytest.raises(RuntimeError):
        with atomic_directory(final) as folder:
            (folder / "model.safetensors").write_bytes(b"half")
            raise RuntimeError("killed while writing")
    assert not final.exists() and list((tmp_path / "checkpoints").iterdir()) == []
    with atomic_directory(final) as folder:
        (folder / "a.txt").write_text("1")
    with atomic_directory(final) as folder:  # an existing checkpoint is replaced whole
        (folder / "b.txt").write_text("2")
    assert sorted(p.name for p in final.iterdir()) == ["b.txt"]
    assert [p.name for p in final.parent.iterdir()] == ["step_0000010"]


def test_last_pointer_resumable_and_pruning(tmp_path):
    for step in (10, 20, 30):
        folder = tmp_path / f"step_{step:07d}"
        folder.mkdir()
        for name in ("model.safetensors", "training_state.json", "training_state.safetensors"):
            (folder / name).write_text("x")
        update_last_pointer(tmp_path, folder.name)
    (tmp_path / ".step_0000040.tmp-123").mkdir()  # a run killed while writing step 40
    assert (tmp_path / "last").resolve() == (tmp_path / "step_0000030").resolve()
    assert [step for step, _ in list_checkpoints(tmp_path)] == [10, 20, 30]
    remove_stale_temporaries(tmp_path)
    assert not (tmp_path / ".step_0000040.tmp-123").exists()
    prune_training_states(tmp_path, keep=1)
    assert not (tmp_path / "step_0000020" / "training_state.json").exists()
    assert (tmp_path / "step_0000020" / "model.safetensors").exists()  # the policy stays
    assert latest_resumable(tmp_path) == tmp_path / "step_0000030"
    (tmp_path / "step_0000030" / "training_state.json").unlink()
    assert latest_resumable(tmp_path) is None
