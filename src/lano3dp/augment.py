"""Training-batch augmentation for point-cloud policies: one rigid motion of the whole scene, point jitter
and point dropout.

Everything a batch holds is in the world frame (object clouds, the EE pose in the state, the absolute EE
actions), so moving the table top's contents by a small rigid motion — a yaw about the vertical axis
through `pivot` plus a horizontal shift, optionally a vertical lift — and moving the hand and its actions with
them gives another valid demonstration of the same skill. The same motion is applied to every step of a window,
and to clouds, state and actions alike; that consistency is what makes it a demonstration rather than noise. Jitter and
dropout touch the clouds only (sensor noise, partial views). Off by default: `TrainConfig.augment`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import torch

# Column layout of the state and action vectors (lano3dp conventions): position 0:3, rotation 6D 3:9.
POSITION, ROTATION_6D = slice(0, 3), slice(3, 9)


@dataclass(frozen=True)
class AugmentConfig:
    """Magnitudes of each augmentation (0 turns one off).

    Attributes:
        shift: largest horizontal shift of the scene, metres (uniform in a square of this half-width).
        yaw: largest rotation about the vertical axis through `pivot`, radians.
        pivot: (x, y) of that axis, metres (the middle of the workspace).
        jitter: standard deviation of Gaussian noise added to every cloud point, metres.
        dropout: largest fraction of a cloud's points replaced by copies of its other points.
        lift: largest vertical shift of the scene, metres (uniform in [-lift, lift]). Demonstrations of one object
            size put every grasp at one height, and a policy learns that height rather than reading it off the
            cloud: open_drawer's handle sits 4 cm under the cabinet's top, 4 or 8 cm high on the 0.8 and 1.2
            instances against 6 cm in training (issue 36). The normaliser's z ranges are widened by `lift`
            (`widened_stats`) so that lifted actions stay inside the range the sampler clips to.
        stretch: largest relative vertical stretch of the scene about the table plane (z -> z * (1 + u), u uniform
            in [-stretch, stretch]): a taller or shorter world whose table stays where it is, as an object scaled
            by 1 + u stands on the same table (a lift moves the object's bottom off the table too). The
            normaliser's z ranges are widened to what it reaches.
    """

    shift: float = 0.02
    yaw: float = math.radians(5.0)
    pivot: tuple[float, float] = (0.45, 0.0)
    jitter: float = 0.002
    dropout: float = 0.1
    lift: float = 0.0
    stretch: float = 0.0

    def __post_init__(self):
        for name in ("shift", "yaw", "jitter", "dropout", "lift", "stretch"):
            if getattr(self, name) < 0:
                raise ValueError(f"AugmentConfig: {name} must be >= 0, got {getattr(self, name)}")
        if self.stretch >= 1:
            raise ValueError(f"AugmentConfig: stretch must be < 1, got {self.stretch}")
        if self.dropout >= 1:
            raise ValueError(f"AugmentConfig: dropout must be < 1, got {self.dropout}")

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        data["pivot"] = list(self.pivot)
        return data


def _rotate_xy(values: torch.Tensor, cos: torch.Tensor, sin: torch.Tensor) -> torch.Tensor:
    """Rotate the x, y components of (..., 3) vectors; cos/sin broadcast over the leading dims."""
    x, y = values[..., 0], values[..., 1]
    return torch.stack([cos * x - sin * y, sin * x + cos * y, values[..., 2]], dim=-1)


def augment_batch(batch: dict, visual_key: str | None, config: AugmentConfig, generator: torch.Generator) -> dict:
    """A new batch {"obs": {visual_key: (B, To, [K,] N, 3), "state": (B, To, 11)}, "action": (B, H, 10)}, raw units.

    `visual_key` names the world-frame xyz clouds moved with the scene; None for an input that is not one (images
    get no geometric augmentation: a moved scene would need a re-render), which passes through unchanged.
    """
    obs, actions = batch["obs"], batch["action"].float()
    state = obs["state"].float()
    batch_size = actions.shape[0]
    device = actions.device

    def uniform(scale: float, *shape: int) -> torch.Tensor:
        return (torch.rand(*shape, generator=generator, device=device) * 2 - 1) * scale

    angle = uniform(config.yaw, batch_size)
    shift = torch.zeros(batch_size, 3, device=device)
    shift[:, :2] = uniform(config.shift, batch_size, 2)
    if config.lift > 0:  # drawn only when asked for, so recipes without it keep their random stream
        shift[:, 2] = uniform(config.lift, batch_size)
    pivot = torch.tensor([*config.pivot, 0.0], device=device)
    cos, sin = angle.cos(), angle.sin()
    # drawn only when asked for, so recipes without it keep their random stream
    height_scale = 1.0 + uniform(config.stretch, batch_size) if config.stretch > 0 else None

    def move_points(points: torch.Tensor) -> torch.Tensor:  # (B, ..., 3)
        view = (batch_size,) + (1,) * (points.ndim - 2)
        moved = _rotate_xy(points - pivot, cos.view(view), sin.view(view)) + pivot + shift.view(*view, 3)
        if height_scale is not None:
            moved = torch.cat([moved[..., :2], moved[..., 2:] * height_scale.view(*view, 1)], dim=-1)
        return moved

    def move_poses(poses: torch.Tensor) -> torch.Tensor:  # (B, T, D) with position and rotation 6D columns
        moved = poses.clone()
        moved[..., POSITION] = move_points(poses[..., POSITION])
        view = (batch_size, 1)
        for column in (slice(3, 6), slice(6, 9)):  # R -> Rz R rotates each column of R
            moved[..., column] = _rotate_xy(poses[..., column], cos.view(view), sin.view(view))
        return moved

    new_obs = dict(obs)
    new_obs["state"] = move_poses(state)
    if visual_key is not None:
        clouds = move_points(obs[visual_key].float())
        if config.jitter > 0:
            clouds = clouds + torch.randn(clouds.shape, generator=generator, device=device) * config.jitter
        if config.dropout > 0:
            clouds = _drop_points(clouds, config.dropout, generator)
        new_obs[visual_key] = clouds
    return {**batch, "obs": new_obs, "action": move_poses(actions)}


def _drop_points(clouds: torch.Tensor, max_fraction: float, generator: torch.Generator) -> torch.Tensor:
    """Replace up to `max_fraction` of each cloud's points (one fraction per cloud) by copies of kept ones."""
    *lead, n, _ = clouds.shape
    flat = clouds.reshape(-1, n, 3)
    count = flat.shape[0]
    fraction = torch.rand(count, 1, generator=generator, device=clouds.device) * max_fraction
    order = torch.rand(count, n, generator=generator, device=clouds.device).argsort(dim=1)
    rank = torch.empty_like(order)
    rank.scatter_(1, order, torch.arange(n, device=clouds.device).expand(count, n))
    kept = n - (fraction * n).floor().long()  # (count, 1): the first `kept` points of `order` stay
    dropped = rank >= kept
    # each dropped point takes the place of a random kept point
    source = (torch.rand(count, n, generator=generator, device=clouds.device) * kept).long()
    replacement = torch.gather(flat, 1, torch.gather(order, 1, source).unsqueeze(-1).expand(count, n, 3))
    return torch.where(dropped.unsqueeze(-1), replacement, flat).reshape(*lead, n, 3)


def widened_stats(stats: dict, config: AugmentConfig, visual_key: str | None) -> dict:
    """Normaliser statistics {key: {"min": (D,), "max": (D,)}} with the z range of the positions (state and action
    columns 2, the clouds' z) widened by `config.lift` either side and by the stretch: what the augmented windows
    reach.

    Without it a lifted action below the demonstrations' lowest z normalises below -1, and the sampler's clip to
    [-1, 1] (clip_sample) keeps the policy from ever commanding it.
    """
    if config.lift <= 0 and config.stretch <= 0:
        return stats
    out = {key: {name: value.copy() for name, value in values.items()} for key, values in stats.items()}
    keys = [key for key in ("state", "action", visual_key) if key is not None and key in out]
    for key in keys:
        low, high = out[key]["min"][2] - config.lift, out[key]["max"][2] + config.lift
        reach = [value * (1 + sign * config.stretch) for value in (low, high) for sign in (-1, 1)]
        out[key]["min"][2], out[key]["max"][2] = min(reach), max(reach)
    return out
