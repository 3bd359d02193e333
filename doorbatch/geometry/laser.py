"""Laser scans as points: beam validity by the conventions of DESIGN.md, and points in base_link.

A beam is a *hit* when its range is finite and range_min ≤ r < range_max. NaN is no information;
+inf or r ≥ range_max is "no return within range" (kept separately so mapping can clear free space);
r < range_min is dropped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from doorbatch.records import Scan

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class ScanPoints:
    """Beam end points of one scan in some frame (N hits), the sensor origin there, and beam masks."""

    stamp_ns: int
    origin: FloatArray  # (2,) sensor origin in the target frame
    points: FloatArray  # (N, 2) hit end points
    beam_index: npt.NDArray[np.int64]  # (N,) index of each hit in the scan
    no_return_directions: FloatArray  # (M, 2) unit directions of no-return beams in the target frame


def beam_masks(scan: Scan) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
    """(hit, no_return) masks over the beams of a scan."""
    r = scan.ranges
    with np.errstate(invalid="ignore"):
        no_return = np.isposinf(r) | (np.isfinite(r) & (r >= scan.range_max))
        hit = np.isfinite(r) & (r >= scan.range_min) & (r < scan.range_max)
    return hit, no_return


def wraps_around(angle_increment_rad: float, beams: int) -> bool:
    """Whether a scan's beams go all the way round (a 360° laser): its last beam then neighbours its first. Within
    half a beam of a full turn, or past it (lasers that repeat a beam)."""
    step = abs(float(angle_increment_rad))
    return beams * step >= 2.0 * np.pi - 0.5 * step


def beam_runs(mask: npt.ArrayLike) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """Start and stop (exclusive) indices of each run of consecutive true beams of ``mask``, in beam order."""
    edges = np.diff(np.concatenate([[0], np.asarray(mask, dtype=bool).reshape(-1).astype(np.int8), [0]]))
    return np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)


def dropouts(no_return: npt.ArrayLike, hit: npt.ArrayLike, max_beams: int, wraps: bool = False
             ) -> npt.NDArray[np.bool_]:
    """The no-return beams that are dropouts: those in runs of at most ``max_beams`` beams without a hit (no
    return, NaN, or below range_min: each a lost echo) with a hit on each side, in beam order, across the first and
    last beams where the scan ``wraps`` (:func:`wraps_around`). A beam that returns nothing between two that hit a
    surface met that surface and lost its echo (a dark or glossy patch): it says nothing about the space behind,
    which clearing to the no-return distance would claim through the wall. Longer runs (an opening, a corridor
    beyond range) and runs at the ends of a scan that does not wrap are kept."""
    nr = np.asarray(no_return, dtype=bool).reshape(-1)
    h = np.asarray(hit, dtype=bool).reshape(-1)
    n = nr.shape[0]
    out = np.zeros(n, dtype=bool)
    if max_beams <= 0 or not nr.any() or not h.any():
        return out
    shift = int(np.argmax(h)) if wraps else 0  # start a full circle at a hit: a run across beam 0 is then one run
    nr, h = np.roll(nr, -shift), np.roll(h, -shift)
    starts, stops = beam_runs(~h)
    flanked = (starts > 0) & ((stops < n) | wraps)  # wrapping, a run that reaches the end ends at beam 0, a hit
    for a, b in zip(starts[flanked], stops[flanked], strict=True):
        if b - a <= max_beams:
            out[a:b] = True
    return np.roll(out & nr, shift)


def scan_points(scan: Scan, transform: FloatArray) -> ScanPoints:
    """Beam end points moved by a 4×4 transform (laser frame → target frame), projected to the plane.

    p = T · [r cos θ, r sin θ, 0, 1]ᵀ for every hit beam; a laser rotated 180° about x with a negative
    angle increment gives the same points as the equivalent upright scan.
    """
    hit, no_return = beam_masks(scan)
    angles = scan.angles
    idx = np.flatnonzero(hit)
    r = scan.ranges[idx].astype(np.float64)
    local = np.stack([r * np.cos(angles[idx]), r * np.sin(angles[idx])], axis=1)
    rot = transform[:2, :2]
    points = local @ rot.T + transform[:2, 3]
    nr = angles[no_return]
    dirs = np.stack([np.cos(nr), np.sin(nr)], axis=1) @ rot.T
    norms = np.linalg.norm(dirs, axis=1, keepdims=True)
    dirs = np.divide(dirs, norms, out=np.zeros_like(dirs), where=norms > 0)
    return ScanPoints(scan.stamp_ns, transform[:2, 3].copy(), points, idx.astype(np.int64), dirs)
