"""Likelihood-field endpoint model (Probabilistic Robotics Sec. 6.4) exactly as Nav2 AMCL's ``likelihood_field``.

Reference: nav2_amcl ``src/sensors/laser/likelihood_field_model.cpp`` (``LikelihoodFieldModel::sensorFunction``),
``src/map/map_cspace.cpp`` (``map_update_cspace``), ``src/amcl_node.cpp`` (``updateFilter``, ``convertMap``),
ros-navigation/navigation2. What AMCL does, and what this module does the same way:

- Distance field: for every cell, the Euclidean distance (cell centre to cell centre, in m) to the nearest
  occupied cell, capped at ``laser_likelihood_max_dist``. AMCL grows it with a priority queue from the occupied
  cells; here ``scipy.ndimage.distance_transform_edt`` gives the same distances. Only occupied cells are
  sources; *unknown cells get their distance like free ones* (AMCL does not penalize them). An end point
  off the map counts as the maximum distance. AMCL takes a cell as occupied when its value is exactly 100
  (``convertMap``); on map_server's trinary maps (0 / 100 / −1) that equals the map_server threshold used
  here (value ≥ 65, ``occupied_thresh`` 0.65), which also classifies maps with intermediate values.
- Beams (``updateFilter`` and ``sensorFunction``): range_max = min(scan range_max, ``laser_max_range``) when
  ``laser_max_range`` > 0; range_min = max(scan range_min, ``laser_min_range``) when > 0; a reading
  ≤ range_min is set to range_max. Beams are taken every ``step = (n − 1) // (max_beams − 1)`` (at least 1)
  from index 0 — so up to max_beams + a few beams — and among them readings ≥ range_max and NaN are skipped.
- Per beam: pz = z_hit · exp(−z² / (2 σ_hit²)) + z_rand / range_max, with z the field's distance at the end
  point. The Gaussian is *not* normalized (AMCL's own comment: "this should have a normalization of
  1/(sqrt(2pi)*sigma)"), so pz ≤ 1.
- Combination: **not** the product of the pz. AMCL computes p = 1 + Σ_beams pz³ ("an ad-hoc weighting
  scheme for combining beam probs; works well, though") and multiplies the particle's weight by p.
  :class:`BeamCombination` offers both: ``AMCL`` (log p = log(1 + Σ pz³), the default, so that comparisons
  with Nav2 are fair) and ``PRODUCT`` (Σ log pz, the book's and paper 000's eq. (5)).

Not copied from AMCL: its world → cell conversion ``MAP_GXWX`` rounds ``(x − origin) / res + 0.5`` and so
puts cell centres on the map's corner grid, half a cell off the OccupancyGrid convention; here the end point
falls in the cell that contains it (:meth:`doorbatch.maps.OccupancyMap.world_to_cell`). AMCL also ignores the
map origin's yaw; here it is honoured.

Hot path: :func:`endpoint_distances` moves all B beam end points of all N particles at once into the
grid's cell coordinates in float32 (particle poses are first expressed in the grid frame in float64, so the
float32 values stay small) and gathers the distances from a copy of the field padded by one cell of
maximum distance, so that clipping indices replaces the bounds test. It works on chunks of 1024 particles
in work arrays reused from chunk to chunk; :func:`field_log_likelihood` fuses the likelihood into the same
loop. NumPy alone reaches 35–50 M particle-beam evaluations per second on one core (bench/bench_mcl.py), so
there is no compiled kernel. A field built with a ``torch_device`` runs both functions, and
:func:`skipped_field_log_likelihood`, in torch instead (:mod:`.torch_field`: the same cells, for a GPU).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from enum import Enum

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from doorbatch.config import LocalizeConfig
from doorbatch.maps import OccupancyMap

FloatArray = npt.NDArray[np.float64]
Float32Array = npt.NDArray[np.float32]
IntArray = npt.NDArray[np.int64]
IntLikeArray = npt.NDArray[np.int32]

# map_server's thresholds in OccupancyGrid percent: occupied_thresh 0.65, free_thresh 0.196.
OCCUPIED_AT_LEAST = 65
FREE_AT_MOST = 19
# Particles per chunk in :func:`endpoint_distances`: (chunk × beams) float32 work arrays of ~0.25 MB.
CHUNK_PARTICLES = 1024


class BeamCombination(Enum):
    """How per-beam likelihoods pz combine into one particle weight."""

    AMCL = "amcl"  # p = 1 + Σ pz³ (nav2_amcl LikelihoodFieldModel::sensorFunction)
    PRODUCT = "product"  # p = Π pz (Probabilistic Robotics Table 6.3; paper 000 eq. 5)


@dataclass(frozen=True, eq=False)
class DistanceField:
    """Distance (m) from each cell of a map to the nearest occupied cell, capped at ``max_dist_m``.

    Attributes:
        dist: (H, W) float32, same indexing as :class:`~doorbatch.maps.OccupancyMap` (row 0 = lowest y).
        resolution_m, origin_x_m, origin_y_m, origin_yaw_rad: the map's geometry.
        max_dist_m: the cap (Nav2 ``laser_likelihood_max_dist``), also the distance of points off the map.
        torch_device: None: the lookups run in NumPy; a torch device ("cuda", "cpu"): :func:`endpoint_distances`
            and :func:`field_log_likelihood` run there (:mod:`.torch_field`, ``localize.backend: torch``).
        device_cache: the field's copies on torch devices, made on first use (:mod:`.torch_field`).
    """

    dist: Float32Array
    resolution_m: float
    origin_x_m: float
    origin_y_m: float
    origin_yaw_rad: float
    max_dist_m: float
    torch_device: str | None = None
    device_cache: dict[str, object] = field(init=False, repr=False, default_factory=dict)
    _padded: Float32Array = field(init=False, repr=False)

    def __post_init__(self) -> None:
        """Build the padded copy used by the lookups.

        Raises:
            ValueError: The grid has 2³¹ cells or more (lookups index it with int32).
        """
        if (self.dist.shape[0] + 2) * (self.dist.shape[1] + 2) >= 2**31:
            raise ValueError(f"grid of {self.dist.shape} cells is too large for int32 lookups")
        padded = np.full((self.dist.shape[0] + 2, self.dist.shape[1] + 2), self.max_dist_m, dtype=np.float32)
        padded[1:-1, 1:-1] = self.dist
        object.__setattr__(self, "_padded", padded)

    @property
    def height(self) -> int:
        """Rows (cells along y)."""
        return int(self.dist.shape[0])

    @property
    def width(self) -> int:
        """Columns (cells along x)."""
        return int(self.dist.shape[1])

    @property
    def padded(self) -> Float32Array:
        """(H + 2, W + 2) copy of ``dist`` with a one-cell border at ``max_dist_m`` (off-map lookups)."""
        return self._padded

    def to_grid(self, pose: npt.ArrayLike) -> FloatArray:
        """Poses (..., 3) in the map frame → (column, row, yaw) in the grid frame, in cell units (float64).

        The cell holding a point is (floor(row), floor(column)).
        """
        p = np.asarray(pose, dtype=np.float64)
        c, s = math.cos(self.origin_yaw_rad), math.sin(self.origin_yaw_rad)
        dx = p[..., 0] - self.origin_x_m
        dy = p[..., 1] - self.origin_y_m
        inv = 1.0 / self.resolution_m
        with np.errstate(invalid="ignore"):  # infinite points become NaN: off the map in the lookups
            return np.stack([(c * dx + s * dy) * inv, (-s * dx + c * dy) * inv, p[..., 2] - self.origin_yaw_rad],
                            axis=-1)


@dataclass(frozen=True)
class FreeCells:
    """Centres (F, 2) of the free cells of a map (map frame), for uniform pose sampling over free space."""

    centers: FloatArray
    grid: OccupancyMap  # the map
    free_mask: npt.NDArray[np.bool_]  # (H, W) which of its cells are free

    @property
    def resolution_m(self) -> float:
        return self.grid.resolution_m

    @property
    def origin_yaw_rad(self) -> float:
        return self.grid.origin_yaw_rad

    def __len__(self) -> int:
        return int(self.centers.shape[0])

    def holds(self, xy_m: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """Whether each position (N, 2) lies in a free cell (outside the map: no)."""
        xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
        ij = self.grid.world_to_cell(xy)
        inside = self.grid.contains(ij)
        out = np.zeros(xy.shape[0], dtype=bool)
        out[inside] = self.free_mask[ij[inside, 0], ij[inside, 1]]
        return out

    def sample_poses(self, n: int, rng: np.random.Generator) -> FloatArray:
        """n poses uniform over the free cells (uniform inside the chosen cell) with yaw uniform in [−π, π).

        AMCL's ``uniformPoseGenerator`` picks a free cell uniformly and uses its centre; the jitter inside
        the cell only makes the distribution continuous.

        Raises:
            ValueError: The map has no free cell.
        """
        if len(self) == 0:
            raise ValueError("the map has no free cell to sample poses from")
        idx = rng.integers(0, len(self), size=n)
        u = (rng.random((n, 2)) - 0.5) * self.resolution_m
        c, s = math.cos(self.origin_yaw_rad), math.sin(self.origin_yaw_rad)
        out = np.empty((n, 3))
        out[:, 0] = self.centers[idx, 0] + c * u[:, 0] - s * u[:, 1]
        out[:, 1] = self.centers[idx, 1] + s * u[:, 0] + c * u[:, 1]
        out[:, 2] = rng.uniform(-np.pi, np.pi, size=n)
        return out


@dataclass(frozen=True)
class BeamSet:
    """The beams of one scan that the endpoint model uses.

    Attributes:
        points_base: (B, 2) float32 beam end points in base_link.
        origin_base: (2,) laser origin in base_link (for models that need the rays, e.g. door association).
        range_max_m: the model's range_max (z_rand / range_max).
        beam_index: (B,) index of each beam in the scan.
    """

    points_base: Float32Array
    origin_base: FloatArray
    range_max_m: float
    beam_index: IntArray

    def __len__(self) -> int:
        return int(self.points_base.shape[0])


def build_distance_field(occupancy_map: OccupancyMap, max_dist_m: float, unknown_as_max: bool = False,
                         occupied_at_least: int = OCCUPIED_AT_LEAST, torch_device: str | None = None
                         ) -> DistanceField:
    """The likelihood field of a map: distance to the nearest occupied cell (value ≥ ``occupied_at_least``).

    Args:
        occupancy_map: any map_server map.
        max_dist_m: cap (Nav2 ``laser_likelihood_max_dist``).
        unknown_as_max: give unknown cells (−1) the maximum distance instead of their distance to the
            nearest occupied cell. AMCL does not (False).
        occupied_at_least: occupancy (percent) from which a cell is an obstacle.
        torch_device: run the lookups on this torch device (:class:`DistanceField`); None: NumPy.

    Raises:
        ValueError: ``max_dist_m`` is not positive.
    """
    if not max_dist_m > 0.0:
        raise ValueError(f"max_dist_m must be positive, got {max_dist_m}")
    occ = occupancy_map.occupancy
    occupied = occ >= occupied_at_least
    if occupied.any():
        cells = ndimage.distance_transform_edt(~occupied)
        dist = np.minimum(np.asarray(cells, dtype=np.float64) * occupancy_map.resolution_m, max_dist_m)
    else:
        dist = np.full(occ.shape, max_dist_m)
    if unknown_as_max:
        dist[occ < 0] = max_dist_m
    return DistanceField(dist.astype(np.float32), occupancy_map.resolution_m, occupancy_map.origin_x_m,
                         occupancy_map.origin_y_m, occupancy_map.origin_yaw_rad, float(max_dist_m), torch_device)


def free_cells(occupancy_map: OccupancyMap, free_at_most: int = FREE_AT_MOST) -> FreeCells:
    """The free cells (0 ≤ value ≤ ``free_at_most``; AMCL: value 0, the same on trinary maps)."""
    occ = occupancy_map.occupancy
    mask = (occ >= 0) & (occ <= free_at_most)
    ij = np.argwhere(mask)
    return FreeCells(occupancy_map.cell_to_world(ij).reshape(-1, 2), occupancy_map, mask)


class _Scratch:
    """Chunk-sized work arrays reused across the chunks of one call.

    Fresh arrays of a few hundred kB are handed back to the OS by malloc when freed and page-faulted in again
    on the next chunk, which costs more than the arithmetic (measured 2–4×, as in ``doorbatch.sim.raycast``).
    """

    def __init__(self, rows: int, beams: int) -> None:
        self.c = np.empty((rows, 1), dtype=np.float32)
        self.s = np.empty((rows, 1), dtype=np.float32)
        self.gx = np.empty((rows, 1), dtype=np.float32)
        self.gy = np.empty((rows, 1), dtype=np.float32)
        self.col = np.empty((rows, beams), dtype=np.float32)
        self.row = np.empty((rows, beams), dtype=np.float32)
        self.tmp = np.empty((rows, beams), dtype=np.float32)
        self.j = np.empty((rows, beams), dtype=np.int32)
        self.flat = np.empty((rows, beams), dtype=np.int32)


def _gather(dist_field: DistanceField, col: Float32Array, row: Float32Array, j: IntLikeArray, flat: IntLikeArray,
            out: Float32Array) -> None:
    """Distances at grid coordinates (cell units) into ``out``, clobbering ``col``, ``row``, ``j``, ``flat``.

    Off the grid (and NaN) → max distance, through the padded copy of the field.
    """
    col += 1.0  # padded grid: cell (i, j) is padded (i + 1, j + 1)
    row += 1.0
    np.fmax(col, 0.0, out=col)  # fmax/fmin, unlike clip, also send NaN to the border
    np.fmin(col, np.float32(dist_field.width + 1), out=col)
    np.fmax(row, 0.0, out=row)
    np.fmin(row, np.float32(dist_field.height + 1), out=row)
    j[...] = col  # truncation = floor for values ≥ 0
    flat[...] = row
    flat *= dist_field.width + 2
    flat += j
    np.take(dist_field.padded.ravel(), flat, out=out)


def lookup(dist_field: DistanceField, xy: npt.ArrayLike) -> Float32Array:
    """Field distance at world points (..., 2): the cell containing each point; off the map → max_dist_m."""
    p = np.asarray(xy, dtype=np.float64)
    g = dist_field.to_grid(np.concatenate([p, np.zeros((*p.shape[:-1], 1))], axis=-1))
    col, row = g[..., 0].astype(np.float32), g[..., 1].astype(np.float32)
    out = np.empty(col.shape, dtype=np.float32)
    _gather(dist_field, col, row, np.empty(col.shape, np.int32), np.empty(col.shape, np.int32), out)
    return out


def _chunk_distances(dist_field: DistanceField, grid_pose: FloatArray, points_cells: Float32Array,
                     scratch: _Scratch, out: Float32Array) -> None:
    """(n, B) distances into ``out`` for particles in grid units (n, 3) and end points in cell units (B, 2)."""
    n = grid_pose.shape[0]
    c, s, gx, gy = scratch.c[:n], scratch.s[:n], scratch.gx[:n], scratch.gy[:n]
    col, row, tmp = scratch.col[:n], scratch.row[:n], scratch.tmp[:n]
    np.cos(grid_pose[:, 2:3], out=c, casting="same_kind")
    np.sin(grid_pose[:, 2:3], out=s, casting="same_kind")
    gx[...] = grid_pose[:, 0:1]
    gy[...] = grid_pose[:, 1:2]
    bx, by = points_cells[None, :, 0], points_cells[None, :, 1]
    np.multiply(c, bx, out=col)  # col = x + cos·bx − sin·by
    np.multiply(s, by, out=tmp)
    col -= tmp
    col += gx
    np.multiply(s, bx, out=row)  # row = y + sin·bx + cos·by
    np.multiply(c, by, out=tmp)
    row += tmp
    row += gy
    _gather(dist_field, col, row, scratch.j[:n], scratch.flat[:n], out)


def _chunks(dist_field: DistanceField, pose: npt.ArrayLike, points_base: npt.ArrayLike, chunk: int
            ) -> Iterator[tuple[slice, FloatArray, Float32Array, _Scratch]]:
    """(particle slice, particles in grid units, end points in cell units, scratch) per chunk of particles."""
    grid = dist_field.to_grid(np.asarray(pose, dtype=np.float64).reshape(-1, 3))
    pts = (np.asarray(points_base, dtype=np.float64).reshape(-1, 2) / dist_field.resolution_m).astype(np.float32)
    scratch = _Scratch(min(chunk, grid.shape[0]), pts.shape[0])
    for start in range(0, grid.shape[0], chunk):
        part = slice(start, min(start + chunk, grid.shape[0]))
        yield part, grid[part], pts, scratch


def endpoint_distances(dist_field: DistanceField, pose: npt.ArrayLike, points_base: npt.ArrayLike,
                       chunk: int = CHUNK_PARTICLES) -> Float32Array:
    """Field distance at every beam end point of every particle.

    Args:
        dist_field: the likelihood field.
        pose: (N, 3) particle poses (map frame).
        points_base: (B, 2) beam end points in base_link.
        chunk: particles per vectorized block (memory / cache trade-off; results do not depend on it).

    Returns:
        (N, B) float32 distances in m (max_dist_m off the map).
    """
    if dist_field.torch_device is not None:
        from doorbatch.pipeline.localize import torch_field

        return torch_field.endpoint_distances(dist_field, pose, points_base)
    n, b = np.asarray(pose).reshape(-1, 3).shape[0], np.asarray(points_base).reshape(-1, 2).shape[0]
    out = np.empty((n, b), dtype=np.float32)
    for part, grid, pts, scratch in _chunks(dist_field, pose, points_base, chunk):
        _chunk_distances(dist_field, grid, pts, scratch, out[part])
    return out


def field_log_likelihood(dist_field: DistanceField, pose: npt.ArrayLike, points_base: npt.ArrayLike, z_hit: float,
                         z_rand: float, sigma_hit: float, max_range: float,
                         combination: BeamCombination = BeamCombination.AMCL, chunk: int = CHUNK_PARTICLES
                         ) -> FloatArray:
    """log p(z | x) (N,) of each particle pose: :func:`endpoint_distances` then :func:`endpoint_log_likelihood`,
    fused per chunk of particles (no (N, B) array)."""
    if dist_field.torch_device is not None:
        from doorbatch.pipeline.localize import torch_field

        return torch_field.field_log_likelihood(dist_field, pose, points_base, z_hit, z_rand, sigma_hit, max_range,
                                                combination)
    n, b = np.asarray(pose).reshape(-1, 3).shape[0], np.asarray(points_base).reshape(-1, 2).shape[0]
    out = np.zeros(n)
    if b == 0:
        return out
    dist = np.empty((min(chunk, n), b), dtype=np.float32)
    for part, grid, pts, scratch in _chunks(dist_field, pose, points_base, chunk):
        d = dist[:grid.shape[0]]
        _chunk_distances(dist_field, grid, pts, scratch, d)
        beam_likelihood(d, z_hit, z_rand, sigma_hit, max_range, out=d)
        out[part] = combine_beams(d, combination, scratch=scratch.tmp[:grid.shape[0]])
    return out


def endpoint_points(pose: npt.ArrayLike, points_base: npt.ArrayLike) -> FloatArray:
    """Beam end points (N, B, 2) in the map frame for every particle pose (N, 3) and base_link point (B, 2).

    For models that need the points themselves (the RBPF's door distances); the static field's distances
    of the same points are :func:`endpoint_distances` (faster) or :func:`lookup` of these.
    """
    p = np.asarray(pose, dtype=np.float64).reshape(-1, 3)
    b = np.asarray(points_base, dtype=np.float64).reshape(-1, 2)
    c, s = np.cos(p[:, 2:3]), np.sin(p[:, 2:3])
    out = np.empty((p.shape[0], b.shape[0], 2))
    out[..., 0] = p[:, 0:1] + c * b[None, :, 0] - s * b[None, :, 1]
    out[..., 1] = p[:, 1:2] + s * b[None, :, 0] + c * b[None, :, 1]
    return out


def beam_likelihood(dist: npt.ArrayLike, z_hit: float, z_rand: float, sigma_hit: float, max_range: float,
                    out: Float32Array | None = None) -> Float32Array:
    """Per-beam pz = z_hit · exp(−d² / (2σ²)) + z_rand / max_range (AMCL's unnormalized Gaussian), float32.

    ``out`` (float32, the shape of ``dist``; may be ``dist`` itself) receives the result.
    """
    d = np.asarray(dist, dtype=np.float32)
    pz = np.multiply(d, d, out=out)
    pz *= np.float32(-0.5 / (sigma_hit * sigma_hit))
    np.exp(pz, out=pz)
    pz *= np.float32(z_hit)
    pz += np.float32(z_rand / max_range)
    return pz


def combine_beams(pz: npt.ArrayLike, combination: BeamCombination = BeamCombination.AMCL,
                  scratch: Float32Array | None = None) -> FloatArray:
    """Log-likelihood per particle (N,) from per-beam likelihoods (N, B).

    ``AMCL``: log(1 + Σ_b pz³); ``PRODUCT``: Σ_b log pz. With no beams both give 0. ``scratch``: an optional
    float32 work array of pz's shape.
    """
    p = np.asarray(pz, dtype=np.float32)
    if combination is BeamCombination.AMCL:
        cubed = np.multiply(p, p, out=scratch)
        cubed *= p
        out: FloatArray = np.log1p(cubed.sum(axis=-1, dtype=np.float64))
    else:
        out = np.log(p, out=scratch).sum(axis=-1, dtype=np.float64)
    return out


def endpoint_log_likelihood(dist: npt.ArrayLike, z_hit: float, z_rand: float, sigma_hit: float, max_range: float,
                            combination: BeamCombination = BeamCombination.AMCL) -> FloatArray:
    """Log-likelihood (N,) of each particle's scan from its beams' field distances (N, B) (module docstring)."""
    return combine_beams(beam_likelihood(dist, z_hit, z_rand, sigma_hit, max_range), combination)


def select_beams(ranges: npt.ArrayLike, angles: npt.ArrayLike, range_min: float, range_max: float,
                 laser_to_base: npt.ArrayLike, max_beams: int, laser_min_range: float = -1.0,
                 laser_max_range: float = -1.0, range_max_fallback_m: float = 30.0) -> BeamSet:
    """The beams AMCL's likelihood field model uses, as end points in base_link.

    Args:
        ranges: (n,) ranges of the scan (NaN, +inf allowed).
        angles: (n,) beam angles in the laser frame.
        range_min, range_max: the scan's limits.
        laser_to_base: 4×4 transform laser → base_link (an upside-down laser works).
        max_beams: Nav2 ``max_beams`` (≥ 2).
        laser_min_range, laser_max_range: Nav2 overrides; ≤ 0 keeps the scan's values.
        range_max_fallback_m: the model's range_max when the scan states none (range_max inf or NaN, and no
            ``laser_max_range``): z_rand / range_max would be 0 and one far end point would make every
            particle impossible under the product of the beams.

    Raises:
        ValueError: ``max_beams`` < 2 or ranges and angles differ in length.
    """
    r = np.asarray(ranges, dtype=np.float64).reshape(-1)
    a = np.asarray(angles, dtype=np.float64).reshape(-1)
    if r.shape != a.shape:
        raise ValueError(f"{r.shape[0]} ranges but {a.shape[0]} angles")
    if max_beams < 2:
        raise ValueError(f"max_beams must be at least 2, got {max_beams}")
    rmax = range_max if math.isfinite(range_max) else math.inf
    rmax = min(rmax, laser_max_range) if laser_max_range > 0.0 else rmax
    if not math.isfinite(rmax):
        rmax = range_max_fallback_m
    rmin = max(range_min, laser_min_range) if laser_min_range > 0.0 else range_min
    step = max((r.shape[0] - 1) // (max_beams - 1), 1)
    idx = np.arange(0, r.shape[0], step)
    sub = r[idx]
    with np.errstate(invalid="ignore"):
        # NaN fails both; ≤ range_min becomes range_max in AMCL: skipped; +inf (no return) too, whatever rmax
        keep = (sub > rmin) & (sub < rmax) & np.isfinite(sub)
    idx = idx[keep]
    local = np.stack([r[idx] * np.cos(a[idx]), r[idx] * np.sin(a[idx]), np.zeros(idx.shape[0])], axis=1)
    tf = np.asarray(laser_to_base, dtype=np.float64)
    pts = local @ tf[:3, :3].T + tf[:3, 3]
    return BeamSet(pts[:, :2].astype(np.float32), tf[:2, 3].copy(), float(rmax), idx.astype(np.int64))


def beam_skip_mask(explained: npt.ArrayLike, weight: npt.ArrayLike, skip_threshold: float,
                   error_threshold: float) -> npt.NDArray[np.bool_]:
    """Nav2 AMCL's beam skipping (``do_beamskip``): the beams (B,) to leave out of every particle's weight.

    A beam is skipped when the particles that explain it (``explained`` (N, B): its end point lies within
    ``beam_skip_distance`` of the model, per particle) carry less than ``skip_threshold`` of the weight
    (``weight`` (N,), or (N, B): a weight per particle per beam, :func:`beam_support_weights`). Such a beam
    hit something the map does not hold at the poses the filter believes in (a person, a closed door whose
    leaf the static map lacks, a door mapping never saw move): kept, it pulls every particle towards a pose
    where the end point happens to meet a wall, and in a corridor, which constrains the position along its
    axis only weakly, a few such beams multiplied in (``product``) outweigh all the others. When the filter
    disagrees with more than ``error_threshold`` of the beams (it is lost, or the map is wrong everywhere),
    nothing is skipped, as in nav2_amcl.
    """
    ok = np.asarray(explained, dtype=bool)
    w = np.asarray(weight)
    if ok.shape[1] == 0:
        return np.zeros(0, dtype=bool)
    if w.ndim == 1:
        w = w[:, None]
    support = np.where(ok, w, 0).sum(axis=0, dtype=np.float64) / np.maximum(w.sum(axis=0, dtype=np.float64), 1e-300)
    skip = support < skip_threshold
    if skip.mean() > error_threshold:
        return np.zeros_like(skip)
    return np.asarray(skip, dtype=bool)


def beam_support_weights(pz: npt.ArrayLike, weight: npt.ArrayLike, floor: float,
                         combination: BeamCombination) -> Float32Array:
    """Per beam b, the particles' posterior weight (N, B) given the *other* beams, each clipped at ``floor``.

    w_ib ∝ w_i · L_i^(−b), with L^(−b) the scan likelihood (``combination``) without beam b and every pz
    raised to at least ``floor`` (the pz of an end point ``beam_skip_distance`` from the model). Asking
    which particles explain a beam under the *prior* weight (nav2_amcl counts the predicted particles) fails
    after a long odometry step: the predicted cloud is wider than ``beam_skip_distance``, only the minority
    near the true pose explains the beams that would pull the cloud back, and they are skipped (the CARMEN
    logs, scans 0.5–1 m apart: intel lost). Under the posterior of the other beams those particles carry the
    weight, so their beams count. The clip makes every unexplained beam the same constant at all particles:
    an obstacle the map lacks neither earns nor costs weight here, so it cannot pull the support towards a
    pose where it happens to meet a wall. Leaving beam b out keeps it from vouching for itself.
    """
    # float32 throughout (N×B work arrays at 50,000 particles): sums of ~60 log terms lose ~1e-4 nats
    p = np.fmax(np.asarray(pz, dtype=np.float32), np.float32(floor))  # NaN (a dropped beam) becomes the floor
    with np.errstate(divide="ignore"):
        log_w = np.log(np.asarray(weight, dtype=np.float64)).astype(np.float32)[:, None]
    if combination is BeamCombination.AMCL:
        cubed = p * p * p
        log_post = np.log1p(cubed.sum(axis=1, keepdims=True) - cubed)
    else:
        log_post = np.log(p, out=p)
        log_post = np.subtract(log_post.sum(axis=1, keepdims=True), log_post, out=log_post)
    log_post += log_w
    log_post -= log_post.max(axis=0, keepdims=True)
    post: Float32Array = np.exp(log_post, out=log_post)
    post /= post.sum(axis=0, keepdims=True)
    return post


def cloud_converged(weight: npt.ArrayLike, pose: npt.ArrayLike, config: LocalizeConfig) -> bool:
    """Weighted position std ≤ ``converged_xy_std_m`` (both axes) and circular yaw std ≤ ``converged_yaw_std_deg``."""
    w = np.asarray(weight, dtype=np.float64)
    w = w / w.sum()
    x = np.asarray(pose, dtype=np.float64).reshape(-1, 3)
    mean_xy = w @ x[:, :2]
    var_xy = w @ ((x[:, :2] - mean_xy) ** 2)
    resultant = abs(complex(float(w @ np.cos(x[:, 2])), float(w @ np.sin(x[:, 2]))))
    yaw_std = math.sqrt(max(-2.0 * math.log(max(resultant, 1e-300)), 0.0))  # circular std
    return bool(math.sqrt(float(var_xy.max())) <= config.converged_xy_std_m
                and yaw_std <= math.radians(config.converged_yaw_std_deg))


def skip_unexplained(pz: npt.ArrayLike, weight: npt.ArrayLike, pose: npt.ArrayLike, config: LocalizeConfig,
                     range_max_m: float, combination: BeamCombination) -> tuple[Float32Array, int]:
    """Per-beam likelihoods (N, B) with :func:`beam_skip_mask` applied when ``do_beamskip`` is on, and the number
    of beams skipped. A beam is explained at a particle when its pz is at least that of an end point
    ``beam_skip_distance`` from the model (for the RBPF: from the model the beam was associated with); the
    share of the weight that explains it is taken under the other beams' clipped posterior
    (:func:`beam_support_weights`), or with ``beam_skip_support: particles`` as nav2_amcl takes it: the share of
    the particles.

    Only a converged filter skips (weighted position std ≤ ``converged_xy_std_m``, yaw std ≤
    ``converged_yaw_std_deg``, particles ``pose`` (N, 3)): "most hypotheses cannot explain this beam" means
    "the map lacks this obstacle" only when the hypotheses are one; during global localization it would
    leave out exactly the beams that tell the hypotheses apart.
    """
    p = np.asarray(pz, dtype=np.float32)
    if not config.do_beamskip or p.ndim != 2 or p.shape[1] == 0:
        return p, 0
    if not cloud_converged(weight, pose, config):
        return p, 0
    floor = beam_skip_floor(config, range_max_m)
    with np.errstate(invalid="ignore"):
        explained = p >= np.float32(floor)
    if config.beam_skip_support == "particles":  # nav2_amcl: the share of the particles, whatever their weight
        support: npt.NDArray[np.floating] = np.ones(p.shape[0], dtype=np.float32)
    else:
        support = beam_support_weights(p, weight, floor, combination)
    skip = beam_skip_mask(explained, support, config.beam_skip_threshold, config.beam_skip_error_threshold)
    return drop_beams(p, skip, combination), int(skip.sum())


def skipped_field_log_likelihood(dist_field: DistanceField, pose: npt.ArrayLike, weight: npt.ArrayLike,
                                 points_base: npt.ArrayLike, config: LocalizeConfig, range_max_m: float,
                                 combination: BeamCombination = BeamCombination.AMCL) -> tuple[FloatArray, int]:
    """log p(z | x) (N,) of each particle with beam skipping, and the number of beams skipped:
    :func:`endpoint_distances`, :func:`beam_likelihood`, :func:`skip_unexplained` (particles ``pose`` (N, 3) with
    ``weight`` (N,)), then :func:`combine_beams`.

    MCL's weighing of a converged cloud. On a field with a ``torch_device`` every step runs there
    (:func:`.torch_field.skipped_field_log_likelihood`), so that the (N, B) likelihoods never cross to the host.
    """
    if dist_field.torch_device is not None:
        from doorbatch.pipeline.localize import torch_field

        return torch_field.skipped_field_log_likelihood(dist_field, pose, weight, points_base, config, range_max_m,
                                                        combination)
    dist = endpoint_distances(dist_field, pose, points_base)
    pz = beam_likelihood(dist, config.z_hit, config.z_rand, config.sigma_hit, range_max_m, out=dist)
    pz, skipped = skip_unexplained(pz, weight, pose, config, range_max_m, combination)
    return combine_beams(pz, combination), skipped


def beam_skip_floor(config: LocalizeConfig, range_max_m: float) -> float:
    """The pz of an end point ``beam_skip_distance`` from the model: a beam is explained at a particle when its
    pz is at least this (:func:`skip_unexplained`)."""
    sig = config.sigma_hit
    return config.z_hit * math.exp(-0.5 * (config.beam_skip_distance / sig) ** 2) + config.z_rand / range_max_m


def drop_beams(pz: npt.ArrayLike, skip: npt.ArrayLike, combination: BeamCombination) -> Float32Array:
    """``pz`` (N, B) with the skipped beams made neutral for ``combination`` (factor 1 / term 0); NaN too."""
    p = np.array(pz, dtype=np.float32)
    neutral = np.float32(1.0 if combination is BeamCombination.PRODUCT else 0.0)
    p[:, np.asarray(skip, dtype=bool)] = neutral
    p[np.isnan(p)] = neutral
    return p
