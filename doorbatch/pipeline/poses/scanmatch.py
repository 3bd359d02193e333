"""Scan matching pose source: odometry corrected scan by scan against a local keyframe submap.

For scans k = 1 … S−1 with odometry o_k (frame odom) and corrected poses x_k (frame map, x_0 = o_0):

    u_k     = o_{k−1}⁻¹ ⊕ o_k,   Σ_k = Cov(u_k)                odometry increment and its α-model covariance
    prior_k = x_{k−1} ⊕ u_k                                    the prediction, N(prior_k, G Σ_k Gᵀ) in the map
    x_k     = MAP-PLICP(submap, scan_k, start = correlative(submap, scan_k, prior_k, window ∝ √diag Σ))

Without odometry (a handheld lidar), u_k is the last matched increment x_{k−2}⁻¹ ⊕ x_{k−1} scaled to the scan
interval (constant velocity) and Σ_k = diag((a·dt²/2)²) for the configured accelerations, plus the floors
(:func:`constant_velocity_covariance`).

Σ_k comes from the odometry motion model of Probabilistic Robotics (Table 5.6): the increment is split
into (δrot1, δtrans, δrot2) with independent variances α1 r1² + α2 δtrans², α3 δtrans² + α4 (r1² + r2²),
α1 r2² + α2 δtrans² (:func:`doorbatch.geometry.odometry.odometry_increments`), mapped to
(x, y, θ) of the previous pose by the Jacobian of (δtrans cos δrot1, δtrans sin δrot1, δrot1 + δrot2), plus
standard-deviation floors; G rotates it into the map frame. The rotation terms are r = min(|δrot|, π − |δrot|)
(Nav2 AMCL's folding, as the localizers' motion model and the simulator's drift model), so a creep backwards
gets the rotation window of the same creep forwards (with δrot in full, a 10 cm creep backwards got a window of
±π-sized rotations). Against the folded drift model applied per scan step, over drift seeds 1–16 on the CARMEN
logs, the folded prior took the geometric-mean ATE from 0.80 / 0.40 / 0.64 m (δrot in full) to 0.57 / 0.37 /
0.41 m on orebro / intel / aces (docs/results.md).

The correlative search (Olson, ICRA 2009; :mod:`.correlative`) looks ``window_sigmas`` standard deviations
of that prediction around it on every map axis (clipped to configured limits), so that a 76° turn between
two keyframes of a corrected log is searched as widely as it is uncertain while a 10 Hz scan stream searches a
few centimetres. The point-to-line ICP (Censi, ICRA 2008; :mod:`.plicp`) that refines the best lattice pose
minimizes the point-to-line residuals together with the Gaussian prior, so a direction the scan does not
observe (along a featureless corridor, along one wall) stays at the odometry prediction while the observable
directions (across the corridor, the heading) are corrected; such scans are flagged ``degenerate``.

The submap is a local piece of the map built so far: the line samples (:func:`.plicp.scan_lines`:
consecutive hits of one surface, sampled densely, with normals) of every keyframe whose pose lies within
``submap_radius_m`` of the newest keyframe, together with the last ``submap_keyframes`` keyframes, in the map
frame, one sample per voxel (the older keyframe's where they overlap, so that a revisited place is matched
against how it was first mapped and the drift accumulated since is taken out). A keyframe that, when made, stood
within ``submap_revisit_m`` and ``submap_revisit_deg`` of an older one (older than the last ``submap_keyframes``,
itself no revisit) stays out of it while old keyframes are matched: its samples mostly lose their voxels to the
older keyframe's anyway, and without this every pass over a place added its keyframes, so that the cost per scan
grew with the passes (a 22.5-minute log of 14 passes: 280 local keyframes). A scan becomes a keyframe when it
moved at least ``keyframe_min_d_m`` or turned ``keyframe_min_a_deg`` since the last one; the submap's KD-tree
and likelihood grid are rebuilt only then, so the cost per scan stays bounded.

The correlative optimum is a lattice pose that maximizes overlap alone; along a corridor it may sit a few
cells off the prediction with nothing to tell them apart. MAP-PLICP is therefore run from the prediction as
well when the two differ, and the local optimum with the lower robust MAP cost wins (both minimize the same
objective, so this only chooses between its basins), the data weighted by the smaller of the two residual σ,
the noise of the better fit (a scan that overlaps the submap poorly fits either pose loosely, and then the
prediction decides). In that comparison a scan point no submap line explains but that lies on a surface the
local keyframes hit (at angles too grazing for lines) counts as fitting (:func:`basin_cost`, :mod:`.free_space`):
a scan entering a corridor whose walls the submap saw only at grazing angles is otherwise pulled back onto the
mapped mouth.

The window is a modelled 3σ, and the odometry has tails beyond it (the rotation error of an in-place turn
with a few centimetres of jitter, a wheel slip). When the match is rejected, the window grows by
``window_growth`` on every axis and the scan is matched again, up to the configured maxima, before the scan
falls back to the prediction (Olson's search bounds the window it is given; a failed match is the front end's
evidence that the window was too narrow). Growing the window whenever the lattice optimum lay on its border
was tried as well: it found more spurious optima on scans that overlap the submap poorly (orebro, drift seeds
1–8: median ATE 0.86 m against 0.60 m growing on failures only).

A match is rejected when it has too few points or inliers, or the ICP leaves the search window; the scan
then keeps the prediction (``fallback``; the number of fallbacks is logged as a warning). The submap did not
confirm that pose, so its uncertainty is carried on: the next scan's prediction covariance compounds it
(first order, J Σ_{k−1} Jᵀ + G Σ_k Gᵀ, :func:`propagated_covariance`), which widens that scan's window and
weakens its prior by as much as the odometry may have gone wrong across both steps. A trusted match carries
nothing (the submap fixed the pose; its frame is the reference of the next match). The same holds for a
``weak`` match, accepted but with fewer than ``min_overlap_fraction`` of the scan's points on submap lines:
the scan sees mostly new ground and a minority of its points picked the basin (4–14 cm residuals where it
went wrong on the CARMEN logs), so its pose is kept but not trusted. Before that, a weak match is searched
again in the wider windows like a rejected one: a wider basin that the scan overlaps well replaces it when its
MAP cost is lower; a wider weak one does not (it is no better evidence than the basin next to the
prediction). A fallback scan is not
made a keyframe (its odometry error would enter the submap, and the next scans would match it), unless
``fallbacks_before_keyframe`` fell back in a row, so that matching resumes against fresh geometry.

Loop closure (``loop_closure``, :func:`close_loop`): the keyframes are the nodes of a pose graph
(:mod:`.keyframe_graph`); each new keyframe adds a sequential edge (the match's relative pose, with its
MAP-PLICP covariance, or the carried prediction covariance for a weak or fallback keyframe) and is searched
against old keyframes near its estimate (:mod:`.loop_closure`); an accepted loop edge triggers the sparse
optimization (:mod:`.pose_graph`), after which the submap is rebuilt from the optimized poses. The graph is
optimized once more at the end, and every scan is placed relative to the keyframe it was matched after.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import numpy.typing as npt

from doorbatch.config import ScanMatchConfig
from doorbatch.geometry.odometry import MIN_TRANS_FOR_BEARING_M, increment_variances, odometry_increments
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import (
    compose,
    compounded_covariance,
    frame_rotation,
    relative,
    rotation_matrix,
    transform_points,
)
from doorbatch.pipeline.poses.correlative import (
    LikelihoodGrid,
    Window,
    build_likelihood_grid,
    correlative_match,
    lattice_steps_apart,
    sigma_window,
    thinned,
)
from doorbatch.pipeline.poses.free_space import RangeProfile, on_seen_surfaces
from doorbatch.pipeline.poses.keyframe_graph import KeyframeGraph
from doorbatch.pipeline.poses.loop_closure import loop_candidates, match_loop, one_pass
from doorbatch.pipeline.poses.plicp import (
    GaussianPrior,
    LineReference,
    PlicpResult,
    ScanLines,
    cauchy_rho,
    line_reference,
    map_cost,
    placed,
    plicp_configured,
    scan_lines,
)
from doorbatch.progress import progress_bar

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class ScanMatchResult:
    """Per-scan output of :func:`scan_match_trajectory` (S scans).

    Attributes:
        poses: (S, 3) x, y, yaw in the map frame (= odom frame at scan 0).
        covariances: (S, 3, 3) covariance of each pose given the submap, map frame: the MAP-PLICP one, the
            odometry prediction's (with the uncertainty carried from earlier untrusted scans) where
            ``fallback``; zero for scan 0.
        n_inliers: (S,) PLICP inliers of the final iteration (0 where ICP did not run).
        residual_m: (S,) mean point-to-line residual (m); NaN where ICP did not run.
        score: (S,) correlative score of the coarse match (mean likelihood in [0, 1]).
        fallback: (S,) the match was rejected and the pose is the odometry prediction.
        degenerate: (S,) the scan left a direction unconstrained, which followed the odometry prediction.
        weak: (S,) the match was accepted but fewer than ``min_overlap_fraction`` of the scan's points found
            a submap line: its prediction's uncertainty was carried to the next scan (module docstring).
        keyframe: (S,) the scan was added to the submap.
        loop_closure: (S,) the scan is a keyframe with a loop edge that the final pose graph kept.
    """

    poses: FloatArray
    covariances: FloatArray
    n_inliers: IntArray
    residual_m: FloatArray
    score: FloatArray
    fallback: BoolArray
    degenerate: BoolArray
    weak: BoolArray
    keyframe: BoolArray
    loop_closure: BoolArray


@dataclass(frozen=True)
class Keyframe:
    """A keyframe's pose, its line samples with unit normals in its own frame and placed in the map frame, its
    downsampled scan and its beams' range profile. The samples are placed when first asked for (:attr:`in_map`):
    a pose-graph optimization moves every keyframe, and only those near the robot are matched again."""

    pose: FloatArray  # (3,)
    lines: ScanLines  # line samples and normals in the scan's own frame
    scan: FloatArray  # (N, 2) the downsampled scan, its own frame (matched for loop closures)
    path_m: float  # path length travelled from the first keyframe to this one
    profile: RangeProfile  # the scan's hits as beams: where it saw free space
    revisit: bool = False  # an older keyframe, not itself a revisit, stood within the revisit radius and angle

    @classmethod
    def at(cls, pose: npt.ArrayLike, lines: ScanLines, scan: FloatArray, path_m: float,
           profile: RangeProfile, revisit: bool = False) -> Keyframe:
        """The keyframe at ``pose``."""
        return cls(np.asarray(pose, dtype=np.float64), lines, scan, path_m, profile, revisit)

    @cached_property
    def in_map(self) -> ScanLines:
        """``lines`` placed at ``pose``."""
        return placed(self.lines, self.pose)

    @cached_property
    def reach_m(self) -> float:
        """How far the farthest placed sample lies from the pose on either map axis (0 without samples)."""
        points = self.in_map.points
        return float(np.abs(points - self.pose[:2]).max()) if points.shape[0] else 0.0

    def moved(self, pose: npt.ArrayLike) -> Keyframe:
        """The keyframe at another pose (after a pose-graph optimization)."""
        return Keyframe.at(pose, self.lines, self.scan, self.path_m, self.profile, self.revisit)


@dataclass(frozen=True, slots=True, eq=False)
class Submap:
    """All keyframes so far, and the matching structures over the local ones (module docstring)."""

    keyframes: tuple[Keyframe, ...]
    lines: LineReference
    grid: LikelihoodGrid
    local_profiles: tuple[RangeProfile, ...]  # the beams of the keyframes whose samples make up ``lines``, ``grid``
    local_poses: FloatArray  # (L, 3) their poses

    @property
    def last_keyframe_pose(self) -> FloatArray:
        """Pose of the newest keyframe."""
        return self.keyframes[-1].pose


@dataclass(frozen=True, slots=True)
class ScanMatch:
    """One scan's match: the MAP-PLICP pose, or the prediction when ``fallback``, with its statistics."""

    pose: FloatArray
    covariance: FloatArray
    n_inliers: int
    residual_m: float
    score: float
    fallback: bool
    degenerate: bool
    weak: bool = False


def scan_match_trajectory(
    scans_xy: Sequence[npt.ArrayLike], odometry_poses: npt.ArrayLike | None, config: ScanMatchConfig | None = None,
    stamps_ns: npt.ArrayLike | None = None,
) -> ScanMatchResult:
    """Correct odometry by matching each scan against a local submap (correlative search, then MAP-PLICP).

    Args:
        scans_xy: S arrays (N_i, 2) of scan end points in base_link (hits only, in beam order: the
            reference lines join consecutive hits).
        odometry_poses: (S, 3) odometry x, y, yaw at the scan times; None: no odometry, each scan predicted at
            constant velocity (the last matched increment scaled to the scan interval; std a·dt²/2 from
            ``no_odometry_accel_*`` plus the floors).
        config: Parameters; the defaults when None.
        stamps_ns: (S,) scan times; needed without odometry.

    Returns:
        Corrected poses in the map frame (scan 0 keeps its odometry pose, or the origin), covariances and
        statistics.

    Raises:
        ValueError: The odometry is not (S, 3) with S = len(scans_xy), or is not finite; no odometry and no
            stamps.
    """
    cfg = config or ScanMatchConfig()
    no_odometry = odometry_poses is None
    if no_odometry and stamps_ns is None:
        raise ValueError("scan matching without odometry needs the scans' stamps")
    if stamps_ns is not None and np.shape(stamps_ns) != (len(scans_xy),):
        raise ValueError(f"stamps_ns must be ({len(scans_xy)},), one stamp per scan; got {np.shape(stamps_ns)}")
    dt_s = np.diff(np.asarray(stamps_ns, dtype=np.int64)) / 1e9 if stamps_ns is not None else None
    odom = np.zeros((len(scans_xy), 3)) if odometry_poses is None else _check_inputs(scans_xy, odometry_poses)
    hits = [_finite(s) for s in scans_xy]
    increments = relative(odom[:-1], odom[1:])
    out = _empty_result(odom.shape[0])
    if odom.shape[0] == 0:
        return out
    out.poses[0], out.covariances[0], out.keyframe[0] = odom[0], 0.0, True
    submap = start_submap(hits[0], odom[0], cfg)
    graph = KeyframeGraph([odom[0].copy()])
    placement = _Placement.start(odom.shape[0])
    carried = np.zeros((3, 3))  # uncertainty of the previous pose that no match to the submap took out
    fallback_run = 0  # fallback scans in a row, none of them a keyframe yet
    with progress_bar(odom.shape[0] - 1, "map: scan matching", unit="scan") as bar:  # long logs take minutes
        for k in range(1, odom.shape[0]):
            accel_dt_s = None
            if no_odometry and dt_s is not None:  # constant velocity: the last matched increment, over this interval
                accel_dt_s = float(dt_s[k - 1])
                increments[k - 1] = (constant_velocity_increment(out.poses[k - 2], out.poses[k - 1], float(dt_s[k - 2]),
                                                                 accel_dt_s) if k >= 2 else 0.0)
            prior = compose(out.poses[k - 1], increments[k - 1])
            cov = propagated_covariance(carried, out.poses[k - 1], increments[k - 1], cfg, accel_dt_s)
            scan = voxel_downsample(hits[k], cfg.scan_voxel_m)
            match = match_scan(submap, scan, prior, cov, cfg)
            _store(out, k, match)
            carried = cov if match.fallback or match.weak else np.zeros((3, 3))
            fallback_run = fallback_run + 1 if match.fallback else 0
            if (fallback_run in (0, cfg.fallbacks_before_keyframe)
                    and _is_keyframe(submap.last_keyframe_pose, match.pose, cfg)):
                submap = add_keyframe(submap, hits[k], match.pose, cfg, old=_old_keyframes_usable(submap, graph, cfg),
                                      downsampled=scan)
                out.keyframe[k], fallback_run = True, 0
                if cfg.loop_closure:  # weak and fallback keyframes: the odometry's wider covariance (module docstring)
                    graph.add_sequential(match.pose, cov if match.fallback or match.weak else match.covariance, cfg)
                    submap = close_loop(submap, graph, cfg)
                    out.poses[k] = submap.last_keyframe_pose
            placement.place(k, len(submap.keyframes) - 1, submap.last_keyframe_pose, out.poses[k])
            bar.update()
    if graph.n_loops:
        _finish_graph(out, graph, placement, cfg)
    if out.fallback.any():
        log.warning("scan matching fell back to odometry on %d of %d scans", int(out.fallback.sum()), len(hits))
    return out


@dataclass(frozen=True, slots=True)
class _Placement:
    """Each scan's keyframe (the newest when it was matched) and its pose in that keyframe's frame."""

    keyframe: IntArray  # (S,)
    offset: FloatArray  # (S, 3)

    @classmethod
    def start(cls, n: int) -> _Placement:
        return cls(np.zeros(n, dtype=np.int64), np.zeros((n, 3)))

    def place(self, k: int, keyframe: int, keyframe_pose: FloatArray, pose: FloatArray) -> None:
        self.keyframe[k], self.offset[k] = keyframe, relative(keyframe_pose, pose)


def _finish_graph(out: ScanMatchResult, graph: KeyframeGraph, placement: _Placement, cfg: ScanMatchConfig) -> None:
    """The final optimization; every scan placed relative to its optimized keyframe."""
    solution = graph.optimize(cfg)
    out.poses[:] = compose(solution.poses[placement.keyframe], placement.offset)
    robust, second = np.asarray(graph.robust, dtype=bool), np.asarray(graph.second, dtype=np.int64)
    kept = solution.active & robust
    keyframe_scans = np.flatnonzero(out.keyframe)
    out.loop_closure[keyframe_scans[second[kept]]] = True
    log.info("loop closure: %d loop edges kept of %d", int(kept.sum()), graph.n_loops)


def close_loop(submap: Submap, graph: KeyframeGraph, cfg: ScanMatchConfig) -> Submap:
    """Search a loop closure for the newest keyframe (:mod:`.loop_closure`); when one is accepted, add its edge,
    optimize the pose graph and return the submap rebuilt from the optimized keyframe poses."""
    keyframes = submap.keyframes
    newest = keyframes[-1]
    if newest.path_m - graph.last_search_path_m < cfg.loop_attempt_spacing_m:
        return submap
    poses = np.stack(graph.poses[:-1])
    candidates = loop_candidates(poses, [kf.path_m for kf in keyframes], newest.pose, graph.uncertainty, cfg)
    if candidates.size == 0:
        return submap
    candidates = one_pass(candidates, poses, newest.pose, cfg.submap_keyframes)
    graph.last_search_path_m = newest.path_m
    reach = newest.reach_m + cfg.loop_window_max_m
    pts, nrm = _merged_samples([keyframes[i] for i in candidates], newest.pose, reach, cfg)
    match = match_loop(pts, nrm, newest.scan, newest.pose, graph.uncertainty, cfg)
    if match is None:
        return submap
    anchor = int(candidates[np.argmin(np.hypot(*(poses[candidates, :2] - match.pose[:2]).T))])
    graph.add_loop(anchor, match.pose, match.covariance, cfg)
    solution = graph.optimize(cfg)
    if solution.active[-1]:
        graph.closed(newest.path_m)
    else:
        graph.drop_last_edge()
    moved = tuple(kf.moved(pose) for kf, pose in zip(keyframes, solution.poses, strict=True))
    return _build_submap(moved, cfg, old=_old_keyframes_usable(submap, graph, cfg))


def _old_keyframes_usable(submap: Submap, graph: KeyframeGraph, cfg: ScanMatchConfig) -> bool:
    """Whether the front end may match keyframes passed long ago: always without loop closure; with it, within
    ``loop_min_travel_m`` of path after an accepted closure (the optimized graph made the old keyframes near the
    robot consistent with its pose), and not otherwise (a match would move the pose onto the old map without
    the pose graph knowing, and the drift would stay in the past poses)."""
    return not cfg.loop_closure or submap.keyframes[-1].path_m - graph.last_closure_path_m < cfg.loop_min_travel_m


def _check_inputs(scans_xy: Sequence[npt.ArrayLike], odometry_poses: npt.ArrayLike) -> FloatArray:
    odom = np.asarray(odometry_poses, dtype=np.float64)
    if odom.ndim != 2 or odom.shape[1] != 3 or odom.shape[0] != len(scans_xy):
        raise ValueError(f"odometry_poses must be ({len(scans_xy)}, 3), one pose per scan; got {odom.shape}")
    if not np.all(np.isfinite(odom)):
        raise ValueError("odometry_poses contains NaN or inf")
    return odom


def _finite(scan_xy: npt.ArrayLike) -> FloatArray:
    """The finite points, in their order."""
    pts = np.asarray(scan_xy, dtype=np.float64).reshape(-1, 2)
    out: FloatArray = pts[np.isfinite(pts).all(axis=1)]
    return out


def _empty_result(n: int) -> ScanMatchResult:
    return ScanMatchResult(
        poses=np.zeros((n, 3)), covariances=np.full((n, 3, 3), np.nan), n_inliers=np.zeros(n, dtype=np.int64),
        residual_m=np.full(n, np.nan), score=np.zeros(n), fallback=np.zeros(n, dtype=bool),
        degenerate=np.zeros(n, dtype=bool), weak=np.zeros(n, dtype=bool), keyframe=np.zeros(n, dtype=bool),
        loop_closure=np.zeros(n, dtype=bool),
    )


def _store(out: ScanMatchResult, k: int, match: ScanMatch) -> None:
    out.poses[k], out.covariances[k], out.n_inliers[k] = match.pose, match.covariance, match.n_inliers
    out.residual_m[k], out.score[k], out.fallback[k] = match.residual_m, match.score, match.fallback
    out.degenerate[k], out.weak[k] = match.degenerate, match.weak


def _is_keyframe(last: FloatArray, pose: FloatArray, cfg: ScanMatchConfig) -> bool:
    """The pose moved ≥ keyframe_min_d_m or turned ≥ keyframe_min_a_deg since the last keyframe."""
    d = relative(last, pose)
    return bool(math.hypot(d[0], d[1]) >= cfg.keyframe_min_d_m or abs(d[2]) >= math.radians(cfg.keyframe_min_a_deg))


def increment_covariance(increment: npt.ArrayLike, cfg: ScanMatchConfig) -> FloatArray:
    """(3, 3) covariance of an odometry increment (dx, dy, dθ), in the frame of its start pose (module docstring)."""
    d = np.asarray(increment, dtype=np.float64)
    inc = odometry_increments(np.array([0.0, d[0]]), np.array([0.0, d[1]]), np.array([0.0, d[2]]),
                              min_trans_m=MIN_TRANS_FOR_BEARING_M)
    rot1, trans = float(inc.rot1[0]), float(inc.trans[0])
    var = np.array(increment_variances(inc.rot1[0], trans, inc.rot2[0],
                                       (cfg.odom_alpha1, cfg.odom_alpha2, cfg.odom_alpha3, cfg.odom_alpha4)))
    c, s = math.cos(rot1), math.sin(rot1)
    jac = np.array([[-trans * s, c, 0.0], [trans * c, s, 0.0], [1.0, 0.0, 1.0]])  # ∂(dx, dy, dθ)/∂(r1, t, r2)
    floor = np.array([cfg.odom_min_std_m, cfg.odom_min_std_m, math.radians(cfg.odom_min_std_deg)]) ** 2
    cov: FloatArray = (jac * var) @ jac.T + np.diag(floor)
    return cov


def constant_velocity_increment(before: FloatArray, last: FloatArray, dt_before_s: float, dt_s: float) -> FloatArray:
    """The increment ``before`` → ``last`` (over ``dt_before_s``) as a twist, repeated over ``dt_s``: the
    constant-velocity prediction of the next scan (small increments: the twist scales linearly)."""
    inc = relative(before, last)
    scale = dt_s / dt_before_s if dt_before_s > 0.0 else 1.0
    out: FloatArray = inc * scale
    return out


def constant_velocity_covariance(dt_s: float, cfg: ScanMatchConfig) -> FloatArray:
    """Covariance of a constant-velocity increment over ``dt_s``: (a·dt²/2)² per axis from ``no_odometry_accel_*``,
    plus the floors' squares (the matched velocity's own noise)."""
    half = 0.5 * dt_s * dt_s
    return np.diag([(cfg.no_odometry_accel_m_s2 * half) ** 2 + cfg.odom_min_std_m ** 2] * 2
                   + [math.radians(cfg.no_odometry_accel_deg_s2 * half) ** 2 + math.radians(cfg.odom_min_std_deg) ** 2])


def prediction_covariance(increment: npt.ArrayLike, yaw: float, cfg: ScanMatchConfig,
                          accel_dt_s: float | None = None) -> FloatArray:
    """Covariance of x ⊕ u in the map frame for a fixed x of heading ``yaw``: G Cov(u) Gᵀ, G = diag(R(yaw), 1);
    Cov(u) from the odometry model, or, given ``accel_dt_s`` (no odometry), :func:`constant_velocity_covariance`."""
    g = frame_rotation(yaw)
    inc_cov = (constant_velocity_covariance(accel_dt_s, cfg) if accel_dt_s is not None
               else increment_covariance(increment, cfg))
    cov: FloatArray = g @ inc_cov @ g.T
    return cov


def propagated_covariance(previous_covariance: npt.ArrayLike, previous_pose: npt.ArrayLike, increment: npt.ArrayLike,
                          cfg: ScanMatchConfig, accel_dt_s: float | None = None) -> FloatArray:
    """Covariance of the prediction x ⊕ u in the map frame: J Σ_x Jᵀ + G Cov(u) Gᵀ (first-order compounding).

    Σ_x is the uncertainty of the previous pose that no match to the submap took out: zero after a trusted
    match, that scan's own prediction covariance after a fallback or a weak match (so that its error stays
    inside the next window). J = ∂(x ⊕ u)/∂x = [[1, 0, −Δy], [0, 1, Δx], [0, 0, 1]] with (Δx, Δy) = R(θ)(u_x, u_y).
    """
    x = np.asarray(previous_pose, dtype=np.float64)
    shift = rotation_matrix(float(x[2])) @ np.asarray(increment, dtype=np.float64)[:2]
    return compounded_covariance(previous_covariance, shift,
                                 prediction_covariance(increment, float(x[2]), cfg, accel_dt_s))


def search_window(covariance: FloatArray, cfg: ScanMatchConfig) -> Window:
    """Correlative half-widths ((x, y) in m, yaw in deg): window_sigmas standard deviations, clipped to the limits."""
    return sigma_window(covariance, cfg.window_sigmas, cfg.correlative_window_min_m, cfg.correlative_window_max_m,
                        cfg.correlative_window_min_deg, cfg.correlative_window_max_deg)


def grown_window(window: Window, cfg: ScanMatchConfig) -> Window | None:
    """The window ``window_growth`` times wider on every axis, clipped to the maxima; None when it is at them."""
    (wx, wy), wyaw = window
    grow = cfg.window_growth
    new = ((min(wx * grow, cfg.correlative_window_max_m), min(wy * grow, cfg.correlative_window_max_m)),
           min(wyaw * grow, cfg.correlative_window_max_deg))
    return None if new == window else new


def voxel_downsample(points: FloatArray, voxel_m: float) -> FloatArray:
    """One centroid per occupied voxel of edge ``voxel_m`` (order: by voxel key)."""
    if points.shape[0] == 0:
        return points
    inverse, counts = _voxel_groups(points, voxel_m)[1:]
    sums = np.stack([np.bincount(inverse, weights=points[:, i]) for i in range(2)], axis=1)
    out: FloatArray = sums / counts[:, None]
    return out


def _voxel_groups(points: FloatArray, voxel_m: float) -> tuple[IntArray, IntArray, IntArray]:
    """np.unique over the voxel keys: (first index, inverse, counts) per occupied voxel."""
    keys = np.floor(points / voxel_m).astype(np.int64)
    keys -= keys.min(axis=0)
    flat = keys[:, 0] * (int(keys[:, 1].max()) + 1) + keys[:, 1]
    first, inverse, counts = np.unique(flat, return_index=True, return_inverse=True, return_counts=True)[1:]
    return first, inverse, counts


def _merged_samples(keyframes: Sequence[Keyframe], centre: FloatArray, reach_m: float, cfg: ScanMatchConfig
                    ) -> tuple[FloatArray, FloatArray]:
    """The keyframes' samples and normals within ±reach_m of ``centre`` per axis, one per voxel (the first
    keyframe's in the given order wins)."""
    lines = [kf.in_map for kf in keyframes]
    pts = np.concatenate([ln.points for ln in lines], axis=0)
    nrm = np.concatenate([ln.normals for ln in lines], axis=0)
    inside = np.all(np.abs(pts - centre[:2]) <= reach_m, axis=1)
    pts, nrm = pts[inside], nrm[inside]
    if pts.shape[0]:
        first = _voxel_groups(pts, cfg.submap_voxel_m)[0]
        pts, nrm = pts[first], nrm[first]
    return pts, nrm


def _build_submap(keyframes: tuple[Keyframe, ...], cfg: ScanMatchConfig, *, old: bool = True) -> Submap:
    """KD-tree and likelihood grid over the local keyframes' samples, one per voxel (the oldest keyframe's wins).

    The local keyframes are those within ``submap_radius_m`` of the newest plus the last ``submap_keyframes``;
    unless ``old``, only those passed less than ``loop_min_travel_m`` of path ago among the former (older ones
    are the loop closure's, :func:`_old_keyframes_usable`). Only samples the next scans can reach are kept:
    those within the newest keyframe's reach (its farthest sample) plus the largest search window of its pose,
    per axis.
    """
    newest = keyframes[-1]
    poses = np.stack([kf.pose for kf in keyframes])
    near = np.hypot(*(poses[:, :2] - newest.pose[:2]).T) <= cfg.submap_radius_m
    if not old:
        near &= newest.path_m - np.array([kf.path_m for kf in keyframes]) < cfg.loop_min_travel_m
    else:  # old ones usable: a revisit adds little to the older keyframe it stands by (module docstring)
        near &= ~np.array([kf.revisit for kf in keyframes])
    near[-cfg.submap_keyframes :] = True
    local = [keyframes[i] for i in np.flatnonzero(near)]
    reach = newest.reach_m + cfg.correlative_window_max_m if newest.lines.points.shape[0] else math.inf
    pts, nrm = _merged_samples(local, newest.pose, reach, cfg)
    grid = build_likelihood_grid(pts, resolution_m=cfg.grid_resolution_m, sigma_m=cfg.grid_sigma_m,
                                 window_m=cfg.correlative_window_max_m, coarse_cells=cfg.coarse_cells)
    return Submap(keyframes, line_reference(pts, nrm), grid, tuple(kf.profile for kf in local), poses[near])


def is_revisit(keyframes: Sequence[Keyframe], pose: npt.ArrayLike, cfg: ScanMatchConfig) -> bool:
    """Whether a new keyframe at ``pose`` revisits a place: some keyframe older than the last
    ``submap_keyframes``, not itself a revisit, stands within ``submap_revisit_m`` and ``submap_revisit_deg``."""
    older = keyframes[: max(len(keyframes) - cfg.submap_keyframes, 0)]
    if not older or cfg.submap_revisit_m <= 0.0:
        return False
    poses = np.stack([kf.pose for kf in older])
    p = np.asarray(pose, dtype=np.float64)
    close = (np.hypot(*(poses[:, :2] - p[:2]).T) <= cfg.submap_revisit_m) & (
        np.abs(wrap_angle(poses[:, 2] - p[2])) <= math.radians(cfg.submap_revisit_deg))
    return bool(np.any(close & ~np.array([kf.revisit for kf in older])))


def _keyframe(scan_xy: FloatArray, pose: npt.ArrayLike, path_m: float, cfg: ScanMatchConfig,
              downsampled: FloatArray | None = None, revisit: bool = False) -> Keyframe:
    """The scan's line samples and normals moved into the map frame at ``pose``; ``downsampled``: the scan's
    voxel_downsample when the caller has it."""
    lines = scan_lines(scan_xy, spacing_m=cfg.submap_voxel_m, max_incidence_deg=cfg.line_max_incidence_deg,
                       range_sigma_m=cfg.range_sigma_m, normal_radius_m=cfg.normal_radius_m,
                       max_missing_beams=cfg.line_max_missing_beams)
    scan = voxel_downsample(scan_xy, cfg.scan_voxel_m) if downsampled is None else downsampled
    return Keyframe.at(pose, lines, scan, path_m, RangeProfile.of_scan(scan_xy), revisit)


def start_submap(scan_xy: FloatArray, pose: npt.ArrayLike, cfg: ScanMatchConfig) -> Submap:
    """A submap holding one keyframe: the scan (hits in beam order) at ``pose``."""
    return _build_submap((_keyframe(scan_xy, pose, 0.0, cfg),), cfg)


def add_keyframe(submap: Submap, scan_xy: FloatArray, pose: npt.ArrayLike, cfg: ScanMatchConfig, *,
                 old: bool = True, downsampled: FloatArray | None = None) -> Submap:
    """The submap with the scan at ``pose`` added, its local part re-selected around that pose (``downsampled``:
    the scan's voxel_downsample when the caller has it)."""
    last = submap.keyframes[-1]
    path_m = last.path_m + float(np.hypot(*(np.asarray(pose, dtype=np.float64)[:2] - last.pose[:2])))
    revisit = is_revisit(submap.keyframes, pose, cfg)
    return _build_submap((*submap.keyframes, _keyframe(scan_xy, pose, path_m, cfg, downsampled, revisit)), cfg,
                         old=old)


def match_scan(submap: Submap, scan_xy: FloatArray, prior: FloatArray, prior_covariance: FloatArray,
               cfg: ScanMatchConfig) -> ScanMatch:
    """Correlative search around the prediction, MAP-PLICP from its best pose (and from the prediction), then
    the acceptance test; a rejected or weak match is searched again in wider windows (module docstring)."""
    rejected = ScanMatch(prior, prior_covariance, 0, math.nan, 0.0, True, False)
    if scan_xy.shape[0] < cfg.min_inliers or submap.lines.size < cfg.min_inliers:
        return rejected
    window: Window = search_window(prior_covariance, cfg)
    sparse = thinned(scan_xy, cfg.correlative_max_points)
    gaussian = GaussianPrior(prior, np.asarray(np.linalg.inv(prior_covariance), dtype=np.float64))
    from_prior: PlicpResult | None = None  # ICP from the prediction does not depend on the window: run it once
    weak: tuple[PlicpResult, float] | None = None  # the first (narrowest-window) weak match and its score
    min_inliers_trusted = cfg.min_overlap_fraction * cfg.trim_fraction * scan_xy.shape[0]
    while True:
        (window_m, window_deg) = window
        coarse = correlative_match(submap.grid, sparse, prior, window_m=window_m, window_deg=window_deg,
                                   step_deg=cfg.correlative_step_deg)
        fine = _refine(submap, scan_xy, coarse.pose, gaussian, cfg)
        if lattice_steps_apart(coarse.pose, prior, cfg.grid_resolution_m, cfg.correlative_step_deg) > 1.0:
            if from_prior is None:
                from_prior = _refine(submap, scan_xy, prior, gaussian, cfg)
            sigma_m = min(fine.sigma_m, from_prior.sigma_m)  # one σ for both: the better fit's noise estimate
            if basin_cost(submap, scan_xy, from_prior, sigma_m, cfg) < basin_cost(submap, scan_xy, fine, sigma_m, cfg):
                fine = from_prior
        if _accept(fine, prior, window_m, window_deg, cfg):
            trusted = fine.n_inliers >= min_inliers_trusted
            if trusted and weak is not None:  # a wider basin the scan overlaps well: the lower MAP cost wins
                sigma_m = min(fine.sigma_m, weak[0].sigma_m)  # one σ for both, as above
                trusted = (basin_cost(submap, scan_xy, fine, sigma_m, cfg)
                           < basin_cost(submap, scan_xy, weak[0], sigma_m, cfg))
            if trusted:
                return ScanMatch(fine.pose, fine.covariance, fine.n_inliers, fine.residual_m, coarse.score, False,
                                 fine.degeneracy < cfg.min_degeneracy)
            if weak is None:  # the weak basin nearest the prediction; a wider weak one is no better evidence
                weak = (fine, coarse.score)
        wider = grown_window(window, cfg)  # no acceptable (or only a weak) match here: search a wider window
        if wider is None and weak is not None:
            fine, score = weak
            return ScanMatch(fine.pose, fine.covariance, fine.n_inliers, fine.residual_m, score, False,
                             fine.degeneracy < cfg.min_degeneracy, weak=True)
        if wider is None:
            return ScanMatch(prior, prior_covariance, fine.n_inliers, fine.residual_m, coarse.score, True, False)
        window = wider


def basin_cost(submap: Submap, scan_xy: FloatArray, result: PlicpResult, sigma_m: float, cfg: ScanMatchConfig
               ) -> float:
    """The MAP cost D/σ² + P (:func:`.plicp.map_cost`) by which two ICP basins of one scan are compared, with the
    scan points that lie on surfaces the submap saw but made no lines of costed as fitting.

    PLICP's D charges ρ(gate) for every scan point that no submap sample lies near (within
    ``max_correspondence_m``). That is right for a point that contradicts the local keyframes' view
    (:mod:`.free_space`: it lies where they saw free space, or behind a surface they saw), and for one on ground
    no keyframe's beam reached (nothing says it fits). It is wrong for a point on a surface the keyframes hit at
    angles too grazing to make lines of (the beams on either side of it stop around it; more keyframes say so
    than contradict it): such a point costs ρ(σ) here, what a point that fits costs. Charged in full, those
    points make the pose that pulls the scan back onto the mapped part win: at intel's corridor entrance (drift
    seed 1, scans 823-827) the submap had the corridor's mouth and its end wall but not its walls, and a pose
    1 m short of the odometry's, which put the scan's dense near-wall points on the mouth, won by 40-200 nats
    against a prior cost of 23-50 for five scans in a row, a 5 m slip.
    In full: C = (D − n_s (ρ(gate) − ρ(σ))) / σ² + P, with D the result's data cost and n_s the number of the
    points it charged ρ(gate) for as outside the gate (its last linearization, ``outside_gate``) that lie on
    seen surfaces, placed at the result's pose; so the relief never exceeds the charge. With
    ``free_space_basins`` off, or σ infinite (three inliers or fewer): :func:`.plicp.map_cost`.
    """
    if not cfg.free_space_basins or not math.isfinite(sigma_m):
        return map_cost(result, sigma_m)
    unmatched = transform_points(result.pose, scan_xy[result.outside_gate])
    silent = int(np.count_nonzero(on_seen_surfaces(submap.local_profiles, submap.local_poses, unmatched,
                                                   cfg.max_correspondence_m)))
    relief = silent * float(cauchy_rho(cfg.max_correspondence_m, cfg.robust_scale_m)
                            - cauchy_rho(sigma_m, cfg.robust_scale_m))
    return (result.data_cost - relief) / sigma_m**2 + result.prior_cost


def _refine(submap: Submap, scan_xy: FloatArray, start: FloatArray, prior: GaussianPrior,
            cfg: ScanMatchConfig) -> PlicpResult:
    """MAP-PLICP of the scan against the submap's lines from ``start``."""
    return plicp_configured(submap.lines, scan_xy, start, prior, cfg)


def _accept(fine: PlicpResult, prior: FloatArray, window_m: tuple[float, float], window_deg: float,
            cfg: ScanMatchConfig) -> bool:
    """Enough inliers, a finite covariance, and a pose inside the search window (plus one gate / one step)."""
    shift = np.abs(fine.pose[:2] - prior[:2])
    turn = abs(float(wrap_angle(fine.pose[2] - prior[2])))
    inside = (bool(np.all(shift <= np.asarray(window_m) + cfg.max_correspondence_m))
              and turn <= math.radians(window_deg + cfg.correlative_step_deg))
    return fine.n_inliers >= cfg.min_inliers and bool(np.all(np.isfinite(fine.covariance))) and inside
