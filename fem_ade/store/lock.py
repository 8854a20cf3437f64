"""One owner per run folder: an advisory lock held for the whole life of a run or a resume.

A run (:func:`fem_ade.engine.runs.simulate`) or a resume (:func:`fem_ade.engine.runs.resume`) takes
the lock
of its folder before it writes anything there and holds it to the end; a second process that
wants the same folder — another run with the same ``--out``, a second resume, ``--force`` —
gets :class:`FolderBusy` (exit 2 on the command line) with one line naming the owner: its
pid, host, start time and command, from the owner file written beside the lock.

The lock is ``filelock``'s (``flock`` on POSIX): the operating system releases it when its
process dies, however it dies, so the lock of a killed run is free for the next one, which
takes it over and replaces the owner file (a stale owner file says who held it last). The
lock file stays in the folder (removing it on release would let two processes lock two
different files); both files are hidden and never count as the folder's content. Advisory:
it binds fem_ade processes, not other programs; on network file systems it is as good as
their ``flock``.
"""

from __future__ import annotations

import json
import os
import socket
import sys
import time
from pathlib import Path

from fem_ade.model.params import ModelError

#: the lock file and the owner file in a run folder
LOCK_NAME = ".fem_ade.store.lock"
OWNER_NAME = ".fem_ade.owner.json"
HIDDEN = (LOCK_NAME, OWNER_NAME)


class FolderBusy(ModelError):
    """The run folder is held by another live process (one line: who, since when)."""


def owner_text(folder: Path) -> str:
    """Who holds (or last held) ``folder``, from its owner file."""
    try:
        o = json.loads((Path(folder) / OWNER_NAME).read_text())
        return (f"pid {o['pid']} on {o['host']}, started {o['started']}: "
                f"{o.get('command', '?')}")
    except (OSError, ValueError, KeyError, TypeError):
        return "a process that has not written its owner file yet"


class FolderLock:
    """The lock of one run folder (a context manager; :meth:`acquire`, :meth:`release`)."""

    def __init__(self, folder: str | Path):
        self.folder = Path(folder)
        self._lock = None
        #: the owner file of a dead previous owner, found when the lock was taken (or None)
        self.stale: str | None = None

    def acquire(self) -> FolderLock:
        """Take the lock now or raise :class:`FolderBusy`; ModelError if the folder cannot
        hold a lock file."""
        from filelock import FileLock, Timeout

        lock = FileLock(str(self.folder / LOCK_NAME), timeout=0)
        try:
            lock.acquire(timeout=0)
        except Timeout:
            raise FolderBusy(f"run folder {self.folder} is in use by another run "
                             f"({owner_text(self.folder)}); wait for it to end, or stop "
                             "it") from None
        except OSError as err:
            raise ModelError(f"run folder {self.folder}: cannot lock it "
                             f"({err.strerror or err})") from None
        self._lock = lock
        if (self.folder / OWNER_NAME).exists():
            self.stale = owner_text(self.folder)
        owner = {"pid": os.getpid(), "host": socket.gethostname(),
                 "started": time.strftime("%Y-%m-%d %H:%M:%S"),
                 "command": " ".join(sys.argv) if sys.argv and sys.argv[0] else "python"}
        tmp = self.folder / (OWNER_NAME + ".tmp")
        try:
            tmp.write_text(json.dumps(owner) + "\n")
            os.replace(tmp, self.folder / OWNER_NAME)
        except OSError as err:
            self.release()
            raise ModelError(f"run folder {self.folder}: cannot write there "
                             f"({err.strerror or err})") from None
        return self

    def release(self) -> None:
        """Remove the owner file and free the lock (idempotent)."""
        if self._lock is None:
            return
        try:
            (self.folder / OWNER_NAME).unlink(missing_ok=True)
        except OSError:
            pass
        self._lock.release()
        self._lock = None

    @property
    def held(self) -> bool:
        return self._lock is not None

    def __enter__(self) -> FolderLock:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()
