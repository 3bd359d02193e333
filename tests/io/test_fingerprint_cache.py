"""The fingerprint cache: a file keeps its cached hash only while its identity (size, inode, times) holds."""

from __future__ import annotations

import os
from pathlib import Path

from doorbatch.io.fingerprint_cache import (
    FingerprintCache,
    file_identity,
    read_fingerprint_cache,
    write_fingerprint_cache,
)
from doorbatch.io.manifest import file_fingerprint


def test_an_unchanged_file_keeps_its_cached_hash_and_a_rewritten_one_is_hashed(tmp_path: Path) -> None:
    log = tmp_path / "a.mcap"
    log.write_bytes(b"scan data")
    first = FingerprintCache()
    assert first.fingerprint(log) == file_fingerprint(log)
    entries = first.new
    assert list(entries) == [str(log.resolve())]

    planted = {k: {**v, "sha256": "cached"} for k, v in entries.items()}  # proves the cache is what answers
    assert FingerprintCache(planted).fingerprint(log)["sha256"] == "cached"

    log.write_bytes(b"other data")  # same size, new content: times change
    again = FingerprintCache(planted)
    assert again.fingerprint(log) == file_fingerprint(log) and list(again.new) == [str(log.resolve())]


def test_a_restored_mtime_does_not_hide_a_change(tmp_path: Path) -> None:
    log = tmp_path / "a.mcap"
    log.write_bytes(b"scan data")
    cache = FingerprintCache()
    cache.fingerprint(log)
    before = log.stat()
    log.write_bytes(b"scan DATA")
    os.utime(log, ns=(before.st_atime_ns, before.st_mtime_ns))  # mtime put back; ctime still moves
    assert cache.fingerprint(log) == file_fingerprint(log)


def test_folders_are_always_hashed(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "x.db3").write_bytes(b"1")
    cache = FingerprintCache()
    assert cache.fingerprint(bag) == file_fingerprint(bag) and cache.new == {} and file_identity(bag) is None


def test_cache_file_round_trip_drops_vanished_files(tmp_path: Path) -> None:
    log = tmp_path / "a.mcap"
    log.write_bytes(b"x")
    cache = FingerprintCache()
    cache.fingerprint(log)
    write_fingerprint_cache(tmp_path, {**cache.entries, str(tmp_path / "gone.mcap"): {"sha256": "0"}})
    assert read_fingerprint_cache(tmp_path) == cache.entries
    (tmp_path / ".doorbatch-fingerprints.json").write_text("[not a cache")
    assert read_fingerprint_cache(tmp_path) == {}
