"""Whether the laser mount the log's TF states agrees with the scans, given reference poses.

A laser turned by δ on its mount against what the TF says puts every scan, in base_link, turned by δ about the
laser's origin: E = T(m) R(δ) T(−m). Two scans whose base poses differ by Δ then align at E Δ E⁻¹, whose translation
is Δ's turned by δ (a rigid motion conjugates a translation into its own rotation of it) and whose rotation is Δ's.
So matching scan j against scan i (point-to-line ICP from the reference's Δ) on a straight stretch gives a motion at
δ to the reference's: the median of those angles over pairs ~``mount_check_step_m`` apart estimates δ. Exact poses
and a right mount give 0; a reference with its own heading error per step does not bias it (it turns Δ and the match
alike). Only the yaw is checked: an offset error of a few cm shows in neither angle nor map much.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import relative
from doorbatch.io.recording import Recording
from doorbatch.pipeline.poses.plicp import plicp, scan_line_reference

FloatArray = npt.NDArray[np.float64]


def mount_yaw_offsets(rec: Recording, poses: npt.ArrayLike, valid: npt.ArrayLike, step_m: float, max_turn_rad: float,
                      max_pairs: int, min_hits: int = 50) -> FloatArray:
    """The angle (rad) between the matched and the reference motion of scan pairs ``step_m`` of travel apart that
    turned less than ``max_turn_rad`` (module docstring), at most ``max_pairs`` spread over the log; a pair whose
    match did not converge, or whose scans have fewer than ``min_hits`` hits, gives none."""
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    ok = np.asarray(valid, dtype=bool)
    idx = np.flatnonzero(ok)
    if idx.size < 2:
        return np.zeros(0)
    travel = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p[idx, :2], axis=0).T))])
    pairs: list[tuple[int, int]] = []
    k = 0
    while k < idx.size - 1:
        j = int(np.searchsorted(travel, travel[k] + step_m))
        if j >= idx.size:
            break
        pairs.append((int(idx[k]), int(idx[j])))
        k = j
    if len(pairs) > max_pairs:
        pairs = [pairs[int(q)] for q in np.linspace(0, len(pairs) - 1, max_pairs).round()]
    out = []
    for i, j in pairs:
        delta = relative(p[i], p[j])
        if abs(float(wrap_angle(delta[2]))) > max_turn_rad or math.hypot(delta[0], delta[1]) < 0.5 * step_m:
            continue
        a, b = rec.scans.hits_base(i), rec.scans.hits_base(j)
        if a.shape[0] < min_hits or b.shape[0] < min_hits:
            continue
        res = plicp(scan_line_reference(a, np.zeros(3)), b, delta)
        if not res.converged or res.n_inliers < min_hits:
            continue
        out.append(float(wrap_angle(math.atan2(res.pose[1], res.pose[0]) - math.atan2(delta[1], delta[0]))))
    return np.asarray(out, dtype=np.float64)
