"""Transient and seen-occupied cells, and the two sets of dynamic points of paper 000, Sec. III.

Per cell (paper 000, Sec. III, after Hähnel et al.):

* *seen free*: its probability was once below ``p_transient_below``. Log-odds only fall through free
  updates and only rise through hits, so this is ``l < l_low`` now, or a hit raised it from below
  (``free_latch``, set by the occupied update).
* *transient*: its probability is below ``p_transient_below`` and every cell of its (2r+1)×(2r+1)
  neighbourhood (r = ``transient_neighborhood_cells``) was seen free — "only cells within a neighborhood
  of cells with low occupancy probability are marked transient", so that small registration errors at
  wall borders never classify wall points as dynamic. The flag never clears. It is evaluated lazily, for
  the cells that scan end points fall into, before the scan is integrated. (Neighbours count when they
  were *ever* low: cells on a wall's free side flicker, and requiring them low at the same moment cut
  leaves short by a further cell near the hinge in simulation.)
* *seen occupied*: its probability once exceeded ``p_seen_occupied_above`` (set by the occupied update).

Passes (DESIGN.md: doors are stationary within a pass, may move between passes). :func:`begin_pass`
records the log-odds and the seen-occupied cells at the start of each pass.

Set 1 (dynamic measurements): scan end points that fall into transient cells and have no cell that was
seen occupied before the pass within the transient neighbourhood; they are not integrated. The second
condition is the neighbourhood rule applied to known structure: a wall that lies on a cell border puts
its hits into two rows of cells, and beams that graze it (or pass it through a doorway next to it) clear
both rows now and then, so "once seen free" alone marks the wall ends beside every doorway transient (in
simulation a third of all set-1 points were such wall points, and they lengthened closed leaves).
Set 2: cells seen occupied before the pass that got no hit during the pass and whose probability fell
below ``p_transient_below`` — over all passes, or by the pass's own evidence (log-odds change during the
pass ≤ logit(p_transient_below)): a leaf seen obliquely through a doorway gets a handful of free updates
per pass, too few to bring a saturated cell (l_max) below the threshold, yet enough to say it has gone
in this pass. The mean of the end points that fell into each such cell joins the set, and its
seen-occupied flag is cleared so that a later rise and fall counts again. Cells still hit during the
pass are a surface present in this pass (a wall on a cell border flickers between hit and free); they
are not returned and keep their flag.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from doorbatch.config import GridConfig
from doorbatch.pipeline.gridmap.kernels import classify_integrate_kernel, classify_kernel
from doorbatch.pipeline.gridmap.occupancy import LogOddsGrid, levels, prepare_scan

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


def seen_free(grid: LogOddsGrid, flat: npt.ArrayLike, config: GridConfig) -> BoolArray:
    """Whether each cell (flat index) was ever below ``p_transient_below``."""
    idx = np.asarray(flat, dtype=np.intp)
    low = grid.log_odds.reshape(-1)[idx] < np.float32(config.l_low)
    return np.asarray(low | grid.free_latch.reshape(-1)[idx], dtype=np.bool_)


def seen_free_grid(grid: LogOddsGrid, config: GridConfig) -> BoolArray:
    """:func:`seen_free` of every cell, as an (H, W) array."""
    return np.asarray((grid.log_odds < np.float32(config.l_low)) | grid.free_latch, dtype=np.bool_)


def transient_cells(grid: LogOddsGrid, flat: npt.ArrayLike, config: GridConfig) -> BoolArray:
    """Whether each cell is transient (sets the flag where it newly is): already flagged, or below
    ``p_transient_below`` now with every cell within Chebyshev distance r seen free.

    Relies on the rim of :func:`~doorbatch.pipeline.gridmap.occupancy.grow_to_fit`: a cell below the
    threshold lies at least r cells inside the grid, so its neighbours are plain flat-index offsets.
    """
    idx = np.asarray(flat, dtype=np.intp).reshape(-1)
    out = grid.transient.reshape(-1)[idx]
    low = np.float32(config.l_low)
    own = grid.log_odds.reshape(-1)[idx] < low
    own &= ~out
    where = np.flatnonzero(own)
    if where.size:
        cand = idx[where]
        nb = cand[:, None] + _offsets(grid.shape[1], config.transient_neighborhood_cells)
        free = grid.log_odds.reshape(-1)[nb] < low
        free |= grid.free_latch.reshape(-1)[nb]
        ok = free.all(axis=1)
        grid.transient.reshape(-1)[cand[ok]] = True
        out[where[ok]] = True
    return out


@functools.lru_cache(maxsize=8)
def _offsets(width: int, r: int) -> npt.NDArray[np.intp]:
    """Flat offsets of the (2r+1)² neighbourhood in a grid of this width."""
    span = np.arange(-r, r + 1, dtype=np.intp)
    return np.asarray((span[:, None] * width + span[None, :]).reshape(1, -1), dtype=np.intp)


def point_cells(grid: LogOddsGrid, points_xy: npt.ArrayLike) -> npt.NDArray[np.intp]:
    """Flat cell index of each point; points outside the grid are clamped onto its rim (never touched)."""
    pts = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
    h, w = grid.shape
    c = np.floor((pts - (grid.origin_x_m, grid.origin_y_m)) * (1.0 / grid.resolution_m))
    ij = np.minimum(np.maximum(c, 0.0), (w - 1, h - 1)).astype(np.intp)
    return np.asarray(ij[:, 1] * w + ij[:, 0], dtype=np.intp)


def classify_endpoints(grid: LogOddsGrid, points_xy: npt.ArrayLike, config: GridConfig) -> BoolArray:
    """Paper 000, Sec. III: True for the end points that are dynamic measurements — in a transient cell,
    with no cell seen occupied before the pass within the transient neighbourhood.

    Call before integrating the scan. Points outside the grid fall on its rim, which no beam ever
    touched: never seen, so static.
    """
    idx = point_cells(grid, points_xy)
    out = transient_cells(grid, idx, config)
    where = np.flatnonzero(out)
    if where.size:  # transient cells lie r cells inside the grid (the rim): plain flat-index offsets
        nb = idx[where][:, None] + _offsets(grid.shape[1], config.transient_neighborhood_cells)
        out[where[grid.occupied_before_pass.reshape(-1)[nb].any(axis=1)]] = False
    return out


def completes_lines(grid: LogOddsGrid, points_xy: npt.ArrayLike, config: GridConfig) -> BoolArray:
    """Whether each end point may complete a line of dynamic points (doors.extract_leaves' ``support``): its
    cell was not seen occupied before the pass, and was seen free (free space that the neighbourhood rule kept
    static) or, after the first pass, never seen before the pass (log-odds 0 when it began) — never a wall or a
    leaf state known before the pass. The second kind: a leaf whose near part stands where no beam reached before
    (twin doors 0.3 m apart, the second seen through the first doorway only) had that part integrated as static
    and its dynamic rest alone was too short for a leaf. In the first pass every cell was unseen before it."""
    idx = point_cells(grid, points_xy)
    out = seen_free(grid, idx, config)
    if len(grid.pass_starts) > 1:
        out |= grid.pass_start_log_odds.reshape(-1)[idx] == 0.0
    out &= ~grid.occupied_before_pass.reshape(-1)[idx]
    return out


class ScanClasses(NamedTuple):
    """What :func:`classify_scan` says of a scan's end points."""

    dynamic: BoolArray
    support: BoolArray
    n_dynamic: int
    n_support: int  # support points that are not dynamic, near the dynamic ones
    dynamic_span_m: float  # diagonal of the dynamic points' bounding box


def classify_scan(grid: LogOddsGrid, points_xy: npt.ArrayLike, config: GridConfig, reach_m: float = 0.0
                  ) -> ScanClasses:
    """Each end point's class before the scan is integrated: dynamic (:func:`classify_endpoints`) and
    support (:func:`completes_lines`), in one compiled pass
    (:func:`doorbatch.pipeline.gridmap.kernels.classify_kernel`; :func:`classify_scan_numpy` is its
    reference). ``n_support`` counts the non-dynamic support points within ``reach_m`` of the dynamic
    points' bounding box (the only ones that can complete their lines)."""
    pts = np.ascontiguousarray(points_xy, dtype=np.float64).reshape(-1, 2)
    dynamic = np.empty(pts.shape[0], dtype=bool)
    support = np.empty(pts.shape[0], dtype=bool)
    n_dyn, n_sup, span2 = classify_kernel(grid.log_odds, grid.free_latch, grid.transient, grid.occupied_before_pass,
                                          grid.pass_start_log_odds, len(grid.pass_starts) > 1,
                                          grid.origin_x_m, grid.origin_y_m,
                                          1.0 / grid.resolution_m, pts, config.transient_neighborhood_cells,
                                          float(levels(config)[4]), reach_m, dynamic, support)
    return ScanClasses(dynamic, support, int(n_dyn), int(n_sup), math.sqrt(span2))


def classify_and_integrate(grid: LogOddsGrid, origin_xy: npt.ArrayLike, points_xy: npt.ArrayLike,
                           no_return_dirs: npt.ArrayLike, config: GridConfig, reach_m: float = 0.0,
                           range_max_m: float = math.inf) -> tuple[LogOddsGrid, ScanClasses]:
    """:func:`classify_scan`, then :func:`~doorbatch.pipeline.gridmap.occupancy.integrate_scan` without the
    dynamic end points, in one compiled call (the mapper's per-scan step; ``range_max_m``: the scan's stated
    maximum range, as ``integrate_scan`` takes it). Returns the grid (a new object when it grew) and the
    classes. Classifying in the grown grid is the same: points outside the old grid
    fall on its never-touched rim, and in the grown grid on never-touched cells; static either way."""
    prep = prepare_scan(grid, origin_xy, points_xy, no_return_dirs, config, range_max_m)
    if prep is None:
        grid.scan_count += 1
        empty = np.zeros(0, dtype=bool)
        return grid, ScanClasses(empty, empty, 0, 0, 0.0)
    grid = prep.grid
    n = prep.points.shape[0]
    dynamic = np.empty(n, dtype=bool)
    support = np.empty(n, dtype=bool)
    n_dyn, n_sup, span2 = classify_integrate_kernel(
        grid.log_odds, grid.hits, grid.hit_sum, grid.free_latch, grid.seen_occupied, grid.last_hit_scan, grid.stamp,
        grid.transient, grid.occupied_before_pass, grid.pass_start_log_odds, len(grid.pass_starts) > 1, grid.origin_x_m,
        grid.origin_y_m, grid.resolution_m, prep.ox, prep.oy, prep.points, prep.dirs, prep.clear, config.surface_band_m,
        prep.cut, config.max_range_m, grid.scan_count, levels(config), config.transient_neighborhood_cells, reach_m,
        dynamic, support)
    grid.scan_count += 1
    return grid, ScanClasses(dynamic, support, int(n_dyn), int(n_sup), math.sqrt(span2))


def classify_scan_numpy(grid: LogOddsGrid, points_xy: npt.ArrayLike, config: GridConfig
                        ) -> tuple[BoolArray, BoolArray]:
    """:func:`classify_scan` in NumPy alone (the reference of the compiled kernel)."""
    support = completes_lines(grid, points_xy, config)
    return classify_endpoints(grid, points_xy, config), support


def begin_pass(grid: LogOddsGrid, config: GridConfig) -> None:
    """Record the state at the start of a pass: its first scan number, the log-odds and the seen-occupied
    cells."""
    grid.pass_starts.append(grid.scan_count)
    np.copyto(grid.pass_start_log_odds, grid.log_odds)
    np.copyto(grid.occupied_before_pass, grid.seen_occupied)


def update_transient(grid: LogOddsGrid, config: GridConfig) -> None:
    """Evaluate the transient flag of every cell now (the lazy flag of :func:`transient_cells`, everywhere).

    Cells below the threshold now whose (2r+1)² neighbourhood was seen free (an erosion; outside the grid
    counts as unknown), added to the flags already set.
    """
    r = config.transient_neighborhood_cells
    free = seen_free_grid(grid, config)
    if r > 0:  # a square erosion: a separable minimum filter, outside the grid = not seen free
        free = ndimage.minimum_filter(free.view(np.uint8), size=2 * r + 1, mode="constant", cval=0).view(bool)
    grid.transient |= free & (grid.log_odds < np.float32(config.l_low))


def take_fallen_cells(grid: LogOddsGrid, config: GridConfig, since_scan: int = 0) -> IntArray:
    """Flat indices of the cells that were seen occupied when the pass began (:func:`begin_pass`), got no
    hit since scan ``since_scan`` (the start of the pass), and are low now: below ``p_transient_below``, or
    brought below it by this pass's evidence alone. Their seen-occupied flag is cleared (each rise and
    fall counts once)."""
    low = np.float32(config.l_low)
    idx = np.flatnonzero(grid.occupied_before_pass)  # a few per cent of the cells
    idx = idx[grid.seen_occupied.reshape(-1)[idx] & (grid.last_hit_scan.reshape(-1)[idx] < since_scan)]
    now = grid.log_odds.reshape(-1)[idx]
    fallen = idx[(now < low) | (now - grid.pass_start_log_odds.reshape(-1)[idx] <= low)]
    grid.seen_occupied.reshape(-1)[fallen] = False
    return fallen.astype(np.int64)


def take_fallen_points(grid: LogOddsGrid, config: GridConfig, since_scan: int = 0) -> FloatArray:
    """Paper 000, Sec. III, second set of dynamic points: the cell means (mean end point of the hits in
    the cell) of the seen-occupied cells that fell low, as :func:`take_fallen_cells`. (K, 2) world points."""
    return grid.cell_means(take_fallen_cells(grid, config, since_scan))
