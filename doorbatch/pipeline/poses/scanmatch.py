"""Scan matching pose source: odometry corrected scan by scan against a local keyframe submap.

For scans k = 1 … S−1 with odometry o_k (frame odom) and corrected poses x_k (frame map, x_0 = o_0):

    prior_k = x_{k−1} ⊕ (o_{k−1}⁻¹ ⊕ o_k)                          odometry increment on the last pose
    x_k     = PLICP(submap, scan_k, correlative(submap, scan_k, prior_k))

The correlative search (Olson, ICRA 2009; :mod:`.correlative`) finds the basin of the right optimum within
a window around the prior, so odometry jumps of a few decimetres and degrees do not derail the
point-to-line ICP (Censi, ICRA 2008; :mod:`.plicp`) that refines it. The submap holds the points of the
last K keyframes in the map frame, voxel-downsampled; a scan becomes a keyframe when it moved at least
``keyframe_min_d_m`` or turned ``keyframe_min_a_deg`` since the last one, and the submap's KD-tree,
normals and likelihood grid are rebuilt only then, so the cost per scan is bounded and the whole run O(S).

When a match is not trustworthy (too few points or inliers, a degenerate geometry such as one straight
wall, or an ICP that leaves the search window), x_k = prior_k and the scan is flagged in ``fallback``.
A fallback scan still becomes a keyframe when it moved far enough, so that matching resumes against
fresh geometry instead of a submap the robot has left behind.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from doorbatch.config import ScanMatchConfig
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import compose, relative, transform_points
from doorbatch.pipeline.poses.correlative import LikelihoodGrid, build_likelihood_grid, correlative_match
from doorbatch.pipeline.poses.plicp import LineReference, PlicpResult, build_line_reference, plicp

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True, slots=True)
class ScanMatchResult:
    """Per-scan output of :func:`scan_match_trajectory` (S scans).

    Attributes:
        poses: (S, 3) x, y, yaw in the map frame (= odom frame at scan 0).
        covariances: (S, 3, 3) PLICP covariance; zero for scan 0, NaN where ``fallback``.
        n_inliers: (S,) PLICP inliers of the final iteration (0 where ICP did not run).
        residual_m: (S,) mean point-to-line residual (m); NaN where ICP did not run.
        score: (S,) correlative score of the coarse match (mean likelihood in [0, 1]).
        fallback: (S,) the match was rejected and the pose is the odometry prior.
        keyframe: (S,) the scan was added to the submap.
    """

    poses: FloatArray
    covariances: FloatArray
    n_inliers: IntArray
    residual_m: FloatArray
    score: FloatArray
    fallback: BoolArray
    keyframe: BoolArray


@dataclass(frozen=True, slots=True, eq=False)
class Submap:
    """The last keyframes' points (map frame) and the matching structures built over their union."""

    keyframe_points: tuple[FloatArray, ...]
    last_keyframe_pose: FloatArray
    lines: LineReference
    grid: LikelihoodGrid


@dataclass(frozen=True, slots=True)
class ScanMatch:
    """One scan's match: the accepted PLICP pose, or the prior when ``fallback``, with its statistics."""

    pose: FloatArray
    covariance: FloatArray
    n_inliers: int
    residual_m: float
    score: float
    fallback: bool


def scan_match_trajectory(
    scans_xy: Sequence[npt.ArrayLike], odometry_poses: npt.ArrayLike, config: ScanMatchConfig | None = None
) -> ScanMatchResult:
    """Correct odometry by matching each scan against a local submap (correlative search, then PLICP).

    Args:
        scans_xy: S arrays (N_i, 2) of scan end points in base_link (hits only).
        odometry_poses: (S, 3) odometry x, y, yaw at the scan times.
        config: Parameters; the defaults when None.

    Returns:
        Corrected poses in the map frame (scan 0 keeps its odometry pose), covariances and statistics.

    Raises:
        ValueError: The odometry is not (S, 3) with S = len(scans_xy), or is not finite.
    """
    cfg = config or ScanMatchConfig()
    odom = _check_inputs(scans_xy, odometry_poses)
    scans = [_prepare_scan(s, cfg.scan_voxel_m) for s in scans_xy]
    increments = relative(odom[:-1], odom[1:])
    out = _empty_result(odom.shape[0])
    if odom.shape[0] == 0:
        return out
    out.poses[0], out.covariances[0], out.keyframe[0] = odom[0], 0.0, True
    submap = start_submap(scans[0], odom[0], cfg)
    for k in range(1, odom.shape[0]):
        prior = compose(out.poses[k - 1], increments[k - 1])
        match = match_scan(submap, scans[k], prior, cfg)
        _store(out, k, match)
        if _is_keyframe(submap.last_keyframe_pose, match.pose, cfg):
            submap = add_keyframe(submap, scans[k], match.pose, cfg)
            out.keyframe[k] = True
    return out


def _check_inputs(scans_xy: Sequence[npt.ArrayLike], odometry_poses: npt.ArrayLike) -> FloatArray:
    odom = np.asarray(odometry_poses, dtype=np.float64)
    if odom.ndim != 2 or odom.shape[1] != 3 or odom.shape[0] != len(scans_xy):
        raise ValueError(f"odometry_poses must be ({len(scans_xy)}, 3), one pose per scan; got {odom.shape}")
    if not np.all(np.isfinite(odom)):
        raise ValueError("odometry_poses contains NaN or inf")
    return odom


def _prepare_scan(scan_xy: npt.ArrayLike, voxel_m: float) -> FloatArray:
    """Finite points only, voxel-downsampled."""
    pts = np.asarray(scan_xy, dtype=np.float64).reshape(-1, 2)
    return voxel_downsample(pts[np.isfinite(pts).all(axis=1)], voxel_m)


def _empty_result(n: int) -> ScanMatchResult:
    return ScanMatchResult(
        poses=np.zeros((n, 3)), covariances=np.full((n, 3, 3), np.nan), n_inliers=np.zeros(n, dtype=np.int64),
        residual_m=np.full(n, np.nan), score=np.zeros(n), fallback=np.zeros(n, dtype=bool),
        keyframe=np.zeros(n, dtype=bool),
    )


def _store(out: ScanMatchResult, k: int, match: ScanMatch) -> None:
    out.poses[k], out.covariances[k], out.n_inliers[k] = match.pose, match.covariance, match.n_inliers
    out.residual_m[k], out.score[k], out.fallback[k] = match.residual_m, match.score, match.fallback


def _is_keyframe(last: FloatArray, pose: FloatArray, cfg: ScanMatchConfig) -> bool:
    """The pose moved ≥ keyframe_min_d_m or turned ≥ keyframe_min_a_deg since the last keyframe."""
    d = relative(last, pose)
    return bool(math.hypot(d[0], d[1]) >= cfg.keyframe_min_d_m or abs(d[2]) >= math.radians(cfg.keyframe_min_a_deg))


def voxel_downsample(points: FloatArray, voxel_m: float) -> FloatArray:
    """One centroid per occupied voxel of edge ``voxel_m`` (order: by voxel key)."""
    if points.shape[0] == 0:
        return points
    keys = np.floor(points / voxel_m).astype(np.int64)
    keys -= keys.min(axis=0)
    flat = keys[:, 0] * (int(keys[:, 1].max()) + 1) + keys[:, 1]
    _, inverse, counts = np.unique(flat, return_inverse=True, return_counts=True)
    sums = np.stack([np.bincount(inverse, weights=points[:, i]) for i in range(2)], axis=1)
    out: FloatArray = sums / counts[:, None]
    return out


def _build_submap(keyframe_points: tuple[FloatArray, ...], last_pose: FloatArray, cfg: ScanMatchConfig) -> Submap:
    points = voxel_downsample(np.concatenate(keyframe_points, axis=0), cfg.submap_voxel_m)
    lines = build_line_reference(points, neighbors=cfg.normal_neighbors, max_extent_m=cfg.max_correspondence_m * 2)
    grid = build_likelihood_grid(points, resolution_m=cfg.grid_resolution_m, sigma_m=cfg.grid_sigma_m,
                                 window_m=cfg.correlative_window_m, coarse_cells=cfg.coarse_cells)
    return Submap(keyframe_points, last_pose, lines, grid)


def start_submap(scan_xy: FloatArray, pose: FloatArray, cfg: ScanMatchConfig) -> Submap:
    """A submap holding one keyframe: the scan at ``pose``."""
    return _build_submap((transform_points(pose, scan_xy),), np.asarray(pose, dtype=np.float64), cfg)


def add_keyframe(submap: Submap, scan_xy: FloatArray, pose: FloatArray, cfg: ScanMatchConfig) -> Submap:
    """The submap with the scan at ``pose`` added and keyframes beyond the last ``submap_keyframes`` dropped."""
    kept = (*submap.keyframe_points, transform_points(pose, scan_xy))[-cfg.submap_keyframes :]
    return _build_submap(kept, np.asarray(pose, dtype=np.float64), cfg)


def match_scan(submap: Submap, scan_xy: FloatArray, prior: FloatArray, cfg: ScanMatchConfig) -> ScanMatch:
    """Correlative search around the prior, PLICP from its best pose, then the acceptance test."""
    if scan_xy.shape[0] < cfg.min_inliers or submap.lines.size < cfg.min_inliers:
        return ScanMatch(prior, np.full((3, 3), np.nan), 0, math.nan, 0.0, True)
    stride = -(-scan_xy.shape[0] // cfg.correlative_max_points)
    coarse = correlative_match(submap.grid, scan_xy[::stride], prior, window_m=cfg.correlative_window_m,
                               window_deg=cfg.correlative_window_deg, step_deg=cfg.correlative_step_deg)
    fine = plicp(submap.lines, scan_xy, coarse.pose, max_iterations=cfg.icp_max_iterations,
                 max_correspondence_m=cfg.max_correspondence_m, trim_fraction=cfg.trim_fraction,
                 min_step_m=cfg.icp_min_step_m, min_step_rad=math.radians(cfg.icp_min_step_deg))
    if not _accept(fine, prior, cfg):
        return ScanMatch(prior, np.full((3, 3), np.nan), fine.n_inliers, fine.residual_m, coarse.score, True)
    return ScanMatch(fine.pose, fine.covariance, fine.n_inliers, fine.residual_m, coarse.score, False)


def _accept(fine: PlicpResult, prior: FloatArray, cfg: ScanMatchConfig) -> bool:
    """Enough inliers, a well-conditioned Hessian, a finite covariance, and a pose inside the window."""
    shift = math.hypot(*(fine.pose[:2] - prior[:2]))
    turn = abs(float(wrap_angle(fine.pose[2] - prior[2])))
    inside = (shift <= cfg.correlative_window_m + cfg.max_correspondence_m
              and turn <= math.radians(cfg.correlative_window_deg + cfg.correlative_step_deg))
    return (fine.n_inliers >= cfg.min_inliers and fine.degeneracy >= cfg.min_degeneracy
            and bool(np.all(np.isfinite(fine.covariance))) and inside)

