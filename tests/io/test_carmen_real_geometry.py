"""The CARMEN reader's beam geometry against a real log: its scans agree best with the log's corrected poses.

orebro's FLASER lines have 181 readings and no PARAMs; the reader lays them from −90° to +90° at 1°
(counter-clockwise, as CARMEN does). Each scan of the west corridor (scans 100–130, a 30 m straight run
with 1 m between scans) is aligned by PLICP to the previous one, both placed at their corrected poses; the
median distance PLICP moves a scan measures how well the scans and the poses agree. A mirrored scan, or a
beam increment 2 % off, agrees worse.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from doorbatch.config import DoorbatchConfig
from doorbatch.geometry.se2 import interpolate_poses, relative
from doorbatch.io.recording import Recording, load_recording
from doorbatch.pipeline.poses.plicp import plicp, scan_line_reference
from tests.conftest import carmen_log

FloatArray = npt.NDArray[np.float64]
CORRIDOR = range(100, 131)


def _hits(rec: Recording, i: int, angle_scale: float) -> FloatArray:
    """Hit points of scan i in base_link with every beam angle multiplied by ``angle_scale``."""
    s = rec.scans
    r = s.ranges[i].astype(np.float64)
    angles = angle_scale * (s.angle_min[i] + s.angle_increment[i] * np.arange(r.shape[0]))
    hit = np.isfinite(r) & (r >= s.range_min[i]) & (r < s.range_max[i])
    local = np.stack([r * np.cos(angles), r * np.sin(angles)], axis=1)[hit]
    if angle_scale < 0:
        local = local[::-1]  # keep the hits in increasing bearing, as the line extraction expects
    affine = s.laser_to_base[i]
    out: FloatArray = local @ affine[:, :2].T + affine[:, 2]
    return out


def _pairwise_median_m(rec: Recording, ref: FloatArray, angle_scale: float) -> float:
    moved = []
    for k in CORRIDOR:
        lines = scan_line_reference(_hits(rec, k - 1, angle_scale), ref[k - 1])
        fit = plicp(lines, _hits(rec, k, angle_scale), ref[k], min_step_m=1e-5, min_step_rad=1e-6)
        d = relative(ref[k], fit.pose)
        moved.append(np.hypot(d[0], d[1]))
    return float(np.median(moved))


def test_orebro_scans_agree_best_with_the_corrected_poses_in_the_readers_geometry() -> None:
    rec = load_recording(carmen_log("orebro"), DoorbatchConfig())
    assert rec.reference is not None and len(rec.scans) == 237
    assert np.allclose(np.degrees(rec.scans.angle_min), -90.0) and np.allclose(
        np.degrees(rec.scans.angle_increment), 1.0)
    ref, ok = interpolate_poses(rec.reference.stamps_ns, rec.reference.poses, rec.scans.stamps_ns)
    assert ok.all()
    ours = _pairwise_median_m(rec, ref, 1.0)
    assert ours < 0.03  # ≈ 2.8 cm: the corrected poses and the 1° scans agree to a few centimetres per step
    for scale in (-1.0, 0.98, 1.02):  # mirrored, increment 2 % short, 2 % long
        assert _pairwise_median_m(rec, ref, scale) > ours
