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

Set 1 (dynamic measurements): scan end points that fall into transient cells; they are not integrated.
Set 2: seen-occupied cells whose probability has fallen below ``p_transient_below`` — an object that
looked static (a door, a parked cart) has gone; the mean of the end points that fell into each such cell
joins the set, and the cell's seen-occupied flag is cleared so that a later rise and fall counts again.
Set 2 is collected once per pass (doors are stationary within a pass) and only from cells that got no
hit during the pass: cells on a wall's border flicker between hit and free within a pass and would
otherwise line every wall with false "vanished" points.
"""

from __future__ import annotations

import functools

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from doorbatch.config import GridConfig
from doorbatch.pipeline.gridmap.occupancy import LogOddsGrid

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


def classify_endpoints(grid: LogOddsGrid, points_xy: npt.ArrayLike, config: GridConfig) -> BoolArray:
    """Paper 000, Sec. III: True for the end points that fall into transient cells (dynamic measurements).

    Call before integrating the scan. Points outside the grid are clamped onto its rim, which no beam
    ever touched: never seen, so static.
    """
    pts = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
    h, w = grid.shape
    c = np.floor((pts - (grid.origin_x_m, grid.origin_y_m)) * (1.0 / grid.resolution_m))
    ij = np.minimum(np.maximum(c, 0.0), (w - 1, h - 1)).astype(np.intp)
    return transient_cells(grid, ij[:, 1] * w + ij[:, 0], config)


def update_transient(grid: LogOddsGrid, config: GridConfig) -> None:
    """Evaluate the transient flag of every cell now (the lazy flag of :func:`transient_cells`, everywhere).

    Cells below the threshold now whose (2r+1)² neighbourhood was seen free (an erosion; outside the grid
    counts as unknown), added to the flags already set.
    """
    r = config.transient_neighborhood_cells
    free = seen_free_grid(grid, config)
    if r > 0:
        free = ndimage.binary_erosion(free, structure=np.ones((2 * r + 1, 2 * r + 1), bool), border_value=0)
    grid.transient |= free & (grid.log_odds < np.float32(config.l_low))


def take_fallen_cells(grid: LogOddsGrid, config: GridConfig, since_scan: int = 0) -> IntArray:
    """Flat indices of seen-occupied cells whose probability is now below ``p_transient_below`` and that got
    no hit since scan ``since_scan`` (the start of the pass).

    Every seen-occupied cell that is low now has its flag cleared (each rise and fall counts once). A cell
    that still got hits in this pass is a border cell flickering between a wall and free space (a wall on
    a cell border, grazing beams), not an object that left; it is consumed without being returned.
    """
    low = grid.seen_occupied & (grid.log_odds < np.float32(config.l_low))
    fallen = np.flatnonzero(low)
    grid.seen_occupied.reshape(-1)[fallen] = False
    quiet = grid.last_hit_scan.reshape(-1)[fallen] < since_scan
    return fallen[quiet].astype(np.int64)


def take_fallen_points(grid: LogOddsGrid, config: GridConfig, since_scan: int = 0) -> FloatArray:
    """Paper 000, Sec. III, second set of dynamic points: the cell means (mean end point of the hits in
    the cell) of the seen-occupied cells that fell low, as :func:`take_fallen_cells`. (K, 2) world points."""
    return grid.cell_means(take_fallen_cells(grid, config, since_scan))
