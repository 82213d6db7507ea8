"""One server per data folder: an exclusive lock on ``<data_dir>/service.lock``.

The job store's queue, its re-queueing of interrupted jobs at start-up and the clean-up of
unfinished uploads all assume that no other process serves the same folder. The lock is an
``flock`` on an open file, so the kernel drops it when the holder exits however it ends (even
SIGKILL): a stale lock file never blocks a restart. The file holds the holder's pid, only to
name it in the refusal. Worker processes do not inherit it (the descriptor is close-on-exec
and the pool's processes start from a fresh executable).
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

LOCK_NAME = "service.lock"


class DataDirBusy(RuntimeError):
    """Another process holds the data folder's lock.

    Attributes
    ----------
    folder : Path
        The data folder (resolved).
    holder : int or None
        Pid written by the holder, when it could be read.
    """

    def __init__(self, folder: Path, holder: int | None):
        self.folder, self.holder = folder, holder
        who = f"process {holder}" if holder is not None else "another process"
        super().__init__(f"the data folder {folder} is in use by {who} (lock file "
                         f"{folder / LOCK_NAME}); stop that server or give this one another "
                         "CURVATURE_DATA_DIR")


class DataDirLock:
    """The held lock of one data folder; :meth:`release` (or process exit) frees it."""

    def __init__(self, folder: Path, fd: int):
        self.folder, self._fd = folder, fd

    @classmethod
    def acquire(cls, data_dir: Path) -> DataDirLock:
        """Create ``data_dir`` if needed and take its lock without waiting.

        Raises
        ------
        DataDirBusy
            Another process holds it.
        OSError
            The folder or lock file cannot be created or opened.
        """
        folder = Path(data_dir).resolve()
        folder.mkdir(parents=True, exist_ok=True)
        fd = os.open(folder / LOCK_NAME, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _read_pid(fd)
            os.close(fd)
            raise DataDirBusy(folder, holder) from None
        except BaseException:
            os.close(fd)
            raise
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        return cls(folder, fd)

    @property
    def held(self) -> bool:
        return self._fd is not None

    def release(self) -> None:
        """Free the lock (the file stays; an unlocked file means nobody serves the folder)."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


def _read_pid(fd: int) -> int | None:
    try:
        return int(os.pread(fd, 32, 0).decode().strip())
    except (OSError, ValueError):
        return None
