"""Point-to-line ICP (PLICP) after Censi, "An ICP variant using a point-to-line metric", ICRA 2008.

The scan points p_i (sensor/base frame) are aligned to a reference by minimizing

    E(x, y, θ) = Σ_i (n_iᵀ (R(θ) p_i + t − q_i))²,

where q_i is the reference point nearest to the current estimate of R p_i + t (a scipy ``cKDTree``) and
n_i the unit normal of the reference surface there. Choice of line: a local PCA normal over the k
nearest reference points, computed once per reference (robust on voxelized submaps, unlike the line
through two noisy neighbours); points whose neighbourhood is not line-like are not used.

Minimization: the small-angle linearized Gauss–Newton step, iterated to convergence with fresh
correspondences at every iteration (not Censi's exact closed form with the Lagrange multiplier). The
increment δ = (δx, δy, δθ) is a right perturbation, T ← T ⊕ δ, with residual Jacobian

    ∂r_i/∂(δx, δy) = m_iᵀ,   ∂r_i/∂δθ = m_iᵀ J p_i,   m_i = R(θ)ᵀ n_i,  J = [[0, −1], [1, 0]],

and δ = −(AᵀA)⁻¹ Aᵀ r. Outliers: correspondences farther than ``max_correspondence_m`` are dropped, then
only the ``trim_fraction`` with the smallest |r_i| are kept (trimmed ICP). The covariance is the
Gauss–Newton one, σ² (AᵀA)⁻¹ with σ² = Σ r_i² / (n − 3), moved to the map frame (x, y, yaw).

Degeneracy: the smallest eigenvalue of AᵀA / n with the rotation column scaled by 1/L (L the RMS range
of the inliers), so that all three axes are dimensionless; a single wall or a featureless corridor gives
≈ 0 along the unobservable direction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import rotation_matrix

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

# A neighbourhood is line-like when its smaller PCA eigenvalue is below this fraction of the total.
LINE_EIGEN_RATIO_MAX = 0.05


@dataclass(frozen=True, slots=True, eq=False)
class LineReference:
    """Reference points with their PCA surface normals and a KD-tree over them (only line-like points)."""

    points: FloatArray  # (M, 2) map frame
    normals: FloatArray  # (M, 2) unit normals
    tree: cKDTree

    @property
    def size(self) -> int:
        """Number of usable reference points."""
        return int(self.points.shape[0])


@dataclass(frozen=True, slots=True)
class PlicpResult:
    """Outcome of one PLICP alignment.

    Attributes:
        pose: (3,) x, y, yaw of the scan in the reference frame.
        covariance: (3, 3) σ²(AᵀA)⁻¹ in the reference frame (inf where AᵀA is singular).
        n_inliers: Correspondences used in the last iteration.
        residual_m: Mean |n_iᵀ(R p_i + t − q_i)| over those inliers (m); NaN when there are none.
        degeneracy: Smallest eigenvalue of the dimensionless AᵀA / n (0: a direction is unconstrained).
        iterations: Gauss–Newton iterations run.
        converged: The last step was below the convergence thresholds.
    """

    pose: FloatArray
    covariance: FloatArray
    n_inliers: int
    residual_m: float
    degeneracy: float
    iterations: int
    converged: bool


@dataclass(frozen=True, slots=True)
class _Linearization:
    """Residuals and Jacobian of the inlier correspondences at one estimate."""

    residuals: FloatArray  # (n,)
    jacobian: FloatArray  # (n, 3)
    points: FloatArray  # (n, 2) scan points (sensor frame) that are inliers


def build_line_reference(points: npt.ArrayLike, *, neighbors: int = 8, max_extent_m: float = 0.5) -> LineReference:
    """Estimate PCA normals over the ``neighbors`` nearest points and keep the line-like points.

    For the neighbourhood covariance C = [[s_xx, s_xy], [s_xy, s_yy]] the major axis has angle
    φ = ½ atan2(2 s_xy, s_xx − s_yy) and the normal is (−sin φ, cos φ); the point is kept when
    λ_min / (λ_min + λ_max) ≤ ``LINE_EIGEN_RATIO_MAX`` and all neighbours lie within ``max_extent_m``.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    k = min(neighbors, pts.shape[0])
    if k < 3:
        empty = np.zeros((0, 2))
        return LineReference(empty, empty, cKDTree(empty))
    dist, idx = cKDTree(pts).query(pts, k=k)
    nb = pts[idx]  # (M, k, 2)
    centered = nb - nb.mean(axis=1, keepdims=True)
    sxx = np.einsum("mk,mk->m", centered[..., 0], centered[..., 0])
    syy = np.einsum("mk,mk->m", centered[..., 1], centered[..., 1])
    sxy = np.einsum("mk,mk->m", centered[..., 0], centered[..., 1])
    phi = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    trace = sxx + syy
    spread = np.sqrt((0.5 * (sxx - syy)) ** 2 + sxy**2)
    lam_min = 0.5 * trace - spread
    with np.errstate(invalid="ignore", divide="ignore"):
        line_like = lam_min <= LINE_EIGEN_RATIO_MAX * trace
    keep = line_like & (trace > 0.0) & (dist[:, -1] <= max_extent_m)
    normals = np.stack([-np.sin(phi[keep]), np.cos(phi[keep])], axis=1)
    kept = pts[keep]
    return LineReference(kept, normals, cKDTree(kept))


def _linearize(
    reference: LineReference, scan: FloatArray, pose: FloatArray, max_correspondence_m: float, trim_fraction: float
) -> _Linearization:
    """Nearest-neighbour correspondences at ``pose``, distance gate, trimming, residuals and Jacobian."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    moved = scan @ np.array([[c, s], [-s, c]]) + pose[:2]
    dist, idx = reference.tree.query(moved, k=1, distance_upper_bound=max_correspondence_m)
    found = np.flatnonzero(dist < np.inf)
    idx_f = idx[found]
    normals = reference.normals[idx_f]
    diff = moved[found] - reference.points[idx_f]
    residuals = normals[:, 0] * diff[:, 0] + normals[:, 1] * diff[:, 1]
    pts = scan[found]
    n_keep = math.ceil(trim_fraction * residuals.shape[0])
    if 0 < n_keep < residuals.shape[0]:
        order = np.argpartition(np.abs(residuals), n_keep - 1)[:n_keep]
        residuals, normals, pts = residuals[order], normals[order], pts[order]
    mx = c * normals[:, 0] + s * normals[:, 1]  # m_i = R(θ)ᵀ n_i
    my = c * normals[:, 1] - s * normals[:, 0]
    jacobian = np.stack([mx, my, my * pts[:, 0] - mx * pts[:, 1]], axis=1)  # [m_iᵀ, m_iᵀ J p_i]
    return _Linearization(residuals, jacobian, pts)


def _degeneracy(lin: _Linearization) -> float:
    """Smallest eigenvalue of AᵀA / n with the rotation column divided by the RMS range L."""
    n = lin.residuals.shape[0]
    if n < 3:
        return 0.0
    length = float(np.sqrt(np.mean(np.einsum("ij,ij->i", lin.points, lin.points))))
    scale = np.array([1.0, 1.0, 1.0 / max(length, 1e-9)])
    a = lin.jacobian * scale
    return float(np.linalg.eigvalsh(a.T @ a / n)[0])


def _covariance(lin: _Linearization, pose: FloatArray) -> FloatArray:
    """σ² (AᵀA)⁻¹ for the right perturbation, moved to (x, y, yaw) of the reference frame."""
    n = lin.residuals.shape[0]
    hessian = lin.jacobian.T @ lin.jacobian
    if n <= 3 or np.linalg.cond(hessian) > 1e12:
        return np.full((3, 3), np.inf)
    sigma2 = float(lin.residuals @ lin.residuals) / (n - 3)
    local = sigma2 * np.linalg.inv(hessian)
    g = np.eye(3)
    g[:2, :2] = rotation_matrix(pose[2])
    cov: FloatArray = g @ local @ g.T
    return 0.5 * (cov + cov.T)


def _step(lin: _Linearization) -> FloatArray:
    """Gauss–Newton increment δ = −(AᵀA)⁻¹ Aᵀ r; NaN when there are fewer than 3 rows or AᵀA is singular."""
    if lin.residuals.shape[0] < 3:
        return np.full(3, np.nan)
    try:
        delta = np.linalg.solve(lin.jacobian.T @ lin.jacobian, -(lin.jacobian.T @ lin.residuals))
    except np.linalg.LinAlgError:
        return np.full(3, np.nan)
    return np.asarray(delta, dtype=np.float64)


def plicp(
    reference: LineReference,
    scan_xy: npt.ArrayLike,
    initial_pose: npt.ArrayLike,
    *,
    max_iterations: int = 30,
    max_correspondence_m: float = 0.3,
    trim_fraction: float = 0.9,
    min_step_m: float = 1e-3,
    min_step_rad: float = 1e-3,
) -> PlicpResult:
    """Align scan points (sensor frame) to a line reference by point-to-line ICP from ``initial_pose``.

    Args:
        reference: Reference points and normals (:func:`build_line_reference`).
        scan_xy: (N, 2) scan points in the sensor (base) frame.
        initial_pose: (3,) x, y, yaw starting guess of the scan in the reference frame.
        max_iterations: Gauss–Newton iterations at most.
        max_correspondence_m: Nearest neighbours farther than this are not correspondences.
        trim_fraction: Fraction (0, 1] of the gated correspondences with the smallest |r| that are used.
        min_step_m: Converged when the translation step is below this ...
        min_step_rad: ... and the rotation step below this.

    Returns:
        The aligned pose, its covariance, inlier count, mean residual and degeneracy.
    """
    scan = np.asarray(scan_xy, dtype=np.float64).reshape(-1, 2)
    pose = np.asarray(initial_pose, dtype=np.float64).copy()
    lin = _Linearization(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 2)))
    converged, iterations = False, 0
    if reference.size == 0 or scan.shape[0] == 0:
        return _result(lin, pose, iterations, converged)
    while iterations < max_iterations:
        iterations += 1
        lin = _linearize(reference, scan, pose, max_correspondence_m, trim_fraction)
        delta = _step(lin)
        if not math.isfinite(float(delta.sum())):
            break
        pose = _right_compose(pose, delta)
        if math.hypot(delta[0], delta[1]) < min_step_m and abs(delta[2]) < min_step_rad:
            converged = True  # statistics from the last linearization: the final step is negligible
            break
    return _result(lin, pose, iterations, converged)


def _right_compose(pose: FloatArray, delta: FloatArray) -> FloatArray:
    """pose ⊕ δ for single poses (scalar math: this runs once per iteration)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    yaw = math.remainder(pose[2] + delta[2], 2.0 * math.pi)
    return np.array([pose[0] + c * delta[0] - s * delta[1], pose[1] + s * delta[0] + c * delta[1], yaw])


def _result(lin: _Linearization, pose: FloatArray, iterations: int, converged: bool) -> PlicpResult:
    """Package the statistics of the final linearization."""
    n = int(lin.residuals.shape[0])
    residual = float(np.mean(np.abs(lin.residuals))) if n else math.nan
    pose[2] = float(wrap_angle(pose[2]))
    return PlicpResult(pose, _covariance(lin, pose), n, residual, _degeneracy(lin), iterations, converged)
