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


def dropouts(no_return: npt.ArrayLike, hit: npt.ArrayLike, max_beams: int) -> npt.NDArray[np.bool_]:
    """The no-return beams that are dropouts: runs of at most ``max_beams`` no-return beams (in beam order) with a
    hit on each side. A beam that returns nothing between two that hit a surface met that surface and lost its echo
    (a dark or glossy patch): it says nothing about the space behind, which clearing to the no-return distance would
    claim through the wall. Longer runs (an opening, a corridor beyond range) and runs at a scan's ends are kept."""
    nr = np.asarray(no_return, dtype=bool).reshape(-1)
    h = np.asarray(hit, dtype=bool).reshape(-1)
    out = np.zeros(nr.shape[0], dtype=bool)
    if max_beams <= 0 or not nr.any():
        return out
    edges = np.diff(np.concatenate([[0], nr.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    inner = (starts > 0) & (stops < nr.shape[0])
    starts, stops = starts[inner], stops[inner]
    short = (stops - starts <= max_beams) & h[starts - 1] & h[stops]
    for a, b in zip(starts[short], stops[short], strict=True):
        out[a:b] = True
    return out


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
