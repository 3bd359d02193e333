"""Content hashes of input files, remembered between runs by file identity (``OUT/.doorbatch-fingerprints.json``).

Hashing every log of a large dataset on every nightly rerun would cost more than the rerun itself. As git's
index and make do, a file whose path, size, inode, modification and status-change times (ns) are those of
the cached entry is taken as unchanged and keeps its cached SHA-256; anything else is hashed again
(:func:`~doorbatch.io.manifest.file_fingerprint`). A folder (a ROS 2 bag) is unchanged while every file in it
is, by name and by those same marks (its own times do not follow the files inside): its identity is their
total size and a hash of the list (``tree``). The cache is a plain JSON object ``{path: {size, ino, mtime_ns,
ctime_ns, sha256}}`` (folders: ``{size, tree, sha256}``), written atomically; an unreadable cache is ignored
(everything is hashed).
"""

from __future__ import annotations

import hashlib
import json
import stat
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from doorbatch.io.atomic import atomic_write_text
from doorbatch.io.manifest import file_fingerprint, folder_files

CACHE_NAME = ".doorbatch-fingerprints.json"
_IDENTITY = ("size", "ino", "mtime_ns", "ctime_ns")


def file_identity(path: Path) -> dict[str, int] | None:
    """Size, inode and times of a regular file (``None`` for folders and missing paths)."""
    try:
        st = Path(path).stat()
    except OSError:
        return None
    if not stat.S_ISREG(st.st_mode):
        return None
    return {"size": st.st_size, "ino": st.st_ino, "mtime_ns": st.st_mtime_ns, "ctime_ns": st.st_ctime_ns}


def folder_identity(path: Path) -> dict[str, int | str] | None:
    """A folder's total size and a hash of its files' names and identities (:func:`file_identity`); ``None``
    for files, missing paths and folders whose files cannot be read."""
    path = Path(path)
    if not path.is_dir():
        return None
    rows: list[list[int | str]] = []
    size = 0
    for relative, file in folder_files(path):
        identity = file_identity(file)
        if identity is None:
            return None
        rows.append([relative, *(identity[k] for k in _IDENTITY)])
        size += identity["size"]
    return {"size": size, "tree": hashlib.sha256(json.dumps(rows).encode()).hexdigest()}


def _identity(path: Path) -> Mapping[str, int | str] | None:
    """A file's identity, or a folder's."""
    found: Mapping[str, int | str] | None = file_identity(path)
    return found if found is not None else folder_identity(path)


class FingerprintCache:
    """Fingerprints by path, reused while a file's identity is unchanged; :attr:`new` holds those computed
    here (a worker returns them, the run merges them into the cache file)."""

    def __init__(self, entries: Mapping[str, Mapping[str, Any]] | None = None) -> None:
        self.entries: dict[str, dict[str, Any]] = {k: dict(v) for k, v in (entries or {}).items()}
        self.new: dict[str, dict[str, Any]] = {}

    def fingerprint(self, path: Path) -> dict[str, Any]:
        """``{"path", "size", "sha256"}`` of ``path``, from the cache when its identity matches.

        Raises:
            InputDataError: the path does not exist or cannot be read.
        """
        key = str(Path(path).resolve())
        identity = _identity(path)
        cached = self.entries.get(key)
        if identity is not None and cached is not None and all(cached.get(k) == v for k, v in identity.items()):
            return {"path": str(Path(path).absolute()), "size": identity["size"], "sha256": cached["sha256"]}
        found = file_fingerprint(path)
        after = _identity(path)
        if identity is not None and after == identity:  # not changed while hashing: safe to remember
            entry = {**identity, "sha256": found["sha256"]}
            self.entries[key] = entry
            self.new[key] = entry
        return found


def read_fingerprint_cache(folder: Path) -> dict[str, dict[str, Any]]:
    """The cache entries in ``folder`` (empty when absent or unreadable)."""
    try:
        data = json.loads((folder / CACHE_NAME).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    if not isinstance(data, dict):
        return {}
    return {k: v for k, v in data.items() if isinstance(v, dict) and isinstance(v.get("sha256"), str)}


def write_fingerprint_cache(folder: Path, entries: Mapping[str, Mapping[str, Any]]) -> None:
    """Write the cache entries of the files that still exist, atomically."""
    kept = {k: dict(v) for k, v in sorted(entries.items()) if Path(k).exists()}
    atomic_write_text(folder / CACHE_NAME, json.dumps(kept, indent=1) + "\n")
