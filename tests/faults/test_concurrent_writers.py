"""One writer per output: a second writer of a dataset, a run or a results file (two evaluations writing one
results file) is refused at once, naming the first one's PID, however the output is spelled; the first one's
result is untouched."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import pytest
from typer.testing import CliRunner

from faults_common import EXAMPLE_ENV, assert_one_line, subprocess_env
from lano3dp.cli import app
from lano3dp.evaluation import EvalConfig, episode_log_path, evaluate
from lano3dp.locking import LockedError, lock_path
from lano3dp.train import Trainer
from test_stale_locks import hold_lock
from test_train import micro_config


def test_a_second_writer_is_refused_with_the_holders_pid(reach_data, tiny_checkpoint, tmp_path):
    from lano3dp.collect import collect

    dataset, run, results = tmp_path / "d.zarr", tmp_path / "run", tmp_path / "r.json"
    holders = [hold_lock(target) for target in (dataset, run, results)]
    try:
        for holder, attempt in zip(holders, [
            lambda: collect("open_drawer", 1, dataset, progress=False),
            lambda: Trainer(micro_config(reach_data, run)),
            lambda: evaluate(EvalConfig(checkpoint=str(tiny_checkpoint), task="open_drawer", episodes=1,
                                        out=str(results))),
        ], strict=True):
            with pytest.raises(LockedError, match=rf"is being written by process {holder.pid} "):
                attempt()
        assert not dataset.exists() and not run.exists() and not results.exists()  # nothing written
        result = CliRunner().invoke(app, ["train", "--data", str(reach_data), "--out", str(run)])
        assert_one_line(result, 1, f"being written by process {holders[1].pid}")
    finally:
        for holder in holders:
            holder.kill()
            holder.wait()


SLOW_ENV = '''
import os, sys, time

sys.path.insert(0, {examples!r})
from own_env import make_env as make_reach_env

DELAY = float(os.environ.get("ENV_STEP_DELAY_S", "0"))


class Slow:
    """The example env, each step taking DELAY seconds (a real robot's pace), so a second writer meets it."""

    def __init__(self, env):
        self.env, self.max_steps, self.control_hz = env, env.max_steps, env.control_hz

    def reset(self, *, seed=None, options=None):
        return self.env.reset(seed=seed)

    def step(self, action):
        time.sleep(DELAY)
        return self.env.step(action)


def make_env(**options):
    return Slow(make_reach_env(**options))
'''


def test_two_evaluations_writing_one_results_file_the_second_is_refused_and_the_first_finishes(
        reach_checkpoint, tmp_path):
    (tmp_path / "slow_env.py").write_text(SLOW_ENV.format(examples=str(EXAMPLE_ENV.parent)))
    env = f"{tmp_path / 'slow_env.py'}:make_env"
    (tmp_path / "results").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "results")
    out = tmp_path / "results" / "r.json"
    args = ["eval", "--checkpoint", str(reach_checkpoint), "--env", env, "--episodes", "3", "--max-steps", "5"]
    first = subprocess.Popen([sys.executable, "-c", "from lano3dp.cli import main; main()", *args, "--out", str(out)],
                             env=subprocess_env() | {"ENV_STEP_DELAY_S": "0.1"}, stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True)
    log = episode_log_path(out)
    deadline = time.monotonic() + 120
    while not (lock_path(out).exists() and log.exists()) and first.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    try:
        for spelling in (out, tmp_path / "link" / "r.json"):  # the same file through a symlinked folder
            second = CliRunner().invoke(app, [*args, "--out", str(spelling)])
            assert_one_line(second, 1, f"is being written by process {first.pid} ")
        assert first.poll() is None, "the first evaluation must still be running for this test to mean anything"
    finally:
        stderr = first.communicate(timeout=300)[1]
    assert first.returncode == 0, stderr
    results = json.loads(out.read_text())
    assert [e["seed"] for e in results["episodes"]] == [1_000_000, 1_000_001, 1_000_002]
    assert results["summary"]["episodes"] == 3 and not lock_path(out).exists()
