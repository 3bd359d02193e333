"""What the submap's scans say about a point a new scan saw: seen free, hidden, on a surface they hit, or nothing.

A scan says that along each beam the space in front of its hit is free and the space behind it is hidden from
it. For a point q (in the scan's frame) at range r and bearing β, take the scan's beams on either side of β
within ``bearing_tolerance_rad`` (one at least: ``near``) with their hit ranges r_j:

    free    ⇔ every such beam passed the point:       r_j − r > margin for all j
    behind  ⇔ every such beam stopped short of it:   r − r_j > margin for all j

Otherwise the point lies on a surface the scan hit: within the margin of the hits, or between the hits of two
beams that graze it ("every", not "any": a point on a corridor wall seen along its length has one neighbouring
beam hit the wall nearer and the other farther). Where no beam points (outside the field of view, a beam
without return) the scan says nothing.

Scan matching uses this to tell a scan point that no submap line explains because it lies on a surface the
keyframes hit but made no lines of (grazing) from one that the keyframes saw free or could not see, or did not
look at (:func:`.scanmatch.basin_cost`): a point counts as on a seen surface when more of the keyframes whose
beams point at it say so than see it free or behind a hit. A vote, because with every scan a keyframe a submap
holds hundreds, from passes whose loops had not closed yet, and one of them contradicts almost any point (intel,
drift seed 4, scan 824: each of the 39 unmatched points behind a hit for one of 310 keyframes). A point behind
a keyframe's hit counts against although the keyframe could not see there: with those points counted as
fitting, a pose turned so that far points swing through walls lost nothing by it (aces, drift seeds 1-16: three
runs of 0.9-1.7 m; docs/results.md).

The beams are taken from the base frame's origin, where the scan points are given (the laser's mount offset,
a few centimetres to decimetres, is well inside the margin for all but the nearest points).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.se2 import inverse, transform_points

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True, slots=True)
class RangeProfile:
    """A scan's hits as beams: bearings sorted ascending (rad) with their ranges (m), and the bearing tolerance
    within which a query direction belongs to a beam (1.5 median beam spacings)."""

    bearing_rad: FloatArray  # (B,)
    range_m: FloatArray  # (B,)
    bearing_tolerance_rad: float

    @classmethod
    def of_scan(cls, scan_xy: npt.ArrayLike) -> RangeProfile:
        """The profile of (N, 2) scan end points in the sensor frame (finite hits; order does not matter)."""
        pts = np.asarray(scan_xy, dtype=np.float64).reshape(-1, 2)
        bearing = np.arctan2(pts[:, 1], pts[:, 0])
        order = np.argsort(bearing)
        bearing, rng = bearing[order], np.hypot(pts[order, 0], pts[order, 1])
        gaps = np.diff(bearing)
        spacing = float(np.median(gaps[gaps > 0])) if np.any(gaps > 0) else math.radians(1.0)
        return cls(bearing, rng, 1.5 * spacing)

    def verdicts(self, points_xy: npt.ArrayLike, margin_m: float) -> tuple[BoolArray, BoolArray, BoolArray]:
        """(M,) masks free, behind, near: each point (sensor frame) lies more than ``margin_m`` in front of (free)
        or behind (behind) the hits of all the beams on either side of its direction within the bearing tolerance,
        of which there is one at least (near)."""
        q = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
        n = self.bearing_rad.shape[0]
        if n == 0 or q.shape[0] == 0:
            none = np.zeros(q.shape[0], dtype=bool)
            return none, none.copy(), none.copy()
        beta = np.arctan2(q[:, 1], q[:, 0])
        r = np.hypot(q[:, 0], q[:, 1])
        right = np.searchsorted(self.bearing_rad, beta)
        any_near = np.zeros(q.shape[0], dtype=bool)
        all_past = np.ones(q.shape[0], dtype=bool)
        all_short = np.ones(q.shape[0], dtype=bool)
        for j in (np.clip(right - 1, 0, n - 1), np.clip(right, 0, n - 1)):  # the beams on either side
            near = np.abs(self.bearing_rad[j] - beta) <= self.bearing_tolerance_rad
            any_near |= near
            all_past &= ~near | (self.range_m[j] - r > margin_m)
            all_short &= ~near | (r - self.range_m[j] > margin_m)
        return any_near & all_past, any_near & all_short, any_near


def on_seen_surfaces(profiles: Sequence[RangeProfile], poses: npt.ArrayLike, points_xy: npt.ArrayLike,
                     margin_m: float) -> BoolArray:
    """(M,) whether each map-frame point lies on a surface for more of the scans (profiles at ``poses``, (K, 3)
    map-frame sensor poses) than see it free or behind a hit (module docstring)."""
    q = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
    against = np.zeros(q.shape[0], dtype=np.int64)
    on_surface = np.zeros(q.shape[0], dtype=np.int64)
    for profile, pose in zip(profiles, np.asarray(poses, dtype=np.float64).reshape(-1, 3), strict=True):
        free, behind, near = profile.verdicts(transform_points(inverse(pose), q), margin_m)
        against += free | behind
        on_surface += near & ~free & ~behind
    out: BoolArray = on_surface > against
    return out
