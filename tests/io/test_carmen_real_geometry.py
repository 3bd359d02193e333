"""The CARMEN reader's beam geometry against the real logs: its scans agree best with the logs' corrected poses.

orebro's FLASER lines have 181 readings and no PARAMs; the reader lays them from −90° to +90° at 1°
(counter-clockwise, as CARMEN does); intel's and aces' have 180, laid from −90° to +89° at 1°, and a
``robot_frontlaser_offset`` of 0. Two measures of agreement:

* pairwise (orebro): each scan of the west corridor (scans 100–130, a 30 m straight run with 1 m between
  scans) is aligned by PLICP to the previous one, both placed at their corrected poses; the median distance
  PLICP moves a scan. A mirrored scan, or a beam increment 2 % off, agrees worse.
* map sharpness (all three logs): the number of 5 cm cells that the hits of all scans, placed at their
  corrected poses, fall in. A wrong beam geometry or laser offset blurs every wall, so the reader's geometry
  must give the fewest cells: fewer than a quarter- or half-beam shift of all bearings (the centred
  −89.5° … +89.5° convention for 180 readings), an increment 0.5 % off (180 readings spanning 179 steps
  is 0.56 % longer), a laser 0.1 m ahead of or behind the pose, or a mirrored scan.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest

from doorbatch.config import DoorbatchConfig
from doorbatch.geometry.se2 import interpolate_poses, relative
from doorbatch.io.recording import Recording, load_recording
from doorbatch.pipeline.poses.plicp import plicp, scan_line_reference
from tests.conftest import carmen_log

FloatArray = npt.NDArray[np.float64]
CORRIDOR = range(100, 131)


def _hits(rec: Recording, i: int, angle_scale: float, shift_deg: float = 0.0, forward_m: float = 0.0) -> FloatArray:
    """Hit points of scan i in base_link with every beam angle multiplied by ``angle_scale``, then turned by
    ``shift_deg``, and the laser moved ``forward_m`` along base_link x."""
    s = rec.scans
    r = s.ranges[i].astype(np.float64)
    angles = angle_scale * (s.angle_min[i] + s.angle_increment[i] * np.arange(r.shape[0])) + np.radians(shift_deg)
    hit = np.isfinite(r) & (r >= s.range_min[i]) & (r < s.range_max[i])
    local = np.stack([r * np.cos(angles), r * np.sin(angles)], axis=1)[hit]
    if angle_scale < 0:
        local = local[::-1]  # keep the hits in increasing bearing, as the line extraction expects
    affine = s.laser_to_base[i]
    out: FloatArray = local @ affine[:, :2].T + affine[:, 2] + np.array([forward_m, 0.0])
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


def _occupied_cells(rec: Recording, ref: FloatArray, cell_m: float, **variant: float) -> int:
    """Number of ``cell_m`` cells hit by all scans placed at their corrected poses (fewer: a sharper map)."""
    placed = []
    for i in range(len(rec.scans)):
        c, s = np.cos(ref[i, 2]), np.sin(ref[i, 2])
        placed.append(_hits(rec, i, **variant) @ np.array([[c, s], [-s, c]]) + ref[i, :2])
    return int(np.unique(np.floor(np.concatenate(placed) / cell_m).astype(np.int64), axis=0).shape[0])


@pytest.mark.parametrize("name", ["orebro", "intel", "aces"])
def test_the_readers_beam_geometry_gives_the_sharpest_map_at_the_corrected_poses(name: str) -> None:
    rec = load_recording(carmen_log(name), DoorbatchConfig())
    assert rec.reference is not None
    assert np.allclose(np.degrees(rec.scans.angle_min), -90.0) and np.allclose(
        np.degrees(rec.scans.angle_increment), 1.0)
    ref, ok = interpolate_poses(rec.reference.stamps_ns, rec.reference.poses, rec.scans.stamps_ns)
    assert ok.all()
    ours = _occupied_cells(rec, ref, 0.05, angle_scale=1.0)
    variants: list[dict[str, float]] = [
        {"angle_scale": 1.0, "shift_deg": d} for d in (-0.5, -0.25, 0.25, 0.5)] + [
        {"angle_scale": a} for a in (0.995, 1.005, -1.0)] + [
        {"angle_scale": 1.0, "forward_m": f} for f in (-0.1, 0.1)]
    for variant in variants:
        assert _occupied_cells(rec, ref, 0.05, **variant) > ours, variant
