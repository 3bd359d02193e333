"""``doorbatch convert`` on the real CARMEN logs in ../shared: scan count, corrected poses, roles."""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np
import pytest

from doorbatch.cli import main
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.io.reader import open_log
from doorbatch.records import Pose2D, Role
from tests.conftest import carmen_log


def _flaser_poses(path: Path) -> np.ndarray:
    """x, y, theta of every FLASER line, parsed independently of doorbatch."""
    poses = []
    with gzip.open(path, "rt") as f:
        for line in f:
            parts = line.split()
            if parts and parts[0] == "FLASER":
                n = int(parts[1])
                poses.append([float(v) for v in parts[2 + n: 5 + n]])
    return np.array(poses)


@pytest.mark.parametrize("name", ["aces", "intel", "orebro"])
def test_convert_real_carmen_log(name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = carmen_log(name)
    out = tmp_path / f"{name}.mcap"
    assert main(["convert", str(src), "-o", str(out), "-q"]) == 0
    expected = _flaser_poses(src)
    with open_log(out) as reader:
        assert reader.topics["/scan"].count == len(expected)
        truth = [rm.record for rm in reader.messages([Role.REFERENCE])]
    assert all(isinstance(p, Pose2D) and p.frame_id == "map" for p in truth)
    got = np.array([[p.x, p.y, p.yaw] for p in truth if isinstance(p, Pose2D)])
    assert got.shape == expected.shape
    np.testing.assert_allclose(got[:, :2], expected[:, :2], atol=1e-9)
    np.testing.assert_allclose(wrap_angle(got[:, 2] - expected[:, 2]), 0.0, atol=1e-9)

    capsys.readouterr()
    assert main(["inspect", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    roles = {t["role"] for t in report["topics"]}
    assert {"scan", "odometry", "reference"} <= roles
