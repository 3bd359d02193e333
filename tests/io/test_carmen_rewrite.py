"""``rewrite_carmen_poses``: every pose field of a CARMEN log replaced, in file order, nothing else touched."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest

from doorbatch.config import DoorbatchConfig
from doorbatch.errors import LogReadError
from doorbatch.io.carmen_rewrite import rewrite_carmen_poses
from doorbatch.io.recording import load_recording
from tests.io.test_carmen import simple_log, write_log


def test_the_poses_come_in_file_order_and_go_back_into_every_pose_field(tmp_path: Path) -> None:
    source = write_log(tmp_path / "corrected.log.gz", simple_log(n_scans=6))
    seen: list[np.ndarray] = []

    def moved(poses: np.ndarray) -> np.ndarray:
        seen.append(poses.copy())
        return poses + np.array([2.0, -1.0, 0.1])

    assert rewrite_carmen_poses(source, tmp_path / "raw.log", moved) == 12  # 6 FLASER + 6 ODOM lines
    # simple_log: FLASER k at (0.1 k, 0, 0.05 k), then ODOM k at (0.1 k + 0.05, 0, 0.05 k)
    k = np.arange(6)
    expected = np.stack([np.stack([0.1 * k, 0 * k, 0.05 * k], 1), np.stack([0.1 * k + 0.05, 0 * k, 0.05 * k], 1)], 1)
    assert np.allclose(seen[0], expected.reshape(-1, 3))

    config = DoorbatchConfig()
    before, after = load_recording(source, config), load_recording(tmp_path / "raw.log", config)
    assert before.odometry is not None and after.odometry is not None
    assert before.reference is not None and after.reference is not None
    assert np.array_equal(before.scans.stamps_ns, after.scans.stamps_ns)
    assert all(np.array_equal(a, b) for a, b in zip(before.scans.ranges, after.scans.ranges, strict=True))
    for b, a in ((before.odometry, after.odometry), (before.reference, after.reference)):
        assert np.array_equal(b.stamps_ns, a.stamps_ns)
        assert np.allclose(a.poses, b.poses + np.array([2.0, -1.0, 0.1]), atol=1e-6)


@pytest.mark.parametrize("line", ["FLASER 3 1.0 1.0 1.0 0.0 0.0", "FLASER x 1.0", "FLASER", "ODOM 1.0"])
def test_a_line_without_its_poses_is_an_error(tmp_path: Path, line: str) -> None:
    source = write_log(tmp_path / "short.log", [line])
    with pytest.raises(LogReadError, match=f"line 1: {line.split()[0]} has no pose fields"):
        rewrite_carmen_poses(source, tmp_path / "out.log", lambda poses: poses)


def test_it_reads_what_the_reader_reads_a_gzipped_clf_with_latin_1_bytes(tmp_path: Path) -> None:
    """Gzip by the file's first bytes, not its name; undecodable bytes replaced (the reader's own opener)."""
    path = tmp_path / "old.clf"
    with gzip.open(path, "wb") as f:
        f.write("# Logfile of the caf\xe9\n".encode("latin-1"))  # 0xE9: no UTF-8
        f.write(("\n".join(simple_log(n_scans=2)) + "\n").encode())
    assert rewrite_carmen_poses(path, tmp_path / "out.log", lambda poses: poses) == 4
