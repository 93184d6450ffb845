"""The runtime on a CUDA device: a shipped policy's guided episodes with every chunk filter, and batched sampling.

CI has no GPU, so this is a check run where one is lent: the packaged put_item_in_drawer policy is loaded on the
CPU and on `--device`, and drives the same synthetic scene (boxes seen by a calibrated camera, the real ground-truth
segmenter and observer; no simulator) with the recommended guidance and all its filters. Recorded per device: that
every chunk was sampled and filtered without a device error, the guided chunks' largest difference from the CPU's
(float rounding of other kernels), the episode's steps and path; and the batched sampler on the device against
each episode alone. One run: `python bench/bench_cuda_runtime.py --device cuda`.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import torch

from _contract import Unused, bench_parser, parse, write_results
from lano3dp.geometry.frame import observe
from lano3dp.geometry.rotations import matrix_to_rot6d
from lano3dp.guidance.settings import guidance_preset
from lano3dp.perception import ObjectObserver, SimOracleSegmenter
from lano3dp.perception.synthetic import Box, render_boxes, top_down_camera
from lano3dp.policy import DiffusionPolicy
from lano3dp.policy.pretrained import packaged_checkpoint
from lano3dp.runtime import PolicyRunner, rollout

BLOCK = Box("block", (0.35, 0.20), (0.04, 0.04, 0.04), {"kind": "block", "color": "blue", "role": "target"})
DRAWER = Box("drawer", (0.58, -0.10), (0.20, 0.25, 0.10), {"kind": "drawer", "color": "brown", "role": "target"})
POST = Box("obstacle_0", (0.33, 0.10), (0.06, 0.06, 0.30), {"kind": "cylinder", "color": "grey", "role": "obstacle"})
ROT6D = matrix_to_rot6d(np.diag([1.0, -1.0, -1.0])).astype(np.float32)  # fingers down


class BoxesEnv:
    """The hand reaches each commanded position exactly over a static scene (no contact physics)."""

    max_ee_step = 0.05

    def __init__(self):
        self.frame = render_boxes(top_down_camera(size=128, height=1.2, fovy_deg=50, tilt_deg=25),
                                  [BLOCK, DRAWER, POST])

    def reset(self, *, seed=None, options=None):
        self.position, self.gripper = np.array([0.3, 0.0, 0.3]), 0.04
        return self._obs(), {}

    def _obs(self):
        return {"frame": self.frame, "state": np.concatenate([self.position, ROT6D, [self.gripper, 0.0]])
                .astype(np.float32)}

    def step(self, action):
        self.position = np.asarray(action[:3], dtype=np.float64)
        return self._obs(), 0.0, False, False, {}


def episode(device: str, steps: int) -> dict[str, Any]:
    policy = DiffusionPolicy.from_pretrained(packaged_checkpoint("put_item_in_drawer"), device=device)
    observer = ObjectObserver(SimOracleSegmenter(), n_points=policy.config.n_points, min_points=5)
    runner = PolicyRunner(policy, observer, guidance_preset("recommended"), step_limit=BoxesEnv.max_ee_step,
                          target_phrases=["block", "drawer"], obstacle_phrases=["obstacle_0"], held_object="block")
    started = time.perf_counter()
    result = rollout(BoxesEnv(), runner, seed=0, max_steps=steps, success_at="end")
    return {"device": device, "error": result.error, "steps": result.steps, "path_length": result.path_length,
            "chunks": len(runner.chunks), "guided_chunks": sum(c.scale > 0 for c in runner.chunks),
            "filter_notes": [c.notes for c in runner.chunks], "executed": [c.executed for c in runner.chunks],
            "wall_s": round(time.perf_counter() - started, 2),
            "trajectories": [c.trajectory for c in runner.chunks]}


def batched(device: str, batch: int) -> dict[str, Any]:
    policy = DiffusionPolicy.from_pretrained(packaged_checkpoint("put_item_in_drawer"), device=device)
    env = BoxesEnv()
    frame, state = observe(env, env.reset(seed=0)[0])
    observer = ObjectObserver(SimOracleSegmenter(), n_points=policy.config.n_points, min_points=5)
    clouds = observer.observe(frame, ["block", "drawer"]).points
    window = {"object_clouds": torch.as_tensor(np.repeat(clouds[None, None], batch, 0)),
              "state": torch.as_tensor(np.repeat(state[None, None], batch, 0))}
    together = policy.predict_action_chunk(window, generator=[torch.Generator().manual_seed(i) for i in range(batch)])
    alone = [policy.predict_action_chunk({k: v[i:i + 1] for k, v in window.items()},
                                         generator=torch.Generator().manual_seed(i)) for i in range(batch)]
    difference = max(float((together.trajectory[i] - a.trajectory[0]).abs().max()) for i, a in enumerate(alone))
    return {"device": device, "batch": batch, "max_difference_batched_vs_alone": difference,
            "output_device": str(together.trajectory.device)}


def main(argv=None) -> None:
    parser = bench_parser(__file__, __doc__, tasks=Unused("the packaged put_item_in_drawer policy is the subject"),
                          episodes=Unused("one episode per device"), seed=Unused("seed 0"),
                          workers=Unused("one process"))
    parser.add_argument("--device", default="cuda")
    parser.add_argument("--steps", type=int, default=24)
    args = parse(parser, argv)
    torch.set_num_threads(1)
    cpu, other = episode("cpu", args.steps), episode(args.device, args.steps)
    differences = [float(np.abs(a - b).max()) for a, b in zip(cpu.pop("trajectories"), other.pop("trajectories"),
                                                             strict=False)]
    body = {"cpu": cpu, args.device: other, "max_chunk_difference_m_or_units": max(differences, default=None),
            "chunk_differences": differences, "batched": batched(args.device, 8),
            "device_name": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
            "torch": torch.__version__}
    print({k: v for k, v in body.items() if k not in ("cpu", args.device)})
    write_results("cuda_runtime", args, body)


if __name__ == "__main__":
    main()
