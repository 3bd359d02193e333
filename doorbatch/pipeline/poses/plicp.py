"""Point-to-line ICP (PLICP, Censi ICRA 2008) with an optional Gaussian pose prior (MAP estimate).

Reference lines. A laser scan samples surfaces in beam order, so the lines are taken from that order
(as Censi does) instead of from nearest neighbours in a merged cloud: at long range the beams of a 1°
scanner are r·Δφ apart (0.9 m at 50 m), far sparser than any neighbourhood radius. Two consecutive hits
are joined when they can lie on one surface: their spacing is at most r·Δφ / cos β_max + 3√2 σ_r (a
surface seen at incidence up to β_max; the range noise σ_r at short range), r the nearer range and Δφ
their bearing difference; a longer jump is a depth discontinuity. A hit's normal is the PCA normal of the
joined hits within ``normal_radius_m`` of it along its chain (at least its chain neighbours); it is kept
when that window spans at least ``normal_radius_m`` and is line-like. The reference is the joined
segments sampled every ``spacing_m``, each sample carrying the normal of its nearer end point, so that a
nearest sample is the foot of a line even where the beams are sparse.

Alignment. The scan points p_i (base frame) are aligned by minimizing

    E(T) = Σ_i (n_iᵀ (R(θ) p_i + t − q_i))² / σ² + (T − μ)ᵀ Λ (T − μ),

T = (x, y, θ) in the reference frame, q_i the reference sample nearest to R p_i + t (a scipy ``cKDTree``)
and n_i its normal. The second term is an optional Gaussian prior N(μ, Λ⁻¹) (the odometry prediction):
along a direction the scan does not constrain (a featureless corridor, one wall) the estimate stays at
the prior, while the observable directions follow the scan. Gauss–Newton on (x, y, θ) with fresh
correspondences at every iteration; the residual rows are

    ∂r_i/∂(x, y) = n_iᵀ,   ∂r_i/∂θ = n_iᵀ J R(θ) p_i,   J = [[0, −1], [1, 0]],

σ² = max(Σ w_i r_i² / (Σ w_i − 3), σ_min²) from the current inliers, and the step solves
(AᵀWA/σ² + Λ) δ = −(AᵀWr/σ² + Λ (T − μ)). Outliers (people, moved doors, clutter): correspondences
farther than ``max_correspondence_m`` are dropped, only the ``trim_fraction`` with the smallest |r_i| are
kept (trimmed ICP: a walking person is a compact set of large residuals), and those are weighted by the
Cauchy M-estimator w_i = 1 / (1 + (r_i / c)²) (iteratively reweighted least squares, c =
``robust_scale_m``), so that moderate outliers (a door moved a little, clutter) count little while the few
points that fix a corridor along its axis (door jambs, niches) still count. The covariance is
(AᵀWA/σ² + Λ)⁻¹ (without a prior σ²(AᵀWA)⁻¹, inf where singular). To compare two local optima (from two
starting poses) the result reports the robust data cost D = Σ ρ(r_i), ρ(r) = c²/2 · log(1 + (r/c)²), every
scan point without a kept correspondence counted at the gate distance, the prior cost P = (T − μ)ᵀ Λ (T − μ)
and σ; the MAP objective is D/σ² + P with one σ for both (:func:`map_cost`).

Degeneracy: the smallest eigenvalue of AᵀWA / n with the rotation column scaled by 1/L (L the RMS range
of the inliers), so that all three axes are dimensionless; a single wall or a featureless corridor gives
≈ 0 along the unobservable direction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from doorbatch.config import ScanMatchConfig
from doorbatch.geometry.rotations import wrap_angle

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

# A neighbourhood is line-like when its smaller PCA eigenvalue is below this fraction of the total.
LINE_EIGEN_RATIO_MAX = 0.05


@dataclass(frozen=True, slots=True, eq=False)
class LineReference:
    """Reference line samples with their unit normals and a KD-tree over them."""

    points: FloatArray  # (M, 2) map frame
    normals: FloatArray  # (M, 2) unit normals
    tree: cKDTree

    @property
    def size(self) -> int:
        """Number of usable reference samples."""
        return int(self.points.shape[0])


@dataclass(frozen=True, slots=True)
class ScanLines:
    """Line samples of one scan in its own frame (see the module docstring)."""

    points: FloatArray  # (M, 2)
    normals: FloatArray  # (M, 2) unit


@dataclass(frozen=True, slots=True)
class GaussianPrior:
    """A pose prior N(mean, information⁻¹) in the reference frame (x, y, yaw; information in m⁻², rad⁻²)."""

    mean: FloatArray  # (3,)
    information: FloatArray  # (3, 3)


@dataclass(frozen=True, slots=True)
class PlicpResult:
    """Outcome of one PLICP alignment.

    Attributes:
        pose: (3,) x, y, yaw of the scan in the reference frame.
        covariance: (3, 3) (AᵀA/σ² + Λ)⁻¹ in the reference frame (inf where singular without a prior).
        n_inliers: Correspondences used in the last iteration.
        residual_m: Mean |n_iᵀ(R p_i + t − q_i)| over those inliers (m); NaN when there are none.
        data_cost: D = Σ ρ(r_i) over the scan at ``pose`` (m², module docstring).
        prior_cost: P = (T − μ)ᵀ Λ (T − μ), 0 without a prior.
        sigma_m: RMS of the kept residuals (unweighted: how well the pose fits), floored at sigma_min_m; inf
            with three inliers or fewer.
        degeneracy: Smallest eigenvalue of the dimensionless AᵀA / n (0: a direction is unconstrained).
        iterations: Gauss–Newton iterations run.
        converged: The last step was below the convergence thresholds.
        outside_gate: (N,) the scan points with no reference sample within the gate in the last linearization,
            those ``data_cost`` charges ρ(gate) for along with the trimmed ones.
    """

    pose: FloatArray
    covariance: FloatArray
    n_inliers: int
    residual_m: float
    data_cost: float
    prior_cost: float
    sigma_m: float
    degeneracy: float
    iterations: int
    converged: bool
    outside_gate: BoolArray


@dataclass(frozen=True, slots=True)
class _Linearization:
    """Residuals and Jacobian of the inlier correspondences at one estimate."""

    residuals: FloatArray  # (n,)
    jacobian: FloatArray  # (n, 3)
    points: FloatArray  # (n, 2) scan points (sensor frame) that are inliers
    weights: FloatArray  # (n,) robust weights in (0, 1]
    n_unmatched: int  # scan points without a kept correspondence (none within the gate, or trimmed)
    outside_gate: BoolArray  # (N,) scan points with no reference sample within the gate


def line_reference(points: npt.ArrayLike, normals: npt.ArrayLike) -> LineReference:
    """A :class:`LineReference` over given samples and unit normals (both (M, 2))."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 2)
    if pts.shape != nrm.shape:
        raise ValueError(f"points {pts.shape} and normals {nrm.shape} differ in shape")
    return LineReference(pts, nrm, cKDTree(pts))


def _joined(pts: FloatArray, max_incidence_rad: float, range_sigma_m: float, max_missing_beams: int) -> BoolArray:
    """(N−1,) consecutive hits i, i+1 lie on one surface seen at incidence ≤ β_max (module docstring).

    The beam step is the median bearing difference of consecutive hits; hits more than
    ``max_missing_beams`` missing beams apart (an unobserved gap, e.g. a doorway with no return) are not joined.
    """
    rng = np.hypot(pts[:, 0], pts[:, 1])
    bearing = np.arctan2(pts[:, 1], pts[:, 0])
    gap = np.abs(wrap_angle(np.diff(bearing)))
    beam_step = float(np.median(gap))
    spacing = np.hypot(*np.diff(pts, axis=0).T)
    near = np.minimum(rng[:-1], rng[1:])
    allowed = near * gap / math.cos(max_incidence_rad) + 3.0 * math.sqrt(2.0) * range_sigma_m
    out: BoolArray = (spacing <= allowed) & (gap <= (max_missing_beams + 1.5) * beam_step)
    return out


def _window_normals(pts: FloatArray, joined: BoolArray, radius_m: float) -> tuple[FloatArray, BoolArray]:
    """PCA normal of each hit over the joined hits within ``radius_m`` along its chain, and whether it is usable.

    Windows are index ranges [lo, hi] of the chain found from the cumulative arc length s (|s_j − s_i| ≤
    radius, widened to the chain neighbours); the sums over them come from cumulative sums, so this is O(N).
    """
    n = pts.shape[0]
    step = np.where(joined, np.hypot(*np.diff(pts, axis=0).T), np.inf)
    chain = np.concatenate([[0], np.cumsum(~joined)])  # chain id of every hit
    arc = np.concatenate([[0.0], np.cumsum(np.where(joined, step, 0.0))])
    key = chain * (arc[-1] + 4.0 * radius_m + 1.0) + arc  # strictly increasing; chains far apart
    lo = np.searchsorted(key, key - radius_m, side="left")
    hi = np.searchsorted(key, key + radius_m, side="right") - 1
    idx = np.arange(n)
    lo = np.minimum(lo, np.where(np.concatenate([[False], joined]), idx - 1, idx))
    hi = np.maximum(hi, np.where(np.concatenate([joined, [False]]), idx + 1, idx))
    x, y = pts[:, 0] - pts[:, 0].mean(), pts[:, 1] - pts[:, 1].mean()
    sums = [np.concatenate([[0.0], np.cumsum(v)]) for v in (np.ones(n), x, y, x * x, y * y, x * y)]
    c, sx, sy, sxx, syy, sxy = (s[hi + 1] - s[lo] for s in sums)
    cxx, cyy, cxy = sxx - sx * sx / c, syy - sy * sy / c, sxy - sx * sy / c
    phi = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)
    trace = cxx + cyy
    lam_min = 0.5 * trace - np.sqrt((0.5 * (cxx - cyy)) ** 2 + cxy**2)
    span = arc[hi] - arc[lo]
    usable = (c >= 2) & (trace > 0.0) & (lam_min <= LINE_EIGEN_RATIO_MAX * trace) & (span >= radius_m)
    return np.stack([-np.sin(phi), np.cos(phi)], axis=1), usable


def scan_lines(
    scan_xy: npt.ArrayLike, *, spacing_m: float = 0.05, max_incidence_deg: float = 75.0, range_sigma_m: float = 0.01,
    normal_radius_m: float = 0.25, max_missing_beams: int = 1,
) -> ScanLines:
    """Line samples and normals of a scan whose hits (N, 2) are in beam order (module docstring).

    Args:
        scan_xy: Hits in the sensor (base) frame, in beam order; non-finite rows are skipped.
        spacing_m: Joined segments are sampled at most this far apart.
        max_incidence_deg: β_max, the steepest incidence at which consecutive hits count as one surface.
        range_sigma_m: Range noise σ_r (1σ) of the scanner.
        normal_radius_m: Half-length of the chain window of a hit's PCA normal, and its minimum span.
        max_missing_beams: Consecutive hits with more missing beams between them are not joined.

    Returns:
        Samples and unit normals in the scan frame (empty when nothing is line-like).
    """
    pts = np.asarray(scan_xy, dtype=np.float64).reshape(-1, 2)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if pts.shape[0] < 2:
        return ScanLines(np.zeros((0, 2)), np.zeros((0, 2)))
    joined = _joined(pts, math.radians(max_incidence_deg), range_sigma_m, max_missing_beams)
    normals, usable = _window_normals(pts, joined, normal_radius_m)
    seg = np.flatnonzero(joined & (usable[:-1] | usable[1:]))
    a, b = pts[seg], pts[seg + 1]
    count = np.maximum(np.ceil(np.hypot(*(b - a).T) / spacing_m).astype(np.int64), 1)
    owner = np.repeat(np.arange(seg.size), count)
    t = (np.arange(owner.size) - np.repeat(np.cumsum(count) - count, count)) / count[owner]
    samples = a[owner] + t[:, None] * (b - a)[owner]
    end = seg[owner] + (t >= 0.5)  # the nearer end point's normal, the other one where that is unusable
    end = np.where(usable[end], end, np.where(end == seg[owner], end + 1, end - 1))
    # Each joined segment contributes its start and interior; chain ends (last hit) are added explicitly.
    last = np.flatnonzero(usable[1:] & joined & ~np.concatenate([joined[1:], [False]])) + 1
    points = np.concatenate([samples, pts[last]])
    nrm = np.concatenate([normals[end], normals[last]])
    return ScanLines(points, nrm)


def placed(lines: ScanLines, pose: npt.ArrayLike) -> ScanLines:
    """The samples and normals moved from the scan frame into the frame where the scan is at ``pose``."""
    p = np.asarray(pose, dtype=np.float64)
    c, s = math.cos(p[2]), math.sin(p[2])
    rot = np.array([[c, s], [-s, c]])  # row vectors times Rᵀ
    return ScanLines(lines.points @ rot + p[:2], lines.normals @ rot)


def scan_line_reference(scan_xy: npt.ArrayLike, pose: npt.ArrayLike) -> LineReference:
    """The line reference of one scan (hits in beam order, sensor frame) seen from ``pose`` (default
    :func:`scan_lines` options)."""
    lines = placed(scan_lines(scan_xy), pose)
    return line_reference(lines.points, lines.normals)


def _linearize(
    reference: LineReference, scan: FloatArray, pose: FloatArray, max_correspondence_m: float, trim_fraction: float,
    robust_scale_m: float,
) -> _Linearization:
    """Nearest-sample correspondences at ``pose``, distance gate, trimming, residuals, Jacobian, Cauchy weights."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    rotated = scan @ np.array([[c, s], [-s, c]])
    dist, idx = reference.tree.query(rotated + pose[:2], k=1, distance_upper_bound=max_correspondence_m)
    found = np.flatnonzero(dist < np.inf)
    idx_f = idx[found]
    normals = reference.normals[idx_f]
    rot_f = rotated[found]
    diff = rot_f + pose[:2] - reference.points[idx_f]
    residuals = normals[:, 0] * diff[:, 0] + normals[:, 1] * diff[:, 1]
    pts = scan[found]
    n_keep = math.ceil(trim_fraction * residuals.shape[0])
    if 0 < n_keep < residuals.shape[0]:
        order = np.argpartition(np.abs(residuals), n_keep - 1)[:n_keep]
        residuals, normals, pts, rot_f = residuals[order], normals[order], pts[order], rot_f[order]
    # ∂r/∂θ = nᵀ J R p = n_y (R p)_x − n_x (R p)_y
    jacobian = np.stack([normals[:, 0], normals[:, 1], normals[:, 1] * rot_f[:, 0] - normals[:, 0] * rot_f[:, 1]],
                        axis=1)
    weights = 1.0 / (1.0 + (residuals / robust_scale_m) ** 2)
    return _Linearization(residuals, jacobian, pts, weights, scan.shape[0] - residuals.shape[0], ~np.isfinite(dist))


def _degeneracy(lin: _Linearization) -> float:
    """Smallest eigenvalue of AᵀA / n with the rotation column divided by the RMS range L."""
    n = lin.residuals.shape[0]
    if n < 3:
        return 0.0
    length = float(np.sqrt(np.mean(np.einsum("ij,ij->i", lin.points, lin.points))))
    scale = np.array([1.0, 1.0, 1.0 / max(length, 1e-9)])
    a = lin.jacobian * scale
    return float(np.linalg.eigvalsh((a * lin.weights[:, None]).T @ a / n)[0])


def _sigma2(lin: _Linearization, sigma_min_m: float) -> float:
    """Residual variance Σr²/(n − 3), floored at σ_min² (inf with three rows or fewer)."""
    n = float(lin.weights.sum())
    if lin.residuals.shape[0] <= 3 or n <= 3.0:
        return math.inf
    return max(float(lin.weights @ lin.residuals**2) / (n - 3), sigma_min_m**2)


def _normal_equations(lin: _Linearization, pose: FloatArray, prior: GaussianPrior | None, sigma2: float
                      ) -> tuple[FloatArray, FloatArray]:
    """Information H = AᵀA/σ² + Λ and gradient g = Aᵀr/σ² + Λ(T − μ) (without rows: the prior's alone)."""
    if math.isfinite(sigma2):
        wj = lin.jacobian * lin.weights[:, None]
        h = wj.T @ lin.jacobian / sigma2
        g = wj.T @ lin.residuals / sigma2
    else:
        h, g = np.zeros((3, 3)), np.zeros(3)
    if prior is not None:
        e = pose - prior.mean
        e[2] = math.remainder(e[2], 2.0 * math.pi)
        h = h + prior.information
        g = g + prior.information @ e
    return h, g


def _is_singular(h: FloatArray) -> bool:
    """H is not finite, or singular relative to its diagonal (det of the correlation-normalized H < 1e-12)."""
    d = np.sqrt(np.abs(np.diag(h)))
    if not (np.all(np.isfinite(h)) and np.all(d > 0.0)):
        return True
    return bool(abs(np.linalg.det(h / np.outer(d, d))) < 1e-12)


def _step(h: FloatArray, g: FloatArray) -> FloatArray:
    """Gauss–Newton increment δ = −H⁻¹ g; NaN when H is singular."""
    if _is_singular(h):
        return np.full(3, np.nan)
    return np.asarray(np.linalg.solve(h, -g), dtype=np.float64)


def plicp(
    reference: LineReference,
    scan_xy: npt.ArrayLike,
    initial_pose: npt.ArrayLike,
    *,
    prior: GaussianPrior | None = None,
    max_iterations: int = 30,
    max_correspondence_m: float = 0.3,
    trim_fraction: float = 0.9,
    robust_scale_m: float = 0.03,
    min_step_m: float = 1e-3,
    min_step_rad: float = 1e-3,
    sigma_min_m: float = 0.01,
) -> PlicpResult:
    """Align scan points (sensor frame) to a line reference by point-to-line ICP from ``initial_pose``.

    Args:
        reference: Reference samples and normals (:func:`line_reference`, :func:`scan_lines`).
        scan_xy: (N, 2) scan points in the sensor (base) frame.
        initial_pose: (3,) x, y, yaw starting guess of the scan in the reference frame.
        prior: Optional Gaussian prior on the pose (MAP estimate); None: plain least squares.
        max_iterations: Gauss–Newton iterations at most.
        max_correspondence_m: Nearest samples farther than this are not correspondences.
        trim_fraction: Fraction (0, 1] of the gated correspondences with the smallest |r| that are used.
        robust_scale_m: Scale c of the Cauchy weights 1 / (1 + (r/c)²).
        min_step_m: Converged when the translation step is below this ...
        min_step_rad: ... and the rotation step below this.
        sigma_min_m: Floor of the residual standard deviation σ that weights the scan against the prior.

    Returns:
        The aligned pose, its covariance, inlier count, mean residual and degeneracy.
    """
    scan = np.asarray(scan_xy, dtype=np.float64).reshape(-1, 2)
    pose = np.asarray(initial_pose, dtype=np.float64).copy()
    lin = _Linearization(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 2)), np.zeros(0), scan.shape[0],
                         np.ones(scan.shape[0], dtype=bool))
    converged, iterations = False, 0
    scales = _Scales(max_correspondence_m, robust_scale_m, sigma_min_m)
    if reference.size == 0 or scan.shape[0] == 0:
        return _result(lin, pose, prior, scales, iterations, converged)
    while iterations < max_iterations:
        iterations += 1
        lin = _linearize(reference, scan, pose, max_correspondence_m, trim_fraction, robust_scale_m)
        delta = _step(*_normal_equations(lin, pose, prior, _sigma2(lin, sigma_min_m)))
        if not math.isfinite(float(delta.sum())):
            break
        pose = pose + delta
        pose[2] = math.remainder(pose[2], 2.0 * math.pi)
        if math.hypot(delta[0], delta[1]) < min_step_m and abs(delta[2]) < min_step_rad:
            converged = True  # statistics from the last linearization: the final step is negligible
            break
    return _result(lin, pose, prior, scales, iterations, converged)


def plicp_configured(reference: LineReference, scan_xy: FloatArray, start: FloatArray, prior: GaussianPrior | None,
                     cfg: ScanMatchConfig) -> PlicpResult:
    """:func:`plicp` with the ``scanmatch`` section's iteration, gate, trimming, robust and σ-floor settings."""
    return plicp(reference, scan_xy, start, prior=prior, max_iterations=cfg.icp_max_iterations,
                 max_correspondence_m=cfg.max_correspondence_m, trim_fraction=cfg.trim_fraction,
                 robust_scale_m=cfg.robust_scale_m,
                 min_step_m=cfg.icp_min_step_m, min_step_rad=math.radians(cfg.icp_min_step_deg),
                 sigma_min_m=math.sqrt(2.0) * cfg.range_sigma_m)


@dataclass(frozen=True, slots=True)
class _Scales:
    """The distances that weight a linearization: gate, Cauchy scale c, residual σ floor (m)."""

    gate_m: float
    robust_m: float
    sigma_min_m: float


def cauchy_rho(residual_m: npt.ArrayLike, robust_scale_m: float) -> FloatArray:
    """The Cauchy loss ρ(r) = ½ c² ln(1 + r²/c²) whose IRLS weights are 1 / (1 + (r/c)²)."""
    c2 = robust_scale_m**2
    out: FloatArray = 0.5 * c2 * np.log1p(np.square(np.asarray(residual_m, dtype=np.float64)) / c2)
    return out


def _data_cost(lin: _Linearization, scales: _Scales) -> float:
    """D = Σ ρ(r_i) over the kept correspondences plus ρ(gate) for every other scan point."""
    return float(cauchy_rho(lin.residuals, scales.robust_m).sum()
                 + lin.n_unmatched * cauchy_rho(scales.gate_m, scales.robust_m))


def _prior_cost(pose: FloatArray, prior: GaussianPrior | None) -> float:
    """P = (T − μ)ᵀ Λ (T − μ) with the yaw difference wrapped; 0 without a prior."""
    if prior is None:
        return 0.0
    e = pose - prior.mean
    e[2] = math.remainder(e[2], 2.0 * math.pi)
    return float(e @ prior.information @ e)


def map_cost(result: PlicpResult, sigma_m: float) -> float:
    """The MAP objective D/σ² + P of a result with a given σ (the same σ for results that are compared)."""
    return result.data_cost / sigma_m**2 + result.prior_cost


def _result(lin: _Linearization, pose: FloatArray, prior: GaussianPrior | None, scales: _Scales,
            iterations: int, converged: bool) -> PlicpResult:
    """Package the statistics of the final linearization."""
    n = int(lin.residuals.shape[0])
    residual = float(np.mean(np.abs(lin.residuals))) if n else math.nan
    pose[2] = float(wrap_angle(pose[2]))
    h, _ = _normal_equations(lin, pose, prior, _sigma2(lin, scales.sigma_min_m))
    if _is_singular(h):
        cov = np.full((3, 3), np.inf)
    else:
        cov = np.linalg.inv(h)
        cov = 0.5 * (cov + cov.T)
    sigma2 = max(float(np.mean(lin.residuals**2)), scales.sigma_min_m**2) if n > 3 else math.inf
    return PlicpResult(pose, cov, n, residual, _data_cost(lin, scales), _prior_cost(pose, prior), math.sqrt(sigma2),
                       _degeneracy(lin), iterations, converged, lin.outside_gate)
