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


def test_a_folder_keeps_its_cached_hash_while_every_file_in_it_does(tmp_path: Path) -> None:
    """A ROS 2 bag folder was hashed again by every step that read it, on every no-op rerun (a 575 MB bag 4
    times, 2.3 s): its own times do not follow the files inside, but its files' identities do."""
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}")
    (bag / "x_0.db3").write_bytes(b"1")
    first = FingerprintCache()
    assert first.fingerprint(bag) == file_fingerprint(bag) and file_identity(bag) is None
    assert list(first.new) == [str(bag.resolve())]
    planted = {k: {**v, "sha256": "cached"} for k, v in first.new.items()}
    assert FingerprintCache(planted).fingerprint(bag)["sha256"] == "cached"
    (bag / "x_0.db3").write_bytes(b"2")  # a file rewritten
    assert FingerprintCache(planted).fingerprint(bag) == file_fingerprint(bag)
    (bag / "x_0.db3").write_bytes(b"1")
    refreshed = FingerprintCache()
    refreshed.fingerprint(bag)
    planted = {k: {**v, "sha256": "cached"} for k, v in refreshed.new.items()}
    (bag / "x_1.db3").write_bytes(b"3")  # a file added
    assert FingerprintCache(planted).fingerprint(bag) == file_fingerprint(bag)


def test_cache_file_round_trip_drops_vanished_files(tmp_path: Path) -> None:
    log = tmp_path / "a.mcap"
    log.write_bytes(b"x")
    cache = FingerprintCache()
    cache.fingerprint(log)
    write_fingerprint_cache(tmp_path, {**cache.entries, str(tmp_path / "gone.mcap"): {"sha256": "0"}})
    assert read_fingerprint_cache(tmp_path) == cache.entries
    (tmp_path / ".doorbatch-fingerprints.json").write_text("[not a cache")
    assert read_fingerprint_cache(tmp_path) == {}
