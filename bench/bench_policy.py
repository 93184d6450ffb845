"""Benchmark the diffusion policy on this machine: training steps/s and inference latency.

Training step = what lano3dp.train does per step: observation encoding, UNet forward/backward, fused
AdamW, EMA update (random tensors of the right shapes, so data loading is not included).
Inference = predict_action_chunk at batch 1: DDPM-100, DDIM-10, and DDIM-10 with cost guidance on
every step (a cylinder-like hinge cost on the xy distance, written inline).

    OMP_NUM_THREADS=2 python bench/bench_policy.py [--threads 2] [--size small] [--out results/bench_policy.json]

Timings are wall-clock medians, with the process CPU time beside them; the machine may be shared, so
the load average before and after is recorded with them. With one thread and a busy machine, the CPU
time is the better estimate of the quiet wall time.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path

import numpy as np
import torch

from lano3dp.guidance import GuidanceConfig
from lano3dp.policy import DiffusionPolicy, PolicyConfig, down_dims_for
from lano3dp.policy.checkpoint import EMA


def make_policy(size: str, n_objects: int, encoder: str) -> DiffusionPolicy:
    torch.manual_seed(0)
    config = PolicyConfig(object_names=tuple(f"object_{i}" for i in range(n_objects)), down_dims=down_dims_for(size),
                          point_encoder=encoder)
    policy = DiffusionPolicy(config)
    ones = {"min": -np.ones(3), "max": np.ones(3)}
    policy.set_normalizer({"action": {"min": -np.ones(10), "max": np.ones(10)},
                           "state": {"min": -np.ones(11), "max": np.ones(11)}, "object_clouds": ones})
    return policy


def random_obs(config: PolicyConfig, batch: int, n_points: int, generator: torch.Generator) -> dict:
    clouds = torch.rand(batch, config.n_obs_steps, config.n_slots, n_points, 3, generator=generator) * 0.4 - 0.2
    state = torch.rand(batch, config.n_obs_steps, config.state_dim, generator=generator) * 2 - 1
    return {"object_clouds": clouds, "state": state}


def time_training(policy: DiffusionPolicy, batch: int, n_points: int, steps: int, bf16: bool) -> tuple[list, list]:
    generator = torch.Generator().manual_seed(0)
    optimizer = torch.optim.AdamW(policy.parameters(), lr=5e-4, betas=(0.95, 0.999), weight_decay=1e-6, fused=True)
    ema = EMA(policy)
    data = {"obs": random_obs(policy.config, batch, n_points, generator),
            "action": torch.rand(batch, policy.config.horizon, 10, generator=generator) * 2 - 1}
    durations, cpu = [], []
    for step in range(steps + 3):  # the first steps warm up oneDNN's kernels
        start, start_cpu = time.perf_counter(), time.process_time()
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            loss = policy.compute_loss(data, generator=generator)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        ema.update(policy)
        if step >= 3:
            durations.append(time.perf_counter() - start)
            cpu.append(time.process_time() - start_cpu)
    return durations, cpu


def time_inference(policy: DiffusionPolicy, n_points: int, repeats: int, **kwargs) -> tuple[list, list]:
    generator = torch.Generator().manual_seed(0)
    obs = random_obs(policy.config, 1, n_points, generator)
    durations, cpu = [], []
    for index in range(repeats + 1):
        start, start_cpu = time.perf_counter(), time.process_time()
        policy.predict_action_chunk(obs, generator=generator, **kwargs)
        if index:
            durations.append(time.perf_counter() - start)
            cpu.append(time.process_time() - start_cpu)
    return durations, cpu


def hinge_cost(positions: torch.Tensor) -> torch.Tensor:
    """(B, H, 3) -> (B,): sum of max(0, 0.1 m - xy distance to an obstacle at the origin)."""
    distance = positions[..., :2].norm(dim=-1)
    return torch.relu(0.1 - distance).sum(dim=-1)


def summary(timings: tuple[list, list]) -> dict:
    """Wall-clock median/min/max, and the median process CPU time (the sum over threads)."""
    durations, cpu = timings
    return {"median_s": statistics.median(durations), "min_s": min(durations), "max_s": max(durations),
            "median_cpu_s": statistics.median(cpu), "n": len(durations)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--size", default="small", choices=["small", "medium", "dp"])
    parser.add_argument("--encoder", default="residual", choices=["residual", "mlp"])
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--n-points", type=int, default=256, help="points per object")
    parser.add_argument("--n-objects", type=int, default=2)
    parser.add_argument("--train-steps", type=int, default=20)
    parser.add_argument("--repeats", type=int, default=10, help="inference repetitions (DDPM-100: a third)")
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parents[1] / "results" /
                        "bench_policy.json")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    load_before = os.getloadavg()
    started = time.time()

    policy = make_policy(args.size, args.n_objects, args.encoder)
    parameters = sum(p.numel() for p in policy.parameters())
    results: dict = {"training": {}, "inference_batch1": {}}
    for bf16 in (False, True):
        entry = summary(time_training(policy.train(), args.batch, args.n_points, args.train_steps, bf16))
        entry["steps_per_s"] = 1.0 / entry["median_s"]
        results["training"]["bf16_autocast" if bf16 else "fp32"] = entry
        print(f"train {'bf16' if bf16 else 'fp32'}: {entry['steps_per_s']:.2f} steps/s "
              f"({entry['median_s'] * 1000:.0f} ms/step)", flush=True)
    policy.eval()
    cases = {
        "ddim_10": dict(scheduler="ddim", num_inference_steps=10),
        "ddpm_100": dict(scheduler="ddpm", num_inference_steps=100),
        "ddim_10_guided_every_step": dict(scheduler="ddim", num_inference_steps=10, position_cost=hinge_cost,
                                          guidance=GuidanceConfig(scale=0.01, last_steps=100)),
    }
    for name, kwargs in cases.items():
        repeats = max(3, args.repeats // 3) if name.startswith("ddpm") else args.repeats
        entry = summary(time_inference(policy, args.n_points, repeats, **kwargs))
        results["inference_batch1"][name] = entry
        print(f"{name}: {entry['median_s'] * 1000:.1f} ms", flush=True)

    record = {
        "benchmark": "bench/bench_policy.py",
        "command": f"OMP_NUM_THREADS={args.threads} python bench/bench_policy.py --threads {args.threads} "
                   f"--size {args.size} --batch {args.batch} --n-points {args.n_points} --n-objects {args.n_objects}",
        "when_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(started)),
        "machine": {"cpu_count": os.cpu_count(), "processor": platform.processor() or platform.machine(),
                    "torch": torch.__version__, "threads": torch.get_num_threads(),
                    "load_average_before": load_before, "load_average_after": os.getloadavg()},
        "setup": {"size": args.size, "down_dims": list(policy.config.down_dims), "encoder": args.encoder,
                  "parameters": parameters, "batch": args.batch, "objects": args.n_objects,
                  "points_per_object": args.n_points, "horizon": policy.config.horizon,
                  "n_obs_steps": policy.config.n_obs_steps},
        "results": results,
        "note": "wall-clock medians on a machine shared with other jobs; compare with the load averages. "
                "median_cpu_s is process CPU time (all threads).",
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(record, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
