"""Planar rigid motions SE(2) on poses stored as arrays (..., 3) = (x, y, yaw), vectorized over leading axes.

A pose a = (x, y, θ) maps a point p of its child frame to its parent frame: a(p) = R(θ) p + (x, y).
Composition (the ⊕ of Smith, Self and Cheeseman) is a ⊕ b = (R(θ_a) t_b + t_a, θ_a + θ_b), so that
(a ⊕ b)(p) = a(b(p)); the inverse is a⁻¹ = (−R(θ_a)ᵀ t_a, −θ_a); the relative pose of b seen from a is
a⁻¹ ⊕ b (an odometry increment). Every yaw returned is wrapped to (−π, π].
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.rotations import wrap_angle

FloatArray = npt.NDArray[np.float64]


def rotation_matrix(yaw: npt.ArrayLike) -> FloatArray:
    """R(θ) = [[cos θ, −sin θ], [sin θ, cos θ]], shape (..., 2, 2) for yaw of shape (...)."""
    theta = np.asarray(yaw, dtype=np.float64)
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], axis=-1), np.stack([s, c], axis=-1)], axis=-2)


def frame_rotation(yaw: float) -> FloatArray:
    """G = diag(R(θ), 1) (3, 3): a pose increment's covariance in the frame of heading θ is G Σ Gᵀ in the map's."""
    g = np.eye(3)
    g[:2, :2] = rotation_matrix(yaw)
    return g


def compounded_covariance(covariance: npt.ArrayLike, shift_xy: npt.ArrayLike, added: npt.ArrayLike) -> FloatArray:
    """Cov(x ⊕ u) to first order, J Σ_x Jᵀ + Σ_u (both map frame), J = ∂(x ⊕ u)/∂x = [[1, 0, −Δy], [0, 1, Δx],
    [0, 0, 1]] with (Δx, Δy) = ``shift_xy`` the increment's translation in the map frame."""
    dx, dy = (float(v) for v in np.asarray(shift_xy, dtype=np.float64)[:2])
    jac = np.array([[1.0, 0.0, -dy], [0.0, 1.0, dx], [0.0, 0.0, 1.0]])
    out: FloatArray = jac @ np.asarray(covariance, dtype=np.float64) @ jac.T + np.asarray(added, dtype=np.float64)
    return out


def compose(a: npt.ArrayLike, b: npt.ArrayLike) -> FloatArray:
    """a ⊕ b = (R(θ_a) t_b + t_a, θ_a + θ_b); broadcasts over leading axes."""
    pa = np.asarray(a, dtype=np.float64)
    pb = np.asarray(b, dtype=np.float64)
    c, s = np.cos(pa[..., 2]), np.sin(pa[..., 2])
    x = pa[..., 0] + c * pb[..., 0] - s * pb[..., 1]
    y = pa[..., 1] + s * pb[..., 0] + c * pb[..., 1]
    return np.stack([x, y, wrap_angle(pa[..., 2] + pb[..., 2])], axis=-1)


def inverse(a: npt.ArrayLike) -> FloatArray:
    """a⁻¹ = (−R(θ)ᵀ t, −θ), so that a ⊕ a⁻¹ = a⁻¹ ⊕ a = 0."""
    pa = np.asarray(a, dtype=np.float64)
    c, s = np.cos(pa[..., 2]), np.sin(pa[..., 2])
    x = -(c * pa[..., 0] + s * pa[..., 1])
    y = -(-s * pa[..., 0] + c * pa[..., 1])
    return np.stack([x, y, wrap_angle(-pa[..., 2])], axis=-1)


def relative(a: npt.ArrayLike, b: npt.ArrayLike) -> FloatArray:
    """a⁻¹ ⊕ b: the pose of b expressed in the frame of a (e.g. the odometry increment between scans)."""
    return compose(inverse(a), b)


def transform_points(pose: npt.ArrayLike, points: npt.ArrayLike) -> FloatArray:
    """pose(p) = R(θ) p + t for (N, 2) points and one (3,) pose."""
    p = np.asarray(pose, dtype=np.float64)
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    c, s = np.cos(p[2]), np.sin(p[2])
    rot_t = np.array([[c, s], [-s, c]])
    out: FloatArray = pts @ rot_t + p[:2]
    return out


def interpolate_poses(stamps_ns: npt.ArrayLike, poses: npt.ArrayLike, query_ns: npt.ArrayLike,
                      max_gap_ns: int | None = None) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    """Poses at ``query_ns`` by linear interpolation of x, y and of the shortest-arc yaw difference.

    Queries outside [stamps[0], stamps[-1]], or between two stamps more than ``max_gap_ns`` apart, are
    flagged invalid (their pose is the nearest end, not an extrapolation).

    Returns:
        (Q, 3) poses and a (Q,) validity mask.
    """
    t = np.asarray(stamps_ns, dtype=np.int64)
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    q = np.asarray(query_ns, dtype=np.int64)
    if t.shape[0] == 0:
        return np.zeros((q.shape[0], 3)), np.zeros(q.shape[0], dtype=bool)
    hi = np.clip(np.searchsorted(t, q, side="left"), 1, max(t.shape[0] - 1, 1))
    lo = hi - 1
    if t.shape[0] == 1:
        lo = hi = np.zeros_like(q)
    span = (t[hi] - t[lo]).astype(np.float64)
    frac = np.clip(np.divide((q - t[lo]).astype(np.float64), span, out=np.zeros_like(span), where=span > 0), 0, 1)
    dyaw = np.arctan2(np.sin(p[hi, 2] - p[lo, 2]), np.cos(p[hi, 2] - p[lo, 2]))
    out = np.empty((q.shape[0], 3))
    out[:, :2] = p[lo, :2] + frac[:, None] * (p[hi, :2] - p[lo, :2])
    yaw = p[lo, 2] + frac * dyaw
    out[:, 2] = np.arctan2(np.sin(yaw), np.cos(yaw))
    valid = (q >= t[0]) & (q <= t[-1])
    if max_gap_ns is not None:  # a query exactly on a stamp needs no interpolation, whatever the gap
        valid &= ((t[hi] - t[lo]) <= max_gap_ns) | (q == t[hi]) | (q == t[lo])
    return out, valid
