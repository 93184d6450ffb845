"""Batch invariance: is a chunk sampled in a batch bit-equal to the chunk sampled alone, and what would equality cost?

A batched evaluation gives each episode its own noise, so a batched chunk differs from the chunk sampled alone only
by float rounding; that rounding still moved 2-3 of 50 guided episodes (`results/bench_eval_speed.json`). This
measures where the rounding comes from and what removing it would cost, on a packaged policy (--tasks), DDIM-10,
one torch thread, process CPU time:

    default       predict_action_chunk on a batch: how many rows equal their chunk sampled alone, bit for bit,
                  and the largest difference in the un-normalised trajectory
    per-sample    the same with every Linear, Conv1d and ConvTranspose1d of the policy called once per sample
                  (the kernels a batch of one takes); the rest of the network (GroupNorm, Mish, the cost) batched
    cost          CPU-ms per chunk alone, in a default batch and in a per-sample-kernel batch

Both unguided and guided (the paper's guidance on A_0|k on every step, one sphere in the path), since the
guided steps add a backward pass whose kernels also depend on the batch size.

    OMP_NUM_THREADS=1 python bench/bench_batch_invariance.py              # ~1 CPU-minute
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import torch
from torch import nn

from _contract import Unused, bench_parser, parse, write_results
from bench_eval_speed import observation
from lano3dp.guidance import GuidanceConfig
from lano3dp.guidance.costs.obstacles import Sphere
from lano3dp.policy import DiffusionPolicy
from lano3dp.policy.pretrained import packaged_checkpoint

# The layers whose CPU kernels depend on the batch size (oneDNN above one sample, im2col and one matrix product
# for one; matrix products pick kernels by shape); GroupNorm and the element-wise operations do not.
SHAPE_DEPENDENT = (nn.Linear, nn.Conv1d, nn.ConvTranspose1d, nn.Conv2d)


class PerSampleKernels:
    """Within `with`, every shape-dependent layer of `policy` runs once per sample of a batch of `batch`: its input
    split into `batch` equal parts along the first axis (a batch of clouds is (batch * slots, ...)), so each part
    has the shape it has when the sample is drawn alone."""

    def __init__(self, policy: DiffusionPolicy, batch: int):
        self.layers = [m for m in policy.modules() if isinstance(m, SHAPE_DEPENDENT)]
        self.batch = batch

    def __enter__(self) -> PerSampleKernels:
        for layer in self.layers:
            layer.forward = self._per_sample(layer.forward)
        return self

    def __exit__(self, *exc) -> None:
        for layer in self.layers:
            del layer.forward  # the instance attribute; the class's forward shows again

    def _per_sample(self, forward: Callable[[torch.Tensor], torch.Tensor]) -> Callable[[torch.Tensor], torch.Tensor]:
        def run(x: torch.Tensor) -> torch.Tensor:
            return torch.cat([forward(part) for part in x.chunk(self.batch)])
        return run


def sample(policy: DiffusionPolicy, obs: dict[str, np.ndarray], seeds: list[int], guided: bool) -> torch.Tensor:
    """The trajectories (B, H, D) of one call, each row from its own generator."""
    options: dict[str, Any] = {}
    if guided:  # a sphere among the sampled positions, pushed on every DDIM step
        options = {"guidance": GuidanceConfig(scale=1.0, last_steps=100),
                   "position_cost": Sphere((0.5, 0.0, 0.15), 0.05)}
    generators = [torch.Generator().manual_seed(seed) for seed in seeds]
    return policy.predict_action_chunk(obs, generator=generators, **options).trajectory.detach()


def rows(obs: dict[str, np.ndarray], index: int) -> dict[str, np.ndarray]:
    return {key: value[index:index + 1] for key, value in obs.items()}


def measure(policy: DiffusionPolicy, batch: int, chunks: int, guided: bool) -> dict[str, Any]:
    """Bit equality with the chunks sampled alone, and CPU-ms per chunk, of a default and a per-sample batch."""
    equal = {"default": 0, "per_sample": 0}
    largest = {"default": 0.0, "per_sample": 0.0}
    spent: dict[str, list[float]] = {"alone": [], "default": [], "per_sample": []}
    for call in range(chunks + 1):  # the first warms up
        obs = observation(policy, call, batch)
        seeds = [1000 * call + i for i in range(batch)]
        started = time.process_time()
        alone = torch.cat([sample(policy, rows(obs, i), seeds[i:i + 1], guided) for i in range(batch)])
        times = {"alone": time.process_time() - started}
        started = time.process_time()
        made = {"default": sample(policy, obs, seeds, guided)}
        times["default"] = time.process_time() - started
        with PerSampleKernels(policy, batch):
            started = time.process_time()
            made["per_sample"] = sample(policy, obs, seeds, guided)
            times["per_sample"] = time.process_time() - started
        if not call:
            continue
        for mode, trajectory in made.items():
            equal[mode] += int((trajectory == alone).flatten(1).all(1).sum())
            largest[mode] = max(largest[mode], float((trajectory - alone).abs().max()))
        for mode, seconds in times.items():
            spent[mode].append(1000 * seconds / batch)
    cost = {mode: round(statistics.median(values), 2) for mode, values in spent.items()}
    return {"batch": batch, "chunks": chunks * batch, "guided": guided,
            "bit_equal_chunks": equal, "largest_difference": largest, "cpu_ms_per_chunk": cost,
            "alone_over_default": round(cost["alone"] / cost["default"], 2),
            "alone_over_per_sample": round(cost["alone"] / cost["per_sample"], 2)}


def main(argv: list[str] | None = None) -> None:
    parser = bench_parser(__file__, __doc__, tasks="put_item_in_drawer",
                          episodes=Unused("it samples chunks, not episodes (--chunks)"),
                          seed=Unused("the observations and noise seeds are fixed per call"),
                          workers=Unused("one process, one torch thread"))
    parser.add_argument("--batches", default="2,16", help="batch sizes, comma-separated (default: 2,16)")
    parser.add_argument("--chunks", type=int, default=3, help="calls per batch size (default: 3)")
    args = parse(parser, argv)
    torch.set_num_threads(1)
    if len(args.tasks) != 1:
        parser.error("--tasks takes one packaged policy here")
    policy = DiffusionPolicy.from_pretrained(packaged_checkpoint(args.tasks[0]))
    cells = []
    for guided in (False, True):
        for batch in (int(b) for b in args.batches.split(",")):
            cells.append(measure(policy, batch, args.chunks, guided))
            print(cells[-1], flush=True)
    write_results("batch_invariance", args, {"cells": cells})  # its page: docs/benchmarks/components.md


if __name__ == "__main__":
    main()
