"""What the submap's scans say about a point a new scan saw: seen free, hidden, on a surface they hit, or nothing.

A scan says that along each beam the space in front of its hit is free and the space behind it is hidden from
it. For a point q (in the scan's frame) at range r and bearing β, take the scan's beams on either side of β
within ``bearing_tolerance_rad`` (one at least: ``near``) with their hit ranges r_j:

    free    ⇔ every such beam passed the point:       r_j − r > margin for all j
    behind  ⇔ every such beam stopped short of it:   r − r_j > margin for all j

Otherwise the point lies on a surface the scan hit: within the margin of a hit, or between the hits of two
beams that graze it ("every", not "any", above: a point on a corridor wall seen along its length has one
neighbouring beam hit the wall nearer and the other farther). Two beams cannot tell that wall from a depth edge
(a door jamb near, the wall behind it far), whose gap then counts as a surface too; the vote over keyframes
(:func:`on_seen_surfaces`) is what outweighs one such view. Where no beam points (outside the field of view, a
beam without return) the scan says nothing.

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

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import inverse, transform_points

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True, slots=True)
class RangeProfile:
    """A scan's hits as beams: bearings in [−π, π] sorted ascending (rad) with their ranges (m), and the bearing
    tolerance within which a query direction belongs to a beam."""

    bearing_rad: FloatArray  # (B,)
    range_m: FloatArray  # (B,)
    bearing_tolerance_rad: float

    @classmethod
    def of_scan(cls, scan_xy: npt.ArrayLike) -> RangeProfile:
        """The profile of (N, 2) scan end points in the sensor frame (finite hits; order does not matter).

        The tolerance is 1.5 beam steps, the step estimated as the median gap between neighbouring hit bearings
        (where many beams returned nothing the median grows, and directions without a return borrow the verdict
        of the nearest one that did)."""
        pts = np.asarray(scan_xy, dtype=np.float64).reshape(-1, 2)
        bearing = np.arctan2(pts[:, 1], pts[:, 0])
        order = np.argsort(bearing, kind="stable")
        bearing, rng = bearing[order], np.hypot(pts[order, 0], pts[order, 1])
        gaps = np.diff(bearing)
        gaps = gaps[gaps > 0]
        step = float(np.median(gaps)) if gaps.size else math.radians(1.0)
        return cls(bearing, rng, 1.5 * step)

    def verdicts(self, points_xy: npt.ArrayLike, margin_m: float) -> tuple[BoolArray, BoolArray, BoolArray]:
        """(M,) masks free, behind, on_surface for points in the sensor frame, from the beams on either side of
        each point's bearing within the bearing tolerance (across ±π for a scan that closes the circle):

        free: more than ``margin_m`` in front of all their hits; behind: more than ``margin_m`` behind all of them;
        on_surface: neither (within ``margin_m`` of a hit, or between a nearer and a farther one).
        """
        q = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
        n = self.bearing_rad.shape[0]
        none = np.zeros(q.shape[0], dtype=bool)
        if n == 0 or q.shape[0] == 0:
            return none, none.copy(), none.copy()
        beta = np.arctan2(q[:, 1], q[:, 0])
        r = np.hypot(q[:, 0], q[:, 1])
        right = np.searchsorted(self.bearing_rad, beta)
        sides = ((right - 1) % n, right % n)  # the beams on either side, wrapping around ±π
        near = [np.abs(wrap_angle(self.bearing_rad[j] - beta)) <= self.bearing_tolerance_rad for j in sides]
        any_near = near[0] | near[1]
        all_past, all_short = any_near.copy(), any_near.copy()
        for j, nj in zip(sides, near, strict=True):
            ahead = self.range_m[j] - r
            all_past &= ~nj | (ahead > margin_m)
            all_short &= ~nj | (-ahead > margin_m)
        return all_past, all_short, any_near & ~all_past & ~all_short


def on_seen_surfaces(profiles: Sequence[RangeProfile], poses: npt.ArrayLike, points_xy: npt.ArrayLike,
                     margin_m: float) -> BoolArray:
    """(M,) whether each map-frame point lies on a surface for more of the scans (profiles at ``poses``, (K, 3)
    map-frame sensor poses) than see it free or behind a hit (module docstring)."""
    q = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
    against = np.zeros(q.shape[0], dtype=np.int64)
    on_surface = np.zeros(q.shape[0], dtype=np.int64)
    for profile, pose in zip(profiles, np.asarray(poses, dtype=np.float64).reshape(-1, 3), strict=True):
        free, behind, surface = profile.verdicts(transform_points(inverse(pose), q), margin_m)
        against += free | behind
        on_surface += surface
    out: BoolArray = on_surface > against
    return out
