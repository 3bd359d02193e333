"""The lock file that keeps two ``doorbatch run`` off one output folder (cron-safe).

``OUT/.doorbatch.lock`` is JSON ``{"pid", "host", "started_at"}``. It is created with its content in one
step (written to a temporary file, then hard-linked to the lock name, which fails if the lock exists), so
a reader never sees an empty lock. A lock whose PID is dead on this host is stale (a killed run): it is
reported and taken over. A lock held by a live process, or by another host (whose PIDs cannot be
checked), is an :class:`~doorbatch.errors.OutputLockedError` (exit 2: the output is in use, retry later).
"""

from __future__ import annotations

import json
import logging
import os
import socket
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path

from doorbatch.errors import OutputLockedError
from doorbatch.io.atomic import temp_path_for
from doorbatch.io.manifest import utc_now_iso

log = logging.getLogger(__name__)
LOCK_NAME = ".doorbatch.lock"


@dataclass(frozen=True)
class LockInfo:
    """Who holds a lock."""

    pid: int
    host: str
    started_at: str

    def describe(self) -> str:
        """``pid 123 on host since 2026-...Z``."""
        return f"pid {self.pid} on {self.host} since {self.started_at}"


def pid_alive(pid: int) -> bool:
    """Whether a process with this PID exists on this host (signal 0 probes without sending)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


def read_lock(path: Path) -> LockInfo | None:
    """The lock's holder, or ``None`` when the file is unreadable or not a lock (treated as stale)."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        return LockInfo(int(data["pid"]), str(data["host"]), str(data["started_at"]))
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _try_create(path: Path, info: LockInfo) -> bool:
    tmp = temp_path_for(path)
    tmp.write_text(json.dumps(asdict(info)) + "\n", encoding="utf-8")
    try:
        os.link(tmp, path)  # atomic, fails when the lock exists
        return True
    except FileExistsError:
        return False
    finally:
        tmp.unlink(missing_ok=True)


def acquire_lock(folder: Path) -> tuple[LockInfo, LockInfo | None]:
    """Take ``folder``/.doorbatch.lock for this process.

    Returns:
        This process's lock, and the stale lock that was taken over (``None`` if there was none).

    Raises:
        OutputLockedError: a live process on this host, or any process on another host, holds it.
    """
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / LOCK_NAME
    mine = LockInfo(os.getpid(), socket.gethostname(), utc_now_iso())
    stale: LockInfo | None = None
    for _ in range(3):  # a race with another run taking over the same stale lock: try again
        if _try_create(path, mine):
            return mine, stale
        held = read_lock(path)
        if held is not None and (held.host != mine.host or pid_alive(held.pid)):
            raise OutputLockedError(f"{folder} is in use by another doorbatch run ({held.describe()}); "
                                    f"if that run is gone, remove {path}")
        stale = held or LockInfo(-1, "?", "?")
        log.warning("taking over the stale lock %s (%s: not running)", path,
                    stale.describe() if held else "unreadable lock file")
        path.unlink(missing_ok=True)
    raise OutputLockedError(f"{folder}: could not take the lock {path} (another run keeps taking it)")


def release_lock(folder: Path, mine: LockInfo) -> None:
    """Remove the lock if it is still ours."""
    path = folder / LOCK_NAME
    if read_lock(path) == mine:
        path.unlink(missing_ok=True)


@contextmanager
def run_lock(folder: Path) -> Iterator[tuple[LockInfo, LockInfo | None]]:
    """Hold the lock of ``folder`` for the ``with`` body (see :func:`acquire_lock`)."""
    mine, stale = acquire_lock(folder)
    try:
        yield mine, stale
    finally:
        release_lock(folder, mine)
