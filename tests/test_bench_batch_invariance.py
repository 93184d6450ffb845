"""bench_batch_invariance's per-sample kernels: a batch sampled through them is the chunks sampled alone, bit for
bit (what its results claim), and leaving them gives the policy its own layers back."""

import torch

from bench_loader import load_bench
from lano3dp.policy import DiffusionPolicy
from lano3dp.policy.pretrained import packaged_checkpoint

bench = load_bench("bench_batch_invariance")


def test_per_sample_kernels_sample_each_chunk_as_it_is_sampled_alone():
    policy = DiffusionPolicy.from_pretrained(packaged_checkpoint("bowl_pour"))
    obs = bench.observation(policy, 5, 3)
    for guided in (False, True):
        alone = torch.cat([bench.sample(policy, bench.rows(obs, i), [20 + i], guided) for i in range(3)])
        with bench.PerSampleKernels(policy, 3) as kernels:
            together = bench.sample(policy, obs, [20, 21, 22], guided)
        assert torch.equal(together, alone), f"guided={guided}"
    assert kernels.layers and all("forward" not in vars(layer) for layer in kernels.layers)
