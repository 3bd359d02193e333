"""Door detection from dynamic points (paper 000, Sec. III): clusters, lines, door leaves, hinged doors.

1. Clusters by proximity, eq. (1): C_i = {p | ∃ q ∈ C_i : ‖p − q‖ < ε} (single linkage: the connected
   components of the ε-graph, :func:`cluster_points`).
2. Lines of minimal length, eq. (2): L_i = {(p, q) ∈ C_i × C_i | ‖p − q‖ > δ}. A cluster whose lines
   disagree in angle by more than ``max_line_angle_deg`` is a non-line object; otherwise its line object is
   the mean line segment (mean direction of L_i, through the cluster centroid) with the length of the
   longest pair in L_i (:func:`fit_leaf`). Lines with length in [λmin, λmax] are potential door leaves.
3. Doors: leaves with close end points (a common hinge) seen at two or more distinguishable angles, and
   rotating no more than 180° unless ``allow_swinging`` (:func:`group_doors`).

A door is its hinge, leaf length, reference (closed) direction and observed opening range
(:class:`DetectedDoor`), and :func:`remove_leaves` takes the leaf out of the static grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from doorbatch.config import DoorDetectionConfig, GridConfig
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.pipeline.gridmap.dynamic import seen_free_grid
from doorbatch.pipeline.gridmap.occupancy import LogOddsGrid

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

SOURCE_TRANSIENT = 1  # set 1: scan end points in transient cells (one time instance per scan)
SOURCE_FALLEN = 2  # set 2: means of seen-occupied cells that fell low (one time instance per pass)
SOURCE_STATIC = 3  # static partner found in the grid for a leaf seen at one angle only (extension)
DENSE_CLUSTER_MAX = 96  # clustering switches from a dense reachability matrix to a k-d tree above this


@dataclass(frozen=True, slots=True)
class Leaves:
    """Potential door leaves (the paper's persistent set): N segments p0 → p1 with their origin.

    Attributes:
        p0, p1: (N, 2) segment end points (order carries no meaning).
        instance: (N,) time instance (scan number for set 1, pass number for set 2).
        pass_index: (N,) pass the observation comes from.
        source: (N,) SOURCE_TRANSIENT, SOURCE_FALLEN or SOURCE_STATIC.
    """

    p0: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    p1: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    instance: IntArray = field(default_factory=lambda: np.zeros(0, np.int64))
    pass_index: IntArray = field(default_factory=lambda: np.zeros(0, np.int64))
    source: IntArray = field(default_factory=lambda: np.zeros(0, np.int64))

    def __len__(self) -> int:
        return int(self.p0.shape[0])

    @staticmethod
    def concat(parts: list[Leaves]) -> Leaves:
        """All leaves of ``parts`` in order."""
        if not parts:
            return Leaves()
        return Leaves(*(np.concatenate([getattr(p, f) for p in parts]) for f in
                        ("p0", "p1", "instance", "pass_index", "source")))

    def lengths(self) -> FloatArray:
        """(N,) segment lengths."""
        d = self.p1 - self.p0
        return np.asarray(np.hypot(d[:, 0], d[:, 1]), dtype=np.float64)


@dataclass(frozen=True, slots=True)
class DetectedDoor:
    """A door as DESIGN.md's doors.parquet holds it (source ``grid``).

    closed_yaw is the global direction hinge → free end of the closed leaf; angle_min / angle_max the
    observed opening range relative to it (rad, CCW positive); the leaf at angle a points along
    closed_yaw + a.
    """

    hinge_x: float
    hinge_y: float
    length: float
    closed_yaw: float
    angle_min: float
    angle_max: float
    n_observations: int
    moved: bool = True
    observed_yaws: tuple[float, ...] = ()


# ------------------------------------------------------------------------------------------ eq. (1), (2)


def cluster_points(points: npt.ArrayLike, eps: float) -> IntArray:
    """Eq. (1): labels 0 … C − 1 of the single-linkage clusters (pairs closer than ε are linked).

    Up to ``DENSE_CLUSTER_MAX`` points (a scan's dynamic points), the ε-adjacency matrix is closed under
    reachability by repeated squaring; beyond, a k-d tree's ε-pairs feed a connected-components search.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    n = pts.shape[0]
    if n <= 1:
        return np.zeros(n, dtype=np.int64)
    if n <= DENSE_CLUSTER_MAX:
        dx = pts[:, 0, None] - pts[None, :, 0]
        dy = pts[:, 1, None] - pts[None, :, 1]
        reach = (dx * dx + dy * dy < eps * eps).astype(np.float32)
        for _ in range(max(1, math.ceil(math.log2(n))) + 1):
            nxt = ((reach @ reach) > 0).astype(np.float32)
            if np.array_equal(nxt, reach):
                break
            reach = nxt
        first = np.argmax(reach > 0, axis=1)  # smallest index in each point's cluster
        return np.asarray(np.unique(first, return_inverse=True)[1], dtype=np.int64)
    pairs = cKDTree(pts).query_pairs(eps * (1.0 - 1e-12), output_type="ndarray")
    graph = coo_matrix((np.ones(pairs.shape[0]), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    return np.asarray(labels, dtype=np.int64)


def _circular_span(angles: FloatArray) -> float:
    """Length of the shortest arc that holds all angles (rad, in [0, 2π))."""
    if angles.size <= 1:
        return 0.0
    a = np.sort(np.mod(angles, 2 * np.pi))
    gaps = np.diff(np.concatenate([a, a[:1] + 2 * np.pi]))
    return float(2 * np.pi - gaps.max())


def fit_leaf(points: npt.ArrayLike, config: DoorDetectionConfig) -> FloatArray | None:
    """Eq. (2): the line object of one cluster as a (2, 2) segment, or None (no line of length > δ, or a
    non-line object whose lines disagree in angle by more than ``max_line_angle_deg``).

    Undirected line angles θ are compared as 2θ on the circle: the largest angle between two lines is half
    the span of the 2θ. The mean line has the circular mean direction of the 2θ and passes through the
    cluster centroid; its segment is centred on the projection of the longest pair, with that pair's length.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if pts.shape[0] > config.max_cluster_points:
        pts = pts[np.linspace(0, pts.shape[0] - 1, config.max_cluster_points).astype(np.int64)]
    i, j = np.triu_indices(pts.shape[0], 1)
    d = pts[j] - pts[i]
    length2 = d[:, 0] ** 2 + d[:, 1] ** 2
    keep = length2 > config.min_line_length_m**2
    if not keep.any():
        return None
    d, length2 = d[keep], length2[keep]
    two_theta = 2.0 * np.arctan2(d[:, 1], d[:, 0])
    if _circular_span(two_theta) / 2.0 > math.radians(config.max_line_angle_deg):
        return None
    mean = 0.5 * math.atan2(float(np.sin(two_theta).sum()), float(np.cos(two_theta).sum()))
    u = np.array([math.cos(mean), math.sin(mean)])
    best = int(np.argmax(length2))
    a, b = pts[i[keep][best]], pts[j[keep][best]]
    centroid = pts.mean(axis=0)
    mid = centroid + float(np.dot((a + b) / 2 - centroid, u)) * u
    half = 0.5 * math.sqrt(float(length2[best]))
    return np.stack([mid - half * u, mid + half * u])


def extract_leaves(points: npt.ArrayLike, config: DoorDetectionConfig, instance: int = 0,
                   pass_index: int = 0, source: int = SOURCE_TRANSIENT) -> Leaves:
    """Potential door leaves among the dynamic points of one time instance: eq. (1) clusters, eq. (2) line
    objects, and the length gate [λmin, λmax]."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if pts.shape[0] < 2:
        return Leaves()
    span = pts.max(axis=0) - pts.min(axis=0)
    if float(span @ span) < config.door_length_min_m**2:  # no pair is as long as a leaf: no leaf here
        return Leaves()
    labels = cluster_points(pts, config.cluster_distance_m)
    counts = np.bincount(labels)
    segs = []
    for label in np.flatnonzero(counts >= 2):
        seg = fit_leaf(pts[labels == label], config)
        if seg is None:
            continue
        length = float(np.hypot(*(seg[1] - seg[0])))
        if config.door_length_min_m <= length <= config.door_length_max_m:
            segs.append(seg)
    if not segs:
        return Leaves()
    arr = np.stack(segs)
    n = arr.shape[0]
    return Leaves(arr[:, 0].copy(), arr[:, 1].copy(), np.full(n, instance, np.int64),
                  np.full(n, pass_index, np.int64), np.full(n, source, np.int64))


# ------------------------------------------------------------------------------------------ doors


@dataclass(frozen=True, slots=True)
class _Hinged:
    """Leaves sharing one end point: the hinge-side end, the direction hinge → free end, and when the leaf
    stood there (:func:`_when`) for each."""

    leaf: IntArray
    near: FloatArray
    far: FloatArray
    yaw: FloatArray
    when: FloatArray

    def subset(self, keep: BoolArray) -> _Hinged:
        """The leaves where ``keep`` is True."""
        return _Hinged(self.leaf[keep], self.near[keep], self.far[keep], self.yaw[keep], self.when[keep])


def _when(leaves: Leaves) -> FloatArray:
    """When each leaf stood where it was seen: set 1 during its pass p; set 2 (cells that fell low in pass
    p) before p, written p − ½; a static partner at an unknown time (NaN)."""
    t = leaves.pass_index.astype(np.float64)
    t = np.where(leaves.source == SOURCE_FALLEN, t - 0.5, t)
    return np.asarray(np.where(leaves.source == SOURCE_STATIC, np.nan, t), dtype=np.float64)


def _hinge_groups(leaves: Leaves, config: DoorDetectionConfig) -> list[_Hinged]:
    """Connected components of leaf end points closer than ``hinge_distance_m`` (each leaf counted once per
    component, by its end in the component)."""
    n = len(leaves)
    ends = np.concatenate([leaves.p0, leaves.p1])
    labels = cluster_points(ends, config.hinge_distance_m)
    owner = np.tile(np.arange(n), 2)
    when = _when(leaves)
    groups = []
    for label in np.unique(labels):
        members = np.flatnonzero(labels == label)
        leaf, first = np.unique(owner[members], return_index=True)
        end = members[first]
        near = ends[end]
        far = ends[np.where(end < n, end + n, end - n)]
        yaw = np.arctan2(far[:, 1] - near[:, 1], far[:, 0] - near[:, 0])
        groups.append(_Hinged(leaf, near, far, yaw, when[leaf]))
    return groups


def angle_modes(yaw: FloatArray, gap_rad: float) -> IntArray:
    """Labels of the observed angles: directions sorted around the circle split where neighbours differ
    by more than ``gap_rad``."""
    n = yaw.size
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    order = np.argsort(np.mod(yaw, 2 * np.pi))
    a = np.mod(yaw, 2 * np.pi)[order]
    gaps = np.diff(np.concatenate([a, a[:1] + 2 * np.pi]))
    cuts = gaps > gap_rad
    if not cuts.any():
        return np.zeros(n, dtype=np.int64)
    # Start counting after the largest gap, so that a mode is never split across 0.
    start = (int(np.argmax(gaps)) + 1) % n
    rolled_cuts = np.roll(cuts, -start)
    lab_sorted = np.concatenate([[0], np.cumsum(rolled_cuts[:-1])])
    labels = np.empty(n, dtype=np.int64)
    labels[order[np.roll(np.arange(n), -start)]] = lab_sorted
    return labels


def _mode_yaws(yaw: FloatArray, labels: IntArray) -> FloatArray:
    """Circular mean direction of each mode."""
    k = int(labels.max()) + 1
    s = np.bincount(labels, np.sin(yaw), minlength=k)
    c = np.bincount(labels, np.cos(yaw), minlength=k)
    return np.asarray(np.arctan2(s, c), dtype=np.float64)


def _range_about(yaws: FloatArray) -> tuple[float, float]:
    """(start, span): the shortest CCW arc from ``start`` that holds all directions."""
    a = np.sort(np.mod(yaws, 2 * np.pi))
    gaps = np.diff(np.concatenate([a, a[:1] + 2 * np.pi]))
    k = int(np.argmax(gaps))
    start = float(a[(k + 1) % a.size])
    return start, float(2 * np.pi - gaps[k])


def intersect_lines(points: FloatArray, yaws: FloatArray) -> FloatArray | None:
    """Least-squares intersection h of lines (point p_m, direction θ_m): min Σ (n_m · (h − p_m))², with
    n_m ⊥ direction; None when the lines are (nearly) parallel."""
    n = np.stack([-np.sin(yaws), np.cos(yaws)], axis=1)
    a = n.T @ n
    if np.linalg.cond(a) > 1e6:
        return None
    return np.asarray(np.linalg.solve(a, n.T @ np.einsum("ij,ij->i", n, points)), dtype=np.float64)


def group_doors(leaves: Leaves, config: DoorDetectionConfig, grid: LogOddsGrid | None = None
                ) -> list[DetectedDoor]:
    """Paper 000, Sec. III: doors are leaves with a common hinge seen at ≥ 2 distinguishable angles.

    For each group of leaves whose end points are within ``hinge_distance_m``: the leaf directions are
    grouped into observed angles (:func:`angle_modes`); the group is a door when two observed angles differ
    by ≥ ``min_opening_deg``, all lie within :func:`_max_span` of each other (office doors rotate at most
    180°; ``allow_swinging`` lifts this), the leaf keeps its length (``min_length_ratio``), and two of
    the angles were seen at different times (``require_distinct_passes``). With a grid, a group with one
    observed angle may get its
    other angle from the static grid (``static_partner_search``), and the closed direction comes from the
    wall behind the hinge (:func:`closed_direction`). Each leaf serves one door; groups with more
    observations are taken first.
    """
    if len(leaves) == 0:
        return []
    occupied = None if grid is None else _occupied_dilated(grid, config)
    gap = math.radians(config.angle_cluster_gap_deg)
    used = np.zeros(len(leaves), dtype=bool)
    doors: list[DetectedDoor] = []
    for g in sorted(_hinge_groups(leaves, config), key=lambda g: -g.leaf.size):
        free = ~used[g.leaf]
        if free.sum() < 1:
            continue
        door = _door_from_group(g.subset(free), gap, config, grid, occupied)
        if door is not None:
            used[g.leaf] = True
            doors.append(door)
    return doors


def _door_from_group(g: _Hinged, gap: float, config: DoorDetectionConfig, grid: LogOddsGrid | None,
                     occupied: BoolArray | None) -> DetectedDoor | None:
    labels = angle_modes(g.yaw, gap)
    modes = _mode_yaws(g.yaw, labels)
    near, far, yaw, when = g.near, g.far, g.yaw, g.when
    if modes.size == 1 and grid is not None and occupied is not None and config.static_partner_search:
        partner = _static_partner(grid, occupied, g, float(modes[0]), config)
        if partner is None:
            return None
        near = np.vstack([near, partner[0][None]])
        far = np.vstack([far, partner[1][None]])
        yaw = np.append(yaw, math.atan2(*(partner[1] - partner[0])[::-1]))
        when = np.append(when, np.nan)
        labels = np.append(labels, 1)
        modes = np.append(modes, yaw[-1])
    if modes.size < 2:
        return None
    start, span = _range_about(modes)
    if not math.radians(config.min_opening_deg) <= span <= _max_span(config):
        return None
    if config.require_distinct_passes and not _moved_between_passes(modes, labels, when, config):
        return None
    hinge = _hinge_estimate(near, far, labels, modes, config)
    dist = np.hypot(far[:, 0] - hinge[0], far[:, 1] - hinge[1])
    per_mode = np.zeros(modes.size)
    np.maximum.at(per_mode, labels, dist)
    if per_mode.min() < config.min_length_ratio * per_mode.max():  # a rigid leaf keeps its length
        return None
    length = float(np.quantile(dist, config.length_quantile))
    closed = start if grid is None or occupied is None else closed_direction(grid, occupied, hinge, modes, config)
    # Positions along the observed arc (CCW from its start), shifted to the closed direction; not wrapped,
    # so a swinging door's range may exceed 180°.
    rel = float(wrap_angle(start - closed)) + np.mod(modes - start, 2 * np.pi)
    return DetectedDoor(float(hinge[0]), float(hinge[1]), length, float(wrap_angle(closed)),
                        float(rel.min()), float(rel.max()), int(yaw.size), True,
                        tuple(float(v) for v in wrap_angle(modes)))


def _moved_between_passes(modes: FloatArray, labels: IntArray, when: FloatArray,
                          config: DoorDetectionConfig) -> bool:
    """Whether two distinguishable observed angles were seen at different times (doors are stationary
    within a pass, DESIGN.md): a line that seems to turn within one pass is not a door leaf."""
    min_open = math.radians(config.min_opening_deg)
    times = [set(when[labels == k].tolist()) for k in range(modes.size)]
    for a in range(modes.size):
        for b in range(a + 1, modes.size):
            if abs(math.remainder(float(modes[a] - modes[b]), 2 * math.pi)) < min_open:
                continue
            both = times[a] | times[b]
            if any(math.isnan(t) for t in both) or len(both) >= 2:
                return True
    return False


def _max_span(config: DoorDetectionConfig) -> float:
    """Largest rotation a door may show (rad): ``max_rotation_deg`` less ``min_opening_deg`` — two leaves
    180° apart are one straight line through the "hinge" (two wall pieces end to end), not a rotation —
    or any distinguishable rotation with ``allow_swinging``."""
    limit = 360.0 if config.allow_swinging else config.max_rotation_deg
    return math.radians(limit - config.min_opening_deg)


def _hinge_estimate(near: FloatArray, far: FloatArray, labels: IntArray, modes: FloatArray,
                    config: DoorDetectionConfig) -> FloatArray:
    """The hinge: least-squares intersection of the mean lines of the observed angles (the end points
    near the hinge are cut short by the transient neighbourhood rule, the lines are not); the mean of
    the near end points if that intersection is farther than ``hinge_distance_m`` from it."""
    k = modes.size
    mids = (near + far) / 2
    sums = np.stack([np.bincount(labels, mids[:, c], minlength=k) for c in (0, 1)], axis=1).astype(np.float64)
    centre = sums / np.bincount(labels, minlength=k).astype(np.float64)[:, None]
    fallback = near.mean(axis=0)
    h = intersect_lines(centre, modes)
    if h is None or np.hypot(*(h - fallback)) > config.hinge_distance_m:
        return np.asarray(fallback, dtype=np.float64)
    return h


# ------------------------------------------------------------------------------------------ grid probes


def _occupied_dilated(grid: LogOddsGrid, config: DoorDetectionConfig) -> BoolArray:
    """Occupied cells (p > p_occupied) grown by one cell, so probes tolerate a cell of misregistration."""
    occ = grid.log_odds > np.float32(math.log(config.p_occupied / (1 - config.p_occupied)))
    return np.asarray(ndimage.binary_dilation(occ, structure=np.ones((3, 3), bool)), dtype=np.bool_)


def _ray_fraction(grid: LogOddsGrid, mask: BoolArray, start: FloatArray, yaws: FloatArray,
                  s0: float, s1: float) -> FloatArray:
    """Fraction of samples (every half cell) at distances [s0, s1] along each direction from ``start``
    that fall into True cells of ``mask`` (outside the grid counts as False)."""
    s = np.arange(s0, s1 + 1e-9, grid.resolution_m / 2)
    if s.size == 0:
        return np.zeros(yaws.size)
    xy = start + s[None, :, None] * np.stack([np.cos(yaws), np.sin(yaws)], axis=-1)[:, None, :]
    c = np.floor(grid.world_to_cell_float(xy)).astype(np.int64)
    h, w = grid.shape
    inside = (c[..., 0] >= 0) & (c[..., 0] < w) & (c[..., 1] >= 0) & (c[..., 1] < h)
    hit = np.zeros(inside.shape, dtype=bool)
    hit[inside] = mask[c[..., 1][inside], c[..., 0][inside]]
    return np.asarray(hit.mean(axis=1), dtype=np.float64)


def _static_partner(grid: LogOddsGrid, occupied: BoolArray, g: _Hinged, mode_yaw: float,
                   config: DoorDetectionConfig) -> tuple[FloatArray, FloatArray] | None:
    """Extension: the leaf's other observed angle as an occupied segment in the static grid.

    For leaves seen at one angle only, with their shared end as the hinge: directions φ at 1° steps,
    between ``min_opening_deg`` and min(180°, ``max_rotation_deg``) − ``min_opening_deg`` from the leaf
    (nearly opposite is the wall going on behind the hinge), score the fraction of occupied cells (grown
    by a cell) along [2 cells, L − 1 cell] (L: the leaf's length); beyond L + 3 cells,
    ``partner_end_clear_m`` must hold no occupied cell (a wall would go on). The best φ scoring
    ≥ ``partner_min_fraction`` is refined by :func:`_refine_partner`, and the search repeats from the
    refined hinge until it moves less than a cell (at most three rounds). Returns (hinge, free end), or
    None.
    """
    length = float(np.quantile(np.hypot(*(g.far - g.near).T), config.length_quantile))
    res = grid.resolution_m
    lo = math.radians(config.min_opening_deg)
    hi = min(math.pi - math.radians(config.min_opening_deg), _max_span(config))
    offsets = np.radians(np.arange(-180.0, 180.0, 1.0))
    yaws = mode_yaw + offsets[(np.abs(offsets) >= lo) & (np.abs(offsets) <= hi)]
    hinge = g.near.mean(axis=0)
    found = None
    for _ in range(3):  # the refined hinge moves back along the leaf: search again from there
        frac = _ray_fraction(grid, occupied, hinge, yaws, 2 * res, length - res)
        clear = (length + 3 * res, length + 3 * res + config.partner_end_clear_m)
        beyond = _ray_fraction(grid, occupied, hinge, yaws, *clear)
        ok = (frac >= config.partner_min_fraction) & (beyond == 0.0)
        if not ok.any():
            return found
        phi = float(yaws[int(np.argmax(np.where(ok, frac, -1.0)))])
        refined = _refine_partner(grid, g, mode_yaw, hinge, phi, length, config)
        if refined is None:
            return found
        moved = float(np.hypot(*(refined[0] - hinge)))
        found, hinge = refined, refined[0]
        if moved < res:
            break
    return found


def _refine_partner(grid: LogOddsGrid, g: _Hinged, mode_yaw: float, hinge: FloatArray, phi: float,
                    length: float, config: DoorDetectionConfig) -> tuple[FloatArray, FloatArray] | None:
    """Fit a line to the occupied cells within two cells of the ray hinge + s·(cos φ, sin φ); the hinge is
    its intersection with the leaf's line (the leaf's near end may be cut short), the free end the last
    occupied cell along it before a gap longer than ``partner_gap_m``."""
    res = grid.resolution_m
    occ = grid.log_odds > np.float32(math.log(config.p_occupied / (1 - config.p_occupied)))
    reach = length + config.partner_end_clear_m
    box0 = np.floor(grid.world_to_cell_float(hinge - reach)).astype(np.int64)
    box1 = np.floor(grid.world_to_cell_float(hinge + reach)).astype(np.int64)
    h, w = grid.shape
    j0, i0 = np.maximum(box0, 0)
    j1, i1 = np.minimum(box1, [w - 1, h - 1])
    ii, jj = np.nonzero(occ[i0:i1 + 1, j0:j1 + 1])
    centres = grid.cell_centers((ii + i0) * w + (jj + j0))
    u = np.array([math.cos(phi), math.sin(phi)])
    rel = centres - hinge
    s = rel @ u
    lateral = np.abs(rel @ np.array([-u[1], u[0]]))
    band = (lateral <= 2 * res) & (s >= 2 * res) & (s <= reach)
    if band.sum() < 3:
        return None
    pts = centres[band]
    mean = pts.mean(axis=0)
    _, vecs = np.linalg.eigh(np.cov((pts - mean).T))
    d = vecs[:, 1] * (1.0 if float(vecs[:, 1] @ u) >= 0 else -1.0)
    yaw_p = math.atan2(d[1], d[0])
    lone_mid = ((g.near + g.far) / 2).mean(axis=0)
    refined = intersect_lines(np.stack([lone_mid, mean]), np.array([mode_yaw, yaw_p]))
    if refined is not None and np.hypot(*(refined - hinge)) <= config.hinge_distance_m:
        hinge = refined
    along = np.sort((pts - hinge) @ d)
    gaps = np.flatnonzero(np.diff(along) > max(config.partner_gap_m, 2 * res))
    far = float(along[gaps[0]] if gaps.size else along[-1]) + res / 2
    return hinge, hinge + far * d


def closed_direction(grid: LogOddsGrid, occupied: BoolArray, hinge: FloatArray, modes: FloatArray,
                     config: DoorDetectionConfig) -> float:
    """The reference (closed) direction of a door: a closed leaf is flush with its wall, so the wall
    continues behind the hinge, opposite to the closed leaf.

    Candidates φ at 1° steps outside the observed range (or at its ends) score the fraction of occupied
    cells along hinge − s·(cos φ, sin φ), s ∈ [2 cells, ``wall_probe_m``]; among those scoring
    ≥ ``wall_min_fraction``, the one nearest to an end of the observed range wins (a perpendicular wall at
    the hinge scores too, but lies far from the range). Without such a wall, the end of the observed range
    with the better score is used (paper 000 only asks for "a reference opening angle in global
    coordinates").
    """
    start, span = _range_about(modes)
    res = grid.resolution_m
    ends = np.array([start, start + span])
    end_score = _ray_fraction(grid, occupied, hinge, ends + math.pi, 2 * res, config.wall_probe_m)
    limit = math.radians(min(config.max_rotation_deg, 360.0)) - span
    cand = start + span + np.radians(np.arange(0.0, 360.0, 1.0))
    rel = np.mod(cand - (start + span), 2 * np.pi)  # CCW beyond the range end …
    back = 2 * np.pi - span - rel  # … and CW before its start
    outside = (back >= -1e-9) & ((rel <= limit + 1e-9) | (back <= limit + 1e-9))
    cand, rel, back = cand[outside], rel[outside], back[outside]
    score = _ray_fraction(grid, occupied, hinge, cand + math.pi, 2 * res, config.wall_probe_m)
    good = score >= config.wall_min_fraction
    if good.any():
        dist = np.minimum(rel, back)[good]
        return float(wrap_angle(cand[good][int(np.argmin(dist))]))
    return float(wrap_angle(ends[int(np.argmax(end_score))]))


# ------------------------------------------------------------------------------------------ static map


def swept_cells(grid: LogOddsGrid, door: DetectedDoor, margin_m: float) -> BoolArray:
    """(H, W) mask of the cells whose centres lie in the sector the leaf swept over its observed range
    (radius = leaf length, angles [angle_min, angle_max] about closed_yaw), or within ``margin_m`` of
    the leaf at either end of the range."""
    h, w = grid.shape
    res = grid.resolution_m
    reach = door.length + margin_m + res
    c0 = np.floor(grid.world_to_cell_float([door.hinge_x - reach, door.hinge_y - reach])).astype(np.int64)
    c1 = np.floor(grid.world_to_cell_float([door.hinge_x + reach, door.hinge_y + reach])).astype(np.int64)
    j0, i0 = np.maximum(c0, 0)
    j1, i1 = np.minimum(c1, [w - 1, h - 1])
    mask = np.zeros((h, w), dtype=bool)
    if j1 < j0 or i1 < i0:
        return mask
    jj, ii = np.meshgrid(np.arange(j0, j1 + 1), np.arange(i0, i1 + 1))
    px = grid.origin_x_m + (jj + 0.5) * res - door.hinge_x
    py = grid.origin_y_m + (ii + 0.5) * res - door.hinge_y
    r = np.hypot(px, py)
    a = wrap_angle(np.arctan2(py, px) - door.closed_yaw)
    inside = (r <= door.length) & (a >= door.angle_min) & (a <= door.angle_max)
    for ang in (door.angle_min, door.angle_max):
        u = (math.cos(door.closed_yaw + ang), math.sin(door.closed_yaw + ang))
        t = np.clip(px * u[0] + py * u[1], 0.0, door.length)
        inside |= np.hypot(px - t * u[0], py - t * u[1]) <= margin_m
    mask[i0:i1 + 1, j0:j1 + 1] = inside
    return mask


def remove_leaves(grid: LogOddsGrid, doors: list[DetectedDoor], config: DoorDetectionConfig,
                  grid_config: GridConfig) -> LogOddsGrid:
    """Take the door leaves out of the static grid (in place; returns the grid).

    Cells the leaf swept over its observed range become free where they were ever seen free, unknown
    elsewhere (their hits are forgotten). The hinge stays: occupied cells within ``hinge_keep_m`` of it are
    kept, and the cell holding the hinge becomes occupied.
    """
    if not doors:
        return grid
    swept = np.zeros(grid.shape, dtype=bool)
    occupied = grid.log_odds > np.float32(math.log(config.p_occupied / (1 - config.p_occupied)))
    for door in doors:
        swept |= swept_cells(grid, door, config.sweep_margin_m) & ~(
            occupied & _near(grid, door.hinge_x, door.hinge_y, config.hinge_keep_m))
    free = seen_free_grid(grid, grid_config)
    grid.log_odds[swept & free] = np.float32(grid_config.l_min)
    unknown = swept & ~free
    grid.log_odds[unknown] = 0.0
    grid.hits[unknown] = 0
    grid.hit_sum[unknown] = 0
    grid.seen_occupied[swept] = False
    for door in doors:
        if grid.contains([door.hinge_x, door.hinge_y]):
            k = int(grid.flat_index([door.hinge_x, door.hinge_y]))
            grid.log_odds.reshape(-1)[k] = np.float32(grid_config.l_max)
            grid.hits.reshape(-1)[k] = max(1, int(grid.hits.reshape(-1)[k]))
    return grid


def _near(grid: LogOddsGrid, x: float, y: float, radius: float) -> BoolArray:
    """(H, W) mask of the cells whose centres lie within ``radius`` of (x, y)."""
    h, w = grid.shape
    res = grid.resolution_m
    mask = np.zeros((h, w), dtype=bool)
    j0 = max(0, math.floor((x - radius - grid.origin_x_m) / res))
    i0 = max(0, math.floor((y - radius - grid.origin_y_m) / res))
    j1 = min(w, math.ceil((x + radius - grid.origin_x_m) / res) + 1)
    i1 = min(h, math.ceil((y + radius - grid.origin_y_m) / res) + 1)
    if j1 <= j0 or i1 <= i0:
        return mask
    cx = grid.origin_x_m + (np.arange(j0, j1) + 0.5) * res - x
    cy = grid.origin_y_m + (np.arange(i0, i1) + 0.5) * res - y
    mask[i0:i1, j0:j1] = cy[:, None] ** 2 + cx[None, :] ** 2 <= radius**2
    return mask
