"""Coarse correlative scan matching after Olson, "Real-time correlative scan matching", ICRA 2009.

The reference points are rasterized into a likelihood grid L(c) = exp(−d(c)² / 2σ²), d the distance from
cell c to the nearest occupied cell (the Euclidean distance transform, truncated at 3σ and computed by
splatting the Gaussian kernel around occupied cells). A candidate pose
(x, y, θ) scores the mean of L over the cells its scan points fall in,

    s(x, y, θ) = (1/N) Σ_i L(cell(R(θ) p_i + (x, y))),

and the search is exhaustive over a window around the prior: yaw in steps of ``step_deg``, x and y in
steps of one cell, so that for one yaw every translation is an integer shift of the points' cell
indices. Olson's two-level multi-resolution search makes that exhaustive search cheap: a coarse cell of
r × r fine shifts is bounded by U = (1/N) Σ_i B(cell_i + coarse shift), B(c) = max of L over the r × r
block at c (a sliding-window maximum), so U ≥ s for every fine shift inside. Coarse candidates are
expanded best bound first; the search stops when the best fine score is at least every remaining bound,
which returns the same optimum as the full fine search (the prior itself wins ties, so a scan that
carries no information, e.g. one straight wall, stays at the prior).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.rotations import wrap_angle

FloatArray = npt.NDArray[np.float64]
Float32Array = npt.NDArray[np.float32]
IntArray = npt.NDArray[np.int64]

Window = tuple[tuple[float, float], float]  # correlative half-widths: (x, y) in m, yaw in deg


def sigma_window(covariance: npt.ArrayLike, sigmas: float, min_m: float, max_m: float, min_deg: float,
                 max_deg: float) -> Window:
    """Correlative half-widths ((x, y) in m, yaw in deg): ``sigmas`` standard deviations of a pose covariance per
    axis, clipped to [min, max]."""
    std = np.sqrt(np.maximum(np.diag(np.asarray(covariance, dtype=np.float64)), 0.0)) * sigmas
    wx, wy = np.clip(std[:2], min_m, max_m)
    wyaw = min(max(math.degrees(float(std[2])), min_deg), max_deg)
    return (float(wx), float(wy)), wyaw


def lattice_steps_apart(a: npt.ArrayLike, b: npt.ArrayLike, resolution_m: float, step_deg: float) -> float:
    """How many search-lattice steps (cells, yaw steps) two poses differ by on the worst axis."""
    pa, pb = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    cells = float(np.max(np.abs(pa[:2] - pb[:2]))) / resolution_m
    steps = abs(float(wrap_angle(pa[2] - pb[2]))) / math.radians(step_deg)
    return max(cells, steps)


def thinned(points: FloatArray, max_points: int) -> FloatArray:
    """Every k-th point, k the smallest stride that leaves at most ``max_points`` (the search's scan)."""
    return points[:: -(-points.shape[0] // max_points)] if points.shape[0] else points


# Coarse candidates expanded at once (a small batch keeps the loop in NumPy without much wasted work).
EXPAND_BATCH = 4


@dataclass(frozen=True, slots=True, eq=False)
class LikelihoodGrid:
    """Gaussian-blurred occupancy of reference points and its r × r block maximum, zero-padded.

    Padded cell (i, j) covers x ∈ [x0 + j·res, x0 + (j+1)·res), y ∈ [y0 + i·res, y0 + (i+1)·res) (row i
    along y, as in :mod:`doorbatch.maps`). The grid proper starts ``pad_cells`` cells in from the corner
    (x0, y0); the zero padding lets every shift of the search window index the arrays without clipping.
    ``bound[i, j] = max values[i : i + r, j : j + r]``.
    """

    values: Float32Array  # (H, W) including the padding
    bound: Float32Array  # (H, W)
    origin_xy: FloatArray  # (2,) world position of the outer corner of padded cell (0, 0)
    resolution_m: float
    coarse_cells: int
    max_shift_cells: int  # largest window half-width (cells) the padding allows
    pad_cells: int

    @property
    def inner_shape(self) -> tuple[int, int]:
        """(rows, columns) of the grid without its padding."""
        h, w = self.values.shape
        return h - 2 * self.pad_cells, w - 2 * self.pad_cells


@dataclass(frozen=True, slots=True)
class CorrelativeResult:
    """Best pose of the exhaustive search and its score (mean likelihood in [0, 1])."""

    pose: FloatArray
    score: float


def _block_max(values: Float32Array, r: int) -> Float32Array:
    """B[i, j] = max values[i : i + r, j : j + r] (zero beyond the array), as r − 1 shifted maxima per axis."""
    h, w = values.shape
    padded = np.pad(values, ((0, r - 1), (0, r - 1)))
    rows = padded[:h].copy()
    for k in range(1, r):
        np.maximum(rows, padded[k : k + h], out=rows)
    out = rows[:, :w].copy()
    for k in range(1, r):
        np.maximum(out, rows[:, k : k + w], out=out)
    return out


def _gaussian_kernel(sigma_cells: float) -> tuple[IntArray, IntArray, Float32Array]:
    """Offsets (di, dj) within 3σ and their weights exp(−(di² + dj²)/2σ²) (σ in cells)."""
    radius = max(math.ceil(3.0 * sigma_cells), 0)
    di, dj = np.mgrid[-radius : radius + 1, -radius : radius + 1]
    d2 = (di * di + dj * dj).ravel()
    keep = d2 <= (3.0 * sigma_cells) ** 2 + 1e-9
    weights = np.exp(-0.5 * d2[keep] / max(sigma_cells, 1e-9) ** 2).astype(np.float32)
    return di.ravel()[keep].astype(np.int64), dj.ravel()[keep].astype(np.int64), weights


def build_likelihood_grid(
    points: npt.ArrayLike, *, resolution_m: float = 0.05, sigma_m: float = 0.05, window_m: float = 0.5,
    coarse_cells: int = 4,
) -> LikelihoodGrid:
    """Rasterize reference points (map frame) into L = exp(−d²/2σ²) for searches up to ±``window_m``.

    d is the distance from a cell to the nearest occupied cell (what ``distance_transform_edt`` gives),
    truncated at 3σ; L is computed by splatting the Gaussian kernel around the occupied cells with a
    running maximum, which costs O(occupied cells · kernel) instead of O(grid). The grid covers the
    points' bounding box plus √2·window + 3σ (a point outside it stays farther than 3σ from every
    reference point under any shift of the window), and is zero-padded for the shifts.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    n_max = math.ceil(window_m / resolution_m - 1e-9)
    pad = 2 * (n_max + coarse_cells) + 1
    empty = pts.shape[0] == 0
    if empty:
        pts = np.zeros((1, 2))
    margin = math.sqrt(2.0) * window_m + 3.0 * sigma_m
    origin = pts.min(axis=0) - margin - pad * resolution_m
    cells = np.floor((pts - origin) / resolution_m).astype(np.int64)
    width = int(np.floor((pts[:, 0].max() + margin - origin[0]) / resolution_m)) + 1 + pad
    height = int(np.floor((pts[:, 1].max() + margin - origin[1]) / resolution_m)) + 1 + pad
    values = np.zeros(height * width, dtype=np.float32)
    if not empty:
        occupied = np.unique(cells[:, 1] * width + cells[:, 0])
        di, dj, weights = _gaussian_kernel(sigma_m / resolution_m)
        index = occupied[:, None] + (di * width + dj)[None, :]
        np.maximum.at(values, index.ravel(), np.broadcast_to(weights, index.shape).ravel())
    grid = values.reshape(height, width)
    return LikelihoodGrid(grid, _block_max(grid, coarse_cells), origin, resolution_m, coarse_cells, n_max, pad)


def _flat_cells(grid: LikelihoodGrid, scan: FloatArray, xy: FloatArray, yaws: FloatArray) -> IntArray:
    """(Y, N) flat padded-cell index of every scan point under each yaw at translation ``xy``.

    Points outside the grid proper go to a "sink" cell in the padding whose whole search neighbourhood is
    zero, so they count as misses for every shift.
    """
    c, s = np.cos(yaws)[:, None], np.sin(yaws)[:, None]
    x, y = scan[:, 0], scan[:, 1]
    inv_res = 1.0 / grid.resolution_m
    col = np.floor((c * x - s * y + (xy[0] - grid.origin_xy[0])) * inv_res).astype(np.int64)
    row = np.floor((s * x + c * y + (xy[1] - grid.origin_xy[1])) * inv_res).astype(np.int64)
    rows, cols = grid.inner_shape
    p = grid.pad_cells
    inside = (col >= p) & (col < p + cols) & (row >= p) & (row < p + rows)
    sink = (grid.max_shift_cells + grid.coarse_cells) * (grid.values.shape[1] + 1)
    out: IntArray = np.where(inside, row * grid.values.shape[1] + col, sink)
    return out


def _scores(table: Float32Array, cells: IntArray, dx: IntArray, dy: IntArray) -> FloatArray:
    """Mean of ``table`` over the points for every shift: cells (B, N) flat, dx/dy (B, K) → (B, K)."""
    offsets = dy * table.shape[1] + dx
    gathered = np.take(table, cells[:, None, :] + offsets[:, :, None])  # (B, K, N)
    out: FloatArray = gathered.sum(axis=-1).astype(np.float64) / cells.shape[1]
    return out


def _coarse_shifts(n: int, r: int) -> IntArray:
    """Lower corners c of the coarse blocks [c, c + r) that tile the fine shifts [−n, n]."""
    return np.arange(-n, n + 1, r, dtype=np.int64)


def _fine_offsets(corner_x: IntArray, corner_y: IntArray, nx: int, ny: int, r: int) -> tuple[IntArray, IntArray]:
    """All fine shifts inside each coarse block, clamped into [−nx, nx] × [−ny, ny] (duplicates are harmless)."""
    b = np.arange(r, dtype=np.int64)
    fx = np.minimum(corner_x[:, None, None] + b[None, None, :], nx)
    fy = np.minimum(corner_y[:, None, None] + b[None, :, None], ny)
    fx, fy = np.broadcast_arrays(fx, fy)
    return fx.reshape(len(corner_x), -1), fy.reshape(len(corner_y), -1)


def correlative_match(
    grid: LikelihoodGrid, scan_xy: npt.ArrayLike, prior: npt.ArrayLike, *, window_m: float | tuple[float, float] = 0.5,
    window_deg: float = 15.0, step_deg: float = 1.0, exclude: Exclusion | None = None,
) -> CorrelativeResult:
    """Exhaustive search of (x, y, yaw) within ±window around ``prior`` for the best-scoring scan pose.

    Args:
        grid: Likelihood grid of the reference (:func:`build_likelihood_grid`).
        scan_xy: (N, 2) scan points in the sensor (base) frame.
        prior: (3,) prior pose x, y, yaw in the grid's frame.
        window_m: Half-width of the translation window (m), one for both axes or (x, y) of the grid's
            frame; the x/y step is the grid resolution.
        window_deg: Half-width of the yaw window (deg).
        step_deg: Yaw step (deg).
        exclude: When given, the best pose outside this box of the lattice (the runner-up to an optimum: how
            unique its basin is); the prior no longer wins ties, and the score is −1 when the box covers all.

    Returns:
        The best pose on the search lattice and its score (mean likelihood; 0 without points).

    Raises:
        ValueError: ``window_m`` exceeds the window the grid was built for.
    """
    scan = np.asarray(scan_xy, dtype=np.float64).reshape(-1, 2)
    prior_arr = np.asarray(prior, dtype=np.float64)
    wx, wy = (window_m, window_m) if isinstance(window_m, float | int) else window_m
    nx, ny, r = round(wx / grid.resolution_m), round(wy / grid.resolution_m), grid.coarse_cells
    if max(nx, ny) > grid.max_shift_cells:
        raise ValueError(f"window_m={window_m} exceeds the grid's {grid.max_shift_cells * grid.resolution_m} m")
    if scan.shape[0] == 0:
        return CorrelativeResult(prior_arr.copy(), 0.0)
    n_yaw = math.floor(window_deg / step_deg + 1e-9)
    yaws = prior_arr[2] + np.deg2rad(step_deg) * np.arange(-n_yaw, n_yaw + 1)
    cells = _flat_cells(grid, scan, prior_arr[:2], yaws)
    cx, cy = (a.ravel() for a in np.meshgrid(_coarse_shifts(nx, r), _coarse_shifts(ny, r)))
    bounds = _scores(grid.bound, cells, np.broadcast_to(cx, (len(yaws), cx.size)),
                     np.broadcast_to(cy, (len(yaws), cy.size))).ravel()
    box = None if exclude is None else _excluded_box(exclude, prior_arr, grid.resolution_m, step_deg)
    yaw_i, sx, sy, score = _expand(grid, cells, bounds, cx, cy, nx, ny, box)
    pose = np.array([prior_arr[0] + sx * grid.resolution_m, prior_arr[1] + sy * grid.resolution_m, yaws[yaw_i]])
    return CorrelativeResult(pose, score)


@dataclass(frozen=True, slots=True)
class Exclusion:
    """A box of the search lattice left out: |Δx|, |Δy| ≤ radius_m and |Δyaw| ≤ radius_deg around ``pose``."""

    pose: FloatArray
    radius_m: float
    radius_deg: float


def _excluded_box(exclude: Exclusion, prior: FloatArray, resolution_m: float, step_deg: float
                  ) -> tuple[IntArray, IntArray]:
    """(centre, half-width) of the excluded box in lattice units (yaw index offset from the window's centre,
    x shift, y shift)."""
    d = exclude.pose - prior
    centre = np.array([round(math.degrees(float(wrap_angle(d[2]))) / step_deg), round(d[0] / resolution_m),
                       round(d[1] / resolution_m)], dtype=np.int64)
    half = np.array([math.floor(exclude.radius_deg / step_deg + 1e-9), math.floor(exclude.radius_m / resolution_m
                                                                                   + 1e-9)], dtype=np.int64)
    return centre, np.array([half[0], half[1], half[1]], dtype=np.int64)


def _expand(
    grid: LikelihoodGrid, cells: IntArray, bounds: FloatArray, cx: IntArray, cy: IntArray, nx: int, ny: int,
    box: tuple[IntArray, IntArray] | None = None,
) -> tuple[int, int, int, float]:
    """Best-bound-first expansion of coarse candidates into their fine shifts (branch and bound).

    Fine candidates inside ``box`` ((centre, half-width) in (yaw index from the centre, x, y) lattice units)
    score −1, so the search returns the best pose outside it.

    Returns:
        (yaw index, x shift, y shift, score) of the best fine candidate.
    """
    n_coarse = cx.size
    centre = cells.shape[0] // 2  # the prior's yaw
    # Ties go to the pose nearest the prior (no information along an axis: stay put, not at the window's edge).
    # Distance: squared lattice steps, cells and yaw steps alike; a block's is that of its shift nearest the prior.
    # Blocks of equal bound are expanded nearest first; once only blocks whose bound equals the best score are
    # left, only those that could hold a nearer pose of that score are expanded, and of equal scores the nearest
    # is kept: the optimum's score and, among its ties, the nearest pose, exactly.
    yaw_all, coarse_all = np.divmod(np.arange(bounds.size), n_coarse)
    r1 = grid.coarse_cells - 1
    gap_x = np.clip(0, cx[coarse_all], np.minimum(cx[coarse_all] + r1, nx))
    gap_y = np.clip(0, cy[coarse_all], np.minimum(cy[coarse_all] + r1, ny))
    block_near = gap_x**2 + gap_y**2 + (yaw_all - centre) ** 2
    order = np.lexsort((block_near, -bounds))
    zero = np.zeros((1, 1), dtype=np.int64)
    best: tuple[int, int, int, float] = (centre, 0, 0, float(_scores(grid.values, cells[centre : centre + 1],
                                                                      zero, zero)[0, 0]) if box is None else -1.0)
    best_near = 0 if box is None else np.iinfo(np.int64).max
    for start in range(0, order.size, EXPAND_BATCH):
        batch = order[start : start + EXPAND_BATCH]
        if bounds[batch[0]] < best[3] or (bounds[batch[0]] == best[3] and block_near[batch[0]] >= best_near):
            break
        batch = batch[(bounds[batch] > best[3]) | (block_near[batch] < best_near)]
        yaw_i, coarse_i = np.divmod(batch, n_coarse)
        fx, fy = _fine_offsets(cx[coarse_i], cy[coarse_i], nx, ny, grid.coarse_cells)
        scores = _scores(grid.values, cells[yaw_i], fx, fy)
        if box is not None:
            inside = ((np.abs(yaw_i - centre - box[0][0]) <= box[1][0])[:, None]
                      & (np.abs(fx - box[0][1]) <= box[1][1]) & (np.abs(fy - box[0][2]) <= box[1][2]))
            scores[inside] = -1.0
        top = scores.max()
        dist = np.where(scores == top, fx**2 + fy**2 + ((yaw_i - centre) ** 2)[:, None], np.iinfo(np.int64).max)
        b, k = np.unravel_index(int(np.argmin(dist)), dist.shape)
        if top > best[3] or (top == best[3] and dist[b, k] < best_near):
            best = (int(yaw_i[b]), int(fx[b, k]), int(fy[b, k]), float(top))
            best_near = int(dist[b, k])
    return best
