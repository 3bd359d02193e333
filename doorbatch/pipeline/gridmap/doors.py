"""Door detection from dynamic points (paper 000, Sec. III): clusters, lines, door leaves, hinged doors.

1. Clusters by proximity, eq. (1): C_i = {p | ∃ q ∈ C_i : ‖p − q‖ < ε} (single linkage: the connected
   components of the ε-graph, :func:`cluster_points`). A cluster of a scan's dynamic points is completed
   along its line by the scan's points in cells once seen free (:func:`complete_line`): the transient
   neighbourhood rule makes a leaf's points next to any static structure (its hinge, its door stop, its
   other states near the hinge) static, so the dynamic part alone is shorter than the leaf.
2. Lines of minimal length, eq. (2): L_i = {(p, q) ∈ C_i × C_i | ‖p − q‖ > δ}. A cluster whose lines
   disagree in angle by more than ``max_line_angle_deg`` is a non-line object; otherwise its line object is
   the mean line segment (mean direction of L_i, through the cluster centroid) with the length of the
   longest pair in L_i (:func:`fit_leaf`). Lines with length in [λmin, λmax] are potential door leaves
   (set-2 lines: longer than δ; the door's length from its hinge is gated instead).
3. Doors: leaves with close end points (a common hinge, where their lines cross) seen at two or more
   distinguishable angles in different passes, rotating no more than 180° unless ``allow_swinging``
   (:func:`group_doors`). Extension: the observed angles the dynamic points cannot see — a leaf state in
   cells never seen free before or after is integrated as static — come from the static grid
   (:func:`_static_states`, :func:`_static_partner`, :func:`_closed_state`), each checked against the
   passes: a line hit while the leaf stood at another angle is something else.

A door is its hinge, leaf length, reference (closed) direction from the wall behind the hinge, and
observed opening range (:class:`DetectedDoor`); :func:`remove_leaves` takes the leaf out of the static grid.
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
from doorbatch.pipeline.gridmap.dynamic import seen_free
from doorbatch.pipeline.gridmap.kernels import (
    band_line_kernel,
    cluster_kernel,
    complete_kernel,
    fit_leaf_kernel,
    ray_fraction_kernel,
    scan_leaves_kernel,
)
from doorbatch.pipeline.gridmap.occupancy import LogOddsGrid

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

SOURCE_TRANSIENT = 1  # set 1: scan end points in transient cells (one time instance per scan)
SOURCE_FALLEN = 2  # set 2: means of seen-occupied cells that fell low (one instance per pass and hit pass)
SOURCE_STATIC = 3  # static partner found in the grid for a leaf seen at one angle only (extension)
DENSE_CLUSTER_MAX = 512  # clustering switches from all pairs (compiled) to a k-d tree above this


@dataclass(frozen=True, slots=True)
class Leaves:
    """Potential door leaves (the paper's persistent set): N segments p0 → p1 with their origin.

    Attributes:
        p0, p1: (N, 2) segment end points (order carries no meaning).
        instance: (N,) time instance (scan number for set 1, the pass it fell in for set 2).
        pass_index: (N,) pass in which the leaf stood there: the scan's pass for set 1; for set 2 the pass
            that last hit its cells (doors are stationary within a pass).
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
    """Eq. (1): labels 0 … C − 1 of the single-linkage clusters (pairs closer than ε are linked), numbered
    in the order of each cluster's first point.

    Up to ``DENSE_CLUSTER_MAX`` points (a scan's dynamic points), a compiled union–find over all pairs
    (:func:`doorbatch.pipeline.gridmap.kernels.cluster_kernel`); beyond, cells of side ε/√2 (any two points of a
    cell are closer than ε, so a cell is linked within) linked to the cells up to two away that hold a point
    within ε of one of theirs (:func:`_cell_links`), and connected components of those cells. Memory stays linear
    in the points where an ε-pair list grows with the square of the points piled on one spot (the leaf ends of
    a hinge seen by every scan of a long log: 16k ends made 450 MB of pairs).
    """
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
    n = pts.shape[0]
    if n <= 1:
        return np.zeros(n, dtype=np.int64)
    if n <= DENSE_CLUSTER_MAX:
        return np.asarray(cluster_kernel(pts, eps), dtype=np.int64)
    reach = eps * (1.0 - 1e-12)  # pairs at most this far apart are linked (a strict "closer than ε")
    side = reach / math.sqrt(2.0) * (1.0 - 1e-9)
    cell_xy = np.floor((pts - pts.min(axis=0)) / side).astype(np.int64)
    cells, cell_of = np.unique(cell_xy, axis=0, return_inverse=True)
    cell_of = cell_of.reshape(-1)
    a, b = _cell_links(pts, cells, cell_of, reach)
    graph = coo_matrix((np.ones(a.shape[0]), (a, b)), shape=(cells.shape[0], cells.shape[0]))
    _, cell_label = connected_components(graph, directed=False)
    labels = cell_label[cell_of]  # components 0 … C − 1, each holding points
    first = np.unique(labels, return_index=True)[1]  # number the clusters in the order of their first point
    rank: IntArray = np.empty(first.shape[0], dtype=np.int64)
    rank[np.argsort(first)] = np.arange(first.shape[0])
    return np.asarray(rank[labels], dtype=np.int64)


def _cell_links(pts: FloatArray, cells: npt.NDArray[np.int64], cell_of: IntArray, reach: float
                ) -> tuple[IntArray, IntArray]:
    """Pairs (A, B) of cells (side ≤ reach/√2, so only cells up to two apart can link) holding points at most
    ``reach`` apart: a cell pair's points are compared in blocks until one such pair is found."""
    width = int(cells[:, 1].max()) + 5
    key = (cells[:, 0] + 2) * width + (cells[:, 1] + 2)  # cells sorted by (x, y): keys sorted too
    order = np.argsort(cell_of, kind="stable")
    starts = np.searchsorted(cell_of[order], np.arange(cells.shape[0] + 1))
    firsts, seconds = [], []
    for dx, dy in [(dx, dy) for dx in range(0, 3) for dy in range(-2, 3) if (dx, dy) > (0, 0)]:
        where = np.searchsorted(key, key + dx * width + dy)
        hit = where < key.shape[0]
        hit[hit] = key[where[hit]] == key[hit] + dx * width + dy
        for c, d in zip(np.flatnonzero(hit), where[hit], strict=True):
            if _any_within(pts[order[starts[c]:starts[c + 1]]], pts[order[starts[d]:starts[d + 1]]], reach):
                firsts.append(c)
                seconds.append(d)
    return np.asarray(firsts, dtype=np.intp), np.asarray(seconds, dtype=np.intp)


def _any_within(p: FloatArray, q: FloatArray, reach: float, block: int = 256) -> bool:
    """Whether some point of ``p`` lies within ``reach`` of some point of ``q`` (blocks of ``p``)."""
    r2 = reach * reach
    for i in range(0, p.shape[0], block):
        d = p[i:i + block, None, :] - q[None, :, :]
        if bool(((d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]) <= r2).any()):
            return True
    return False


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
    At most ``max_cluster_points`` points, evenly subsampled, enter the all-pairs evaluation (compiled,
    :func:`doorbatch.pipeline.gridmap.kernels.fit_leaf_kernel`; :func:`fit_leaf_numpy` is its reference).
    """
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
    if pts.shape[0] > config.max_cluster_points:
        pts = pts[np.linspace(0, pts.shape[0] - 1, config.max_cluster_points).astype(np.int64)]
    out = np.empty((2, 2))
    ok = fit_leaf_kernel(pts, config.min_line_length_m, math.radians(config.max_line_angle_deg), out)
    return out if ok else None


def fit_leaf_numpy(points: npt.ArrayLike, config: DoorDetectionConfig) -> FloatArray | None:
    """:func:`fit_leaf` in NumPy alone (the reference of the compiled kernel)."""
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


def complete_line(cluster: FloatArray, support: FloatArray, config: DoorDetectionConfig) -> FloatArray:
    """The cluster grown along its own line by eq. (1) linkage over ``support`` points.

    The line is the cluster's principal axis; support points within ``line_tolerance_m`` of it join when
    they continue the cluster along the line with gaps below ε (``cluster_distance_m``), up to λmax beyond
    it. Returns the cluster's points followed by the support points that joined. Compiled
    (:func:`doorbatch.pipeline.gridmap.kernels.complete_kernel`); :func:`complete_line_numpy` is its
    reference.
    """
    if support.shape[0] == 0 or cluster.shape[0] < 2:
        return cluster
    join = np.empty(support.shape[0], dtype=bool)
    n = complete_kernel(np.ascontiguousarray(cluster, dtype=np.float64),
                        np.ascontiguousarray(support, dtype=np.float64), config.line_tolerance_m,
                        config.cluster_distance_m, config.door_length_max_m, join)
    return np.concatenate([cluster, support[join]]) if n else cluster


def complete_line_numpy(cluster: FloatArray, support: FloatArray, config: DoorDetectionConfig) -> FloatArray:
    """:func:`complete_line` in NumPy alone (the reference of the compiled kernel)."""
    if support.shape[0] == 0 or cluster.shape[0] < 2:
        return cluster
    centre = cluster.mean(axis=0)
    e = cluster - centre
    theta = 0.5 * math.atan2(2.0 * float(e[:, 0] @ e[:, 1]), float(e[:, 0] @ e[:, 0]) - float(e[:, 1] @ e[:, 1]))
    u = np.array([math.cos(theta), math.sin(theta)])  # principal axis
    v = np.array([-u[1], u[0]])
    t_own = e @ u
    lo, hi = float(t_own.min()), float(t_own.max())
    rel = support - centre
    t = rel @ u
    near = (np.abs(rel @ v) <= config.line_tolerance_m) & (t >= lo - config.door_length_max_m) & (
        t <= hi + config.door_length_max_m) & ((t < lo) | (t > hi))
    if not near.any():
        return cluster
    cand = np.flatnonzero(near)
    keep = np.zeros(cand.size, dtype=bool)
    for side, edge in ((t[cand] < lo, lo), (t[cand] > hi, hi)):
        idx = np.flatnonzero(side)
        if idx.size == 0:
            continue
        dist = np.abs(t[cand[idx]] - edge)
        order = np.argsort(dist)
        steps = np.diff(np.concatenate([[0.0], dist[order]]))
        run = int(np.argmax(steps >= config.cluster_distance_m)) if (steps >= config.cluster_distance_m).any() \
            else order.size
        keep[idx[order[:run]]] = True
    return np.concatenate([cluster, support[cand[keep]]])


def extract_leaves(points: npt.ArrayLike, config: DoorDetectionConfig, instance: int = 0,
                   pass_index: int = 0, source: int = SOURCE_TRANSIENT,
                   support: npt.ArrayLike | None = None) -> Leaves:
    """Potential door leaves among the dynamic points of one time instance: eq. (1) clusters, eq. (2) line
    objects, and the length gate [λmin, λmax].

    ``support``: other points of the same scan that may complete a cluster along its line
    (:func:`complete_line`). The transient neighbourhood rule turns the points of a leaf within r cells of
    static structure into static ones — at the hinge always, at the door stop for a closed leaf, and
    along any other state of the leaf near the hinge (0.2 m / sin α of a leaf at α from it) — so the
    dynamic part alone is short of the leaf, often short of λmin. The caller passes the points in cells
    that were seen free and held no structure known before the pass: the rest of the leaf, not a wall.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    extra = np.zeros((0, 2)) if support is None else np.asarray(support, dtype=np.float64).reshape(-1, 2)
    if pts.shape[0] < 2:
        return Leaves()
    # Set 2 loses the cells near the hinge that the leaf's state in this pass still hits (two states
    # overlap there over ~2 cells / sin Δ), so a fallen line may be shorter than its leaf: it only needs
    # to be a line (longer than δ); the door's length is checked from its hinge (group_doors).
    shortest = config.min_line_length_m if source == SOURCE_FALLEN else config.door_length_min_m
    span = pts.max(axis=0) - pts.min(axis=0)
    if extra.shape[0] == 0 and float(span @ span) < shortest**2:  # no pair long enough
        return Leaves()
    labels = cluster_points(pts, config.cluster_distance_m)
    counts = np.bincount(labels)
    segs = []
    for label in np.flatnonzero(counts >= 2):
        seg = fit_leaf(complete_line(pts[labels == label], extra, config), config)
        if seg is None:
            continue
        length = float(np.hypot(*(seg[1] - seg[0])))
        if shortest <= length <= config.door_length_max_m:
            segs.append(seg)
    if not segs:
        return Leaves()
    arr = np.stack(segs)
    n = arr.shape[0]
    return Leaves(arr[:, 0].copy(), arr[:, 1].copy(), np.full(n, instance, np.int64),
                  np.full(n, pass_index, np.int64), np.full(n, source, np.int64))


def scan_leaves(points: npt.ArrayLike, support: npt.ArrayLike | None, config: DoorDetectionConfig, instance: int,
                pass_index: int) -> Leaves:
    """:func:`extract_leaves` of one scan's dynamic points (set 1) in one compiled call
    (:func:`doorbatch.pipeline.gridmap.kernels.scan_leaves_kernel`): the per-scan path of the mapper."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
    extra = np.zeros((0, 2)) if support is None else np.ascontiguousarray(support, dtype=np.float64).reshape(-1, 2)
    if pts.shape[0] < 2:
        return Leaves()
    segs = np.empty((pts.shape[0], 2, 2))
    count = scan_leaves_kernel(pts, extra, config.cluster_distance_m, config.line_tolerance_m,
                               config.min_line_length_m, math.radians(config.max_line_angle_deg),
                               config.door_length_min_m, config.door_length_max_m, config.max_cluster_points, segs)
    if count == 0:
        return Leaves()
    arr = segs[:count]
    return Leaves(arr[:, 0].copy(), arr[:, 1].copy(), np.full(count, instance, np.int64),
                  np.full(count, pass_index, np.int64), np.full(count, SOURCE_TRANSIENT, np.int64))


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
    chained: bool = False  # both ends of some leaf in the group: which end is the hinge was a guess (_hinge_end)
    scan: IntArray | None = None  # the scan each leaf was seen in (set 1), −1 set 2, −2 static; None: all set 1

    def subset(self, keep: BoolArray) -> _Hinged:
        """The leaves where ``keep`` is True."""
        return _Hinged(self.leaf[keep], self.near[keep], self.far[keep], self.yaw[keep], self.when[keep], self.chained,
                       None if self.scan is None else self.scan[keep])

    def reversed(self) -> _Hinged:
        """The same leaves with the other end as the hinge-side one."""
        return _Hinged(self.leaf, self.far, self.near, np.asarray(wrap_angle(self.yaw + math.pi), dtype=np.float64),
                       self.when, self.chained, self.scan)

    def scans_of(self, keep: BoolArray) -> int:
        """In how many scans the leaves where ``keep`` is True were seen as dynamic points (set 1)."""
        if self.scan is None:
            return int(keep.sum())
        return int(np.unique(self.scan[keep & (self.scan >= 0)]).size)

    def scans_seen(self, config: DoorDetectionConfig) -> int:
        """In how many scans these leaves were seen: distinct scans of set 1, and ``lone_min_scans`` for any set-2 one
        (cells that held the leaf through a pass)."""
        fallen = self.scan is not None and bool((self.scan == -1).any())
        return self.scans_of(np.ones(self.leaf.size, dtype=bool)) + (config.lone_min_scans if fallen else 0)


def _when(leaves: Leaves) -> FloatArray:
    """The pass in which each leaf stood where it was seen (``pass_index``); a static partner at an unknown
    time (NaN)."""
    t = leaves.pass_index.astype(np.float64)
    return np.asarray(np.where(leaves.source == SOURCE_STATIC, np.nan, t), dtype=np.float64)


def _hinge_end(ends: FloatArray, others: FloatArray, radius: float, gap: float) -> tuple[FloatArray, int]:
    """The end point (of ``ends``; ``others`` the same leaves' other ends) where the most lines meet: the
    directions of the leaves with an end within ``radius`` of it, away from that end, folded onto lines (a
    direction and its opposite are one line: pieces of one straight leaf or wall continue each other through a
    door stop, which single linkage chains to the hinge), counted as :func:`angle_modes` with ``gap``; ties go
    to the end with the most others within ``radius``, where leaves share an end (the hinge), not where their
    free ends spread along an arc. A closed leaf chained to a wall seen moving beyond its door stop has its
    densest end there, and only its hinge meets another of its angles. Also how many lines meet there."""
    if ends.shape[0] <= 2:
        return np.asarray(ends[0], dtype=np.float64), 1
    tree = cKDTree(ends)
    counts = tree.query_ball_point(ends, radius, return_length=True)
    doubled = 2.0 * np.arctan2(others[:, 1] - ends[:, 1], others[:, 0] - ends[:, 0])  # lines: angles mod π

    def lines_at(i: int) -> int:
        return int(angle_modes(doubled[tree.query_ball_point(ends[i], radius)], 2.0 * gap).max()) + 1

    best = int(np.argmax(counts))
    best_score = (lines_at(best), int(counts[best]))
    _, first = np.unique(np.floor(ends / (radius / 4)).astype(np.int64), axis=0, return_index=True)
    for i in first.tolist():  # one candidate per quarter-radius cell: the ends of one hinge are all alike
        score = (lines_at(i), int(counts[i]))
        if score > best_score:
            best, best_score = i, score
    return np.asarray(ends[best], dtype=np.float64), best_score[0]


def _hinge_groups(leaves: Leaves, config: DoorDetectionConfig) -> list[_Hinged]:
    """Connected components of leaf end points closer than ``hinge_distance_m`` (each leaf counted once per
    component, by its end in the component). Where both ends of a leaf are in one component (single linkage
    chains a door's hinge to its free ends once many passes and partial leaves fill the sector between), the
    end nearer the component's hinge end (:func:`_hinge_end`) is the hinge-side one."""
    n = len(leaves)
    ends = np.concatenate([leaves.p0, leaves.p1])
    labels = cluster_points(ends, config.hinge_distance_m)
    owner = np.tile(np.arange(n), 2)
    twin = np.concatenate([np.arange(n, 2 * n), np.arange(n)])  # the index of each end's other end
    when = _when(leaves)
    groups = []
    for label in np.unique(labels):
        members = np.flatnonzero(labels == label)
        leaf, first, count = np.unique(owner[members], return_index=True, return_counts=True)
        end = members[first]
        other = twin[end]
        chained = bool((count > 1).any())
        if chained:
            hinge, lines = _hinge_end(ends[members], ends[twin[members]], config.hinge_distance_m,
                                      math.radians(config.angle_cluster_gap_deg))
            swap = (count > 1) & (np.hypot(*(ends[other] - hinge).T) < np.hypot(*(ends[end] - hinge).T))
            end, other = np.where(swap, other, end), np.where(swap, end, other)
            if lines > 1:  # a hinge where angles meet: a leaf whose near end lies over 2 hinge distances from it
                # (more than λmin / 2, config check) is chained on, no leaf of this hinge
                keep = np.hypot(*(ends[end] - hinge).T) <= 2.0 * config.hinge_distance_m
                leaf, end, other = leaf[keep], end[keep], other[keep]
        near, far = ends[end], ends[other]
        yaw = np.arctan2(far[:, 1] - near[:, 1], far[:, 0] - near[:, 0])
        source = leaves.source[leaf]
        scan = np.where(source == SOURCE_TRANSIENT, leaves.instance[leaf], np.where(source == SOURCE_FALLEN, -1, -2))
        groups.append(_Hinged(leaf, near, far, yaw, when[leaf], chained, scan))
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
    nx, ny = -np.sin(yaws), np.cos(yaws)
    axx, axy, ayy = float(nx @ nx), float(nx @ ny), float(ny @ ny)  # A = Σ n nᵀ (2 × 2, symmetric)
    mid, rad = (axx + ayy) / 2, math.hypot((axx - ayy) / 2, axy)
    if mid - rad <= (mid + rad) * 1e-6:  # condition number λmax / λmin > 1e6
        return None
    c = nx * points[:, 0] + ny * points[:, 1]
    bx, by = float(nx @ c), float(ny @ c)
    det = axx * ayy - axy * axy
    return np.array([(ayy * bx - axy * by) / det, (axx * by - axy * bx) / det])


def group_doors(leaves: Leaves, config: DoorDetectionConfig, grid: LogOddsGrid | None = None
                ) -> list[DetectedDoor]:
    """Paper 000, Sec. III: doors are leaves with a common hinge seen at ≥ 2 distinguishable angles.

    For each group of leaves whose end points are within ``hinge_distance_m``: the leaf directions are
    grouped into observed angles (:func:`angle_modes`); the hinge is where their lines cross (a group
    formed around the free ends of a small rotation is dropped, :func:`_hinge_estimate`). With a grid
    (``static_partner_search``), a group with one observed angle gets its other angle from the static grid
    (:func:`_lone_partner`), the closed direction comes from the wall behind the hinge
    (:func:`closed_direction`), and further observed angles come from the static grid
    (:func:`_static_states`, :func:`_closed_state`). The group is a door when two observed angles differ
    by ≥ ``min_opening_deg``, all lie within :func:`_max_span` of each other (office doors rotate at most
    180°; ``allow_swinging`` lifts this), the leaf keeps its length (``min_length_ratio``) and is a leaf's
    length [λmin, λmax] from the hinge, and two of the angles were seen in different passes
    (``require_distinct_passes``). Each leaf serves one door; groups with more observations are taken
    first.
    """
    if len(leaves) == 0:
        return []
    occupied, raw = (None, None) if grid is None else _occupied_masks(grid, config, leaves)
    gap = math.radians(config.angle_cluster_gap_deg)
    used = np.zeros(len(leaves), dtype=bool)
    doors: list[DetectedDoor] = []
    for g in sorted(_hinge_groups(leaves, config), key=lambda g: -g.leaf.size):
        free = ~used[g.leaf]
        if free.sum() < 1:
            continue
        door = _door_from_group(g.subset(free), gap, config, grid, occupied, raw)
        if door is not None:
            used[g.leaf] = True
            doors.append(door)
    return doors


@dataclass
class _Observed:
    """A door's observations while it is being built: per observation the hinge-side end, the free end,
    the direction, the pass it stood there (NaN: unknown) and its observed-angle label; and the angles."""

    near: FloatArray
    far: FloatArray
    yaw: FloatArray
    when: FloatArray
    labels: IntArray
    modes: FloatArray

    def add(self, near: FloatArray, far: FloatArray, when: float) -> None:
        """One more observed angle, seen once (a state found in the static grid)."""
        self.near = np.vstack([self.near, near[None]])
        self.far = np.vstack([self.far, far[None]])
        self.yaw = np.append(self.yaw, math.atan2(far[1] - near[1], far[0] - near[0]))
        self.when = np.append(self.when, when)
        self.labels = np.append(self.labels, self.modes.size)
        self.modes = np.append(self.modes, self.yaw[-1])

    def passes(self) -> set[int]:
        """The passes in which the leaf was seen at one of its angles."""
        return {int(t) for t in self.when if not math.isnan(t)}


def _door_from_group(g: _Hinged, gap: float, config: DoorDetectionConfig, grid: LogOddsGrid | None,
                     occupied: BoolArray | None, raw: BoolArray | None) -> DetectedDoor | None:
    """One hinge group as a door, or None (:func:`group_doors`); ``occupied``/``raw``: :func:`_occupied_masks`."""
    labels = angle_modes(g.yaw, gap)
    obs = _Observed(g.near, g.far, g.yaw, g.when, labels, _mode_yaws(g.yaw, labels))
    probes = (grid, occupied, raw) if (grid is not None and occupied is not None and raw is not None
                                       and config.static_partner_search) else None  # the static grid's evidence
    if probes is not None and obs.modes.size >= 2:
        door = _without_wall_angles(g, obs, gap, config, *probes)
        if door is not None:
            return door
    if obs.modes.size == 1:
        if probes is None or g.scans_seen(config) < config.lone_min_scans:
            return None
        grid, occupied, raw = probes
        if not _lone_partner(grid, occupied, raw, g, obs, config):
            if not g.chained:
                return None
            # Which end is the hinge was a guess (_hinge_groups, _hinge_end): the other end's turn. A closed leaf's
            # lines, cut short here and there, chain its hinge and its door stop into one group, and the door stop's
            # ends were the densest (an outside user's 1.2 m leaf whose open state is static: the door was missed).
            g = g.reversed()
            obs = _Observed(g.near, g.far, g.yaw, g.when, labels, _mode_yaws(g.yaw, labels))
            if not _lone_partner(grid, occupied, raw, g, obs, config):
                return None
    hinge = _hinge_estimate(obs.near, obs.far, obs.labels, obs.modes, config)
    if hinge is None:
        return None
    closed = _range_about(obs.modes)[0] if probes is None else closed_direction(*probes[:2], hinge, obs.modes, config)
    dist = np.hypot(obs.far[:, 0] - hinge[0], obs.far[:, 1] - hinge[1])
    if not _rigid(dist, obs, closed, config):
        return None
    if probes is not None:
        grid, occupied, _ = probes
        length = _leaf_length(dist, obs.yaw, closed, config)
        states = _static_states(grid, occupied, hinge, obs.modes, length, obs.passes(), config)
        for end, when in states:
            obs.add(hinge, end, when)
        start, span = _range_about(obs.modes)
        if states and np.min(np.abs(wrap_angle(closed - np.array([start, start + span])))) > gap:  # now inside
            closed = closed_direction(grid, occupied, hinge, obs.modes, config)
        if np.min(np.abs(wrap_angle(obs.modes - closed))) > gap:
            state = _closed_state(grid, hinge, closed, length, obs.passes(), config)
            if state is not None:
                obs.add(hinge, *state)
    start, span = _range_about(obs.modes)
    if not math.radians(config.min_opening_deg) <= span <= _max_span(config):
        return None
    if config.require_distinct_passes and not _moved_between_passes(obs.modes, obs.labels, obs.when, config):
        return None
    dist = np.hypot(obs.far[:, 0] - hinge[0], obs.far[:, 1] - hinge[1])
    length = _leaf_length(dist, obs.yaw, closed, config)
    if not config.door_length_min_m <= length <= config.door_length_max_m:  # [λmin, λmax], from the hinge
        return None
    # Positions along the observed arc (CCW from its start), shifted to the closed direction; not wrapped,
    # so a swinging door's range may exceed 180°. (The ε keeps the start itself at 0, not at 2π.)
    rel = float(wrap_angle(start - closed)) + np.mod(obs.modes - start + 1e-9, 2 * np.pi) - 1e-9
    return DetectedDoor(float(hinge[0]), float(hinge[1]), length, float(wrap_angle(closed)),
                        float(rel.min()), float(rel.max()), int(obs.yaw.size), True,
                        tuple(float(v) for v in wrap_angle(obs.modes)))


def _without_wall_angles(g: _Hinged, obs: _Observed, gap: float, config: DoorDetectionConfig, grid: LogOddsGrid,
                         occupied: BoolArray, raw: BoolArray) -> DetectedDoor | None:
    """The door of ``g`` without its angles along a wall (:func:`_on_walls`), when that door has an angle ``obs`` had
    not: a state the static grid holds, hit in the pass the wall line claims (its presence made that state "hit while
    the leaf stood elsewhere"): one door, two angles, one pass, so the line is the wall. Else None, and the angles
    stay (a leaf opened against a wall, 0.1 m from a corner)."""
    hinge = _hinge_estimate(obs.near, obs.far, obs.labels, obs.modes, config)
    if hinge is None:
        return None
    keep = ~_on_walls(grid, occupied, hinge, obs, g, config)[obs.labels]
    if keep.all() or not keep.any():
        return None
    door = _door_from_group(g.subset(keep), gap, config, grid, occupied, raw)
    if door is None:
        return None
    off = np.min(np.abs(wrap_angle(np.asarray(door.observed_yaws)[:, None] - obs.modes[None, :])), axis=1)
    return door if off.max() > gap else None


def _on_walls(grid: LogOddsGrid, occupied: BoolArray, hinge: FloatArray, obs: _Observed, g: _Hinged,
              config: DoorDetectionConfig) -> BoolArray:
    """Extension: which observed angles may be a wall seen out of place, not the leaf: seen as dynamic points in fewer
    than ``lone_min_scans`` scans (set 2 alone, a pass's cells that fell), with occupied cells (grown by a cell) in
    the static grid along ``partner_min_fraction`` of [L/3, 0.95 L] of the angle's line from the hinge and beyond its
    end (not :func:`_clear_beyond`); L is the group's leaf length (``length_quantile`` of its segments). A pass
    registered a cell off (scan matching 0.1 m off where a pass ends) hits a wall beside its place, and those cells
    fall in the next pass: a fallen line along the wall. Taken for a state of the door beside it, the wall behind the
    hinge became the door's closed direction: the door was mirrored and its sweep erased the wall (an outside user's
    skid-steer base). These are candidates (:func:`_without_wall_angles`)."""
    length = float(np.quantile(np.hypot(*(obs.far - obs.near).T), config.length_quantile))
    along = _ray_fraction(grid, occupied, hinge, obs.modes, length / 3, 0.95 * length) >= config.partner_min_fraction
    for k in np.flatnonzero(along):
        if g.scans_of(obs.labels == k) >= config.lone_min_scans:
            along[k] = False
            continue
        end = hinge + length * np.array([math.cos(obs.modes[k]), math.sin(obs.modes[k])])
        along[k] = not _clear_beyond(grid, occupied, hinge, end, config)
    return np.asarray(along, dtype=bool)


def _leaf_length(dist: FloatArray, yaw: FloatArray, closed: float, config: DoorDetectionConfig) -> float:
    """The ``length_quantile`` of the hinge → free end distances. A closed leaf is collinear with its wall,
    so its free end cannot be told from the wall beyond the door stop (wall cells beside a doorway may
    even hold dynamic points); the length comes from the observations that stand away from the closed
    direction, where the free end stands free (all, if there are none)."""
    away = np.abs(wrap_angle(yaw - closed)) >= math.radians(config.min_opening_deg)
    return float(np.quantile(dist[away] if away.any() else dist, config.length_quantile))


def _rigid(dist: FloatArray, obs: _Observed, closed: float, config: DoorDetectionConfig) -> bool:
    """A rigid leaf keeps its length: the median hinge → free end distance of each observed angle is at
    least ``min_length_ratio`` of the longest. Angles within ``min_opening_deg`` of the closed direction
    are left out when others remain (a closed leaf's free end runs on into the wall beyond the door stop)."""
    away = np.abs(wrap_angle(obs.modes - closed)) >= math.radians(config.min_opening_deg)
    keep = np.flatnonzero(away) if away.sum() >= 2 else np.arange(obs.modes.size)
    med = np.array([np.median(dist[obs.labels == k]) for k in keep])
    return bool(med.min() >= config.min_length_ratio * med.max())


def _lone_partner(grid: LogOddsGrid, occupied: BoolArray, raw: BoolArray, g: _Hinged, obs: _Observed,
                  config: DoorDetectionConfig) -> bool:
    """Extension for leaves seen at one angle only: their other state from the static grid, as a leaf-shaped
    occupied segment hinged at their common end (:func:`_static_partner`), or else as the closed leaf
    (:func:`_closed_state`, along the wall behind the hinge). Adds it to ``obs``; whether one was found."""
    partner = _static_partner(grid, occupied, raw, g, float(obs.modes[0]), obs.passes(), config)
    if partner is not None:
        obs.add(*partner)
        return True
    hinge = g.near.mean(axis=0)
    closed, wall_point = _wall_behind(grid, occupied, hinge, obs.modes, config)
    if wall_point is None:
        return False
    # The hinge is where the leaf's line meets the wall's (the leaf's near end may be cut short).
    crossing = intersect_lines(np.stack([((g.near + g.far) / 2).mean(axis=0), wall_point]),
                               np.array([float(obs.modes[0]), closed]))
    if crossing is not None and np.hypot(*(crossing - hinge)) <= config.hinge_distance_m:
        hinge = crossing
    length = float(np.quantile(np.hypot(*(g.far - g.near).T), config.length_quantile))
    state = _closed_state(grid, hinge, closed, length, obs.passes(), config)
    if state is None:
        return False
    obs.add(hinge, *state)
    return True


def _closed_state(grid: LogOddsGrid, hinge: FloatArray, closed: float, length: float, seen_in: set[int],
                  config: DoorDetectionConfig) -> tuple[FloatArray, float] | None:
    """Extension: the closed leaf as an observed angle when its cells never fell (the leaf that opened hid
    them). A closed leaf is flush with its wall, so it cannot be told from the wall by shape; it is told
    by time: along the closed direction over [L/3, L − 2 cells] (off the hinge and the door stop), at
    least ``partner_min_fraction`` of the samples (every half cell) have a cell within one cell that was
    hit, and none of those cells was last hit in a pass in which the leaf stood at another angle (a wall
    is hit in every pass that sees it; the doorway is empty, or hidden, while the leaf stands open).
    Returns (free end, the last pass the closed leaf was hit), or None."""
    res = grid.resolution_m
    s = np.arange(length / 3, length - 2 * res + 1e-9, res / 2)
    if s.size == 0:
        return None
    u = np.array([math.cos(closed), math.sin(closed)])
    centre = np.floor(grid.world_to_cell_float(hinge + s[:, None] * u)).astype(np.int64)
    h, w = grid.shape
    di, dj = np.meshgrid(np.arange(-1, 2), np.arange(-1, 2), indexing="ij")
    rows = np.clip(centre[:, 1, None] + di.reshape(1, -1), 0, h - 1)
    cols = np.clip(centre[:, 0, None] + dj.reshape(1, -1), 0, w - 1)
    hit = grid.hits[rows, cols] > 0
    if hit.any(axis=1).mean() < config.partner_min_fraction:
        return None
    passes = grid.pass_of_scan(grid.last_hit_scan[rows, cols][hit])
    # any, not half (_stood_when): a closed state seen as dynamic points in a pass is hit near its ends in that pass
    if seen_in & set(passes.tolist()):
        return None
    return hinge + length * u, float(passes.max())


def _static_states(grid: LogOddsGrid, occupied: BoolArray, hinge: FloatArray, modes: FloatArray, length: float,
                   seen_in: set[int], config: DoorDetectionConfig) -> list[tuple[FloatArray, float]]:
    """Extension: further observed angles of a door as leaf-shaped occupied segments in the static grid.

    A leaf seen in cells that were never seen free before, and never seen free afterwards (the leaf's
    later states hide them: a leaf opened 100° into a room, then 50°, leaves the 100° cells behind the
    50° leaf), is integrated as static and never joins either set of dynamic points; it is still an
    observed angle of the door, and a part of the opening range. Directions φ at 1° steps on either side of
    the observed arc, within the rotation limit (:func:`_max_span`, which also keeps off the wall behind the
    hinge) and farther than ``angle_cluster_gap_deg`` from the observed angles score the fraction of occupied
    cells (grown by a cell) along [2 cells, L − 1 cell]. Each run of directions scoring ≥ ``partner_min_fraction``
    gives one candidate, its best φ, checked by :func:`_leaf_end` (a line along φ that ends) and
    :func:`_stood_when` (not hit while the leaf stood at another angle), and kept if the arc of all angles stays
    within the limit. Returns the free end of each angle found, with the last pass its cells were hit.
    """
    res = grid.resolution_m
    gap = math.radians(config.angle_cluster_gap_deg)
    start, span = _range_about(modes)
    limit = _max_span(config)
    if span > limit:
        return []  # beyond the rotation limit already: no door (group_doors' span test)
    # Around the observed arc, on both sides: the closed direction may be wrong (a door at the back of a recess, whose
    # wall behind the hinge is hidden, took the recess corner's diagonal for it), and a state found beyond it says so
    # (the caller then chooses the closed direction again); a static line there that is not the leaf was hit in a
    # pass in which the leaf stood elsewhere (_stood_when).
    room = limit - span
    yaws = start - room + np.radians(np.arange(0.0, math.degrees(span + 2 * room) + 1e-9, 1.0))
    free_of_modes = np.min(np.abs(wrap_angle(yaws[:, None] - modes[None, :])), axis=1) > gap
    frac = _ray_fraction(grid, occupied, hinge, yaws, 2 * res, length - res)
    ok = (frac >= config.partner_min_fraction) & free_of_modes
    found: list[tuple[FloatArray, float]] = []
    lo, hi = _unwrapped_arc(start, span, yaws)  # the arc held so far, on the yaws' axis
    runs = np.split(np.arange(yaws.size), np.flatnonzero(np.diff(ok.astype(np.int8)) != 0) + 1)
    for run in sorted((r for r in runs if r.size and ok[r[0]]), key=lambda r: -float(frac[r].max())):  # none: no yaw
        tries, extent = _run_directions(run, frac, float(yaws[run[0]]), float(yaws[1] - yaws[0]), gap)
        end = None
        for phi in tries:
            end = _leaf_end(grid, occupied, hinge, phi, length, config, extent)
            if end is not None:
                break
        if end is None or np.hypot(*(end - hinge)) < config.min_length_ratio * length:
            continue
        phi = float(yaws[run[0]]) + float(wrap_angle(math.atan2(end[1] - hinge[1], end[0] - hinge[0]) - yaws[run[0]]))
        if max(hi, phi) - min(lo, phi) > _max_span(config):
            continue
        when = _stood_when(grid, hinge, end, seen_in)
        if when is None:
            continue
        lo, hi = min(lo, phi), max(hi, phi)
        found.append((end, when))
    return found


def _stood_when(grid: LogOddsGrid, hinge: FloatArray, end: FloatArray, seen_in: set[int]) -> float | None:
    """The last pass in which the cells of a static leaf state were hit (those beyond a third of its length:
    near the hinge all states share cells; the pass most of them were last hit in), or None if they were hit while
    the leaf stood at another angle (:func:`_hit_while_standing`; doors are stationary within a pass: a line hit then
    is something else)."""
    t = np.linspace(1 / 3, 1.0, 12)
    cells = grid.flat_index(hinge + t[:, None] * (end - hinge))
    last = grid.last_hit_scan.reshape(-1)[cells]
    last = last[last >= 0]
    if last.size == 0:
        return None
    passes = _hit_while_standing(grid.pass_of_scan(last), seen_in)
    if passes is None:
        return None
    return float(np.bincount(passes - passes.min()).argmax() + passes.min())


def _hit_while_standing(passes: IntArray, seen_in: set[int]) -> IntArray | None:
    """The passes in which a leaf state's cells were last hit, less those in which the leaf stood at another angle
    (``seen_in``); None when those are half of them or more: then the cells are something else, a wall (hit in every
    pass that sees it) or a person. Half, not any: a laser's stray returns (1.5 % random short ranges, sunlight) land
    on a few of a leaf state's cells through its doorway in a later pass, and that pass had made the state a wall."""
    elsewhere = np.isin(passes, np.fromiter(seen_in, dtype=np.int64, count=len(seen_in)))
    if elsewhere.mean() >= 0.5:
        return None
    return np.asarray(passes[~elsewhere], dtype=np.int64)


def _run_directions(run: IntArray, score: FloatArray, first: float, step: float, spacing: float
                    ) -> tuple[list[float], tuple[float, float]]:
    """A run of consecutive directions (``first``: the direction of its first index, ``step`` apart, in
    run order, which may wrap around the circle): directions to try, from the middle of its best-scoring
    ones outwards every ``spacing`` (a run may hold two states of a leaf a few degrees apart), and its
    extent, unwrapped."""
    best = np.flatnonzero(score[run] >= score[run].max() - 1e-9)
    middle = first + step * float(best[best.size // 2])
    lo, hi = first, first + step * (run.size - 1)
    k = np.arange(1, int((hi - lo) / max(spacing, 1e-9)) + 2)
    around = np.stack([middle - k * spacing, middle + k * spacing], axis=1).reshape(-1)
    return [middle, *(float(a) for a in around if lo <= a <= hi)], (lo, hi)


def _unwrapped_arc(start: float, span: float, axis: FloatArray) -> tuple[float, float]:
    """The arc [start, start + span] shifted by a multiple of 2π to overlap ``axis`` (monotone angles)."""
    mid = start + span / 2
    centre = float(axis[axis.size // 2]) if axis.size else mid
    shift = 2 * math.pi * round((centre - mid) / (2 * math.pi))
    return start + shift, start + span + shift


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
                    config: DoorDetectionConfig) -> FloatArray | None:
    """The hinge: least-squares intersection of the mean lines of the observed angles (the end points
    near the hinge are cut short by the transient neighbourhood rule, the lines are not); the mean of
    the near end points if that intersection is farther than ``hinge_distance_m`` from it. None when the
    lines cross at the other ends: for a small rotation the free ends lie within ``hinge_distance_m``
    too (2 L sin(Δ/2): 0.24 m for 0.9 m and 15°), and a leaf turns about its hinge, not its free end."""
    k = modes.size
    mids = (near + far) / 2
    sums = np.stack([np.bincount(labels, mids[:, c], minlength=k) for c in (0, 1)], axis=1).astype(np.float64)
    centre = sums / np.bincount(labels, minlength=k).astype(np.float64)[:, None]
    fallback = near.mean(axis=0)
    h = intersect_lines(centre, modes)
    if h is not None and np.hypot(*(h - far.mean(axis=0))) < np.hypot(*(h - fallback)):
        return None
    if h is None or np.hypot(*(h - fallback)) > config.hinge_distance_m:
        return np.asarray(fallback, dtype=np.float64)
    return h


# ------------------------------------------------------------------------------------------ grid probes


def _logit(p: float) -> float:
    return math.log(p / (1.0 - p))


def _occupied_masks(grid: LogOddsGrid, config: DoorDetectionConfig, leaves: Leaves | None = None
                    ) -> tuple[BoolArray, BoolArray]:
    """Occupied cells (p > p_occupied, hit in ``occupied_min_hits`` scans) grown by one cell, so probes tolerate a
    cell of misregistration, and as they are (a wall through a hinge, not beside it). With ``leaves``, only within
    2 λmax of them (where the probes from their hinges reach; zeros beyond)."""
    h, w = grid.shape
    i0, i1, j0, j1 = 0, h, 0, w
    if leaves is not None and len(leaves):
        ends = np.concatenate([leaves.p0, leaves.p1])
        lo = np.floor(grid.world_to_cell_float(ends.min(axis=0) - 2 * config.door_length_max_m)).astype(np.int64)
        hi = np.floor(grid.world_to_cell_float(ends.max(axis=0) + 2 * config.door_length_max_m)).astype(np.int64)
        j0, i0 = (int(v) for v in np.maximum(lo, 0))
        j1, i1 = (int(v) for v in np.minimum(hi + 1, [w, h]))
    grown = np.zeros((h, w), dtype=bool)
    raw = np.zeros((h, w), dtype=bool)
    if i1 > i0 and j1 > j0:
        raw[i0:i1, j0:j1] = (grid.log_odds[i0:i1, j0:j1] > np.float32(_logit(config.p_occupied))) & (
            grid.hits[i0:i1, j0:j1] >= config.occupied_min_hits)
        grown[i0:i1, j0:j1] = ndimage.maximum_filter(raw[i0:i1, j0:j1].view(np.uint8), size=3, mode="constant",
                                                     cval=0).view(bool)
    return grown, raw


def _ray_fraction(grid: LogOddsGrid, mask: BoolArray, start: FloatArray, yaws: FloatArray,
                  s0: float, s1: float) -> FloatArray:
    """Fraction of samples (every half cell) at distances [s0, s1] along each direction from ``start``
    that fall into True cells of ``mask`` (outside the grid counts as False); compiled
    (:func:`doorbatch.pipeline.gridmap.kernels.ray_fraction_kernel`)."""
    s = np.arange(s0, s1 + 1e-9, grid.resolution_m / 2)
    out = np.zeros(np.shape(yaws)[0])
    if s.size:
        ray_fraction_kernel(mask, grid.origin_x_m, grid.origin_y_m, 1.0 / grid.resolution_m, float(start[0]),
                            float(start[1]), np.ascontiguousarray(yaws, dtype=np.float64), s, out)
    return out


def _static_partner(grid: LogOddsGrid, occupied: BoolArray, raw: BoolArray, g: _Hinged, mode_yaw: float,
                    seen_in: set[int], config: DoorDetectionConfig) -> tuple[FloatArray, FloatArray, float] | None:
    """Extension: the leaf's other observed angle as an occupied segment in the static grid.

    For leaves seen at one angle only, with their shared end as the hinge: directions φ at 1° steps,
    between ``min_opening_deg`` and min(180°, ``max_rotation_deg``) − ``min_opening_deg`` from the leaf
    (nearly opposite is the wall going on behind the hinge), score the fraction of occupied cells (grown
    by a cell) along [2 cells, L − 1 cell] (L: the leaf's length). Runs of directions scoring
    ≥ ``partner_min_fraction``, best first, are refined by :func:`_refine_partner` (refitted from the
    refined hinge until it moves less than a cell, at most twice), which asks ``partner_end_clear_m`` beyond
    the partner's free end to hold no occupied cell (a wall would go on). A partner whose cells were hit in
    a pass in which the leaf stood at its one angle is something else (:func:`_stood_when`). Without one,
    the hinge is moved back along the leaf a cell at a time, up to ``partner_hinge_back_m``, and the search
    repeated: the leaf's near end is cut short where it meets the static hinge cells, and probed from that
    end, off the partner's line, the partner's directions score lopsided runs. Returns (hinge, free end, the
    last pass the partner's cells were hit), or None.
    """
    length = float(np.quantile(np.hypot(*(g.far - g.near).T), config.length_quantile))
    res = grid.resolution_m
    lo = math.radians(config.min_opening_deg)
    hi = min(math.pi - math.radians(config.min_opening_deg), _max_span(config))
    offsets = np.radians(np.arange(-180.0, 180.0, 1.0))
    yaws = mode_yaw + offsets[(np.abs(offsets) >= lo) & (np.abs(offsets) <= hi)]
    near = g.near.mean(axis=0)
    back = np.array([-math.cos(mode_yaw), -math.sin(mode_yaw)])  # from the near end away from the free end
    for step in np.arange(0.0, config.partner_hinge_back_m + 1e-9, res):
        found = _partner_from(grid, occupied, raw, g, mode_yaw, near + step * back, yaws, length, seen_in, config)
        if found is not None:
            return found
    return None


def _partner_from(grid: LogOddsGrid, occupied: BoolArray, raw: BoolArray, g: _Hinged, mode_yaw: float,
                  hinge: FloatArray,
                  yaws: FloatArray, length: float, seen_in: set[int], config: DoorDetectionConfig
                  ) -> tuple[FloatArray, FloatArray, float] | None:
    """:func:`_static_partner`'s search from one hinge guess."""
    res = grid.resolution_m
    frac = _ray_fraction(grid, occupied, hinge, yaws, 2 * res, length - res)
    # Clear beyond the partner is tested at its own free end (_refine_partner), not at the lone leaf's length: a
    # leaf seen at one angle is cut short where its ends meet static cells (a closed leaf at both jambs, 0.12 m
    # of a 0.9 m leaf in an outside tester's world), and its open state, longer by that much, failed the test.
    ok = frac >= config.partner_min_fraction
    breaks = (np.diff(ok.astype(np.int8)) != 0) | (np.diff(yaws) > math.radians(1.5))  # the gap about the leaf
    runs = np.split(np.arange(yaws.size), np.flatnonzero(breaks) + 1)
    gap = math.radians(config.angle_cluster_gap_deg)
    for run in sorted((r for r in runs if r.size and ok[r[0]]), key=lambda r: -float(frac[r].max())):  # none: no yaw
        tries, extent = _run_directions(run, frac, float(yaws[run[0]]), math.radians(1.0), gap)
        for phi in tries:
            found = _refine_partner(grid, occupied, g, mode_yaw, hinge, phi, length, config, extent)
            # The refined hinge moves back along the leaf (its near end is cut short): refit from there,
            # along the direction found, until it moves less than a cell.
            for _ in range(2):
                if found is None or np.hypot(*(found[0] - hinge)) < res:
                    break
                d = found[1] - found[0]
                again = _refine_partner(grid, occupied, g, mode_yaw, found[0], math.atan2(d[1], d[0]), length,
                                        config)
                hinge, found = found[0], again if again is not None else found
            if found is not None:
                d = found[1] - found[0]
                # occupied cells not grown: a wall through the hinge, not one beside it (a recess's side wall)
                behind = _ray_fraction(grid, raw, found[0], np.array([math.atan2(-d[1], -d[0])]), 2 * res,
                                       config.wall_probe_m)[0]
                when = None if behind >= config.wall_min_fraction else _stood_when(grid, *found, seen_in)
                if when is not None:
                    return found[0], found[1], when
                # hit while the leaf stood at its one angle, or going on through the hinge (a wall that ends at a
                # doorway, reached from a hinge guess stepped back onto it): not this run
                break
    return None


def _refine_partner(grid: LogOddsGrid, occupied: BoolArray, g: _Hinged, mode_yaw: float, hinge: FloatArray,
                    phi: float, length: float, config: DoorDetectionConfig,
                    within: tuple[float, float] | None = None) -> tuple[FloatArray, FloatArray] | None:
    """The occupied line along φ (:func:`_band_line`); the hinge is its intersection with the leaf's line
    (the leaf's near end may be cut short), the free end as :func:`_free_end`; None unless it is clear
    beyond the leaf (:func:`_clear_beyond`)."""
    fit = _band_line(grid, hinge, phi, length + config.partner_end_clear_m, config, within)
    if fit is None:
        return None
    pts, mean, d = fit
    lone_mid = ((g.near + g.far) / 2).mean(axis=0)
    refined = intersect_lines(np.stack([lone_mid, mean]), np.array([mode_yaw, math.atan2(d[1], d[0])]))
    if refined is not None and np.hypot(*(refined - hinge)) <= config.hinge_distance_m:
        hinge = refined
    end = _free_end(grid, pts, hinge, d, config)
    if not _clear_beyond(grid, occupied, hinge, end, config):
        return None
    return hinge, end


def _leaf_end(grid: LogOddsGrid, occupied: BoolArray, hinge: FloatArray, phi: float, length: float,
              config: DoorDetectionConfig, within: tuple[float, float] | None = None) -> FloatArray | None:
    """The free end of the occupied leaf along hinge + s·(cos φ, sin φ) (:func:`_band_line`,
    :func:`_free_end`), or None unless it is clear beyond the leaf (:func:`_clear_beyond`)."""
    fit = _band_line(grid, hinge, phi, length + config.partner_end_clear_m, config, within)
    if fit is None:
        return None
    end = _free_end(grid, fit[0], hinge, fit[2], config)
    return end if _clear_beyond(grid, occupied, hinge, end, config) else None


def _band_line(grid: LogOddsGrid, hinge: FloatArray, phi: float, reach: float, config: DoorDetectionConfig,
               within: tuple[float, float] | None = None) -> tuple[FloatArray, FloatArray, FloatArray] | None:
    """The occupied cells (p > ``p_occupied``) within two cells of the ray hinge + s·(cos φ, sin φ),
    s ∈ [2 cells, reach], as their mean end points; their mean and principal direction (pointing along φ).

    None with fewer than three cells, or when the direction differs from φ by more than
    ``angle_cluster_gap_deg``: a ray at a shallow angle to a wall runs inside the wall's grown cells for a
    leaf's length, but the cells it crossed line up with the wall, not with the ray. With ``within`` (the
    directions (lo, hi) of the run of directions φ came from), a fit that points elsewhere inside the run
    moves the band there (at most twice): probed from a point off the object's line (a hinge guess from a
    leaf cut short), a run is lopsided and its middle is off the object's direction. Compiled
    (:func:`doorbatch.pipeline.gridmap.kernels.band_line_kernel`).
    """
    res = grid.resolution_m
    side = 2 * math.ceil(reach / res) + 2
    out = np.empty((side * side, 2))
    lo, hi = within if within is not None else (0.0, 0.0)
    n, mx, my, dx, dy = band_line_kernel(grid.log_odds, grid.hits, grid.hit_sum, _logit(config.p_occupied),
                                         config.occupied_min_hits,
                                         float(hinge[0]), float(hinge[1]), grid.origin_x_m, grid.origin_y_m, res,
                                         phi, reach, math.radians(config.angle_cluster_gap_deg), within is not None,
                                         lo, hi, out)
    if n == 0:
        return None
    return out[:n] + hinge, np.array([mx, my]) + hinge, np.array([dx, dy])


def _clear_beyond(grid: LogOddsGrid, occupied: BoolArray, hinge: FloatArray, end: FloatArray,
                  config: DoorDetectionConfig) -> bool:
    """No occupied cell (grown by a cell) along hinge → end over ``partner_end_clear_m`` from three cells
    past the end (one for the growth, one for where in its last cell the leaf ends, one spare): a leaf
    ends there, a wall would go on (the line fit reaches no farther than L + ``partner_end_clear_m``, so
    a wall's "end" is followed by more wall)."""
    d = end - hinge
    s0 = float(np.hypot(*d)) + 3 * grid.resolution_m
    yaw = np.array([math.atan2(d[1], d[0])])
    return bool(_ray_fraction(grid, occupied, hinge, yaw, s0, s0 + config.partner_end_clear_m)[0] == 0.0)


def _free_end(grid: LogOddsGrid, pts: FloatArray, hinge: FloatArray, d: FloatArray,
              config: DoorDetectionConfig) -> FloatArray:
    """The last of the cells along d before a gap longer than ``partner_gap_m`` (a slanted leaf's cells are
    hit from grazing angles and some stay below p_occupied), plus half a cell."""
    res = grid.resolution_m
    along = np.sort((pts - hinge) @ d)
    gaps = np.flatnonzero(np.diff(along) > max(config.partner_gap_m, 2 * res))
    return np.asarray(hinge + (float(along[gaps[0]] if gaps.size else along[-1]) + res / 2) * d, dtype=np.float64)


def closed_direction(grid: LogOddsGrid, occupied: BoolArray, hinge: FloatArray, modes: FloatArray,
                     config: DoorDetectionConfig) -> float:
    """The reference (closed) direction of a door (:func:`_wall_behind`)."""
    return _wall_behind(grid, occupied, hinge, modes, config)[0]


def _wall_behind(grid: LogOddsGrid, occupied: BoolArray, hinge: FloatArray, modes: FloatArray,
                 config: DoorDetectionConfig) -> tuple[float, FloatArray | None]:
    """The reference (closed) direction of a door: a closed leaf is flush with its wall, so the wall
    continues behind the hinge, opposite to the closed leaf.

    Directions φ at 1° steps score the fraction of occupied cells (grown by a cell) along
    hinge − s·(cos φ, sin φ), s ∈ [2 cells, ``wall_probe_m``]; each run of directions scoring
    ≥ ``wall_min_fraction`` is one wall, its direction a line fit to its cells (the grown cells score
    fully over a spread of directions). Among the walls whose closed direction lies outside the observed
    range (or within ``angle_cluster_gap_deg`` of its ends) and within the rotation limit of it, the one
    nearest to an end of the range wins (a perpendicular wall at the hinge scores too, but lies far from
    the range). An end of the observed range within ``angle_cluster_gap_deg`` of that wall's direction (one
    angle, as the leaf's observations cluster) is the leaf seen closed, and its direction is the closed one: a
    leaf's length of cells says it better than ``wall_probe_m`` of a wall that may stand off the hinge, as behind a
    recessed frame (4.3° off in an outside tester's world). Without such a wall, the end of the observed range with
    the better score is used (paper 000 only asks for "a reference opening angle in global coordinates"). Returns
    the closed direction and a point on the wall's fitted line (None without a wall).
    """
    start, span = _range_about(modes)
    res = grid.resolution_m
    gap = math.radians(config.angle_cluster_gap_deg)
    ends = np.array([start, start + span])
    end_score = _ray_fraction(grid, occupied, hinge, ends + math.pi, 2 * res, config.wall_probe_m)
    limit = math.radians(min(config.max_rotation_deg, 360.0)) - span
    cand = start + span + np.radians(np.arange(0.0, 360.0, 1.0))  # CCW from the range end, once around
    score = _ray_fraction(grid, occupied, hinge, cand + math.pi, 2 * res, config.wall_probe_m)
    good = score >= config.wall_min_fraction
    if good.all() or not good.any():
        return float(wrap_angle(ends[int(np.argmax(end_score))])), None
    shift = int(np.argmin(good))  # start the runs at a direction that is not a wall: none wraps around
    order = np.roll(np.arange(cand.size), -shift)
    best: tuple[float, float, FloatArray | None] | None = None  # (distance to the range, direction, wall point)
    for run in np.split(order, np.flatnonzero(np.diff(good[order].astype(np.int8)) != 0) + 1):
        if not good[run[0]]:
            continue
        tries, (lo, hi) = _run_directions(run, score, float(cand[run[0]]), math.radians(1.0), gap)
        phi = tries[0]
        fit = _band_line(grid, hinge, phi + math.pi, config.wall_probe_m, config, (lo + math.pi, hi + math.pi))
        point = None
        if fit is not None:
            phi = math.atan2(-fit[2][1], -fit[2][0])
            point = fit[1]
        if np.min(np.abs(wrap_angle(phi + math.pi - modes))) <= gap:
            continue  # the cells behind are the leaf itself, at one of its angles (a recess hides the wall there)
        beyond_end = float(np.mod(phi - (start + span) + gap, 2 * np.pi)) - gap  # CCW past the range end
        before_start = 2 * np.pi - span - beyond_end  # CW before its start
        if before_start < -gap or min(beyond_end, before_start) > limit:
            continue  # inside the observed range, or farther from it than a door turns
        dist = max(0.0, min(beyond_end, before_start))
        if best is None or dist < best[0]:
            best = (dist, phi, point)
    if best is not None:
        phi = best[1]
        off = np.abs(wrap_angle(ends - phi))
        if off.min() <= gap:  # one angle with the wall's (angle_cluster_gap_deg): the leaf seen closed says it best
            phi = float(ends[int(np.argmin(off))])
        return float(wrap_angle(phi)), best[2]
    return float(wrap_angle(ends[int(np.argmax(end_score))])), None


# ------------------------------------------------------------------------------------------ static map


def swept_cells(grid: LogOddsGrid, door: DetectedDoor, margin_m: float, thickness_m: float = 0.0) -> BoolArray:
    """(H, W) mask of the cells whose centres lie in the sector the leaf swept over its observed range
    (radius = leaf length, angles [angle_min, angle_max] about closed_yaw), or within ``margin_m`` of
    the leaf at either end of the range, or within ``margin_m + thickness_m`` of its line alongside it there,
    from that far from the hinge to ``margin_m`` past its free end (the fitted line may lie on either face of a
    leaf seen from one side; its other face's cells are that much farther)."""
    mask = np.zeros(grid.shape, dtype=bool)
    mask.reshape(-1)[_swept_flat(grid, door, margin_m, thickness_m)] = True
    return mask


def _swept_flat(grid: LogOddsGrid, door: DetectedDoor, margin_m: float, thickness_m: float = 0.0) -> IntArray:
    """Flat indices of :func:`swept_cells` (computed in the door's box only)."""
    h, w = grid.shape
    res = grid.resolution_m
    reach = door.length + margin_m + thickness_m + res
    c0 = np.floor(grid.world_to_cell_float([door.hinge_x - reach, door.hinge_y - reach])).astype(np.int64)
    c1 = np.floor(grid.world_to_cell_float([door.hinge_x + reach, door.hinge_y + reach])).astype(np.int64)
    j0, i0 = np.maximum(c0, 0)
    j1, i1 = np.minimum(c1, [w - 1, h - 1])
    if j1 < j0 or i1 < i0:
        return np.zeros(0, dtype=np.int64)
    jj, ii = np.meshgrid(np.arange(j0, j1 + 1), np.arange(i0, i1 + 1))
    px = grid.origin_x_m + (jj + 0.5) * res - door.hinge_x
    py = grid.origin_y_m + (ii + 0.5) * res - door.hinge_y
    r = np.hypot(px, py)
    a = wrap_angle(np.arctan2(py, px) - door.closed_yaw)
    inside = (r <= door.length) & (a >= door.angle_min) & (a <= door.angle_max)
    for ang in (door.angle_min, door.angle_max):
        u = (math.cos(door.closed_yaw + ang), math.sin(door.closed_yaw + ang))
        along = px * u[0] + py * u[1]
        t = np.clip(along, 0.0, door.length)
        inside |= np.hypot(px - t * u[0], py - t * u[1]) <= margin_m
        # alongside the leaf only: not past its free end by more than margin_m (the far jamb of a closed leaf stays),
        # nor within the band's width of the hinge (the wall the door hangs in, across an open leaf there)
        band = margin_m + thickness_m
        inside |= (along >= band) & (along <= door.length + margin_m) & (np.abs(px * u[1] - py * u[0]) <= band)
    return np.asarray((ii * w + jj)[inside], dtype=np.int64)


def remove_leaves(grid: LogOddsGrid, doors: list[DetectedDoor], config: DoorDetectionConfig,
                  grid_config: GridConfig) -> LogOddsGrid:
    """Take the door leaves out of the static grid (in place; returns the grid).

    Cells the leaf swept over its observed range become free where they were ever seen free, unknown
    elsewhere (their hits are forgotten). The hinge stays: occupied cells within ``hinge_keep_m`` of it are
    kept, and the cell holding the hinge becomes occupied.
    """
    if not doors:
        return grid
    threshold = np.float32(_logit(config.p_occupied))
    parts = []
    for door in doors:
        flat = _swept_flat(grid, door, config.sweep_margin_m, config.leaf_thickness_m)
        near_hinge = np.hypot(*(grid.cell_centers(flat) - (door.hinge_x, door.hinge_y)).T) <= config.hinge_keep_m
        parts.append(flat[~(near_hinge & (grid.log_odds.reshape(-1)[flat] > threshold))])
    swept = np.unique(np.concatenate(parts))
    free = seen_free(grid, swept, grid_config)
    grid.log_odds.reshape(-1)[swept[free]] = np.float32(grid_config.l_min)
    unknown = swept[~free]
    grid.log_odds.reshape(-1)[unknown] = 0.0
    grid.hits.reshape(-1)[unknown] = 0
    grid.hit_sum.reshape(-1)[unknown] = 0
    grid.seen_occupied.reshape(-1)[swept] = False
    for door in doors:
        if grid.contains([door.hinge_x, door.hinge_y]):
            k = int(grid.flat_index([door.hinge_x, door.hinge_y]))
            grid.log_odds.reshape(-1)[k] = np.float32(grid_config.l_max)
            grid.hits.reshape(-1)[k] = max(1, int(grid.hits.reshape(-1)[k]))
    return grid
