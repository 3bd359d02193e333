"""Absolute trajectory error of planar trajectories sampled at the same stamps."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import compose, inverse

FloatArray = npt.NDArray[np.float64]


def first_pose_correction(estimate: npt.ArrayLike, reference: npt.ArrayLike) -> FloatArray:
    """The rigid motion T = r₀ ⊕ e₀⁻¹ (x, y, yaw) that takes the estimate's first pose onto the reference's."""
    est = np.asarray(estimate, dtype=np.float64).reshape(-1, 3)
    ref = np.asarray(reference, dtype=np.float64).reshape(-1, 3)
    return compose(ref[0], inverse(est[0]))


def align_first_pose(estimate: npt.ArrayLike, reference: npt.ArrayLike) -> FloatArray:
    """The estimate moved rigidly so that its first pose equals the reference's (odometry-style evaluation:
    both start at the same pose; :func:`first_pose_correction`)."""
    est = np.asarray(estimate, dtype=np.float64).reshape(-1, 3)
    return compose(np.broadcast_to(first_pose_correction(est, reference), est.shape), est)


def position_errors(estimate: npt.ArrayLike, reference: npt.ArrayLike) -> FloatArray:
    """|p_est − p_ref| per pose (m)."""
    est = np.asarray(estimate, dtype=np.float64).reshape(-1, 3)
    ref = np.asarray(reference, dtype=np.float64).reshape(-1, 3)
    return np.asarray(np.hypot(est[:, 0] - ref[:, 0], est[:, 1] - ref[:, 1]), dtype=np.float64)


def yaw_errors(estimate: npt.ArrayLike, reference: npt.ArrayLike) -> FloatArray:
    """|wrap(θ_est − θ_ref)| per pose (rad)."""
    est = np.asarray(estimate, dtype=np.float64).reshape(-1, 3)
    ref = np.asarray(reference, dtype=np.float64).reshape(-1, 3)
    return np.abs(wrap_angle(est[:, 2] - ref[:, 2]))


def rigid_copy_offset(estimate: npt.ArrayLike, reference: npt.ArrayLike) -> tuple[float, float]:
    """How far ``estimate`` is from being ``reference`` moved rigidly: after :func:`align_first_pose`, the largest
    position (m) and heading (rad) error. Both zero for a copy in another frame (odometry republished as a pose
    topic, a raw CARMEN log's laser poses)."""
    if np.asarray(estimate).reshape(-1, 3).shape[0] == 0:
        return 0.0, 0.0
    aligned = align_first_pose(estimate, reference)
    return float(np.max(position_errors(aligned, reference))), float(np.max(yaw_errors(aligned, reference)))


def ate_rmse(estimate: npt.ArrayLike, reference: npt.ArrayLike) -> float:
    """Translational ATE RMSE (m), no alignment: √(mean |p_est − p_ref|²)."""
    err = position_errors(estimate, reference)
    return float(np.sqrt(np.mean(err**2))) if err.size else 0.0
