"""Loop-closure detection: a new keyframe matched against the old keyframes near its estimate.

The scan-matching front end (:mod:`.scanmatch`) follows the scans step by step, so its error is a random walk
of the per-step matching noise; a back end that recognizes places seen long ago takes it out (Karto's and
slam_toolbox's loop closure, Cartographer's global constraints; Olson, ICRA 2009 for the search). For the
newest keyframe k at estimate x_k with the uncertainty Σ accumulated along the pose graph since the last
accepted closure (first-order compounding of the sequential edges' covariances):

1. Candidates: keyframes passed at least ``loop_min_travel_m`` of path ago and not among the last
   ``submap_keyframes`` (those are the front end's own submap), whose poses lie within
   r = ``loop_search_radius_m`` + ``loop_search_sigmas`` · √λ_max(Σ_xy) of x_k.
2. Of those, the ones from one pass: within ``submap_keyframes`` keyframe indices of the candidate nearest
   x_k (Karto matches against one chain of old scans at a time: keyframes of different passes are only as
   consistent with each other as the graph has made them, and a submap merged from two passes that disagree
   by a few centimetres and degrees gives a loop edge biased by that disagreement; on intel, drift seeds 4
   and 5, one pass took the ATE from 0.72 to 0.15 m and from 0.55 to 0.22 m). Their line samples near x_k
   form the loop submap; the exhaustive branch-and-bound correlative search looks ``loop_search_sigmas``
   standard deviations of Σ around x_k on every axis (clipped to the loop window limits), and PLICP without a
   prior refines its optimum (the loop constraint must not lean on the drifted estimate).
3. Accepted only when strong (one false loop is worse than none): correlative score ≥ ``loop_min_score``;
   at least ``loop_min_overlap_fraction`` of the (trimmed) scan points matched old lines; PLICP's Hessian not
   degenerate (a corridor seen along its axis fixes no position along it) and its optimum within a lattice
   step of the correlative one; a unique basin: the best lattice pose outside ±``loop_ambiguity_radius_m``,
   ±``loop_ambiguity_deg`` of the optimum scores at most ``loop_max_ambiguity`` times as much (Olson's
   ambiguity test, done with the same branch and bound).

The caller turns an accepted match into a loop edge from the candidate keyframe nearest the matched pose and
optimizes the pose graph (:mod:`.pose_graph`), whose robust kernel and χ² gate are the last line of defence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from doorbatch.config import ScanMatchConfig
from doorbatch.pipeline.poses.correlative import (
    Exclusion,
    Window,
    build_likelihood_grid,
    correlative_match,
    lattice_steps_apart,
    sigma_window,
    thinned,
)
from doorbatch.pipeline.poses.plicp import line_reference, plicp_configured

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class LoopMatch:
    """An accepted loop match: the scan's pose against the old keyframes (map frame) and its evidence."""

    pose: FloatArray  # (3,)
    covariance: FloatArray  # (3, 3) PLICP's, map frame
    score: float  # correlative mean likelihood in [0, 1]
    overlap_fraction: float  # PLICP inliers / (trim_fraction · scan points)
    ambiguity: float  # runner-up score / best score


def search_radius_m(uncertainty: FloatArray, cfg: ScanMatchConfig) -> float:
    """r = loop_search_radius_m + loop_search_sigmas · √λ_max(Σ_xy) (module docstring, step 1)."""
    largest = float(np.linalg.eigvalsh(np.asarray(uncertainty, dtype=np.float64)[:2, :2])[-1])
    return cfg.loop_search_radius_m + cfg.loop_search_sigmas * math.sqrt(max(largest, 0.0))


def loop_candidates(keyframe_poses: npt.ArrayLike, path_m: npt.ArrayLike, estimate: npt.ArrayLike,
                    uncertainty: FloatArray, cfg: ScanMatchConfig) -> IntArray:
    """Indices of the keyframes a new keyframe at ``estimate`` may close a loop with (module docstring, step 1).

    Args:
        keyframe_poses: (K, 3) poses of the keyframes before the new one.
        path_m: (K + 1,) path length travelled up to each keyframe, the new one last.
        estimate: (3,) the new keyframe's pose.
        uncertainty: (3, 3) covariance accumulated since the last closure, map frame.
        cfg: The ``scanmatch`` section.
    """
    poses = np.asarray(keyframe_poses, dtype=np.float64).reshape(-1, 3)
    path = np.asarray(path_m, dtype=np.float64)
    old = path[-1] - path[:-1] >= cfg.loop_min_travel_m
    old[max(poses.shape[0] - cfg.submap_keyframes, 0):] = False
    near = np.hypot(*(poses[:, :2] - np.asarray(estimate, dtype=np.float64)[:2]).T) <= search_radius_m(
        uncertainty, cfg)
    out: IntArray = np.flatnonzero(old & near).astype(np.int64)
    return out


def one_pass(candidates: IntArray, keyframe_poses: npt.ArrayLike, estimate: npt.ArrayLike, span: int) -> IntArray:
    """The candidates within ``span`` keyframe indices of the one nearest ``estimate`` (module docstring, step 2)."""
    poses = np.asarray(keyframe_poses, dtype=np.float64).reshape(-1, 3)
    x = np.asarray(estimate, dtype=np.float64)
    nearest = candidates[int(np.argmin(np.hypot(*(poses[candidates, :2] - x[:2]).T)))]
    out: IntArray = candidates[np.abs(candidates - nearest) <= span]
    return out


def loop_window(uncertainty: FloatArray, cfg: ScanMatchConfig) -> Window:
    """Correlative half-widths ((x, y) m, yaw deg): loop_search_sigmas σ per axis, clipped to the loop limits."""
    return sigma_window(uncertainty, cfg.loop_search_sigmas, cfg.loop_window_min_m, cfg.loop_window_max_m,
                        cfg.loop_window_min_deg, cfg.loop_window_max_deg)


def match_loop(points: npt.ArrayLike, normals: npt.ArrayLike, scan_xy: FloatArray, estimate: npt.ArrayLike,
               uncertainty: FloatArray, cfg: ScanMatchConfig) -> LoopMatch | None:
    """Match a scan against old keyframes' line samples around its estimate; None unless strong (steps 2–3).

    Args:
        points: (M, 2) line samples of the candidate keyframes, map frame (one per voxel).
        normals: (M, 2) their unit normals.
        scan_xy: (N, 2) the new keyframe's scan points (downsampled), its own frame.
        estimate: (3,) the new keyframe's pose estimate, map frame.
        uncertainty: (3, 3) covariance accumulated since the last closure, map frame.
        cfg: The ``scanmatch`` section.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    x0 = np.asarray(estimate, dtype=np.float64)
    n_scan = scan_xy.shape[0]
    if n_scan < cfg.min_inliers or pts.shape[0] < cfg.min_inliers:
        return None
    window_m, window_deg = loop_window(uncertainty, cfg)
    grid = build_likelihood_grid(pts, resolution_m=cfg.grid_resolution_m, sigma_m=cfg.grid_sigma_m,
                                 window_m=max(window_m), coarse_cells=cfg.coarse_cells)
    sparse = thinned(scan_xy, cfg.correlative_max_points)
    best = correlative_match(grid, sparse, x0, window_m=window_m, window_deg=window_deg,
                             step_deg=cfg.correlative_step_deg)
    if best.score < cfg.loop_min_score:
        return None
    runner_up = correlative_match(grid, sparse, x0, window_m=window_m, window_deg=window_deg,
                                  step_deg=cfg.correlative_step_deg,
                                  exclude=Exclusion(best.pose, cfg.loop_ambiguity_radius_m, cfg.loop_ambiguity_deg))
    ambiguity = max(runner_up.score, 0.0) / best.score
    if ambiguity > cfg.loop_max_ambiguity:
        return None
    fine = plicp_configured(line_reference(pts, normals), scan_xy, best.pose, None, cfg)
    overlap = fine.n_inliers / (cfg.trim_fraction * n_scan)
    consistent = lattice_steps_apart(fine.pose, best.pose, cfg.grid_resolution_m, cfg.correlative_step_deg) <= 1.0
    if (overlap < cfg.loop_min_overlap_fraction or fine.degeneracy < cfg.min_degeneracy or not consistent
            or not np.all(np.isfinite(fine.covariance))):
        return None
    return LoopMatch(fine.pose, fine.covariance, best.score, overlap, ambiguity)
