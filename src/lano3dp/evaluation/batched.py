"""Batched rollouts: several episodes stepped together in one process, their chunks sampled in one policy call.

At batch 1 the UNet's many small operations cost more in dispatch than in arithmetic, so sampling 8 chunks in one
call costs a fraction of 8 calls. Each episode runs in its own thread with its own env, runner and control state
(`PolicyHandle`); when it needs a chunk it hands the request to the `Batcher` and waits. When every running episode
is waiting, the batcher samples all of them at once, grouped by what the sampler needs alike (guidance, scheduler,
steps): the observation windows concatenated, each episode's own noise generator (so its noise is what it would be
alone), each guided episode's own obstacle cost (`BatchedCost`: row i is costed by episode i's obstacles).

Threads rather than processes: the envs' simulation and perception are what the threads interleave (their CPU time
counts as before); one torch thread does every sampling call. Each thread builds and renders its own env (their
renderers draw in turn in one shared GL context, `sim.render`). The threads take turns (`Batcher.turn`): one
works from one chunk request to the next while the others wait, instead of all switching every few milliseconds
(the GIL's interval) with 16 working sets in one core's caches; that cost 11-14% more CPU per batched evaluation
(two runs each, 50 episodes at batch 16), and nothing runs in parallel on one torch thread anyway.

A batched chunk equals the chunk sampled alone up to float rounding (matrix products of another batch size take
other kernels; about 1e-6 in the normalised action): the noise is the same, an episode's outcome can still differ
where a contact turns on such a difference. `bench/bench_eval_speed.py` measures both;
`bench/bench_batch_invariance.py` what bit-equal chunks would cost (the one-sample kernels: most of the saving).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import torch

from lano3dp.evaluation.config import EvalConfig
from lano3dp.guidance.settings import GuidanceSettings
from lano3dp.policy.modeling import ActionChunk, ChunkedControl


class BatchedCost:
    """Per-row obstacle costs as one cost on a batch: row i of (B, T, 3) positions is costed by `costs[i]`."""

    def __init__(self, costs):
        self.costs = list(costs)

    def __call__(self, positions: torch.Tensor) -> torch.Tensor:
        return torch.cat([cost(positions[i:i + 1]) for i, cost in enumerate(self.costs)])

    def clearance(self, positions: torch.Tensor) -> torch.Tensor:
        return torch.cat([cost.clearance(positions[i:i + 1]) for i, cost in enumerate(self.costs)])


@dataclass
class _Request:
    window: dict[str, torch.Tensor]
    options: dict[str, Any]
    done: threading.Event = field(default_factory=threading.Event)
    chunk: ActionChunk | None = None
    error: BaseException | None = None

    def key(self) -> tuple:
        """What requests sampled in one call must share: everything but the window, the cost and the noise."""
        guidance = self.options.get("guidance")
        return (guidance, self.options.get("scheduler"), self.options.get("num_inference_steps"))


class Batcher:
    """Collects chunk requests from the episodes' threads and samples them together once all are waiting."""

    def __init__(self, policy):
        self.policy = policy
        self.lock = threading.Lock()
        self.live = 0
        self.waiting: list[_Request] = []
        self.calls = 0  # policy calls made (for the benchmark: chunks per call)
        # Held by the one episode thread that works; `sample` hands it on while the thread waits for its chunk.
        self.turn = threading.Lock()

    def join(self) -> None:
        with self.lock:
            self.live += 1

    def leave(self) -> None:
        with self.lock:
            self.live -= 1
            self._run_if_all_wait()

    def sample(self, window: dict[str, torch.Tensor], **options) -> ActionChunk:
        request = _Request(window, options)
        with self.lock:
            self.waiting.append(request)
            self._run_if_all_wait()
        self.turn.release()
        request.done.wait()
        self.turn.acquire()
        if request.error is not None:
            raise request.error
        return request.chunk

    def _run_if_all_wait(self) -> None:
        """(Holding the lock.) Sample every waiting request when no running episode is still working."""
        if not self.waiting or len(self.waiting) < self.live:
            return
        waiting, self.waiting = self.waiting, []
        groups: dict[tuple, list[_Request]] = {}
        for request in waiting:
            groups.setdefault(request.key(), []).append(request)
        for group in groups.values():
            self._sample_group(group)

    def _sample_group(self, group: list[_Request]) -> None:
        options = dict(group[0].options)
        try:
            window = {key: torch.cat([r.window[key] for r in group]) for key in group[0].window}
            if options.get("position_cost") is not None:
                options["position_cost"] = BatchedCost(r.options["position_cost"] for r in group)
            options["generator"] = [r.options["generator"] for r in group]
            chunk = self.policy.predict_action_chunk(window, **options)
            self.calls += 1
            for i, request in enumerate(group):
                request.chunk = ActionChunk(chunk.actions[i:i + 1], chunk.trajectory[i:i + 1])
        except BaseException as error:  # every episode of the call fails with it, and says why
            for request in group:
                request.error = error
        for request in group:
            request.done.set()


class PolicyHandle(ChunkedControl):
    """One episode's control state (observation window, action queue) over a policy shared by a batch; its chunks
    are sampled through the batcher."""

    def __init__(self, policy, batcher: Batcher):
        self.policy, self.batcher = policy, batcher
        self.config, self.normalizer = policy.config, policy.normalizer
        self.reset()

    @property
    def device(self) -> torch.device:
        return self.policy.device

    def predict_action_chunk(self, obs, **options) -> ActionChunk:
        return self.batcher.sample(obs, **options)


def run_batched(config: EvalConfig, guidance: GuidanceSettings, jobs: list, finished: Callable, bundle) -> int:
    """Run `jobs` (pool.Job) in `config.batch` threads of one process; `finished(index, record)` as each ends
    (called under a lock). Returns the number of episodes run together at most."""
    from lano3dp.evaluation.episodes import EpisodeRunner

    batcher = Batcher(bundle.policy)
    todo = list(reversed(jobs))
    lock = threading.Lock()
    errors: list[BaseException] = []

    def episode_thread() -> None:
        runner = None
        with batcher.turn:
            try:
                runner = EpisodeRunner(config, guidance, bundle, policy=PolicyHandle(bundle.policy, batcher))
                while True:
                    with lock:
                        if not todo or errors:
                            return
                        job = todo.pop()
                    record = runner.run(job.seed, job.video, job.rerun)
                    with lock:
                        finished(job.index, record)
            except BaseException as error:
                with lock:
                    errors.append(error)
            finally:
                batcher.leave()
                if runner is not None:
                    runner.close()

    threads = [threading.Thread(target=episode_thread, daemon=True) for _ in range(min(config.batch, len(jobs)))]
    for _ in threads:  # every episode counts as running before any can wait
        batcher.join()
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    if errors:
        raise errors[0]
    return len(threads)
