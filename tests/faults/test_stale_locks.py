"""A writer killed while holding its lock leaves the lock file behind; the next writer takes it at once (the
kernel dropped the flock with the process), whatever the file holds."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

from faults_common import EXAMPLE_ENV, subprocess_env
from lano3dp.locking import WriteLock, lock_path
from lano3dp.train import train
from test_train import micro_config

HOLD_LOCK = "import sys, time; from lano3dp.locking import WriteLock; lock = WriteLock(sys.argv[1]).acquire(); " \
            "print('held', flush=True); time.sleep(120)"


def hold_lock(target: Path) -> subprocess.Popen:
    """A process holding `target`'s write lock (as a collect, train or eval does while it writes)."""
    process = subprocess.Popen([sys.executable, "-c", HOLD_LOCK, str(target)], env=subprocess_env(),
                               stdout=subprocess.PIPE, text=True)
    assert process.stdout.readline().strip() == "held"
    return process


def killed_holder(target: Path) -> int:
    holder = hold_lock(target)
    holder.send_signal(signal.SIGKILL)
    holder.wait()
    return holder.pid


def test_a_stale_lock_after_sigkill_does_not_block_the_next_training(reach_data, tmp_path):
    run = tmp_path / "run"
    pid = killed_holder(run)
    assert lock_path(run).read_text().strip() == str(pid)  # the dead writer's lock file is still there
    final = train(micro_config(reach_data, run, steps=1, val_ratio=0.0))
    assert final.name == "step_0000001" and not lock_path(run).exists()
    with WriteLock(run) as lock:
        assert lock.held and lock_path(run).read_text().strip() == str(os.getpid())


def test_a_stale_dataset_lock_does_not_block_the_next_collection(tmp_path):
    from lano3dp.collect import collect_from_env
    from test_kill_resume import SLOW_EXPERT

    (tmp_path / "experts.py").write_text(SLOW_EXPERT)
    out = tmp_path / "d.zarr"
    killed_holder(out)
    result = collect_from_env(f"{EXAMPLE_ENV}:make_env", f"{tmp_path / 'experts.py'}:reach", 1, out, slots=["block"],
                              image_size=48, follow_through_s=0.0, progress=False)
    assert result.added == 1 and not lock_path(out).exists()


def test_a_lock_file_with_garbage_in_it_is_taken_over(tmp_path):
    target = tmp_path / "results.json"
    lock_path(target).write_bytes(b"\x00not a pid\xff")  # e.g. a disk that filled while the PID was written
    with WriteLock(target) as lock:
        assert lock.held and lock_path(target).read_text().strip() == str(os.getpid())
    assert not lock_path(target).exists()
