"""Static ground-truth occupancy maps of a world: doors drawn closed, or door leaves left out.

Segments are rasterized by sampling each one every resolution/4 (so diagonal walls are 8-connected and
block a 4-connected flood fill). Free space is the 4-connected component of non-wall cells, with the door
leaves left out, that contains the robot's start: the corridor and every room reachable through a doorway.
Everything else is unknown. The closed map is that map with the closed leaves drawn occupied; the static
map (DESIGN.md: "the static part only: door leaves are removed, hinge cells stay occupied") leaves them out.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from doorbatch.maps import FREE, OCCUPIED, UNKNOWN, OccupancyMap
from doorbatch.sim.world import World, door_leaf_segments

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


def _rasterize(segments: FloatArray, shape: tuple[int, int], origin: FloatArray, resolution_m: float) -> BoolArray:
    """Cells (rows: y, columns: x) touched by the segments."""
    grid = np.zeros(shape, dtype=bool)
    if segments.shape[0] == 0:
        return grid
    a, b = segments[:, 0], segments[:, 1]
    n = np.maximum(np.ceil(np.hypot(*(b - a).T) / (resolution_m / 4)).astype(np.int64), 1) + 1
    seg = np.repeat(np.arange(segments.shape[0]), n)
    f = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n - 1, n)
    pts = a[seg] + f[:, None] * (b - a)[seg]
    ij = np.floor((pts - origin) / resolution_m).astype(np.int64)[:, ::-1]
    inside = (ij[:, 0] >= 0) & (ij[:, 0] < shape[0]) & (ij[:, 1] >= 0) & (ij[:, 1] < shape[1])
    grid[ij[inside, 0], ij[inside, 1]] = True
    return grid


def truth_maps(world: World, start_xy: tuple[float, float], resolution_m: float = 0.05, margin_m: float = 1.0
               ) -> tuple[OccupancyMap, OccupancyMap]:
    """(closed, static) occupancy maps of a world; see the module docstring."""
    closed_leaves = door_leaf_segments(world.doors, np.zeros(world.doors.count))
    open_leaves = door_leaf_segments(world.doors, world.doors.max_angle_rad)
    every = np.concatenate([world.segments, closed_leaves, open_leaves]).reshape(-1, 2)
    # cell centres on multiples of the resolution: a wall on a round coordinate lies on a row of cell
    # centres, not on a cell border (where floor() put it half a cell, 2.5 cm, to one side)
    lo = (np.floor((every.min(axis=0) - margin_m) / resolution_m) - 0.5) * resolution_m
    hi = every.max(axis=0) + margin_m
    width, height = (math.ceil(v) for v in (hi - lo) / resolution_m)
    walls = _rasterize(world.segments, (height, width), lo, resolution_m)
    leaves = _rasterize(closed_leaves, (height, width), lo, resolution_m) & ~walls
    labels, _ = ndimage.label(~walls)
    si, sj = (int(v) for v in np.floor((np.asarray(start_xy) - lo) / resolution_m)[::-1])
    free = labels == labels[si, sj] if not walls[si, sj] else np.zeros_like(walls)
    static = np.full((height, width), UNKNOWN, dtype=np.int8)
    static[free] = FREE
    static[walls] = OCCUPIED
    closed = static.copy()
    closed[leaves] = OCCUPIED
    ox, oy = float(lo[0]), float(lo[1])
    return (OccupancyMap(closed, resolution_m, ox, oy, 0.0), OccupancyMap(static, resolution_m, ox, oy, 0.0))
