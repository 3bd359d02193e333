"""Deskewing a sweeping laser: each beam moved to where the laser stood at the scan's stamp.

A rotating laser measures beam i at t_i = stamp + i · time_increment (sensor_msgs/LaserScan: the stamp is the first
beam's time), so a robot that moves during the sweep bends walls and, turning, doubles them. With M_i the base's pose
at t_i seen from the base at the stamp (odometry(t₀)⁻¹ ⊕ odometry(t_i), interpolated) and L the laser → base mount,
beam i's end point e_i = r_i (cos α_i, sin α_i) is, in the laser frame at the stamp,

    q_i = L⁻¹ (M_i (L e_i)),

which is what ROS's laser_geometry (transformLaserScanToPointCloud) does with a TF lookup per beam. doorbatch keeps
scans as ranges on a fixed fan of angles, so the q_i go back to that fan. Where two consecutive end points lie on
one surface (Borges and Aldon's adaptive breakpoint test: |q_{i+1} − q_i| ≤ r_i sin Δα / sin(λ − Δα) + 3σ, λ the
least incidence a surface is seen at), each fan angle between their bearings gets the range at which its ray meets
the segment q_i q_{i+1}: exact on straight walls, where moving a point to the nearest fan angle would shift it off
a wall seen at a grazing angle by up to r·Δα/2 (9 cm at 10 m for a 1° fan). Other fan angles take |q_i| of the
end point whose bearing is nearest. Several on one angle: the nearest range (the surface in front). A beam
without an end point (no return, or a reading below range_min) keeps its value on the angle its direction turns
to; an angle nothing lands on is NaN (no information).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.se2 import interpolate_poses, relative

FloatArray = npt.NDArray[np.float64]
Float32Array = npt.NDArray[np.float32]
IntArray = npt.NDArray[np.intp]


def deskewed_ranges(ranges: npt.ArrayLike, angle_min: float, angle_increment: float, range_min: float,
                    range_max: float, laser_to_base: npt.ArrayLike, base_motion: npt.ArrayLike,
                    breakpoint_rad: float = math.radians(10.0), sigma_m: float = 0.01
                    ) -> tuple[Float32Array, IntArray]:
    """One scan's ranges (B,) as the laser would have measured them all at the stamp (module docstring), and for
    each fan angle the measured beam its range came from (−1: none), to carry per-beam data (colours) along.

    Args:
        laser_to_base: 2×3 affine [A | b] taking laser-frame points to base_link (A may mirror: upside down).
        base_motion: (B, 3) M_i, the base's pose at beam i's time in the base frame at the stamp.
        breakpoint_rad, sigma_m: λ and σ of the breakpoint test that joins consecutive end points.
    """
    r = np.asarray(ranges, dtype=np.float64)
    motion = np.asarray(base_motion, dtype=np.float64).reshape(-1, 3)
    affine = np.asarray(laser_to_base, dtype=np.float64)
    a, b = affine[:, :2], affine[:, 2]
    a_inv = np.linalg.inv(a)
    n = r.shape[0]
    alpha = angle_min + angle_increment * np.arange(n)
    unit = np.stack([np.cos(alpha), np.sin(alpha)], axis=1)
    c, s = np.cos(motion[:, 2]), np.sin(motion[:, 2])
    with np.errstate(invalid="ignore"):
        hit = np.isfinite(r) & (r >= range_min) & (r < range_max)
    # base-frame point at beam time → base frame at the stamp → laser frame at the stamp
    p = (np.where(hit, r, 0.0)[:, None] * unit) @ a.T + b
    moved = np.stack([c * p[:, 0] - s * p[:, 1] + motion[:, 0], s * p[:, 0] + c * p[:, 1] + motion[:, 1]], axis=1)
    q = (moved - b) @ a_inv.T
    # a beam without an end point only turns: its direction A⁻¹ R(θ_i) A u_i
    d = unit @ a.T
    d = np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]], axis=1) @ a_inv.T
    bearing = np.where(hit, np.arctan2(q[:, 1], q[:, 0]), np.arctan2(d[:, 1], d[:, 0]))
    slot, inside = fan_slots(bearing, angle_min, angle_increment, n)
    out = np.full(n, np.nan)
    source = np.full(n, -1, dtype=np.intp)
    endless = np.flatnonzero(~hit & ~np.isnan(r) & inside)
    out[slot[endless]] = r[endless]
    source[slot[endless]] = endless
    landed = np.flatnonzero(hit & inside)
    nearest, nearest_from = nearest_per_slot(slot[landed], np.hypot(q[landed, 0], q[landed, 1]), landed, n)
    between, between_from = _ranges_between(q, hit, r, bearing, angle_min, angle_increment, breakpoint_rad, sigma_m)
    use = np.isfinite(between)
    nearest = np.where(use, between, nearest)
    nearest_from = np.where(use, between_from, nearest_from)
    filled = np.isfinite(nearest)
    out[filled] = nearest[filled]
    source[filled] = nearest_from[filled]
    return out.astype(np.float32), source


def nearest_per_slot(slot: npt.NDArray[np.intp], value: FloatArray, source: npt.NDArray[np.intp], n: int
                     ) -> tuple[FloatArray, IntArray]:
    """Per slot of 0 … n − 1 the smallest value put there and its source (+inf and −1 where none)."""
    best = np.full(n, np.inf)
    best_from = np.full(n, -1, dtype=np.intp)
    if slot.size:
        order = np.lexsort((value, slot))  # per slot, smallest first
        first = np.ones(order.size, dtype=bool)
        first[1:] = slot[order][1:] != slot[order][:-1]
        keep = order[first]
        best[slot[keep]] = value[keep]
        best_from[slot[keep]] = source[keep]
    return best, best_from


def _ranges_between(q: FloatArray, hit: npt.NDArray[np.bool_], r: FloatArray, bearing: FloatArray,
                    angle_min: float, angle_increment: float, breakpoint_rad: float, sigma_m: float
                    ) -> tuple[FloatArray, IntArray]:
    """(B,) the range at which each fan angle's ray meets the segment between two consecutive end points on one
    surface whose bearings it lies between (+inf where none: module docstring), and the first beam of that pair."""
    n = q.shape[0]
    step = abs(angle_increment)
    out = np.full(n, np.inf), np.full(n, -1, dtype=np.intp)
    gap = np.hypot(*(q[1:] - q[:-1]).T)
    limit = r[:-1] * math.sin(step) / math.sin(max(breakpoint_rad - step, 1e-6)) + 3.0 * sigma_m
    with np.errstate(invalid="ignore"):
        joined = np.flatnonzero(hit[:-1] & hit[1:] & (gap <= limit))
    if joined.size == 0:
        return out
    sign = math.copysign(1.0, angle_increment)
    first = fan_coordinate(bearing[joined], angle_min, angle_increment, n)  # of q_i
    turn = np.arctan2(np.sin(bearing[joined + 1] - bearing[joined]), np.cos(bearing[joined + 1] - bearing[joined]))
    second = first + turn * sign / step
    lo = np.ceil(np.minimum(first, second)).astype(np.intp)
    count = np.floor(np.maximum(first, second)).astype(np.intp) - lo + 1
    count = np.where(count <= 4, np.maximum(count, 0), 0)  # neighbours a few fan steps apart at most
    pair = np.repeat(joined, count)
    j = np.repeat(lo, count) + (np.arange(pair.size) - np.repeat(np.cumsum(count) - count, count))
    if n * step >= 2.0 * np.pi - 0.5 * step:  # a full circle: past the last beam is the first
        j = np.mod(j, n)
    keep = (j >= 0) & (j < n)
    pair, j = pair[keep], j[keep]
    a = angle_min + angle_increment * j
    u = np.stack([np.cos(a), np.sin(a)], axis=1)
    e = q[pair + 1] - q[pair]
    # ray t·u meets q_i + s·e: t = (q_i × e) / (u × e)
    denom = u[:, 0] * e[:, 1] - u[:, 1] * e[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (q[pair, 0] * e[:, 1] - q[pair, 1] * e[:, 0]) / denom
    ok = np.isfinite(t) & (t > 0.0)
    return nearest_per_slot(j[ok], t[ok], pair[ok], n)


def fan_slots(bearing: FloatArray, angle_min: float, angle_increment: float, beams: int
              ) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.bool_]]:
    """The beam j of the fan angle_min + j · angle_increment nearest each bearing (rad), and whether it lies within
    the fan (a full circle wraps: beam ``beams`` is beam 0)."""
    j = np.rint(fan_coordinate(bearing, angle_min, angle_increment, beams)).astype(np.intp)
    if beams * abs(angle_increment) >= 2.0 * np.pi - 0.5 * abs(angle_increment):  # a full circle
        return np.mod(j, beams), np.ones(j.shape, dtype=bool)
    inside = (j >= 0) & (j < beams)
    return np.clip(j, 0, beams - 1), inside


def fan_coordinate(bearing: FloatArray, angle_min: float, angle_increment: float, beams: int) -> FloatArray:
    """(bearing − angle_min) / angle_increment, taken in [0, 2π) along the fan's direction; for a fan short of a
    circle, a bearing nearer its start than its end from outside is negative (just before angle_min)."""
    step = abs(angle_increment)
    offset = np.mod((bearing - angle_min) * math.copysign(1.0, angle_increment), 2.0 * np.pi)
    if beams * step < 2.0 * np.pi - 0.5 * step:
        offset = np.where(offset > np.pi + 0.5 * (beams - 1) * step, offset - 2.0 * np.pi, offset)
    return np.asarray(offset / step, dtype=np.float64)


def deskewed_scans(ranges: Sequence[npt.ArrayLike], stamps_ns: npt.ArrayLike, time_increment_s: npt.ArrayLike,
                   angle_min: npt.ArrayLike, angle_increment: npt.ArrayLike, range_min: npt.ArrayLike,
                   range_max: npt.ArrayLike, laser_to_base: npt.ArrayLike, odometry_stamps_ns: npt.ArrayLike,
                   odometry_poses: npt.ArrayLike) -> tuple[list[Float32Array], list[IntArray | None]]:
    """Every scan with a sweep (time_increment ≠ 0) that the odometry spans, deskewed (:func:`deskewed_ranges`)
    with the base's motion from the odometry interpolated at each beam's time, as laser_geometry's per-beam TF
    lookups do (a constant twist over the sweep, LOAM's and KISS-ICP's model, placed the sample's doors worse:
    hinges 3.7 cm off against 0.7 cm on a simulated 5 Hz laser); the others as they were.

    Returns:
        The ranges, and per scan the measured beam each fan angle's range came from (None: left as measured).
    """
    t_odom = np.asarray(odometry_stamps_ns, dtype=np.int64)
    p_odom = np.asarray(odometry_poses, dtype=np.float64).reshape(-1, 3)
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    dt = np.asarray(time_increment_s, dtype=np.float64)
    out: list[Float32Array] = []
    sources: list[IntArray | None] = []
    for i, r in enumerate(ranges):
        beams = np.asarray(r).shape[0]
        if dt[i] == 0.0 or beams < 2:
            out.append(np.asarray(r, dtype=np.float32))
            sources.append(None)
            continue
        query = stamps[i] + np.rint(np.arange(beams) * dt[i] * 1e9).astype(np.int64)
        poses, valid = interpolate_poses(t_odom, p_odom, np.concatenate([[stamps[i]], query]))
        if not valid.all():  # the odometry does not span the sweep: leave the scan as it was measured
            out.append(np.asarray(r, dtype=np.float32))
            sources.append(None)
            continue
        fixed, source = deskewed_ranges(r, float(np.asarray(angle_min)[i]), float(np.asarray(angle_increment)[i]),
                                        float(np.asarray(range_min)[i]), float(np.asarray(range_max)[i]),
                                        np.asarray(laser_to_base)[i], relative(poses[0], poses[1:]))
        out.append(fixed)
        sources.append(source)
    return out, sources
