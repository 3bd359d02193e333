"""The output lock: one holder at a time, stale locks taken over, live ones refused (exit 2)."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from doorbatch.errors import ExitCode, OutputLockedError
from doorbatch.io.manifest import utc_now_iso
from doorbatch.io.run_lock import (
    LOCK_NAME,
    LockInfo,
    acquire_lock,
    pid_alive,
    process_start_epoch_s,
    read_lock,
    run_lock,
)


def dead_pid() -> int:
    """The PID of a process that has exited."""
    done = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True,
                          check=True)
    return int(done.stdout)


def write_lock(folder: Path, pid: int, host: str | None = None, started_at: str | None = None) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / LOCK_NAME).write_text(json.dumps({"pid": pid, "host": host or socket.gethostname(),
                                                "started_at": started_at or utc_now_iso()}))


def test_lock_holds_pid_host_and_time_and_is_removed_after(tmp_path: Path) -> None:
    with run_lock(tmp_path / "out") as (mine, stale):
        assert stale is None
        held = read_lock(tmp_path / "out" / LOCK_NAME)
        assert held == mine and held.pid == os.getpid() and held.host == socket.gethostname()
        assert held.started_at.endswith("Z")
        with pytest.raises(OutputLockedError, match=f"pid {os.getpid()}") as err:
            acquire_lock(tmp_path / "out")
        assert err.value.exit_code == ExitCode.USAGE
    assert not (tmp_path / "out" / LOCK_NAME).exists()
    assert [p.name for p in (tmp_path / "out").iterdir()] == []  # no temporary file left either


def test_a_dead_pid_lock_is_reported_and_taken_over(tmp_path: Path) -> None:
    pid = dead_pid()
    assert not pid_alive(pid)
    write_lock(tmp_path, pid)
    mine, stale = acquire_lock(tmp_path)
    assert stale is not None and stale.pid == pid and mine.pid == os.getpid()
    assert read_lock(tmp_path / LOCK_NAME) == mine


def test_a_live_pid_that_started_after_the_lock_is_a_reused_pid(tmp_path: Path) -> None:
    if process_start_epoch_s(os.getpid()) is None:
        pytest.skip("process start times are not available here")
    write_lock(tmp_path, os.getpid(), started_at="2000-01-01T00:00:00.000Z")  # e.g. a lock from before a reboot
    _, stale = acquire_lock(tmp_path)
    assert stale is not None and stale.pid == os.getpid()
    write_lock(tmp_path, os.getpid())  # the same live process, lock taken now: it holds it
    with pytest.raises(OutputLockedError):
        acquire_lock(tmp_path)


def test_an_unreadable_lock_is_stale(tmp_path: Path) -> None:
    (tmp_path / LOCK_NAME).write_text("{not json")
    mine, stale = acquire_lock(tmp_path)
    assert stale == LockInfo(-1, "?", "?") and read_lock(tmp_path / LOCK_NAME) == mine


def test_a_lock_from_another_host_is_taken_only_when_no_one_holds_its_flock(tmp_path: Path) -> None:
    """Another host's PID cannot be checked: its holder keeps a flock on the lock while it runs. Held: the output
    is in use. Not held (a run killed in a container that is gone, whose hostname no later container has): stale,
    taken over, where it used to refuse every night until someone removed it by hand."""
    import fcntl

    write_lock(tmp_path, dead_pid(), host="some-other-host")
    fd = os.open(tmp_path / LOCK_NAME, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)  # the other host's run, alive
        with pytest.raises(OutputLockedError, match="some-other-host"):
            acquire_lock(tmp_path)
    finally:
        os.close(fd)
    mine, stale = acquire_lock(tmp_path)
    assert stale is not None and stale.host == "some-other-host" and read_lock(tmp_path / LOCK_NAME) == mine


def test_a_held_lock_keeps_its_flock_until_released(tmp_path: Path) -> None:
    """The flock another host probes is held from the lock's creation to its release."""
    from doorbatch.io.run_lock import flock_held

    with run_lock(tmp_path):
        assert flock_held(tmp_path / LOCK_NAME)
    assert not (tmp_path / LOCK_NAME).exists()


def test_release_leaves_a_lock_that_is_not_ours(tmp_path: Path) -> None:
    with run_lock(tmp_path):
        write_lock(tmp_path, os.getppid())  # someone replaced it meanwhile
    assert read_lock(tmp_path / LOCK_NAME) is not None


def test_two_runs_taking_over_one_stale_lock_never_both_hold_it(tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """Run B reads the stale lock, then is slow; run A takes the lock over meanwhile. B must not remove A's new
    lock and take it too (it did: two runs wrote one OUT)."""
    import threading
    import time

    from doorbatch.io import run_lock as rl

    write_lock(tmp_path, dead_pid())
    slow = threading.local()
    original = rl.read_lock

    def read_lock_slowly(path: Path) -> LockInfo | None:
        info = original(path)
        time.sleep(getattr(slow, "delay", 0.0))
        return info

    monkeypatch.setattr(rl, "read_lock", read_lock_slowly)
    outcome: dict[str, object] = {}

    def take(name: str, delay: float) -> None:
        slow.delay = delay
        try:
            outcome[name] = acquire_lock(tmp_path)[0]
        except OutputLockedError as err:
            outcome[name] = err

    b = threading.Thread(target=take, args=("b", 0.4))
    a = threading.Thread(target=take, args=("a", 0.0))
    b.start()
    time.sleep(0.1)
    a.start()
    a.join()
    b.join()
    assert isinstance(outcome["a"], LockInfo) and isinstance(outcome["b"], OutputLockedError)
    assert original(tmp_path / LOCK_NAME) == outcome["a"]


def test_a_file_system_without_flock_still_locks_by_the_link(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """flock failing with ENOLCK (NFS without lockd): the lock is taken by its hard link alone, as before."""
    import errno
    import fcntl

    from doorbatch.io import run_lock as rl

    def no_locks(fd: int, op: int) -> None:
        raise OSError(errno.ENOLCK, "No locks available")

    monkeypatch.setattr(rl.fcntl, "flock", no_locks)
    assert fcntl.flock is no_locks
    with run_lock(tmp_path) as (mine, _):
        assert read_lock(tmp_path / LOCK_NAME) == mine
    assert not (tmp_path / LOCK_NAME).exists()
