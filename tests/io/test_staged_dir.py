"""Staged output folders: complete or absent, never partial; leftovers of a killed run removed."""

from __future__ import annotations

from pathlib import Path

import pytest

from doorbatch.io.atomic import atomic_write_text, temp_path_for
from doorbatch.io.staged_dir import is_leftover, remove_leftovers, staged_dir, staged_files


def test_a_finished_step_replaces_the_folder(tmp_path: Path) -> None:
    dest = tmp_path / "site" / "map"
    dest.mkdir(parents=True)
    (dest / "old.txt").write_text("old")
    with staged_dir(dest) as tmp:
        assert tmp.parent == dest.parent and is_leftover(tmp) and not any(tmp.iterdir())
        (tmp / "new.txt").write_text("new")
        assert (dest / "old.txt").exists()  # the old folder stays until the step is done
    assert [p.name for p in dest.iterdir()] == ["new.txt"]
    assert [p.name for p in dest.parent.iterdir()] == ["map"]


@pytest.mark.parametrize("error", [RuntimeError("step failed"), KeyboardInterrupt()])
def test_a_failed_or_interrupted_step_leaves_the_folder_as_it_was(tmp_path: Path, error: BaseException) -> None:
    dest = tmp_path / "map"
    dest.mkdir()
    (dest / "old.txt").write_text("old")
    with pytest.raises(type(error)), staged_dir(dest) as tmp:
        (tmp / "half.txt").write_text("half")
        raise error
    assert [p.name for p in dest.iterdir()] == ["old.txt"]
    assert [p.name for p in tmp_path.iterdir()] == ["map"]


def test_a_commands_files_replace_theirs_and_leave_the_users(tmp_path: Path) -> None:
    """``doorbatch localize -o run`` into a folder of an earlier run and a user's notes: the new files replace the
    old ones of their names, the notes stay; a new folder is made whole at the end."""
    dest = tmp_path / "run"
    dest.mkdir()
    (dest / "manifest.json").write_text("old")
    (dest / "notes.txt").write_text("mine")
    with staged_files(dest) as stage:
        (stage / "manifest.json").write_text("new")
        (stage / "trajectory.tum").write_text("new")
        assert (dest / "manifest.json").read_text() == "old"
    assert {p.name: p.read_text() for p in dest.iterdir()} == {"manifest.json": "new", "trajectory.tum": "new",
                                                                "notes.txt": "mine"}
    fresh = tmp_path / "deep" / "fresh"
    with staged_files(fresh) as stage:
        assert stage.parent == fresh and is_leftover(stage)  # inside: the same file system and permissions
        (stage / "map.yaml").write_text("new")
    assert [p.name for p in fresh.iterdir()] == ["map.yaml"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["deep", "run"]


def test_output_into_the_current_folder_is_staged_inside_it(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``-o .`` has no sibling to stage beside (a reviewer's ValueError after all the work): staged inside."""
    monkeypatch.chdir(tmp_path)
    with staged_files(Path()) as stage:  # what click makes of -o .
        (stage / "trajectory.tum").write_text("new")
    assert [p.name for p in tmp_path.iterdir()] == ["trajectory.tum"]


@pytest.mark.parametrize("error", [RuntimeError("write failed"), KeyboardInterrupt()])
def test_an_interrupted_command_leaves_its_output_folder_as_it_was(tmp_path: Path, error: BaseException) -> None:
    """hAM's SIGTERM while localize wrote annotated.mcap: the new trajectory had stood beside the old run's
    manifest, and a new folder was left with some files and no manifest. Now neither folder is touched."""
    dest, fresh = tmp_path / "run", tmp_path / "fresh"
    dest.mkdir()
    (dest / "manifest.json").write_text("old")
    for folder in (dest, fresh):
        with pytest.raises(type(error)), staged_files(folder) as stage:
            (stage / "trajectory.parquet").write_text("new")
            raise error
    assert [(p.name, p.read_text()) for p in dest.iterdir()] == [("manifest.json", "old")]
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


def test_leftovers_of_a_killed_run_are_removed_and_outputs_kept(tmp_path: Path) -> None:
    keep = tmp_path / "site" / "runs" / "log" / "mcl"
    keep.mkdir(parents=True)
    (keep / "trajectory.parquet").write_text("x")
    staged = keep.parent / ".rbpf.0123456789abcdef.tmp"
    staged.mkdir()
    (staged / "trajectory.parquet").write_text("partial")
    old = tmp_path / "site" / ".map.0123456789abcdef.old"
    old.mkdir()
    leftover_file = temp_path_for(keep / "a.parquet")  # what a kill during an atomic write leaves
    leftover_file.write_text("partial")
    assert sorted(p.name for p in remove_leftovers(tmp_path)) == sorted([staged.name, old.name, leftover_file.name])
    assert sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*")) == [
        "site", "site/runs", "site/runs/log", "site/runs/log/mcl", "site/runs/log/mcl/trajectory.parquet"]
    atomic_write_text(keep / "b.txt", "b")
    assert remove_leftovers(tmp_path) == []
