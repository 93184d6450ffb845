"""Where a training step's CPU time goes, per policy configuration and observation type; inference latency.

A training step is split as lano3dp.train runs it: data loading (windows from a SequenceDataset over a
zarr store of random episodes, collated), point or image encoder, state encoder, UNet and loss forward,
then the backward of each of them (autograd is stopped at the encoders' outputs so each part is timed
alone), fused AdamW and the EMA update. Each part is reported in CPU milliseconds per training sample
(process CPU time, `time.process_time`, median over steps), and the configurations are measured side by
side in one run so that their ratio holds even on a busy machine:

    previous   the default before the learning-efficiency work (d63c154): 2 x 128 points, 2 observation
               steps, point MLP 64-128-256, UNet 64-128-256, step embedding 128 (5.9 M parameters)
    default    PolicyConfig() today (lano3dp.policy.config)

Inference = predict_action_chunk at batch 1 of the default: DDIM-10, DDPM-100, and DDIM-10 with cost
guidance on every step (the recommended preset's sampler at rho 0.01).

    OMP_NUM_THREADS=1 python bench/bench_policy.py [--threads 1]

Writes <out-dir>/bench_policy<tag>.json.
"""

from __future__ import annotations

import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch.utils.data import default_collate

from _contract import Unused, bench_parser, parse, write_results
from lano3dp.data import EpisodeStore, SequenceDataset
from lano3dp.guidance.settings import guidance_preset
from lano3dp.policy import DiffusionPolicy, PolicyConfig
from lano3dp.policy.checkpoint import EMA
from lano3dp.runtime.sampling import guidance_config

SLOTS = ("object_0", "object_1")
CONFIGS = {
    "previous": dict(n_points=128, n_obs_steps=2, down_dims=(64, 128, 256), point_hidden_dims=(64, 128, 256),
                     diffusion_step_embed_dim=128),
    "default": {},
}
PARTS = ("data", "visual_forward", "state_forward", "unet_loss_forward", "unet_loss_backward", "visual_backward",
         "state_backward", "optimizer", "ema")


def make_policy(obs_type: str, seed: int = 0, **changes) -> DiffusionPolicy:
    torch.manual_seed(seed)
    config = PolicyConfig(obs_type=obs_type, object_names=SLOTS if obs_type == "objects" else (), **changes)
    policy = DiffusionPolicy(config)
    stats = {"action": {"min": -np.ones(10), "max": np.ones(10)}, "state": {"min": -np.ones(11), "max": np.ones(11)}}
    if obs_type != "image":
        stats[config.visual_key] = {"min": -np.ones(3), "max": np.ones(3)}
    policy.set_normalizer(stats)
    return policy


def random_store(path: Path, config: PolicyConfig, episodes: int = 12, length: int = 80,
                 seed: int = 0) -> EpisodeStore:
    """A zarr store of random episodes with the keys and shapes `config` reads (the values do not matter)."""
    rng = np.random.default_rng(seed)
    store = EpisodeStore.create(path, attrs={"object_names": list(config.object_names)})
    visual = {"objects": (config.n_slots, config.n_points, 3), "scene": (config.scene_points, 3),
              "image": (config.image_size, config.image_size, 3)}[config.obs_type]
    for _ in range(episodes):
        episode = {"state": rng.random((length, config.state_dim), dtype=np.float32),
                   "action": rng.random((length, config.action_dim), dtype=np.float32)}
        if config.obs_type == "image":
            episode["rgb"] = rng.integers(0, 255, (length, *visual), dtype=np.uint8)
        else:
            episode[config.visual_key] = rng.random((length, *visual), dtype=np.float32) * 0.4 - 0.2
        store.append_episode(episode)
    return store


def time_training(policy: DiffusionPolicy, dataset: SequenceDataset, batch: int, steps: int,
                  seed: int = 0) -> dict[str, float]:
    """Median CPU seconds of each part of a training step (see the module docstring)."""
    config = policy.config
    generator = torch.Generator().manual_seed(seed)
    rng = np.random.default_rng(seed)
    optimizer = torch.optim.AdamW(policy.parameters(), lr=5e-4, betas=(0.95, 0.999), weight_decay=1e-6, fused=True)
    ema = EMA(policy)
    encoder = policy.obs_encoder
    times: dict[str, list[float]] = {part: [] for part in PARTS}
    for step in range(steps + 3):  # the first steps warm up oneDNN's kernels
        marks = [time.process_time()]
        data = default_collate([dataset[int(i)] for i in rng.integers(0, len(dataset), batch)])
        marks.append(time.process_time())
        obs = policy._prepare_obs(data["obs"])
        visual = encoder.visual(obs[config.visual_key].flatten(0, 1))
        marks.append(time.process_time())
        state = encoder.state(obs["state"].flatten(0, 1))
        marks.append(time.process_time())
        visual_out, state_out = visual.detach().requires_grad_(), state.detach().requires_grad_()
        cond = torch.cat([visual_out, state_out], dim=-1).reshape(batch, -1)
        trajectory = policy.normalize_actions(data["action"].float(), data["obs"]["state"])
        noise = torch.randn(trajectory.shape, generator=generator)
        timesteps = torch.randint(0, config.num_train_timesteps, (batch,), generator=generator)
        loss = F.mse_loss(policy.unet(policy.noise_scheduler.add_noise(trajectory, noise, timesteps), timesteps,
                                      cond), noise)
        marks.append(time.process_time())
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        marks.append(time.process_time())
        visual.backward(visual_out.grad)
        marks.append(time.process_time())
        state.backward(state_out.grad)
        marks.append(time.process_time())
        optimizer.step()
        marks.append(time.process_time())
        ema.update(policy)
        marks.append(time.process_time())
        if step >= 3:
            for part, begin, end in zip(PARTS, marks[:-1], marks[1:], strict=True):
                times[part].append(end - begin)
    return {part: statistics.median(values) for part, values in times.items()}


def time_inference(policy: DiffusionPolicy, repeats: int, seed: int = 0, **kwargs) -> dict[str, float]:
    config = policy.config
    generator = torch.Generator().manual_seed(seed)
    obs = {"object_clouds": torch.rand(1, config.n_obs_steps, config.n_slots, config.n_points, 3) * 0.4 - 0.2,
           "state": torch.rand(1, config.n_obs_steps, config.state_dim) * 2 - 1}
    wall, cpu = [], []
    for index in range(repeats + 1):
        start, start_cpu = time.perf_counter(), time.process_time()
        policy.predict_action_chunk(obs, generator=generator, **kwargs)
        if index:
            wall.append(time.perf_counter() - start)
            cpu.append(time.process_time() - start_cpu)
    return {"median_cpu_s": statistics.median(cpu), "median_wall_s": statistics.median(wall), "n": len(cpu)}


def hinge_cost(positions: torch.Tensor) -> torch.Tensor:
    """(B, H, 3) -> (B,): sum of max(0, 0.1 m - xy distance to an obstacle at the origin)."""
    return torch.relu(0.1 - positions[..., :2].norm(dim=-1)).sum(dim=-1)


def main(argv=None) -> None:
    parser = bench_parser(__file__, __doc__, tasks=Unused("it times policy configurations on random data"),
                          episodes=Unused("it times training steps and chunks: see --train-steps, --repeats"),
                          seed=0, workers=Unused("it times one process; see --threads"))
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--train-steps", type=int, default=12)
    parser.add_argument("--obs-types", default="objects,scene,image")
    parser.add_argument("--repeats", type=int, default=10, help="inference repetitions (DDPM-100: a third)")
    args = parse(parser, argv)
    torch.set_num_threads(args.threads)
    load_before = os.getloadavg()
    training: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as folder:
        for obs_type in args.obs_types.split(","):
            for name, changes in CONFIGS.items():
                policy = make_policy(obs_type, seed=args.seed, **changes).train()
                config = policy.config
                store = random_store(Path(folder) / f"{obs_type}_{name}.zarr", config, seed=args.seed)
                dataset = SequenceDataset(store, obs_keys=config.obs_keys, n_obs_steps=config.n_obs_steps,
                                          horizon=config.horizon, n_action_steps=config.n_action_steps)
                parts = time_training(policy, dataset, args.batch, args.train_steps, seed=args.seed)
                total = sum(parts.values())
                entry = {"parameters": sum(p.numel() for p in policy.parameters()),
                         "config": {key: config.to_dict()[key] for key in ("n_points", "n_obs_steps", "down_dims",
                                                                            "point_hidden_dims",
                                                                            "diffusion_step_embed_dim")},
                         "cpu_s_per_step": total, "cpu_ms_per_sample": 1000 * total / args.batch,
                         "cpu_ms_per_sample_by_part": {k: 1000 * v / args.batch for k, v in parts.items()}}
                training[f"{obs_type}/{name}"] = entry
                print(f"{obs_type:8s} {name:9s} {entry['parameters'] / 1e6:5.2f} M  {total:.3f} CPU-s/step  "
                      f"{entry['cpu_ms_per_sample']:.2f} ms/sample  " + " ".join(
                          f"{k} {v:.2f}" for k, v in entry["cpu_ms_per_sample_by_part"].items()), flush=True)
    ratios = {obs_type: training[f"{obs_type}/previous"]["cpu_ms_per_sample"] /
              training[f"{obs_type}/default"]["cpu_ms_per_sample"] for obs_type in args.obs_types.split(",")}
    print("previous / default, CPU per training sample: " + ", ".join(f"{k} {v:.2f}x" for k, v in ratios.items()))

    policy = make_policy("objects", seed=args.seed).eval()
    cases = {
        "ddim_10": dict(scheduler="ddim", num_inference_steps=10),
        "ddpm_100": dict(scheduler="ddpm", num_inference_steps=100),
        "ddim_10_guided_every_step": dict(scheduler="ddim", num_inference_steps=10, position_cost=hinge_cost,
                                          guidance=guidance_config(guidance_preset("recommended").with_changes(
                                              {"sampler.rho": 0.01}))),
    }
    inference = {}
    for name, kwargs in cases.items():
        repeats = max(3, args.repeats // 3) if name.startswith("ddpm") else args.repeats
        inference[name] = time_inference(policy, repeats, seed=args.seed, **kwargs)
        print(f"inference {name}: {1000 * inference[name]['median_cpu_s']:.1f} CPU-ms", flush=True)

    path = write_results("bench_policy", args, {
        "batch": args.batch,
        "training": training,
        "previous_over_default_cpu_per_sample": ratios,
        "inference_batch1_default_objects": inference,
        "load_average_before": load_before, "load_average_after": os.getloadavg(),
        "note": "process CPU time (all threads), medians; both configurations measured in this one run. "
                "Backward parts: autograd stopped at the encoders' outputs, so each part is timed alone.",
    }, kind="policy")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
