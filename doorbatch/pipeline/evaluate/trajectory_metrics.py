"""Trajectory metrics defined exactly as evo (github.com/MichaelGrupp/evo) computes them, for planar poses.

Poses are (N, 3) arrays (x, y, yaw) in the map frame; stamps are int64 nanoseconds.

* Association (evo ``sync.associate_trajectories`` with ``nearest_time``): start from the trajectory with
  fewer poses (the estimate when both have as many); for each of its stamps t take the nearest stamp of the
  other trajectory (searchsorted on the right side; a tie goes to the earlier stamp) and keep the pair when
  |Δt| ≤ ``max_diff``. Stamps outside [first − max_diff, last + max_diff] are skipped.
* Alignment ``se2`` (evo ``--align`` without ``--correct_scale``): Umeyama (1991) eqs. 34–43 without scale on
  the positions, i.e. R = U S Vᵀ of the cross-covariance Σ_xy = 1/n Σ (y_i − μ_y)(x_i − μ_x)ᵀ, t = μ_y − R μ_x,
  applied to the estimate (R becomes a yaw offset).
* APE (evo ``metrics.APE``): translation part e_i = ‖p_est,i − p_ref,i‖; rotation angle
  e_i = |log(R_est,iᵀ R_ref,i)| = |wrap(θ_ref,i − θ_est,i)| (rad, or degrees as ``angle_deg``).
* RPE (evo ``metrics.RPE`` with ``--delta D --delta_unit m``, consecutive pairs): pair ids from the
  estimate's path: starting at 0, the next id is the first pose at which the path accumulated since the last
  id reaches D; E_i = (Q_i⁻¹ Q_j)⁻¹ (P_i⁻¹ P_j) (TUM RGB-D eq. 1, Q reference, P estimate); translation
  ‖t(E_i)‖, rotation |θ(E_i)|. With ``all_pairs`` every pose i pairs with the later pose whose path distance
  from i is nearest D, kept when within ``rel_delta_tol``·D of it.
* Statistics (evo ``PE.get_all_statistics``): rmse √(mean e²), mean, median, std (population), min, max.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np
import numpy.typing as npt

from doorbatch.errors import PipelineError
from doorbatch.geometry.se2 import compose, relative
from doorbatch.pipeline.evaluate.trajectory_error import position_errors, yaw_errors

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]
STATISTICS = ("rmse", "mean", "median", "std", "min", "max")


class Alignment(Enum):
    """How the estimate is moved onto the reference before the metrics."""

    NONE = "none"
    SE2 = "se2"


@dataclass(frozen=True)
class Association:
    """Indices of the matched poses: ``reference[ref_index[k]]`` goes with ``estimate[est_index[k]]``."""

    ref_index: IntArray
    est_index: IntArray

    def __len__(self) -> int:
        return int(self.ref_index.shape[0])


def matching_time_indices(stamps_1_ns: npt.ArrayLike, stamps_2_ns: npt.ArrayLike,
                          max_diff_ns: int) -> tuple[IntArray, IntArray]:
    """For each stamp of ``stamps_1`` the nearest stamp of the sorted ``stamps_2`` within ``max_diff_ns``
    (evo ``sync.matching_time_indices``; integer nanoseconds instead of float seconds, so no rounding).

    Raises:
        PipelineError: ``stamps_2`` not sorted.
    """
    s1 = np.asarray(stamps_1_ns, dtype=np.int64)
    s2 = np.asarray(stamps_2_ns, dtype=np.int64)
    if s2.size == 0 or s1.size == 0:
        return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
    if np.any(np.diff(s2) < 0):
        raise PipelineError("trajectory stamps are not sorted")
    inside = (s1 >= s2[0] - max_diff_ns) & (s1 <= s2[-1] + max_diff_ns)
    upper = np.minimum(np.searchsorted(s2, s1, side="right"), s2.size - 1)
    diff_ub = (s2[upper] - s1).astype(np.float64)
    diff_lb = np.where(upper > 0, (s1 - s2[np.maximum(upper - 1, 0)]).astype(np.float64), np.inf)
    take_ub = (diff_ub <= max_diff_ns) & (diff_ub < diff_lb)
    take_lb = ~take_ub & (diff_lb <= max_diff_ns) & (diff_lb <= diff_ub)
    keep = inside & (take_ub | take_lb)
    best = np.where(take_ub, upper, upper - 1)
    return np.flatnonzero(keep).astype(np.intp), best[keep].astype(np.intp)


def associate(ref_stamps_ns: npt.ArrayLike, est_stamps_ns: npt.ArrayLike, max_diff_s: float) -> Association:
    """Pairs of reference and estimate poses at (nearly) equal stamps, as evo ``associate_trajectories``.

    Raises:
        PipelineError: no pair within ``max_diff_s``.
    """
    ref = np.asarray(ref_stamps_ns, dtype=np.int64)
    est = np.asarray(est_stamps_ns, dtype=np.int64)
    max_diff_ns = round(max_diff_s * 1e9)
    if est.size > ref.size:  # evo: start from the shorter one (the estimate when equally long)
        ref_idx, est_idx = matching_time_indices(ref, est, max_diff_ns)
    else:
        est_idx, ref_idx = matching_time_indices(est, ref, max_diff_ns)
    if ref_idx.size == 0:
        hint = ""
        if ref.size and est.size and not (est[0] <= ref[-1] and ref[0] <= est[-1]):  # the spans do not overlap
            gap_s = (float(np.median(est)) - float(np.median(ref))) / 1e9
            hint = (f"; the estimate's stamps lie {gap_s:+.1f} s from the reference's: another clock (sim time "
                    "against wall-clock time)?")
        raise PipelineError(f"no reference pose within {max_diff_s} s of any estimated pose{hint}")
    return Association(ref_idx, est_idx)


def umeyama_se2(estimate_xy: npt.ArrayLike, reference_xy: npt.ArrayLike) -> FloatArray:
    """The SE(2) pose T = (t, θ) minimizing Σ ‖T(x_i) − y_i‖² (Umeyama 1991 eqs. 34–43, scale 1).

    Raises:
        PipelineError: fewer than two distinct positions (degenerate covariance).
    """
    x = np.asarray(estimate_xy, dtype=np.float64).reshape(-1, 2)
    y = np.asarray(reference_xy, dtype=np.float64).reshape(-1, 2)
    mean_x, mean_y = x.mean(axis=0), y.mean(axis=0)
    cov_xy = (y - mean_y).T @ (x - mean_x) / x.shape[0]  # eq. 38
    u, d, vt = np.linalg.svd(cov_xy)
    if np.count_nonzero(d > np.finfo(np.float64).eps) < 1:
        raise PipelineError("degenerate trajectory: Umeyama alignment is not possible")
    s = np.eye(2)
    if np.linalg.det(u) * np.linalg.det(vt) < 0.0:  # eq. 43: a rotation, never a reflection
        s[1, 1] = -1.0
    rot = u @ s @ vt  # eq. 40
    t = mean_y - rot @ mean_x  # eq. 41
    return np.array([t[0], t[1], math.atan2(rot[1, 0], rot[0, 0])])


def ape_translation(estimate: npt.ArrayLike, reference: npt.ArrayLike) -> FloatArray:
    """APE translation part: ‖p_est − p_ref‖ per pose (m)."""
    return position_errors(estimate, reference)


def ape_rotation(estimate: npt.ArrayLike, reference: npt.ArrayLike) -> FloatArray:
    """APE rotation angle: |θ(P_est⁻¹ P_ref)| = |wrap(θ_ref − θ_est)| per pose (rad); in the plane the same
    as |wrap(θ_est − θ_ref)|."""
    return yaw_errors(estimate, reference)


def rpe_pairs(poses: npt.ArrayLike, delta_m: float, all_pairs: bool = False,
              rel_delta_tol: float = 0.1) -> tuple[IntArray, IntArray]:
    """Index pairs (i, j) a path distance ``delta_m`` apart (evo ``filters.filter_pairs_by_path``; consecutive pairs
    start at pose 0, as in evo ≥ 1.32: evo 1.31 started at the first pose ``delta_m`` along the path).

    Raises:
        PipelineError: no pair (the trajectory is shorter than ``delta_m``).
    """
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    dxy = np.diff(p[:, :2], axis=0)
    steps = np.sqrt(np.sum(dxy * dxy, axis=1))
    path = np.concatenate([[0.0], np.cumsum(steps)])
    if all_pairs:
        # for each i, the later pose whose path distance from i is nearest delta (ties: the earliest)
        i = np.arange(p.shape[0] - 1)
        j = np.searchsorted(path, path[i] + delta_m)
        j_hi = np.minimum(j, p.shape[0] - 1)
        j_lo = np.maximum(j - 1, i + 1)
        d_hi = np.abs(path[j_hi] - path[i] - delta_m)
        d_lo = np.abs(path[j_lo] - path[i] - delta_m)
        best = np.where(d_lo <= d_hi, j_lo, j_hi)
        best = np.maximum(np.searchsorted(path, path[best], side="left"), i + 1)  # first of equal distances
        keep = np.abs(path[best] - path[i] - delta_m) <= delta_m * rel_delta_tol
        first, second = i[keep], best[keep]
    else:
        ids = [0]
        while True:  # one step per pair: evo sums the steps since the last id in order (cumsum does too),
            start = ids[-1]  # over a window that the global path says reaches delta, doubled until it does
            width = int(np.searchsorted(path, path[start] + delta_m)) - start + 2
            while True:
                reached = np.flatnonzero(np.cumsum(steps[start:start + width]) >= delta_m)
                if reached.size or start + width >= steps.size:
                    break
                width *= 2
            if reached.size == 0:
                break
            ids.append(start + int(reached[0]) + 1)
        first, second = np.asarray(ids[:-1], dtype=np.intp), np.asarray(ids[1:], dtype=np.intp)
    if first.size == 0:
        raise PipelineError(f"RPE: no pose pair {delta_m} m apart along the path")
    return first.astype(np.intp), second.astype(np.intp)


def rpe_errors(estimate: npt.ArrayLike, reference: npt.ArrayLike, first: IntArray, second: IntArray
               ) -> tuple[FloatArray, FloatArray]:
    """Translation (m) and rotation angle (rad) of E = (Q_i⁻¹ Q_j)⁻¹ (P_i⁻¹ P_j) per pair (i, j)."""
    est = np.asarray(estimate, dtype=np.float64).reshape(-1, 3)
    ref = np.asarray(reference, dtype=np.float64).reshape(-1, 3)
    err = relative(relative(ref[first], ref[second]), relative(est[first], est[second]))
    return np.asarray(np.hypot(err[:, 0], err[:, 1]), dtype=np.float64), np.abs(err[:, 2])


def statistics(errors: npt.ArrayLike) -> dict[str, float]:
    """rmse, mean, median, std (population), min, max of the errors (NaN for none)."""
    e = np.asarray(errors, dtype=np.float64).ravel()
    if e.size == 0:
        return dict.fromkeys(STATISTICS, math.nan)
    return {"rmse": math.sqrt(float(np.mean(e**2))), "mean": float(np.mean(e)), "median": float(np.median(e)),
            "std": float(np.std(e)), "min": float(np.min(e)), "max": float(np.max(e))}


@dataclass(frozen=True)
class TrajectoryErrors:
    """Per-pose APE and per-pair RPE of an estimate against a reference, after association and alignment.

    Attributes:
        stamps_ns: (K,) the estimate's stamps of the associated poses; estimate, reference: (K, 3).
        ape_m, ape_rad: (K,) APE translation and rotation angle.
        rpe_m, rpe_rad: (M,) RPE over ``rpe_delta_m`` (NaN-free; empty when the path is shorter).
        alignment: (3,) the SE(2) transform applied to the estimate (zero without alignment).
    """

    stamps_ns: npt.NDArray[np.int64]
    estimate: FloatArray
    reference: FloatArray
    ape_m: FloatArray
    ape_rad: FloatArray
    rpe_m: FloatArray
    rpe_rad: FloatArray
    rpe_delta_m: float
    alignment: FloatArray


def trajectory_errors(est_stamps_ns: npt.ArrayLike, estimate: npt.ArrayLike, ref_stamps_ns: npt.ArrayLike,
                      reference: npt.ArrayLike, *, max_diff_s: float = 0.01, align: Alignment = Alignment.NONE,
                      rpe_delta_m: float = 1.0, rpe_all_pairs: bool = False,
                      rpe_rel_delta_tol: float = 0.1) -> TrajectoryErrors:
    """Associate, align if asked, then APE and RPE as evo (``evo_ape``/``evo_rpe`` with ``-r trans_part`` and
    ``-r angle_rad``, ``--t_max_diff``, ``--delta D --delta_unit m``).

    Raises:
        PipelineError: no associated pair, or a degenerate trajectory for alignment.
    """
    est_t = np.asarray(est_stamps_ns, dtype=np.int64)
    est = np.asarray(estimate, dtype=np.float64).reshape(-1, 3)
    ref = np.asarray(reference, dtype=np.float64).reshape(-1, 3)
    pairs = associate(ref_stamps_ns, est_t, max_diff_s)
    est_k, ref_k = est[pairs.est_index], ref[pairs.ref_index]
    transform = np.zeros(3)
    if align is Alignment.SE2:
        transform = umeyama_se2(est_k[:, :2], ref_k[:, :2])
        est_k = compose(np.broadcast_to(transform, est_k.shape), est_k)
    try:
        first, second = rpe_pairs(est_k, rpe_delta_m, rpe_all_pairs, rpe_rel_delta_tol)
        rpe_m, rpe_rad = rpe_errors(est_k, ref_k, first, second)
    except PipelineError:
        rpe_m = rpe_rad = np.zeros(0)
    return TrajectoryErrors(est_t[pairs.est_index], est_k, ref_k, ape_translation(est_k, ref_k),
                            ape_rotation(est_k, ref_k), rpe_m, rpe_rad, rpe_delta_m, transform)

