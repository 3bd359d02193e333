"""The lock file that keeps two ``doorbatch run`` off one output folder (cron-safe).

``OUT/.doorbatch.lock`` is JSON ``{"pid", "host", "started_at"}``. It is created with its content in one
step (written to a temporary file, then hard-linked to the lock name, which fails if the lock exists), so
a reader never sees an empty lock. A lock whose PID is dead on this host is stale (a killed run): it is
reported and taken over, and so is one whose PID now belongs to a process started after the lock was
taken (PIDs are reused after a reboot; Linux tells start times). The holder also keeps an exclusive ``flock`` on
the lock file while it runs, which the kernel drops when it dies: a lock of another host (whose PIDs cannot be
checked: another container, another machine on a shared volume) is stale when no process holds that flock (a run
killed in a container that is gone). A lock held by a live process is an
:class:`~doorbatch.errors.OutputLockedError` (exit 2: the output is in use, retry later).
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import logging
import os
import socket
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from datetime import datetime
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
        """``pid 123 on host since 2026-...Z`` (``an unreadable lock file`` for :data:`UNREADABLE`)."""
        if self == UNREADABLE:
            return "an unreadable lock file"
        return f"pid {self.pid} on {self.host} since {self.started_at}"


UNREADABLE = LockInfo(-1, "?", "?")  # the holder of a lock file that cannot be read


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


def process_start_epoch_s(pid: int) -> float | None:
    """When process ``pid`` started (Unix time), from Linux's /proc; ``None`` where that is unavailable."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        boot_s = next(float(line.split()[1]) for line in Path("/proc/stat").read_text().splitlines()
                      if line.startswith("btime "))
        return boot_s + int(fields[19]) / os.sysconf("SC_CLK_TCK")  # field 22 of stat(5): start time in ticks
    except (OSError, ValueError, IndexError, StopIteration):
        return None


def holder_running(info: LockInfo) -> bool:
    """Whether the lock's holder still runs: its PID is alive and, where the start time of processes is
    known, that process started before the lock did (after a reboot, PIDs are reused)."""
    if not pid_alive(info.pid):
        return False
    started = process_start_epoch_s(info.pid)
    try:
        locked = datetime.fromisoformat(info.started_at.replace("Z", "+00:00")).timestamp()
    except ValueError:
        return True
    return started is None or started <= locked + 2.0  # /proc's start time has clock-tick resolution


def read_lock(path: Path) -> LockInfo | None:
    """The lock's holder, or ``None`` when the file is unreadable or not a lock (treated as stale)."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        return LockInfo(int(data["pid"]), str(data["host"]), str(data["started_at"]))
    except (OSError, ValueError, KeyError, TypeError):
        return None


_HELD: dict[Path, int] = {}  # lock path → the open file whose flock this process holds while it runs


def _try_create(path: Path, info: LockInfo) -> bool:
    """Create the lock with ``info``, flocked before it gets its name (so that no one sees it unflocked); the
    flock is held (:data:`_HELD`) until :func:`release_lock`."""
    tmp = temp_path_for(path)
    fd = os.open(tmp, os.O_CREAT | os.O_EXCL | os.O_RDWR, 0o644)
    try:
        # a file system without flock (Lustre without -o flock, NFS without lockd): the link alone
        with contextlib.suppress(OSError):
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        os.write(fd, (json.dumps(asdict(info)) + "\n").encode("utf-8"))
        os.link(tmp, path)  # atomic, fails when the lock exists
    except FileExistsError:
        os.close(fd)
        return False
    except BaseException:
        os.close(fd)
        raise
    finally:
        tmp.unlink(missing_ok=True)
    _HELD[path] = fd
    return True


def flock_held(path: Path) -> bool:
    """Whether some process holds the lock file's flock (a running holder; the kernel drops it when it dies)."""
    try:  # read-write: NFS emulates flock with fcntl locks, whose exclusive kind needs a file open for writing
        fd = os.open(path, os.O_RDWR)
    except PermissionError:
        try:
            fd = os.open(path, os.O_RDONLY)
        except OSError:
            return False
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:  # a file system without flock: nothing can be told, so the holder is taken to run
        return True
    finally:
        os.close(fd)  # releases the probe's flock, if it got it
    return False


@contextmanager
def _takeover_guard(folder: Path) -> Iterator[None]:
    """An exclusive ``flock`` on ``folder``/.doorbatch.lock.guard for the read-check-remove of a stale lock: two
    runs that both found it stale cannot both remove it (the second would remove the first's new lock)."""
    fd = os.open(folder / f"{LOCK_NAME}.guard", os.O_CREAT | os.O_RDWR, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the flock


def acquire_lock(folder: Path) -> tuple[LockInfo, LockInfo | None]:
    """Take ``folder``/.doorbatch.lock for this process.

    Returns:
        This process's lock, and the stale lock that was taken over (``None`` if there was none).

    Raises:
        OutputLockedError: a live process on this host holds it, or a process on another host that holds its flock.
    """
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / LOCK_NAME
    mine = LockInfo(os.getpid(), socket.gethostname(), utc_now_iso())
    stale: LockInfo | None = None
    for _ in range(3):  # a race with another run taking over the same stale lock: try again
        if _try_create(path, mine):
            return mine, stale
        held = read_lock(path)
        running = holder_running(held) if held is not None and held.host == mine.host else flock_held(path)
        if held is not None and running:
            raise OutputLockedError(f"{folder} is in use by another doorbatch run ({held.describe()}); "
                                    f"if that run is gone, remove {path}")
        stale = held or UNREADABLE
        log.debug("taking over the stale lock %s (%s: not running)", path, stale.describe())  # run.log says so
        with _takeover_guard(folder):  # another run taking over too: only one removes it, and only the stale one
            if read_lock(path) == held:
                path.unlink(missing_ok=True)
    raise OutputLockedError(f"{folder}: could not take the lock {path} (another run keeps taking it)")


def release_lock(folder: Path, mine: LockInfo) -> None:
    """Remove the lock if it is still ours."""
    path = folder / LOCK_NAME
    if read_lock(path) == mine:
        path.unlink(missing_ok=True)
    fd = _HELD.pop(path, None)
    if fd is not None:
        os.close(fd)


@contextmanager
def run_lock(folder: Path) -> Iterator[tuple[LockInfo, LockInfo | None]]:
    """Hold the lock of ``folder`` for the ``with`` body (see :func:`acquire_lock`)."""
    mine, stale = acquire_lock(folder)
    try:
        yield mine, stale
    finally:
        release_lock(folder, mine)
