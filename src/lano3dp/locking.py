"""One writer per output: a lock file beside every dataset, run folder and results file a command writes.

    with WriteLock("data/bowl.zarr"):      # data/bowl.zarr.lock holds this process's PID while it writes
        ...

A second writer is refused at once with `LockedError` naming the holder's PID. The lock is an
advisory `fcntl.flock` on the lock file rather than an O_EXCL "PID file": the kernel drops it when
the holding process dies, however it dies (SIGKILL included), so a stale lock file never blocks the
next run and there is no guess about whether a PID still lives (PIDs are reused). The PID written
inside is only there for the error message. The file is removed on release; a writer that opened
it just before that removal notices (the path no longer names the file it locked) and tries again.
"""

from __future__ import annotations

import errno
import fcntl
import os
from pathlib import Path

from lano3dp.errors import Lano3dpError, StorageError, describe_os_error

LOCK_SUFFIX = ".lock"


class LockedError(Lano3dpError, RuntimeError):
    """Another process is writing the same dataset, run or results file."""

    def __init__(self, target: Path, pid: int | None):
        self.target, self.pid = target, pid
        holder = f"process {pid}" if pid else "another process"
        super().__init__(f"{target} is being written by {holder} (lock {lock_path(target)}); wait for it to "
                         "finish, stop it, or write somewhere else")


def lock_path(target: str | Path) -> Path:
    """The lock file of `target`: beside the folder or file it names, reached through any symlink, so two
    spellings of one output (a link and its target) take the same lock."""
    target = Path(target).resolve()
    return target.with_name(target.name + LOCK_SUFFIX)


def prepare_parent(path: str | Path) -> Path:
    """Create the parent folders of `path`; a regular file in the way is a one-line error naming it."""
    path = Path(path).absolute()
    for ancestor in [path.parent, *path.parent.parents]:
        if ancestor.exists():
            if not ancestor.is_dir():
                raise NotADirectoryError(f"cannot write {path}: {ancestor} is a file, not a folder")
            break
    path.parent.mkdir(parents=True, exist_ok=True)
    return path


class WriteLock:
    """An exclusive, non-blocking lock on `target` (a file or folder, existing or not), held by this process."""

    def __init__(self, target: str | Path):
        self.target = Path(target)
        self.path = lock_path(target)
        self._fd: int | None = None

    @property
    def held(self) -> bool:
        return self._fd is not None

    def acquire(self) -> WriteLock:
        if self._fd is not None:
            return self
        prepare_parent(self.path)
        for _ in range(100):  # retries only when the file was removed between our open and our lock
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as error:  # a read-only folder: one line naming the lock file
                raise StorageError(self.path, describe_os_error(error)) from error
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as error:
                os.close(fd)
                if error.errno in (errno.EAGAIN, errno.EACCES):
                    raise LockedError(self.target, read_holder(self.path)) from None
                raise
            try:
                same_file = os.path.samestat(os.fstat(fd), os.stat(self.path))
            except FileNotFoundError:
                same_file = False
            if not same_file:  # the holder released (and removed) it after our open: lock the new file
                os.close(fd)
                continue
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode())
            self._fd = fd
            return self
        raise LockedError(self.target, read_holder(self.path))

    def release(self) -> None:
        if self._fd is None:
            return
        fd, self._fd = self._fd, None
        try:
            self.path.unlink(missing_ok=True)  # while still locked, so no other writer holds it yet
        finally:
            os.close(fd)  # closing drops the flock

    def __enter__(self) -> WriteLock:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()

    def __del__(self):
        try:
            self.release()
        except Exception:  # interpreter shutdown
            pass


def read_holder(path: Path) -> int | None:
    try:
        return int(Path(path).read_text().strip() or 0) or None
    except (OSError, ValueError):
        return None
