"""Log-odds occupancy grid mapping with known poses, all beams of a scan ray cast at once (paper 000, Sec. III).

Each cell holds the log-odds l = log(p / (1 − p)) of being occupied. A scan updates, for every beam from the
sensor origin o to its end point e (inverse sensor model of Thrun et al., "Probabilistic Robotics", 9.2):

* every cell the beam crosses before e gets l ← max(l + l_free, l_min) (free),
* the cell holding e gets l ← min(l + l_occ, l_max) (occupied), unless e is a dynamic measurement,

and each cell gets at most one free update and at most one occupied update per scan; a cell that is the end
point of some beam is not also made free by another beam of the same scan. A hit beam stops clearing where
it comes within ``surface_band_m`` of the surface it hit (band / sin θ before its end, θ its angle to the
surface, taken from the neighbouring end points): a wall on a cell border puts its hits into two rows of
cells, and beams grazing it would otherwise clear both rows and make its points look dynamic. A no-return
beam (+inf or ≥ range_max) clears free space up to ``no_return_clear_m``, and never beyond the scan's own
``range_max`` (such a reading says only that nothing was within it); a hit farther than ``max_range_m`` is cut
there and only clears.

The beams are traversed by DDA: beam b takes n_b = ⌈max(|Δi|, |Δj|)⌉ steps of Δ/n_b (at most one cell along
the major axis, so the sampled cells form an 8-connected line like Bresenham's), sample positions in
float32. :func:`integrate_scan` runs a compiled loop (:mod:`doorbatch.pipeline.gridmap.kernels`) that marks
the cells it updated in a per-cell stamp; :func:`integrate_scan_numpy`, its reference, builds one flat index
array of all beams' cells with ``np.repeat`` and updates by gather–scatter ``L[idx] = f(L[idx])`` (every
duplicate reads the value from before the scan and writes the same result: "one free update per cell per
scan"). Both give the same grid, bit for bit.

The grid grows to fit (by at least half its size and a margin, so growth is amortized) and keeps every
integrated cell at the same world position: the origin moves by whole cells.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from doorbatch.config import GridConfig
from doorbatch.maps import UNKNOWN, OccupancyMap
from doorbatch.pipeline.gridmap.kernels import integrate_kernel, scan_bounds

FloatArray = npt.NDArray[np.float64]
Float32Array = npt.NDArray[np.float32]
Int32Array = npt.NDArray[np.int32]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(eq=False)
class LogOddsGrid:
    """The mapping state: per-cell log-odds and the bookkeeping of paper 000, Sec. III.

    Arrays are (H, W); row i grows with y, column j with x, as :class:`~doorbatch.maps.OccupancyMap`.
    ``integrate_scan`` updates them in place and returns a new grid object only when the grid grew.

    Attributes:
        log_odds: float32 log-odds (0: unknown prior p = 0.5).
        hits: int32 number of scans with an end point in the cell that was integrated as occupied.
        hit_sum: complex64 sum of those end points' offsets (one per scan) from the cell's lower corner, in
            cells, u + i·v with u, v ∈ [0, 1); the cell mean is ``corner + resolution · hit_sum / hits``
            (complex: one scatter accumulates both coordinates, twice as fast as a (H, W, 2) array).
        free_latch: bool, set when a cell whose log-odds was below ``l_low`` is raised by a hit, so that
            "seen free once" survives later hits (:func:`doorbatch.pipeline.gridmap.dynamic.seen_free`).
        seen_occupied: bool, p once rose above ``p_seen_occupied_above``; cleared when the cell's mean
            joined the second dynamic set (so the next rise and fall counts again).
        transient: bool, the paper's transient flag (monotone); set lazily for the cells that were queried,
            :func:`doorbatch.pipeline.gridmap.dynamic.update_transient` sets it everywhere.
        last_hit_scan: int32 number of the last scan that integrated a hit in the cell (−1: never).
        pass_start_log_odds: float32 log-odds when the current pass began (the pass's own evidence is the
            difference; :func:`doorbatch.pipeline.gridmap.dynamic.begin_pass`).
        occupied_before_pass: bool, ``seen_occupied`` when the current pass began: structure known before it.
        stamp: int32 scratch of the compiled kernel: which scan last updated the cell (one update per scan).
        scan_count: Scans integrated so far (the number the next scan gets).
        pass_starts: Scan number at which each pass began (``begin_pass``).
        origin_x_m, origin_y_m: World position of the outer corner of cell (0, 0).
        resolution_m: Cell edge (m).
    """

    log_odds: Float32Array
    hits: Int32Array
    hit_sum: npt.NDArray[np.complex64]
    free_latch: BoolArray
    seen_occupied: BoolArray
    transient: BoolArray
    last_hit_scan: Int32Array
    pass_start_log_odds: Float32Array
    occupied_before_pass: BoolArray
    stamp: Int32Array
    origin_x_m: float
    origin_y_m: float
    resolution_m: float
    scan_count: int = 0
    pass_starts: list[int] = field(default_factory=list)

    def pass_of_scan(self, scan: npt.ArrayLike) -> IntArray:
        """The pass each scan number belongs to (−1 before the first pass, or for −1: never)."""
        s = np.asarray(scan, dtype=np.int64)
        out = np.searchsorted(np.asarray(self.pass_starts, dtype=np.int64), s, side="right") - 1
        return np.asarray(np.where(s < 0, -1, out), dtype=np.int64)

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W)."""
        return int(self.log_odds.shape[0]), int(self.log_odds.shape[1])

    def world_to_cell_float(self, xy: npt.ArrayLike) -> FloatArray:
        """Continuous cell coordinates (column, row) = (p − origin) / resolution; floor gives the cell."""
        return (np.asarray(xy, dtype=np.float64) - (self.origin_x_m, self.origin_y_m)) / self.resolution_m

    def flat_index(self, xy: npt.ArrayLike) -> IntArray:
        """Flat index i·W + j of the cell holding each point (points must lie inside the grid)."""
        cj = np.floor(self.world_to_cell_float(xy)).astype(np.int64)
        return cj[..., 1] * self.shape[1] + cj[..., 0]

    def contains(self, xy: npt.ArrayLike) -> BoolArray:
        """Whether each point lies inside the grid."""
        c = self.world_to_cell_float(xy)
        h, w = self.shape
        return np.asarray((c[..., 0] >= 0) & (c[..., 0] < w) & (c[..., 1] >= 0) & (c[..., 1] < h), dtype=np.bool_)

    def cell_centers(self, flat: npt.ArrayLike) -> FloatArray:
        """World centres (N, 2) of cells given by flat index."""
        i, j = np.divmod(np.asarray(flat, dtype=np.int64), self.shape[1])
        return np.stack([self.origin_x_m + (j + 0.5) * self.resolution_m,
                         self.origin_y_m + (i + 0.5) * self.resolution_m], axis=-1)

    def cell_means(self, flat: npt.ArrayLike) -> FloatArray:
        """Mean end point (N, 2) of the hits in each cell (the cell centre where a cell has no hit)."""
        idx = np.asarray(flat, dtype=np.int64)
        n = self.hits.reshape(-1)[idx].astype(np.float64)
        sums = self.hit_sum.reshape(-1)[idx].astype(np.complex128) / np.maximum(n, 1.0)
        frac = np.where(n[:, None] > 0, np.stack([sums.real, sums.imag], axis=-1), 0.5)
        return self.cell_centers(idx) + (frac - 0.5) * self.resolution_m


_LEVELS: dict[int, tuple[GridConfig, FloatArray]] = {}


def levels(config: GridConfig) -> FloatArray:
    """(l_free, l_min, l_occ, l_max, l_low, l_high) of a config, computed once per config object (a logit
    per scan adds up)."""
    hit = _LEVELS.get(id(config))
    if hit is None or hit[0] is not config:
        if len(_LEVELS) > 64:
            _LEVELS.clear()
        values = np.array([config.l_free, config.l_min, config.l_occ, config.l_max, config.l_low, config.l_high])
        hit = _LEVELS[id(config)] = (config, values)
    return hit[1]


GRID_ARRAYS = ("log_odds", "hits", "hit_sum", "free_latch", "seen_occupied", "transient", "last_hit_scan",
               "pass_start_log_odds", "occupied_before_pass", "stamp")


def new_grid(config: GridConfig, center_xy: npt.ArrayLike, size_m: float | None = None) -> LogOddsGrid:
    """An all-unknown square grid of side ``size_m`` (default ``config.initial_size_m``) centred near a point.

    The origin is snapped to a multiple of the resolution, so grids started anywhere share cell borders.
    """
    res = config.resolution_m
    n = max(1, math.ceil((config.initial_size_m if size_m is None else size_m) / res))
    cx, cy = (float(v) for v in np.asarray(center_xy, dtype=np.float64).reshape(2))
    ox = math.floor(cx / res - n / 2) * res
    oy = math.floor(cy / res - n / 2) * res
    return _allocate(n, n, ox, oy, res)


def _allocate(h: int, w: int, ox: float, oy: float, res: float) -> LogOddsGrid:
    return LogOddsGrid(
        log_odds=np.zeros((h, w), np.float32), hits=np.zeros((h, w), np.int32),
        hit_sum=np.zeros((h, w), np.complex64), free_latch=np.zeros((h, w), bool),
        seen_occupied=np.zeros((h, w), bool), transient=np.zeros((h, w), bool),
        last_hit_scan=np.full((h, w), -1, np.int32), pass_start_log_odds=np.zeros((h, w), np.float32),
        occupied_before_pass=np.zeros((h, w), bool),
        stamp=np.zeros((h, w), np.int32),
        origin_x_m=ox, origin_y_m=oy, resolution_m=res,
    )


def rim_cells(config: GridConfig) -> int:
    """Width of the border rim that integration never touches: max(1, transient neighbourhood radius)."""
    return max(1, config.transient_neighborhood_cells)


def grow_to_fit(grid: LogOddsGrid, lo_xy: tuple[float, float], hi_xy: tuple[float, float],
                config: GridConfig) -> LogOddsGrid:
    """The grid itself if the box [lo, hi] lies inside it, else a larger copy that holds the box.

    The box must stay ``rim_cells(config)`` cells away from the border: no beam ever touches that rim, so
    the transient neighbourhood of any observed cell lies inside the grid and reaches never-seen cells
    there. A side that must grow grows by the margin plus at least half the current size (amortized O(1)
    growth over a log); the origin moves by whole cells, so each cell keeps its world position.
    """
    res = grid.resolution_m
    h, w = grid.shape
    rim = rim_cells(config)
    lo = ((lo_xy[0] - grid.origin_x_m) / res, (lo_xy[1] - grid.origin_y_m) / res)
    hi = ((hi_xy[0] - grid.origin_x_m) / res, (hi_xy[1] - grid.origin_y_m) / res)
    if lo[0] >= rim and lo[1] >= rim and hi[0] < w - rim and hi[1] < h - rim:
        return grid
    margin = math.ceil(config.growth_margin_m / res)
    add_lo = [0, 0]
    add_hi = [0, 0]
    for axis, size in ((0, w), (1, h)):
        if lo[axis] < rim:
            add_lo[axis] = max(math.ceil(rim - lo[axis]) + margin, size // 2)
        if hi[axis] >= size - rim:
            add_hi[axis] = max(math.ceil(hi[axis] + rim + 1 - size) + margin, size // 2)
    out = _allocate(h + add_lo[1] + add_hi[1], w + add_lo[0] + add_hi[0], grid.origin_x_m - add_lo[0] * res,
                    grid.origin_y_m - add_lo[1] * res, res)
    out.scan_count = grid.scan_count
    out.pass_starts = list(grid.pass_starts)
    rows = slice(add_lo[1], add_lo[1] + h)
    cols = slice(add_lo[0], add_lo[0] + w)
    for name in GRID_ARRAYS:
        getattr(out, name)[rows, cols] = getattr(grid, name)
    return out


class _ScanCells(NamedTuple):
    """A scan in the grid's continuous cell coordinates: the origin, each beam's free part (Δ from the
    origin), the hit end points and which hits are integrated."""

    ocx: float
    ocy: float
    dx: FloatArray
    dy: FloatArray
    hx: FloatArray
    hy: FloatArray
    keep: BoolArray


def integrate_scan(grid: LogOddsGrid, origin_xy: npt.ArrayLike, points_xy: npt.ArrayLike,
                   no_return_dirs: npt.ArrayLike, config: GridConfig,
                   dynamic_mask: npt.ArrayLike | None = None, range_max_m: float = math.inf) -> LogOddsGrid:
    """Integrate one scan (map frame) into the grid; returns the grid, a new object when it had to grow.

    Args:
        grid: The grid to update (in place).
        origin_xy: (2,) sensor origin.
        points_xy: (N, 2) finite hit end points, in beam order (the surface at each end point is taken
            from its neighbours, ``surface_band_m``).
        no_return_dirs: (M, 2) unit directions of no-return beams.
        config: Grid parameters.
        dynamic_mask: (N,) True for end points that are dynamic measurements (paper 000: end points in
            transient cells): their beams clear free space up to them, but they are not integrated.
        range_max_m: The scan's stated maximum range: no-return beams clear no farther.

    The free update is applied first to every beam's cells; then each occupied end cell is set to
    min(l_before_scan + l_occ, l_max), which undoes any free update it got from another beam of the scan.
    The compiled kernel (:func:`doorbatch.pipeline.gridmap.kernels.integrate_kernel`) does the work;
    :func:`integrate_scan_numpy` is its NumPy reference.
    """
    prep = prepare_scan(grid, origin_xy, points_xy, no_return_dirs, config, range_max_m)
    if prep is not None:
        grid = prep.grid
        dynamic = _NO_MASK if dynamic_mask is None else np.asarray(dynamic_mask, dtype=bool).reshape(-1)
        integrate_kernel(grid.log_odds, grid.hits, grid.hit_sum, grid.free_latch, grid.seen_occupied,
                         grid.last_hit_scan, grid.stamp, grid.origin_x_m, grid.origin_y_m, grid.resolution_m,
                         prep.ox, prep.oy, prep.points, prep.dirs, dynamic, prep.clear, config.surface_band_m,
                         prep.cut, config.max_range_m, grid.scan_count, levels(config))
    grid.scan_count += 1
    return grid


class PreparedScan(NamedTuple):
    """A scan ready for the compiled kernels: the grid grown to hold it, the origin, contiguous float64
    hits and no-return directions, how far no-return beams clear, and whether some beam exceeds max range."""

    grid: LogOddsGrid
    ox: float
    oy: float
    points: FloatArray
    dirs: FloatArray
    clear: float
    cut: bool


def prepare_scan(grid: LogOddsGrid, origin_xy: npt.ArrayLike, points_xy: npt.ArrayLike,
                 no_return_dirs: npt.ArrayLike, config: GridConfig, range_max_m: float = math.inf
                 ) -> PreparedScan | None:
    """Grow the grid to hold the scan's beams (:func:`grow_to_fit`); None when the scan has no beam."""
    o = np.asarray(origin_xy, dtype=np.float64).reshape(2)
    ox, oy = float(o[0]), float(o[1])
    pts = np.ascontiguousarray(points_xy, dtype=np.float64).reshape(-1, 2)
    dirs = np.ascontiguousarray(no_return_dirs, dtype=np.float64).reshape(-1, 2)
    clear = no_return_clear_distance(config, range_max_m)
    if pts.shape[0] == 0 and (clear <= 0.0 or dirs.shape[0] == 0):
        return None
    lox, loy, hix, hiy = scan_bounds(pts, dirs, ox, oy, clear)
    grid = grow_to_fit(grid, (lox, loy), (hix, hiy), config)
    cut = max(hix - ox, ox - lox, hiy - oy, oy - loy) > config.max_range_m
    return PreparedScan(grid, ox, oy, pts, dirs, clear, cut)


_NO_MASK = np.zeros(0, dtype=bool)


def integrate_scan_numpy(grid: LogOddsGrid, origin_xy: npt.ArrayLike, points_xy: npt.ArrayLike,
                         no_return_dirs: npt.ArrayLike, config: GridConfig,
                         dynamic_mask: npt.ArrayLike | None = None, range_max_m: float = math.inf) -> LogOddsGrid:
    """:func:`integrate_scan` in NumPy alone (the reference the compiled kernel is tested against): the
    vectorized DDA of :func:`dda_cells` and gather–scatter updates."""
    grid, sc = _scan_cells(grid, origin_xy, points_xy, no_return_dirs, config, dynamic_mask, range_max_m)
    if sc is not None:
        hx, hy = sc.hx[sc.keep], sc.hy[sc.keep]
        ix, iy = hx.astype(np.intp), hy.astype(np.intp)
        occ_idx = iy * grid.shape[1] + ix
        flat_l = grid.log_odds.reshape(-1)
        before = flat_l[occ_idx]
        free_idx = dda_cells(sc.ocx, sc.ocy, sc.dx, sc.dy, grid.shape[1])
        vals = flat_l[free_idx]
        vals += np.float32(config.l_free)
        np.maximum(vals, np.float32(config.l_min), out=vals)
        flat_l[free_idx] = vals
        if occ_idx.size:
            _occupied_update(grid, occ_idx, before, (hx - ix) + 1j * (hy - iy), config)
    grid.scan_count += 1
    return grid


def _scan_cells(grid: LogOddsGrid, origin_xy: npt.ArrayLike, points_xy: npt.ArrayLike,
                no_return_dirs: npt.ArrayLike, config: GridConfig, dynamic_mask: npt.ArrayLike | None,
                range_max_m: float) -> tuple[LogOddsGrid, _ScanCells | None]:
    """Grow the grid to hold the scan, and express the scan in its cells (None: no beam)."""
    o = np.asarray(origin_xy, dtype=np.float64).reshape(2)
    ox, oy = float(o[0]), float(o[1])
    pts = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
    ends = beam_ends(ox, oy, pts, no_return_dirs, no_return_clear_distance(config, range_max_m))
    if ends.shape[1] == 0:
        return grid, None
    lo, hi = ends.min(axis=1), ends.max(axis=1)
    grid = grow_to_fit(grid, (min(float(lo[0]), ox), min(float(lo[1]), oy)),
                       (max(float(hi[0]), ox), max(float(hi[1]), oy)), config)
    inv = 1.0 / grid.resolution_m
    ocx, ocy = (ox - grid.origin_x_m) * inv, (oy - grid.origin_y_m) * inv
    cells = (ends - np.array([[grid.origin_x_m], [grid.origin_y_m]])) * inv  # continuous cell coordinates
    n_hits = pts.shape[0]
    d = cells - np.array([[ocx], [ocy]])
    keep = np.ones(n_hits, dtype=bool) if dynamic_mask is None else ~np.asarray(dynamic_mask, dtype=bool).reshape(-1)
    r2 = d[0] * d[0] + d[1] * d[1]
    if config.surface_band_m > 0.0 and n_hits:
        # The free part of a hit beam stops where the beam comes within surface_band_m of the surface it hit
        # (band / sin θ before its end): a wall on a cell border puts its hits into two rows of cells, and
        # beams at grazing incidence would clear both rows along their last metres.
        scale = np.ones(d.shape[1])
        scale[:n_hits] = free_fraction(pts, ox, oy, config.surface_band_m)
        d = d * scale
    if max(float(hi[0]) - ox, ox - float(lo[0]), float(hi[1]) - oy, oy - float(lo[1])) > config.max_range_m:
        lim = config.max_range_m * inv  # some beam may be longer than max range: cut it, do not mark its end
        keep &= r2[:n_hits] <= lim * lim
        d = d * np.minimum(1.0, lim / np.sqrt(np.maximum(d[0] * d[0] + d[1] * d[1], 1e-300)))
    return grid, _ScanCells(ocx, ocy, np.ascontiguousarray(d[0]), np.ascontiguousarray(d[1]),
                            np.ascontiguousarray(cells[0, :n_hits]), np.ascontiguousarray(cells[1, :n_hits]), keep)


def free_fraction(points: FloatArray, ox: float, oy: float, band_m: float) -> FloatArray:
    """(N,) fraction of each hit beam that clears free space, 1 − band / (r sin θ): the beam comes within
    ``band_m`` of the surface it hit band / sin θ before its end (θ: the angle between the beam and the
    surface, r: the range). The surface's direction is the segment to the nearer neighbouring end point in
    beam order (``points`` must be in beam order), so r sin θ = |b × t| / |t| (b: the beam, t: that
    segment)."""
    n = points.shape[0]
    bx, by = points[:, 0] - ox, points[:, 1] - oy
    if n < 2:
        return np.asarray(np.clip(1.0 - band_m / np.maximum(np.hypot(bx, by), 1e-12), 0.0, 1.0), dtype=np.float64)
    seg = np.diff(points, axis=0)
    seg_len2 = seg[:, 0] * seg[:, 0] + seg[:, 1] * seg[:, 1]
    prev2 = np.concatenate([[np.inf], seg_len2])
    next2 = np.concatenate([seg_len2, [np.inf]])
    use_next = next2 <= prev2
    tx = np.where(use_next, np.concatenate([seg[:, 0], [0.0]]), np.concatenate([[0.0], seg[:, 0]]))
    ty = np.where(use_next, np.concatenate([seg[:, 1], [0.0]]), np.concatenate([[0.0], seg[:, 1]]))
    r_sin = np.abs(bx * ty - by * tx) / np.maximum(np.sqrt(np.minimum(prev2, next2)), 1e-12)
    return np.asarray(np.clip(1.0 - band_m / np.maximum(r_sin, 1e-12), 0.0, 1.0), dtype=np.float64)


def no_return_clear_distance(config: GridConfig, range_max_m: float = math.inf) -> float:
    """How far a no-return beam clears: min(no_return_clear_m, max_range_m, the scan's range_max). A reading
    of +inf or ≥ range_max says nothing was within range_max (sensor_msgs/LaserScan); beyond it the sensor
    saw nothing at all, so a short-range lidar (3.5 m) must not clear free space through the walls behind."""
    return min(config.no_return_clear_m, config.max_range_m, range_max_m)


def beam_ends(ox: float, oy: float, points: FloatArray, no_return_dirs: npt.ArrayLike, clear: float) -> FloatArray:
    """(2, B) x and y of where the free part of each beam ends: the hits, then o + clear·u for each no-return
    direction u (none when ``clear`` is 0; :func:`no_return_clear_distance`)."""
    dirs = np.asarray(no_return_dirs, dtype=np.float64).reshape(-1, 2)
    if clear <= 0.0 or dirs.shape[0] == 0:
        return np.ascontiguousarray(points.T)
    return np.concatenate([points.T, (clear * dirs + (ox, oy)).T], axis=1)


def _occupied_update(grid: LogOddsGrid, idx: npt.NDArray[np.intp], before: Float32Array,
                     offsets: npt.NDArray[np.complex128], config: GridConfig) -> None:
    """One occupied update per end cell (duplicates write the same value), hit counts and sums, flags."""
    after = before + np.float32(config.l_occ)
    np.minimum(after, np.float32(config.l_max), out=after)
    grid.log_odds.reshape(-1)[idx] = after
    grid.free_latch.reshape(-1)[idx[before < config.l_low]] = True
    grid.seen_occupied.reshape(-1)[idx[after > config.l_high]] = True
    grid.last_hit_scan.reshape(-1)[idx] = grid.scan_count
    # Gather–add–scatter: hits in one cell count once per scan, and its sum takes one of them.
    grid.hits.reshape(-1)[idx] += 1
    grid.hit_sum.reshape(-1)[idx] += offsets.astype(np.complex64)


def dda_cells(ocx: float, ocy: float, dx: FloatArray, dy: FloatArray, width: int) -> npt.NDArray[np.intp]:
    """Flat indices i·W + j of the cells that beams from o cross before their ends (with duplicates).

    Vectorized DDA in continuous cell coordinates: beam b with Δ = (dx_b, dy_b) takes
    n_b = max(1, ⌈max(|dx_b|, |dy_b|)⌉) samples o + k·Δ/n_b, k = 0 … n_b − 1 (at most one cell per step
    along the major axis, so the cells form an 8-connected line); the floor of each sample is a cell. The
    samples of all beams are one array: k is a global ramp minus each beam's first position in it.
    """
    n = np.ceil(np.maximum(np.abs(dx), np.abs(dy)))
    np.maximum(n, 1.0, out=n)
    counts = n.astype(np.intp)
    k = np.arange(int(counts.sum()), dtype=np.float32)
    k -= np.repeat((np.cumsum(counts) - counts).astype(np.float32), counts)
    x = np.repeat((dx / n).astype(np.float32), counts)
    x *= k
    x += np.float32(ocx)
    y = np.repeat((dy / n).astype(np.float32), counts)
    y *= k
    y += np.float32(ocy)
    idx = y.astype(np.int32)
    idx *= np.int32(width)
    idx += x.astype(np.int32)
    return idx.astype(np.intp)  # intp: NumPy's fancy indexing is several times faster with it than with int32


def occupancy_probability(grid: LogOddsGrid) -> FloatArray:
    """p = 1 / (1 + exp(−l)) per cell."""
    return 1.0 / (1.0 + np.exp(-grid.log_odds.astype(np.float64)))


def observed(grid: LogOddsGrid) -> BoolArray:
    """Cells that any update touched (log-odds moved off the prior, or a hit landed there)."""
    return np.asarray((grid.log_odds != 0.0) | (grid.hits > 0), dtype=np.bool_)


def to_occupancy_map(grid: LogOddsGrid) -> OccupancyMap:
    """The grid as an :class:`~doorbatch.maps.OccupancyMap`: round(100·p) where observed, −1 elsewhere."""
    occ = np.rint(100.0 * occupancy_probability(grid)).astype(np.int8)
    occ[~observed(grid)] = UNKNOWN
    return OccupancyMap(occ, grid.resolution_m, grid.origin_x_m, grid.origin_y_m, 0.0)
