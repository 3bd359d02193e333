"""The odometry at a CARMEN scan's stamp is that scan's own odometry field, not an ODOM line at the same stamp.

In the intel and aces logs the last ODOM line before each FLASER carries the scan's stamp but a dead-reckoned
pose that differs from the scan's odometry field (by up to 0.54 m on intel); the reader moves such lines
off the scan's stamp (interpolating between their neighbours in file order).
The truth here is parsed from the log text independently of the reader.
"""

from __future__ import annotations

import gzip
import math
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from doorbatch.geometry.se2 import interpolate_poses
from doorbatch.io.carmen import CarmenReader, odom_at_scan_stamps, separate_odom_from_scan_stamps
from doorbatch.io.recording import Recording, load_recording
from tests.conftest import carmen_log

FloatArray = npt.NDArray[np.float64]
POSITION_TOL_M = 1e-3
YAW_TOL_RAD = math.radians(0.01)


def _scan_odometry_fields(path: Path) -> FloatArray:
    """(S, 3) odometry fields of the FLASER / ROBOTLASER1 lines, in file order, by plain text parsing."""
    opener = gzip.open if path.suffix == ".gz" else open
    fields: list[list[float]] = []
    with opener(path, "rt") as f:
        for line in f:
            parts = line.split()
            if parts and parts[0] == "FLASER":  # FLASER n r_1..r_n laser_x y theta odom_x y theta ...
                n = int(parts[1])
                fields.append([float(v) for v in parts[2 + n + 3 : 2 + n + 6]])
            elif parts and parts[0] == "ROBOTLASER1":  # ... n r.. n_rem rem.. laser_pose robot_pose ...
                n = int(parts[8])
                n_rem = int(parts[9 + n])
                rest = 10 + n + n_rem
                fields.append([float(v) for v in parts[rest + 3 : rest + 6]])
    return np.array(fields, dtype=np.float64)


def _odometry_errors(rec: Recording, truth: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Position (m) and yaw (rad) differences between the loaded odometry at the scan stamps and ``truth``."""
    assert rec.odometry is not None
    got, valid = interpolate_poses(rec.odometry.stamps_ns, rec.odometry.poses, rec.scans.stamps_ns)
    assert valid.all()
    position = np.hypot(got[:, 0] - truth[:, 0], got[:, 1] - truth[:, 1])
    dyaw = got[:, 2] - truth[:, 2]
    return position, np.abs(np.arctan2(np.sin(dyaw), np.cos(dyaw)))


@pytest.mark.parametrize("name", ["intel", "aces", "orebro"])
def test_real_log_odometry_at_scan_stamps_is_the_scans_own(name: str) -> None:
    path = carmen_log(name)
    truth = _scan_odometry_fields(path)
    rec = load_recording(path)
    assert len(rec.scans.stamps_ns) == truth.shape[0]
    position, yaw = _odometry_errors(rec, truth)
    assert position.max() < POSITION_TOL_M, f"scan {int(position.argmax())} off by {position.max():.4f} m"
    assert yaw.max() < YAW_TOL_RAD


def _flaser(pose: tuple[float, float, float], odom: tuple[float, float, float], stamp: str) -> str:
    ranges = " ".join(["2.0"] * 181)
    values = " ".join(f"{v:.6f}" for v in (*pose, *odom))
    return f"FLASER 181 {ranges} {values} {stamp} host {stamp}"


def _odom(pose: tuple[float, float, float], stamp: str) -> str:
    return f"ODOM {pose[0]:.6f} {pose[1]:.6f} {pose[2]:.6f} 0.5 0.1 0 {stamp} host {stamp}"


def _intel_like_log(path: Path, n_scans: int) -> tuple[Path, FloatArray]:
    """Scans 1 s apart on a line, each one's odometry field 0.3 m (and 0.2 rad) from a dead-reckoned ODOM
    line logged with the scan's own stamp just before it; after the scan an ODOM line repeats its pose with
    stamp 0, the next one is logged with the scan's stamp too, then dead-reckoning ODOM lines follow, as in
    the intel log. The first scan has an ODOM line with its stamp before it and nothing else before."""
    lines = ["# message formats defined: PARAM SYNC ODOM FLASER"]
    truth = []
    for k in range(n_scans):
        t = 10.0 + k
        own = (1.0 * k, 0.1 * k, 0.05 * k)
        truth.append(own)
        lines.append(_odom((own[0] - 0.3, own[1], own[2] + 0.2), f"{t:.6f}"))  # same stamp, other pose
        lines.append(_flaser(own, own, f"{t:.6f}"))
        lines.append(_odom(own, "0"))
        lines.append(_odom((own[0] + 0.05, own[1], own[2]), f"{t:.6f}"))  # after the scan, its stamp
        for j in (1, 2, 3):
            lines.append(_odom((own[0] + 0.3 * j / 3, own[1], own[2]), f"{t + 0.25 * j:.6f}"))
    path.write_text("\n".join(lines) + "\n")
    return path, np.array(truth)


def test_odom_lines_at_a_scan_stamp_lose_to_the_scans_own_odometry(tmp_path: Path) -> None:
    path, truth = _intel_like_log(tmp_path / "intel_like.log", n_scans=6)
    np.testing.assert_allclose(_scan_odometry_fields(path), truth, atol=1e-9)
    rec = load_recording(path)
    position, yaw = _odometry_errors(rec, truth)
    assert position.max() < POSITION_TOL_M
    assert yaw.max() < YAW_TOL_RAD
    with CarmenReader(path) as reader:
        assert reader.topics["/scan"].count == 6
        # 6 · 6 ODOM lines, 18 on a scan's stamp (the stamp-0 repeats are repaired onto it as well): 17
        # re-stamped, the first line (nothing before it) dropped
        assert reader.topics["/odom"].count == 6 + 6 * 6 - 1
        assert reader.topics["/tf"].count == reader.topics["/odom"].count
        odom = list(reader.raw_messages(["/odom"]))
        assert len(odom) == reader.topics["/odom"].count
        assert any("18 of 36 ODOM lines share a scan's time stamp" in w and "re-stamped 17" in w
                   and "dropped 1" in w for w in reader.warnings)
    stamps = np.array([m.log_time_ns for m in odom])
    assert bool(np.all(np.diff(stamps) >= 0))
    scan_stamps = rec.scans.stamps_ns
    on_scan = np.isin(stamps, scan_stamps)
    assert on_scan.sum() == 6  # only the scans' own odometry sits on the scan stamps


def test_separate_odom_from_scan_stamps_interpolates_by_file_order() -> None:
    # lines: odom, odom@scan, scan, odom@scan, odom@scan, odom, scan, odom@scan (last: nothing after it)
    stamps = np.array([0, 100, 100, 100, 100, 400, 500, 500], dtype=np.int64)
    is_scan = np.array([False, False, True, False, False, False, True, False])
    got = separate_odom_from_scan_stamps(stamps, is_scan)
    assert got.stamps_ns.tolist() == [0, 50, 100, 200, 300, 400, 500, 500]
    assert got.dropped.tolist() == [False] * 7 + [True]
    assert got.n_restamped == 3


def test_odom_at_scan_stamps_marks_only_odom_lines_on_a_scan_stamp() -> None:
    stamps = np.array([0, 5, 5, 5, 7, 9, 9, 12], dtype=np.int64)
    is_scan = np.array([True, False, True, False, False, True, True, False])
    expected = [False, True, False, True, False, False, False, False]
    assert odom_at_scan_stamps(stamps, is_scan).tolist() == expected
