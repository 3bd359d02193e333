"""Atomic writes: the destination appears whole or not at all, and no temporary file is left behind."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from doorbatch.io.atomic import atomic_path, atomic_write_bytes, atomic_write_text


class BoomError(RuntimeError):
    pass


def test_atomic_path_writes_destination_and_leaves_only_it(tmp_path: Path) -> None:
    dest = tmp_path / "out.parquet"
    with atomic_path(dest) as tmp:
        assert tmp.parent == dest.parent
        assert tmp.name.startswith(".") and ".tmp" in tmp.name
        assert tmp.suffix == ".parquet"
        assert tmp.exists() and not dest.exists()
        tmp.write_bytes(b"payload")
    assert dest.read_bytes() == b"payload"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.parquet"]


def test_crash_inside_atomic_path_leaves_no_destination_and_no_temp(tmp_path: Path) -> None:
    dest = tmp_path / "out.txt"
    with pytest.raises(BoomError), atomic_path(dest) as tmp:
        tmp.write_bytes(b"half a fi")
        raise BoomError
    assert not dest.exists()
    assert list(tmp_path.iterdir()) == []


def test_crash_keeps_previous_destination_content(tmp_path: Path) -> None:
    dest = tmp_path / "out.txt"
    atomic_write_text(dest, "old\n")
    with pytest.raises(BoomError), atomic_path(dest) as tmp:
        tmp.write_text("new, but never finished")
        raise BoomError
    assert dest.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_keyboard_interrupt_also_cleans_up(tmp_path: Path) -> None:
    dest = tmp_path / "out.bin"
    with pytest.raises(KeyboardInterrupt), atomic_path(dest) as tmp:
        tmp.write_bytes(b"x")
        raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []


def test_write_replaces_existing_file(tmp_path: Path) -> None:
    dest = tmp_path / "a.bin"
    atomic_write_bytes(dest, b"first")
    atomic_write_bytes(dest, b"second")
    assert dest.read_bytes() == b"second"


def test_parent_folders_are_created(tmp_path: Path) -> None:
    dest = tmp_path / "x" / "y" / "z.txt"
    atomic_write_text(dest, "héllo\nworld\n")
    assert dest.read_bytes() == "héllo\nworld\n".encode()


def test_temp_names_are_unique(tmp_path: Path) -> None:
    dest = tmp_path / "same.txt"
    with atomic_path(dest) as first, atomic_path(dest) as second:
        assert first != second
        first.write_text("1")
        second.write_text("2")
    assert dest.read_text() == "1"  # the outer context finishes last and wins


def test_file_gets_default_permissions_not_private(tmp_path: Path) -> None:
    umask = os.umask(0o022)
    try:
        atomic_write_text(tmp_path / "perm.txt", "x")
    finally:
        os.umask(umask)
    assert stat.S_IMODE((tmp_path / "perm.txt").stat().st_mode) == 0o644


def test_failed_rename_onto_a_folder_removes_temp(tmp_path: Path) -> None:
    dest = tmp_path / "taken"
    (dest / "inner").mkdir(parents=True)
    with pytest.raises(OSError):
        atomic_write_bytes(dest, b"x")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken"]
