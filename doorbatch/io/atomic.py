"""Atomic file writes: write to a temporary file beside the destination, then rename it into place.

Every writer in :mod:`doorbatch.io` goes through :func:`atomic_path`, so a crash (an exception, a kill, a
power cut after the rename) never leaves a half-written file under the destination name (DESIGN.md,
Reliability). Temporary files are named ``.<dest name>.<random>.tmp<dest suffix>``: hidden, recognizable
by ``.tmp``, and ending in the destination's suffix so that libraries choosing a format by suffix (cv2,
pyarrow) do the right thing.
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

TEMP_MARKER = ".tmp"


def temp_path_for(dest: Path) -> Path:
    """A fresh temporary path in ``dest``'s folder: ``.<name>.<16 hex>.tmp<suffix>``."""
    return dest.with_name(f".{dest.name}.{secrets.token_hex(8)}{TEMP_MARKER}{dest.suffix}")


def _reserve(path: Path) -> None:
    """Create ``path`` empty and exclusively, with the default permissions (0o666 less the umask)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    os.close(fd)


def _fsync_file(path: Path) -> None:
    """Flush a file's content to the disk."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(folder: Path) -> None:
    """Flush a folder's entries (the rename) to the disk, where the platform allows it."""
    flags = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0)
    try:
        fd = os.open(folder, flags)
    except OSError:  # platforms that cannot open a folder (Windows)
        return
    try:
        with suppress(OSError):  # file systems that do not support fsync on a folder
            os.fsync(fd)
    finally:
        os.close(fd)


@contextmanager
def atomic_path(dest: Path) -> Iterator[Path]:
    """Yield a temporary path to write; on success it replaces ``dest`` atomically.

    The temporary file exists (empty) when yielded, in ``dest``'s folder (created if missing). When the
    ``with`` body returns, the file is fsynced, renamed onto ``dest`` (:func:`os.replace`), and the
    folder is fsynced. When the body raises, the temporary file is removed and the error propagates;
    ``dest`` is left as it was.

    Args:
        dest: The final path.

    Yields:
        The temporary path to write to.

    Raises:
        OSError: The folder cannot be created, or the file cannot be synced or renamed.
    """
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = temp_path_for(dest)
    _reserve(tmp)
    try:
        yield tmp
        _fsync_file(tmp)
        tmp.replace(dest)  # os.replace: atomic on POSIX
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_dir(dest.parent)


def atomic_write_bytes(dest: Path, data: bytes) -> None:
    """Write ``data`` to ``dest`` atomically (see :func:`atomic_path`)."""
    with atomic_path(dest) as tmp:
        tmp.write_bytes(data)


def atomic_write_text(dest: Path, text: str, encoding: str = "utf-8") -> None:
    """Write ``text`` to ``dest`` atomically, encoded as given, line endings untranslated."""
    atomic_write_bytes(dest, text.encode(encoding))
