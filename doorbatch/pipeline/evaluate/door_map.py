"""Door-map scoring against ground truth: match by hinge distance, then hinge, length and range errors (a door
that never moved and was seen closed shows no hinge: it is matched at the other end of its leaf where that leaf is
a truth door's, :func:`nearer_ends`).

A detected door matches the nearest unmatched truth door whose hinge lies within ``max_hinge_distance_m``
(greedy by distance). Only truth doors seen at two or more distinguishable angles (``moved``) should be
found by the grid stage; a detection matched to a door that never moved counts as a false positive, and
so does a detection matched to nothing. Which doors moved comes from the truth's ``leaf_observations``; a truth
without them cannot tell, and the caller then counts every truth door (:func:`truth_doors`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.io.sim_truth import SimTruth
from doorbatch.maps import DoorSet, OccupancyMap
from doorbatch.pipeline.localize.door_geometry import leaf_endpoints, other_end

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class DoorScore:
    """Matches and errors. ``matches`` pairs (detected index, truth index) of true positives."""

    precision: float
    recall: float
    matches: list[tuple[int, int]]
    false_positives: list[int]
    missed: list[int]
    hinge_error_m: FloatArray
    length_error_m: FloatArray
    range_error_rad: FloatArray


def _range_error(det: DoorSet, i: int, truth: DoorSet, j: int) -> float:
    """Largest difference between the ends of the two opening ranges (either orientation of the range)."""
    d_lo, d_hi = (a[i] for a in det.range_global)
    t_lo, t_hi = (a[j] for a in truth.range_global)
    same = max(abs(float(wrap_angle(d_lo - t_lo))), abs(float(wrap_angle(d_hi - t_hi))))
    swapped = max(abs(float(wrap_angle(d_lo - t_hi))), abs(float(wrap_angle(d_hi - t_lo))))
    return min(same, swapped)


def match_by_hinge(detected_hinge: npt.ArrayLike, truth_hinge: npt.ArrayLike, max_hinge_distance_m: float
                   ) -> tuple[list[tuple[int, int]], FloatArray]:
    """Greedy one-to-one matching by hinge distance: pairs (detected, truth) in increasing distance, each
    within ``max_hinge_distance_m``; also the (D, T) distance matrix."""
    det = np.asarray(detected_hinge, dtype=np.float64).reshape(-1, 2)
    tru = np.asarray(truth_hinge, dtype=np.float64).reshape(-1, 2)
    dist = np.linalg.norm(det[:, None, :] - tru[None, :, :], axis=2)
    close = np.argwhere(dist <= max_hinge_distance_m)
    order = np.lexsort((close[:, 1], close[:, 0], dist[close[:, 0], close[:, 1]]))
    used_d: set[int] = set()
    used_t: set[int] = set()
    matched: list[tuple[int, int]] = []
    for i, j in close[order].tolist():
        if i not in used_d and j not in used_t:
            used_d.add(i)
            used_t.add(j)
            matched.append((i, j))
    return matched, dist


def nearer_ends(detected: DoorSet, hinge_unknown: npt.ArrayLike, truth: DoorSet, max_hinge_distance_m: float
                ) -> DoorSet:
    """``detected`` with each door of ``hinge_unknown`` (D,) hinged at the other end of its closed leaf
    (:func:`~doorbatch.pipeline.localize.door_geometry.other_end`) where that is a truth door's leaf: its free end
    then lies within ``max_hinge_distance_m`` of a truth hinge and its hinge of that door's closed free end, while
    its own hinge is farther from every truth hinge. A door that never moved shows no hinge, and the em stage's
    choice of end is a guess, as localization treats it; a leaf across a doorway is no door either way."""
    unknown = np.asarray(hinge_unknown, dtype=bool)
    if not unknown.any() or not len(truth):
        return detected
    flipped = other_end(detected)
    truth_tip = leaf_endpoints(truth, np.zeros(len(truth)))

    def distances(points: FloatArray, to: FloatArray) -> FloatArray:
        return np.asarray(np.linalg.norm(points[:, None, :] - to[None, :, :], axis=2))

    to_hinge = distances(flipped.hinge, truth.hinge)  # (D, T): the flipped door's hinge to each truth hinge
    same_leaf = (to_hinge <= max_hinge_distance_m) & (distances(detected.hinge, truth_tip) <= max_hinge_distance_m)
    flip = unknown & same_leaf.any(axis=1) & (np.where(same_leaf, to_hinge, np.inf).min(axis=1)
                                              < distances(detected.hinge, truth.hinge).min(axis=1))

    def pick(a: npt.ArrayLike, b: npt.ArrayLike) -> FloatArray:
        a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
        return np.where(flip.reshape((-1,) + (1,) * (a.ndim - 1)), b, a)

    return DoorSet(pick(detected.hinge, flipped.hinge), np.asarray(detected.length, dtype=np.float64),
                   pick(detected.closed_yaw, flipped.closed_yaw), pick(detected.angle_min, flipped.angle_min),
                   pick(detected.angle_max, flipped.angle_max), detected.door_id)


def score_doors(detected: DoorSet, truth: DoorSet, moved: npt.ArrayLike,
                max_hinge_distance_m: float = 0.3, hinge_unknown: npt.ArrayLike | None = None) -> DoorScore:
    """Precision over all detections, recall over the truth doors that moved, and errors of the matches. A map
    with no doors has no precision, and a truth with no counted door no recall (NaN): an empty doors.parquet
    scored 1.0 looked perfect beside a recall of 0. Doors of ``hinge_unknown`` are scored at the other end of
    their leaf where that leaf is a truth door's (:func:`nearer_ends`)."""
    if hinge_unknown is not None:
        detected = nearer_ends(detected, hinge_unknown, truth, max_hinge_distance_m)
    moved_mask = np.asarray(moved, dtype=bool)
    matched, dist = match_by_hinge(detected.hinge, truth.hinge, max_hinge_distance_m)
    true_pos = [(i, j) for i, j in matched if moved_mask[j]]
    false_pos = sorted(set(range(len(detected))) - {i for i, _ in true_pos})
    missed = [j for j in np.flatnonzero(moved_mask) if j not in {t for _, t in true_pos}]
    n_moved = int(moved_mask.sum())
    return DoorScore(
        precision=len(true_pos) / len(detected) if len(detected) else math.nan,  # no detection: undefined, as
        recall=len(true_pos) / n_moved if n_moved else math.nan,  # sklearn's zero_division=nan; not a perfect 1.0
        matches=true_pos,
        false_positives=false_pos,
        missed=[int(j) for j in missed],
        hinge_error_m=np.array([dist[i, j] for i, j in true_pos]),
        length_error_m=np.array([detected.length[i] - truth.length[j] for i, j in true_pos]),
        range_error_rad=np.array([_range_error(detected, i, truth, j) for i, j in true_pos]),
    )


@dataclass(frozen=True)
class StaticMapScore:
    """Agreement of a static occupancy map with the truth's door-less static map on observed cells."""

    agreement: float
    observed_cells: int
    spurious_occupied_cells: int


def score_static_map(estimate: npt.NDArray[np.int8], truth: npt.NDArray[np.int8], tolerance_cells: int = 1,
                     occupied_above: int = 65, free_below: int = 20) -> StaticMapScore:
    """Fraction of observed cells (known in the estimate) whose state agrees with the truth map, both on the
    same grid. An occupied estimate agrees when a truth-occupied cell lies within ``tolerance_cells`` (the
    truth is drawn at the same resolution, so a wall may fall in the neighbouring cell); a free estimate
    agrees when the truth cell is not occupied. ``spurious_occupied_cells`` counts occupied estimate cells
    with no truth wall nearby (what walking people or a left-behind door leaf would leave)."""
    from scipy.ndimage import maximum_filter

    est_occ = estimate >= occupied_above
    est_free = (estimate >= 0) & (estimate < free_below)
    truth_occ = truth >= occupied_above
    near_truth = maximum_filter(truth_occ, size=2 * tolerance_cells + 1)
    observed = est_occ | est_free
    agree = (est_occ & near_truth) | (est_free & ~truth_occ)
    n = int(observed.sum())
    return StaticMapScore(float(agree.sum()) / n if n else 1.0, n, int((est_occ & ~near_truth).sum()))


def resample_onto(truth: OccupancyMap, grid: OccupancyMap) -> npt.NDArray[np.int8]:
    """The truth map's value at the centre of every cell of ``grid`` (−1 outside the truth map)."""
    rows, cols = np.mgrid[0: grid.height, 0: grid.width]
    xy = grid.cell_to_world(np.stack([rows.ravel(), cols.ravel()], axis=1))
    ij = truth.world_to_cell(xy)  # (row, column)
    inside = truth.contains(ij)
    out = np.full(xy.shape[0], -1, dtype=np.int8)
    out[inside] = truth.occupancy[ij[inside, 0], ij[inside, 1]]
    return out.reshape(grid.height, grid.width)


def score_static_occupancy(estimate: OccupancyMap, truth: OccupancyMap, tolerance_cells: int = 1) -> StaticMapScore:
    """:func:`score_static_map` for two maps on different grids (the truth is resampled onto the estimate)."""
    return score_static_map(estimate.occupancy, resample_onto(truth, estimate), tolerance_cells)


def truth_doors(truth: SimTruth, min_opening_rad: float) -> tuple[DoorSet, npt.NDArray[np.bool_]]:
    """The simulator's doors with the opening range the laser *saw* over the passes, and which doors were
    seen at two or more distinguishable angles (range ≥ ``min_opening_rad``).

    Uses the truth's ``leaf_observations`` (per pass, the angles at which the leaf returned enough beams);
    a door never seen gets an empty range at its first pass's angle and does not count as moved. A truth without
    them (``None``: written by hand) gives each door the range of the angles it took at the passes (at the knots
    of ``door_angles`` where there are no passes), what a laser that saw every leaf would have seen.
    """
    doors = truth.doors
    angles = _pass_angles(truth)
    if truth.leaf_observations is None:
        lo, hi = angles.min(axis=0), angles.max(axis=0)
    else:
        lo = np.full(len(doors), np.inf)
        hi = np.full(len(doors), -np.inf)
        index = {door.door_id: k for k, door in enumerate(doors)}
        for _, door_id, _, _, a_min, a_max in truth.leaf_observations:
            d = index[int(door_id)]  # a hand-written truth may number its doors from 1
            lo[d], hi[d] = min(lo[d], a_min), max(hi[d], a_max)
        never = ~np.isfinite(lo)
        lo[never], hi[never] = angles[0, never], angles[0, never]
    door_set = DoorSet(
        hinge=np.array([[d.hinge_x, d.hinge_y] for d in doors]).reshape(-1, 2),
        length=np.array([d.length for d in doors]),
        closed_yaw=np.array([d.closed_yaw for d in doors]),
        angle_min=lo,
        angle_max=hi,
    )
    return door_set, (hi - lo) >= min_opening_rad


def _pass_angles(truth: SimTruth) -> FloatArray:
    """(P, D) the doors' angles in the middle of each pass's stationary interval; without passes, at the knots of
    ``door_angles`` (and at the truth's start), so that there is always a row."""
    if truth.passes:
        stamps = np.array([(p.stationary_ns + p.end_ns) // 2 for p in truth.passes], dtype=np.int64)
    else:
        stamps = np.unique(np.append(truth.angle_stamp_ns, truth.start_ns))
    return np.atleast_2d(truth.door_angles_at(stamps)).reshape(len(stamps), len(truth.doors))
