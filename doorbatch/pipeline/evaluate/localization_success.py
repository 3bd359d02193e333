"""Global localization success (paper 000 Sec. V-C, Figs. 8–9).

Paper 000 counts a run as localized "if the localization error and the number of particles falls below a
threshold". Here (as scripts/localize_global.py did): the filter reported convergence (weighted position and
yaw std below ``localize.converged_*``, which is what shrinks KLD's particle count) within ``window_s`` of the
first update, and the estimate is within ``max_xy_m`` and ``max_yaw_rad`` of the reference both at
convergence and at the end of the log (a filter converged on the wrong hypothesis fails). The reference is
interpolated at those two instants (between reference poses at most ``max_reference_gap_s`` apart): a
ground-truth stream at its own rate seldom has a pose at the very stamp of a scan.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import interpolate_poses


@dataclass(frozen=True)
class ConvergenceCheck:
    """Thresholds of a successful global localization."""

    window_s: float
    max_xy_m: float
    max_yaw_rad: float
    max_reference_gap_s: float


def global_success(stamps_ns: npt.ArrayLike, pose: npt.ArrayLike, converged_ns: int | None,
                   ref_stamps_ns: npt.ArrayLike, ref_pose: npt.ArrayLike, check: ConvergenceCheck) -> bool:
    """Whether a global localization run succeeded (see the module docstring). An instant the reference does
    not cover (outside it, or in a gap wider than ``max_reference_gap_s``) counts as a failure."""
    t = np.asarray(stamps_ns, dtype=np.int64)
    est = np.asarray(pose, dtype=np.float64).reshape(-1, 3)
    if converged_ns is None or t.size == 0 or (converged_ns - int(t[0])) / 1e9 > check.window_s:
        return False
    at = min(int(np.searchsorted(t, converged_ns)), t.size - 1)
    idx = np.array([at, t.size - 1])
    ref, valid = interpolate_poses(ref_stamps_ns, ref_pose, t[idx], round(check.max_reference_gap_s * 1e9))
    if not valid.all():
        return False
    xy = np.hypot(est[idx, 0] - ref[:, 0], est[idx, 1] - ref[:, 1])
    yaw = np.abs(wrap_angle(est[idx, 2] - ref[:, 2]))
    return bool(np.all(xy <= check.max_xy_m) and np.all(yaw <= check.max_yaw_rad))
