"""Door-state error over time: the RBPF's door angles against the simulator's true angles.

Map doors match truth doors by hinge distance (:func:`door_map.match_by_hinge`). At each update t, a matched
door k counts while it was observed within ``window_ns`` before t (an unobserved door's angle is a prior, not
an estimate); its error is |wrap((closed_yaw_k + α_k(t)) − (closed_yaw_j + α*_j(t)))|, the difference of the
global leaf directions (so map and truth may differ in closed_yaw). The update's error is the mean over the
counted doors; updates with none are left out. With ``observed_only=False`` every matched door counts at every
update, observed or not: a door whose true angle lies outside the range the map gives it is never "observed" (no
hypothesis fits its leaf), and only this reading shows how far off its estimate stays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.io.sim_truth import SimTruth
from doorbatch.maps import DoorSet
from doorbatch.pipeline.evaluate.door_map import match_by_hinge

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class DoorStateErrors:
    """Per update with at least one recently observed matched door: its stamp and mean |angle error| (rad)."""

    stamps_ns: npt.NDArray[np.int64]
    error_rad: FloatArray


def door_state_errors(stamps_ns: npt.ArrayLike, door_id: npt.ArrayLike, angle: npt.ArrayLike,
                      observed: npt.ArrayLike, map_doors: DoorSet, truth: SimTruth, max_hinge_distance_m: float,
                      window_ns: int, *, observed_only: bool = True) -> DoorStateErrors:
    """Door-state error per update from door_states.parquet's rows (see the module docstring): over the doors
    observed within ``window_ns``, or (``observed_only=False``) over all matched doors."""
    t_rows = np.asarray(stamps_ns, dtype=np.int64)
    updates, u_idx = np.unique(t_rows, return_inverse=True)
    n_doors = len(map_doors)
    row_of = {int(i): k for k, i in enumerate(map_doors.ids.tolist())}  # door_id → the map's row
    named, d_idx = np.unique(np.asarray(door_id, dtype=np.int64), return_inverse=True)
    d_rows = np.array([row_of.get(int(i), -1) for i in named], dtype=np.int64)[d_idx.ravel()]
    valid = d_rows >= 0
    est = np.full((updates.size, n_doors), np.nan)
    seen = np.zeros((updates.size, n_doors), dtype=bool)
    est[u_idx[valid], d_rows[valid]] = np.asarray(angle, dtype=np.float64)[valid]
    seen[u_idx[valid], d_rows[valid]] = np.asarray(observed, dtype=bool)[valid]
    truth_hinge = np.array([[d.hinge_x, d.hinge_y] for d in truth.doors]).reshape(-1, 2)
    pairs, _ = match_by_hinge(map_doors.hinge, truth_hinge, max_hinge_distance_m)
    if not pairs or updates.size == 0:
        return DoorStateErrors(np.zeros(0, dtype=np.int64), np.zeros(0))
    k = np.array([p[0] for p in pairs])
    j = np.array([p[1] for p in pairs])
    # last observation stamp of each door at or before each update (running maximum over the updates)
    last = np.where(seen[:, k], updates[:, None], np.iinfo(np.int64).min // 2)
    last = np.maximum.accumulate(last, axis=0)
    recent = updates[:, None] - last <= window_ns
    true_dir = np.array([d.closed_yaw for d in truth.doors])[j] + truth.door_angles_at(updates)[:, j]
    est_dir = map_doors.closed_yaw[k] + est[:, k]
    err = np.abs(wrap_angle(est_dir - true_dir))
    counted = (recent if observed_only else True) & np.isfinite(err)
    n = counted.sum(axis=1)
    keep = n > 0
    mean = np.where(counted, err, 0.0).sum(axis=1)[keep] / n[keep]
    return DoorStateErrors(updates[keep], mean.astype(np.float64))
