"""Door state update of the RBPF (paper 000, Sec. IV, step 3 and Fig. 3).

Once per scan, the scan points (base_link, in scan order) are approximated by a polygon with the
Douglas–Peucker algorithm (:func:`douglas_peucker`). For every particle the polygon's segments are moved to
the particle's pose, and each door looks for its leaf among them (:func:`associate_segments`):

1. a segment with an end within ``door_hinge_gate_m`` of the hinge, a length within
   ``door_length_gate_ratio`` of the leaf's, and a direction (from its hinge end) inside the door's opening
   range widened by a margin;
2. otherwise (a door flush with its wall merges with it into one longer segment) a segment at least
   (1 − ratio)·L long that passes within ``door_flush_line_gate_m`` of the hinge, whose hinge's foot lies on
   it, and that extends at least (1 − ratio)·L beyond the foot in a direction inside the opening range.

The measured angle is that direction relative to closed_yaw, folded into the range's sense (the
representative of the angle nearest the middle of [angle_min, angle_max]). Each particle's door Kalman
filter then takes the measurement (:func:`kalman_update`); between scans the angles follow a random walk
(:func:`predict_doors`). :func:`update_doors` chains the three.

Per particle only the (segment, door) pairs that can pass the gates for *some* particle are evaluated: in
base_link, the hinge seen from particle i is R(θ_i)ᵀ(h − t_i); a pair whose segment stays farther than the
gates from the bounding box of these N points (or whose length fails both length rules) is dropped for all
particles at once. This is exact (it only drops pairs that fail for every particle) and leaves a few pairs
per door while tracking. The per-particle work is a numba kernel over particles × doors × candidate pairs, with
a NumPy reference on (particles, pairs) arrays; both give the same result.
"""

from __future__ import annotations

import math
from typing import Literal, NamedTuple

import numpy as np
import numpy.typing as npt

from doorbatch.config import LocalizeConfig
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.maps import DoorSet
from doorbatch.pipeline.localize.door_geometry import jit_kernel
from doorbatch.pipeline.localize.particles import ParticleSet

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
IntArray = npt.NDArray[np.intp]
Backend = Literal["auto", "numba", "numpy"]

DEFAULT_MAX_GAP_M = 0.3  # consecutive scan points farther apart than this break the polyline
DEFAULT_MIN_POINTS = 3  # scan points a segment must span
DEFAULT_ANGLE_MARGIN_RAD = math.radians(10.0)  # tolerance around the door's opening range
PAIR_CHUNK_ELEMENTS = 1 << 19  # (particle, pair) elements per chunk in associate_segments


class DoorUpdate(NamedTuple):
    """New door means and variances (N, D), which doors each particle observed (N, D), the measured angles
    (N, D; rad, 0 where not observed), and, where an update under a door prior computed it (the RBPF's global
    phase, doors at their prior), each measurement's log-evidence log p(z) (N, D; NaN elsewhere)."""

    mean: FloatArray
    var: FloatArray
    observed: BoolArray
    angle: FloatArray
    log_evidence: FloatArray | None = None


# --------------------------------------------------------------------------------------------- polygon


def douglas_peucker(points: npt.ArrayLike, epsilon_m: float, max_gap_m: float = DEFAULT_MAX_GAP_M,
                    min_points: int = DEFAULT_MIN_POINTS, fit_lines: bool = True, backend: Backend = "auto"
                    ) -> FloatArray:
    """Polyline of the scan points (Douglas–Peucker), as segments.

    Non-finite points are dropped; consecutive points farther apart than ``max_gap_m`` start a new
    polyline. Within each polyline, the range between two vertices is split at its point farthest from the
    chord (distance to the chord segment; the first such point on ties) while that distance exceeds
    ``epsilon_m``. The numba kernel does this with an explicit stack; the NumPy reference splits all open
    ranges together, one level per iteration. Both give the same vertices.

    Args:
        points: (M, 2) scan points in scan order (base_link).
        epsilon_m: DP tolerance (``dp_epsilon_m``).
        max_gap_m: Polyline break distance.
        min_points: Segments spanning fewer scan points are dropped (at least 2).
        fit_lines: Replace each segment by the total-least-squares line through all its points, cut at the
            projections of its first and last point (a less noisy direction than the two vertices alone).
        backend: ``numba``, ``numpy`` or ``auto`` (numba when installed).

    Returns:
        (K, 2, 2) segments [[x0, y0], [x1, y1]] in scan order.

    Raises:
        ValueError: ``backend='numba'`` without numba.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    pts = np.ascontiguousarray(pts[np.isfinite(pts).all(axis=1)])
    kernel = jit_kernel(_dp_kernel) if backend in ("auto", "numba") else None
    if kernel is None and backend == "numba":
        raise ValueError("backend 'numba' asked for but numba is not installed (pip install numba)")
    if pts.shape[0] < 2:
        return np.zeros((0, 2, 2))
    if kernel is not None:
        out: FloatArray = kernel(pts[:, 0].copy(), pts[:, 1].copy(), float(epsilon_m), float(max_gap_m),
                                 max(int(min_points), 2), bool(fit_lines))
        return out
    a, b = _dp_vertices_numpy(pts, epsilon_m, max_gap_m, min_points)
    return _fit_segments(pts, a, b) if fit_lines else np.stack([pts[a], pts[b]], axis=1)


def _dp_vertices_numpy(pts: FloatArray, epsilon_m: float, max_gap_m: float, min_points: int
                       ) -> tuple[IntArray, IntArray]:
    """NumPy reference of the DP split: first and last point index (a, b) of every kept segment."""
    m = pts.shape[0]
    x, y = pts[:, 0], pts[:, 1]
    breaks = (np.hypot(np.diff(x), np.diff(y)) > max_gap_m).nonzero()[0]
    run = np.zeros(m, dtype=np.intp)
    run[breaks + 1] = 1
    run = np.cumsum(run)
    keys = np.unique(np.concatenate([[0, m - 1], breaks, breaks + 1]))
    done = np.zeros(m, dtype=bool)  # done[a]: the range starting at vertex a needs no split
    idx = np.arange(m)
    while True:
        a, b = keys[:-1], keys[1:]
        open_ = (run[a] == run[b]) & (b - a >= 2) & ~done[a]
        if not open_.any():
            break
        r = np.searchsorted(keys, idx, side="right") - 1  # range of each point: [a_r, b_r)
        r[-1] = a.shape[0] - 1
        ar, br = a[r], b[r]
        ex, ey = x[br] - x[ar], y[br] - y[ar]
        px, py = x - x[ar], y - y[ar]
        t = np.minimum(np.maximum((px * ex + py * ey) / np.maximum(ex * ex + ey * ey, 1e-300), 0.0), 1.0)
        dist = np.hypot(px - t * ex, py - t * ey)
        dist[~open_[r] | (idx == ar) | (idx == br)] = -1.0
        gmax = np.maximum.reduceat(dist, a)  # max over each range [a_j, a_{j+1})
        split = open_ & (gmax > epsilon_m)
        done[a[open_ & ~split]] = True
        if not split.any():
            break
        new = ((dist == gmax[r]) & split[r]).nonzero()[0]
        new = new[np.concatenate([[True], r[new][1:] != r[new][:-1]])]  # the first farthest point per range
        keys = np.sort(np.concatenate([keys, new]))
    a, b = keys[:-1], keys[1:]
    keep = (run[a] == run[b]) & (b - a + 1 >= max(min_points, 2))
    return a[keep], b[keep]


def _dp_kernel(x: FloatArray, y: FloatArray, epsilon_m: float, max_gap_m: float, min_points: int,
               fit_lines: bool) -> FloatArray:  # pragma: no cover - compiled by numba
    """Numba kernel: DP with an explicit stack per polyline, then the segments (optionally line-fitted)."""
    m = x.shape[0]
    vertex = np.zeros(m, dtype=np.bool_)
    run_end = np.zeros(m, dtype=np.bool_)  # last point of a polyline
    stack = np.empty((m + 1, 2), dtype=np.int64)
    start = 0
    for i in range(1, m + 1):
        if i < m and math.hypot(x[i] - x[i - 1], y[i] - y[i - 1]) <= max_gap_m:
            continue
        end = i - 1
        vertex[start] = True
        vertex[end] = True
        run_end[end] = True
        stack[0, 0] = start
        stack[0, 1] = end
        top = 1
        while top > 0:
            top -= 1
            a = stack[top, 0]
            b = stack[top, 1]
            if b - a < 2:
                continue
            ex = x[b] - x[a]
            ey = y[b] - y[a]
            ee = max(ex * ex + ey * ey, 1e-300)
            best = -1.0
            split = -1
            for j in range(a + 1, b):
                px = x[j] - x[a]
                py = y[j] - y[a]
                t = min(max((px * ex + py * ey) / ee, 0.0), 1.0)
                d = math.hypot(px - t * ex, py - t * ey)
                if d > best:
                    best = d
                    split = j
            if best > epsilon_m:
                vertex[split] = True
                stack[top, 0] = split
                stack[top, 1] = b
                stack[top + 1, 0] = a
                stack[top + 1, 1] = split
                top += 2
        start = i
    out = np.empty((m, 2, 2))
    k = 0
    a = 0
    for b in range(1, m):
        if not vertex[b]:
            continue
        if not run_end[a] and b - a + 1 >= min_points:  # a run end starts no segment (a break follows)
            if fit_lines:
                ox = x[a]
                oy = y[a]
                n = b - a + 1
                sx = sy = sxx = sxy = syy = 0.0
                for j in range(a, b + 1):
                    qx = x[j] - ox
                    qy = y[j] - oy
                    sx += qx
                    sy += qy
                    sxx += qx * qx
                    sxy += qx * qy
                    syy += qy * qy
                cx = sx / n
                cy = sy / n
                phi = 0.5 * math.atan2(2.0 * (sxy / n - cx * cy), (sxx / n - cx * cx) - (syy / n - cy * cy))
                dx = math.cos(phi)
                dy = math.sin(phi)
                ta = (x[a] - ox - cx) * dx + (y[a] - oy - cy) * dy
                tb = (x[b] - ox - cx) * dx + (y[b] - oy - cy) * dy
                out[k, 0, 0] = ox + cx + ta * dx
                out[k, 0, 1] = oy + cy + ta * dy
                out[k, 1, 0] = ox + cx + tb * dx
                out[k, 1, 1] = oy + cy + tb * dy
            else:
                out[k, 0, 0] = x[a]
                out[k, 0, 1] = y[a]
                out[k, 1, 0] = x[b]
                out[k, 1, 1] = y[b]
            k += 1
        a = b
    return out[:k].copy()


def _fit_segments(pts: FloatArray, a: IntArray, b: IntArray) -> FloatArray:
    """Total-least-squares line through points a..b (inclusive) of each segment, cut at pts[a] and pts[b]."""
    origin = pts.mean(axis=0)
    q = pts - origin
    moments = np.stack([np.ones(q.shape[0]), q[:, 0], q[:, 1], q[:, 0] ** 2, q[:, 0] * q[:, 1], q[:, 1] ** 2], axis=1)
    cum = np.vstack([np.zeros(6), np.cumsum(moments, axis=0)])
    s = cum[b + 1] - cum[a]  # sums over a..b
    n = s[:, 0]
    cx, cy = s[:, 1] / n, s[:, 2] / n
    sxx = s[:, 3] / n - cx * cx
    sxy = s[:, 4] / n - cx * cy
    syy = s[:, 5] / n - cy * cy
    phi = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)  # principal axis
    d = np.stack([np.cos(phi), np.sin(phi)], axis=1)
    c = np.stack([cx, cy], axis=1)
    ends = np.stack([q[a], q[b]], axis=1)  # (K, 2, 2)
    along = np.sum((ends - c[:, None]) * d[:, None], axis=2)
    return np.asarray(c[:, None] + along[:, :, None] * d[:, None] + origin, dtype=np.float64)


# ----------------------------------------------------------------------------------------- association


def _fold(rel: FloatArray, mid: FloatArray) -> FloatArray:
    """The representative of each angle nearest ``mid`` (the middle of the door's range)."""
    return mid + wrap_angle(rel - mid)


def associate_segments(segments_base: npt.ArrayLike, pose: npt.ArrayLike, doors: DoorSet,
                       door_mean: npt.ArrayLike, config: LocalizeConfig,
                       angle_margin_rad: float = DEFAULT_ANGLE_MARGIN_RAD,
                       backend: Backend = "auto") -> tuple[FloatArray, BoolArray]:
    """Observed door angles per particle from the scan's segments (Fig. 3 of paper 000).

    Among the candidates of a door, the leaf segment with the lowest (hinge distance / gate)² +
    (length error / ratio gate)² wins; failing any, the flush segment passing closest to the hinge.

    Args:
        segments_base: (K, 2, 2) segments in base_link (from :func:`douglas_peucker`).
        pose: (N, 3) particle poses (x, y, yaw) in the map frame.
        doors: D doors.
        door_mean: (N, D) the particles' door angle means: when a flush segment could be read both ways
            round (both directions inside the range), the reading nearer the mean is taken.
        config: ``door_hinge_gate_m``, ``door_length_gate_ratio``, ``door_flush_line_gate_m``.
        angle_margin_rad: How far outside [angle_min, angle_max] a measured angle may lie.
        backend: ``numba`` (kernel over particles × doors × candidate segments), ``numpy`` (reference,
            (n, P) arrays per chunk of particles), ``auto`` (numba when installed).

    Returns:
        ``(angle, mask)``, each (N, D): the measured angle (rad, relative to closed_yaw, folded into the
        range's sense; 0 where unobserved) and whether door d was observed from particle i.

    Raises:
        ValueError: ``backend='numba'`` without numba.
    """
    angle, kind = _associate(segments_base, pose, doors, door_mean, config, angle_margin_rad, backend)
    return angle, kind > 0


def leaves_outside_range(points_base: npt.ArrayLike, pose: npt.ArrayLike, doors: DoorSet, config: LocalizeConfig,
                         behind_hinge_rad: float) -> FloatArray:
    """(D,) the angle (rad, relative to closed_yaw, within ±(π − ``behind_hinge_rad``)) at which each door's leaf
    is seen from ``pose`` outside its opening range widened by ``door_angle_margin_deg``, NaN where it is not: the
    scan's polygon (:func:`douglas_peucker`) associated as for the door update, but with every direction allowed
    but those within ``behind_hinge_rad`` of the closed direction's opposite (the wall beyond the hinge, which
    would otherwise win the match over the leaf), and leaf segments only (an end at the hinge, the leaf's
    length). A door map older than the log (a door opened further than while mapping, a double-acting door swung
    the other way) shows so."""
    segments = douglas_peucker(points_base, config.dp_epsilon_m, max_gap_m=config.dp_max_gap_m)
    n = len(doors)
    out = np.full(n, np.nan)
    if not n or not len(segments):
        return out
    reach = math.pi - behind_hinge_rad  # the wall beyond the hinge is no candidate: it would win over the leaf
    around = DoorSet(doors.hinge, doors.length, doors.closed_yaw, np.full(n, -reach), np.full(n, reach))
    angle, kind = _associate(segments, pose, around, np.zeros((1, n)), config, 0.0, "auto")
    a = wrap_angle(angle[0])
    margin = math.radians(config.door_angle_margin_deg)
    outside = (kind[0] == 1) & ((a < doors.angle_min - margin) | (a > doors.angle_max + margin))
    out[outside] = a[outside]
    return out


def _associate(segments_base: npt.ArrayLike, pose: npt.ArrayLike, doors: DoorSet, door_mean: npt.ArrayLike,
               config: LocalizeConfig, margin: float, backend: Backend) -> tuple[FloatArray, npt.NDArray[np.int8]]:
    """:func:`associate_segments` with the kind of match: 0 none, 1 leaf segment, 2 flush segment."""
    segs = np.asarray(segments_base, dtype=np.float64).reshape(-1, 2, 2)
    segs = segs[np.hypot(*(segs[:, 1] - segs[:, 0]).T) > 0.0]  # a zero-length segment has no direction
    poses = np.ascontiguousarray(np.asarray(pose, dtype=np.float64).reshape(-1, 3))
    mean = np.ascontiguousarray(door_mean, dtype=np.float64)
    n, n_doors = poses.shape[0], len(doors)
    if mean.shape != (n, n_doors):
        raise ValueError(f"door_mean {mean.shape} must be (N, D) = ({n}, {n_doors})")
    kernel = jit_kernel(_associate_kernel) if backend in ("auto", "numba") else None
    if kernel is None and backend == "numba":
        raise ValueError("backend 'numba' asked for but numba is not installed (pip install numba)")
    angle = np.zeros((n, n_doors))
    kind = np.zeros((n, n_doors), dtype=np.int8)
    if n == 0 or n_doors == 0 or segs.shape[0] == 0:
        return angle, kind
    pairs = _candidate_pairs(segs, poses, doors, config)
    if pairs.shape[0] == 0:
        return angle, kind
    if kernel is not None:
        pairs = pairs[np.argsort(pairs[:, 1], kind="stable")]
        offsets = np.searchsorted(pairs[:, 1], np.arange(n_doors + 1)).astype(np.int64)
        vec = segs[:, 1] - segs[:, 0]
        kernel(np.ascontiguousarray(segs), np.ascontiguousarray(pairs[:, 0], dtype=np.int64), offsets, poses,
               *(np.ascontiguousarray(a, dtype=np.float64) for a in (
                   doors.hinge, doors.length, doors.closed_yaw, doors.angle_min, doors.angle_max)),
               mean, float(config.door_hinge_gate_m), float(config.door_length_gate_ratio),
               float(config.door_flush_line_gate_m), float(margin), np.hypot(vec[:, 0], vec[:, 1]),
               np.arctan2(vec[:, 1], vec[:, 0]), angle, kind)
        return angle, kind
    step = max(1, PAIR_CHUNK_ELEMENTS // pairs.shape[0])
    for lo in range(0, n, step):  # chunks of particles (memory), not a per-particle loop
        sl = slice(lo, min(n, lo + step))
        angle[sl], kind[sl] = _associate_chunk(segs, poses[sl], doors, mean[sl], config, margin, pairs)
    return angle, kind


def _candidate_pairs(segs: FloatArray, poses: FloatArray, doors: DoorSet, config: LocalizeConfig) -> IntArray:
    """(P, 2) [segment, door] pairs that may pass the gates for some particle.

    Works in base_link: the hinge seen from particle i is R(θ_i)ᵀ(h − t_i); a pair is kept when the segment
    comes close enough to the bounding box of those N hinge positions (a lower bound of the distance for
    every particle) and its length passes the length gate of the leaf or of the flush case.
    """
    hinge = np.asarray(doors.hinge, dtype=np.float64).reshape(-1, 2)
    length = np.asarray(doors.length, dtype=np.float64)
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    dx, dy = hinge[:, 0, None] - poses[:, 0], hinge[:, 1, None] - poses[:, 1]  # (D, N)
    bx, by = c * dx + s * dy, c * dy - s * dx
    box_lo = np.stack([bx.min(axis=1), by.min(axis=1)], axis=1)  # (D, 2)
    box_hi = np.stack([bx.max(axis=1), by.max(axis=1)], axis=1)

    def box_distance(lo: FloatArray, hi: FloatArray) -> FloatArray:  # (K, 2) boxes vs the (D, 2) boxes
        gap = np.maximum(np.maximum(lo[:, None] - box_hi[None], box_lo[None] - hi[:, None]), 0.0)
        return np.asarray(np.hypot(gap[..., 0], gap[..., 1]), dtype=np.float64)

    end_dist = np.minimum(box_distance(segs[:, 0], segs[:, 0]), box_distance(segs[:, 1], segs[:, 1]))
    seg_dist = box_distance(segs.min(axis=1), segs.max(axis=1))
    ratio = config.door_length_gate_ratio
    seg_len = np.hypot(*(segs[:, 1] - segs[:, 0]).T)[:, None]
    primary = (np.abs(seg_len - length) < ratio * length) & (end_dist < config.door_hinge_gate_m)
    flush = (seg_len >= (1.0 - ratio) * length) & (
        seg_dist <= config.door_hinge_gate_m + config.door_flush_line_gate_m)
    k, d = np.nonzero(primary | flush)
    return np.stack([k, d], axis=1)


def _associate_chunk(segs: FloatArray, poses: FloatArray, doors: DoorSet, mean: FloatArray,
                     config: LocalizeConfig, margin: float, pairs: IntArray) -> tuple[FloatArray, npt.NDArray[np.int8]]:
    """NumPy reference of the association for a chunk of particles over the candidate pairs (n, P)."""
    k, d = pairs[:, 0], pairs[:, 1]
    n, n_doors = poses.shape[0], mean.shape[1]
    gate_h, ratio, gate_line = config.door_hinge_gate_m, config.door_length_gate_ratio, config.door_flush_line_gate_m
    hinge = np.asarray(doors.hinge, dtype=np.float64)[d]  # (P, 2)
    length = np.asarray(doors.length, dtype=np.float64)[d]
    closed = np.asarray(doors.closed_yaw, dtype=np.float64)[d]
    lo_a = np.asarray(doors.angle_min, dtype=np.float64)[d] - margin
    hi_a = np.asarray(doors.angle_max, dtype=np.float64)[d] + margin
    mid = 0.5 * (lo_a + hi_a)
    seg_vec = segs[k, 1] - segs[k, 0]
    seg_len = np.hypot(seg_vec[:, 0], seg_vec[:, 1])  # (P,)
    seg_dir = np.arctan2(seg_vec[:, 1], seg_vec[:, 0])
    # The pairs' segment ends moved to every particle pose, relative to the hinge: (n, P) each.
    c, s = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]
    tx, ty = poses[:, 0, None] - hinge[:, 0], poses[:, 1, None] - hinge[:, 1]
    r0x = c * segs[k, 0, 0] - s * segs[k, 0, 1] + tx
    r0y = s * segs[k, 0, 0] + c * segs[k, 0, 1] + ty
    r1x = c * segs[k, 1, 0] - s * segs[k, 1, 1] + tx
    r1y = s * segs[k, 1, 0] + c * segs[k, 1, 1] + ty
    d0, d1 = np.sqrt(r0x * r0x + r0y * r0y), np.sqrt(r1x * r1x + r1y * r1y)
    heading = seg_dir + poses[:, 2, None] - closed  # direction end 0 → end 1, relative to closed_yaw

    # 1. The leaf itself: an end at the hinge, the leaf's length, a direction inside the range.
    rel = _fold(heading + np.where(d1 < d0, np.pi, 0.0), mid)
    len_err = np.abs(seg_len - length) / length
    near = np.minimum(d0, d1)
    ok = (near < gate_h) & (len_err < ratio) & (rel >= lo_a) & (rel <= hi_a)
    cost = np.where(ok, (near / gate_h) ** 2 + (len_err / ratio) ** 2, np.inf)

    # 2. Flush with the wall: a longer segment through the hinge, reaching (1 − ratio)·L beyond it.
    ex, ey = seg_vec[:, 0] / seg_len, seg_vec[:, 1] / seg_len
    ux, uy = c * ex - s * ey, s * ex + c * ey
    along = -(r0x * ux + r0y * uy)  # foot of the hinge, from end 0 towards end 1
    perp = np.abs(r0x * uy - r0y * ux)
    reach = (1.0 - ratio) * length
    close = (perp < gate_line) & (along >= -gate_h) & (along <= seg_len + gate_h) & (seg_len >= reach)
    fwd = _fold(heading, mid)  # the leaf towards end 1
    bwd = _fold(heading + np.pi, mid)  # towards end 0
    fwd_ok = close & (seg_len - along >= reach) & (fwd >= lo_a) & (fwd <= hi_a)
    bwd_ok = close & (along >= reach) & (bwd >= lo_a) & (bwd <= hi_a)
    m_d = mean[:, d]
    use_bwd = bwd_ok & (~fwd_ok | (np.abs(wrap_angle(bwd - m_d)) < np.abs(wrap_angle(fwd - m_d))))
    flush_rel = np.where(use_bwd, bwd, fwd)
    flush_cost = np.where(fwd_ok | bwd_ok, perp / gate_line, np.inf)

    angle = np.zeros((n, n_doors))
    kind = np.zeros((n, n_doors), dtype=np.int8)
    rows = np.arange(n)
    for door in np.unique(d):  # a loop over doors, vectorized over particles and candidate segments
        cols = np.flatnonzero(d == door)
        best = cols[np.argmin(cost[:, cols], axis=1)]
        best_f = cols[np.argmin(flush_cost[:, cols], axis=1)]
        has = np.isfinite(cost[rows, best])
        has_f = ~has & np.isfinite(flush_cost[rows, best_f])
        angle[:, door] = np.where(has, rel[rows, best], np.where(has_f, flush_rel[rows, best_f], 0.0))
        kind[:, door] = np.where(has, 1, np.where(has_f, 2, 0))
    return angle, kind


def _associate_kernel(segs: FloatArray, pair_seg: npt.NDArray[np.int64], offsets: npt.NDArray[np.int64],
                      poses: FloatArray, hinge: FloatArray, length: FloatArray, closed: FloatArray,
                      angle_min: FloatArray, angle_max: FloatArray, mean: FloatArray, gate_h: float, ratio: float,
                      gate_line: float, margin: float, seg_len: FloatArray, seg_dir: FloatArray, angle: FloatArray,
                      kind: npt.NDArray[np.int8]) -> None:  # pragma: no cover - compiled by numba
    """Numba kernel of :func:`_associate_chunk`: the same arithmetic per particle, door and candidate pair."""
    two_pi = 2.0 * math.pi
    n = poses.shape[0]
    n_doors = length.shape[0]
    for i in range(n):
        c = math.cos(poses[i, 2])
        s = math.sin(poses[i, 2])
        for d in range(n_doors):
            lo_a = angle_min[d] - margin
            hi_a = angle_max[d] + margin
            mid = 0.5 * (lo_a + hi_a)
            reach = (1.0 - ratio) * length[d]
            best = math.inf
            best_rel = 0.0
            best_f = math.inf
            best_f_rel = 0.0
            for p in range(offsets[d], offsets[d + 1]):
                k = pair_seg[p]
                vx = segs[k, 1, 0] - segs[k, 0, 0]
                vy = segs[k, 1, 1] - segs[k, 0, 1]
                r0x = c * segs[k, 0, 0] - s * segs[k, 0, 1] + (poses[i, 0] - hinge[d, 0])
                r0y = s * segs[k, 0, 0] + c * segs[k, 0, 1] + (poses[i, 1] - hinge[d, 1])
                r1x = c * segs[k, 1, 0] - s * segs[k, 1, 1] + (poses[i, 0] - hinge[d, 0])
                r1y = s * segs[k, 1, 0] + c * segs[k, 1, 1] + (poses[i, 1] - hinge[d, 1])
                d0 = math.sqrt(r0x * r0x + r0y * r0y)
                d1 = math.sqrt(r1x * r1x + r1y * r1y)
                heading = seg_dir[k] + poses[i, 2] - closed[d]
                len_err = abs(seg_len[k] - length[d]) / length[d]
                near = min(d0, d1)
                if near < gate_h and len_err < ratio:
                    a = heading + (math.pi if d1 < d0 else 0.0) - mid
                    w = (a + math.pi) % two_pi - math.pi
                    rel = mid + (math.pi if w == -math.pi else w)
                    if lo_a <= rel <= hi_a:
                        cost = (near / gate_h) ** 2 + (len_err / ratio) ** 2
                        if cost < best:
                            best = cost
                            best_rel = rel
                if seg_len[k] < reach:
                    continue
                ex = vx / seg_len[k]
                ey = vy / seg_len[k]
                ux = c * ex - s * ey
                uy = s * ex + c * ey
                along = -(r0x * ux + r0y * uy)
                perp = abs(r0x * uy - r0y * ux)
                if not (perp < gate_line and -gate_h <= along <= seg_len[k] + gate_h):
                    continue
                w = (heading - mid + math.pi) % two_pi - math.pi
                fwd = mid + (math.pi if w == -math.pi else w)
                w = (heading + math.pi - mid + math.pi) % two_pi - math.pi
                bwd = mid + (math.pi if w == -math.pi else w)
                fwd_ok = seg_len[k] - along >= reach and lo_a <= fwd <= hi_a
                bwd_ok = along >= reach and lo_a <= bwd <= hi_a
                if not (fwd_ok or bwd_ok):
                    continue
                use_bwd = bwd_ok
                if fwd_ok and bwd_ok:
                    w = (bwd - mean[i, d] + math.pi) % two_pi - math.pi
                    e_b = abs(math.pi if w == -math.pi else w)
                    w = (fwd - mean[i, d] + math.pi) % two_pi - math.pi
                    e_f = abs(math.pi if w == -math.pi else w)
                    use_bwd = e_b < e_f
                cost = perp / gate_line
                if cost < best_f:
                    best_f = cost
                    best_f_rel = bwd if use_bwd else fwd
            if best < math.inf:
                angle[i, d] = best_rel
                kind[i, d] = 1
            elif best_f < math.inf:
                angle[i, d] = best_f_rel
                kind[i, d] = 2


# ---------------------------------------------------------------------------------------- Kalman filter


def predict_doors(door_var: npt.ArrayLike, dt_s: float, sigma_d: float,
                  max_var: float | npt.ArrayLike | None = None) -> FloatArray:
    """Random-walk prediction d_t = d_{t−1} + ε, ε ~ N(0, σ_d²·Δt): the means stay, the variances grow.

    Args:
        door_var: (N, D) door angle variances (rad²).
        dt_s: Time since the last prediction (s, ≥ 0).
        sigma_d: Random-walk standard deviation per √s (``door_sigma_rad_per_sqrt_s``).
        max_var: Optional cap (scalar or (D,)), e.g. the initial variance, so that a door unseen for long
            does not become wider than its whole opening range.

    Returns:
        (N, D) new variances.
    """
    var = np.asarray(door_var, dtype=np.float64) + sigma_d**2 * max(dt_s, 0.0)
    if max_var is not None:
        var = np.minimum(var, np.asarray(max_var, dtype=np.float64))
    return var


def kalman_update(door_mean: npt.ArrayLike, door_var: npt.ArrayLike, observed: npt.ArrayLike,
                  mask: npt.ArrayLike, meas_var: float | npt.ArrayLike, change_gate_chi2: float = math.inf,
                  moved_var: float | npt.ArrayLike = 0.0) -> tuple[FloatArray, FloatArray]:
    """Linear Kalman update of each particle's door angles with the measured angles (H = 1).

    K = P / (P + R), μ' = μ + K·wrap(z − μ), P' = (1 − K)·P where ``mask``; unchanged elsewhere.

    A door that somebody moved: where the innovation fails the gate, wrap(z − μ)² > ``change_gate_chi2``·(P + R)
    (the measurement is implausible under the random walk), P is first raised to ``moved_var`` (the door's
    angle is as unknown as an unobserved door's), so that the update takes the new angle at once instead of
    creeping towards it with the small gain of a door that has been still for long.

    Args:
        door_mean: (N, D) means (rad).
        door_var: (N, D) variances (rad²).
        observed: (N, D) measured angles (rad), from :func:`associate_segments`.
        mask: (N, D) which measurements exist.
        meas_var: R (rad²): scalar, (D,) or (N, D).
        change_gate_chi2: the gate (χ², 1 degree of freedom); inf: never.
        moved_var: P of a door found moved (rad²): scalar, (D,) or (N, D).

    Returns:
        ``(mean, var)``, new (N, D) arrays.
    """
    mu = np.asarray(door_mean, dtype=np.float64)
    m = np.asarray(mask, dtype=bool)
    r = np.asarray(meas_var, dtype=np.float64)
    innovation = wrap_angle(np.asarray(observed, dtype=np.float64) - mu)
    p = _gated(innovation, np.asarray(door_var, dtype=np.float64), m, r, change_gate_chi2, moved_var)
    gain = np.where(m, p / (p + r), 0.0)
    return mu + gain * np.where(m, innovation, 0.0), (1.0 - gain) * p


def gated_prior_variance(door_mean: npt.ArrayLike, door_var: npt.ArrayLike, observed: npt.ArrayLike,
                         mask: npt.ArrayLike, meas_var: float | npt.ArrayLike, change_gate_chi2: float,
                         moved_var: float | npt.ArrayLike) -> FloatArray:
    """(N, D) the prior variance :func:`kalman_update` updates: P, or ``moved_var`` (if larger) where a measurement
    fails the moved-door gate wrap(z − μ)² > ``change_gate_chi2``·(P + R)."""
    innovation = wrap_angle(np.asarray(observed, dtype=np.float64) - np.asarray(door_mean, dtype=np.float64))
    return _gated(innovation, np.asarray(door_var, dtype=np.float64), np.asarray(mask, dtype=bool),
                  np.asarray(meas_var, dtype=np.float64), change_gate_chi2, moved_var)


def _gated(innovation: FloatArray, p: FloatArray, mask: BoolArray, r: FloatArray, change_gate_chi2: float,
           moved_var: float | npt.ArrayLike) -> FloatArray:
    """P raised to ``moved_var`` where the innovation fails the gate (:func:`gated_prior_variance`)."""
    moved = mask & (innovation**2 > change_gate_chi2 * (p + r))
    out: FloatArray = np.where(moved, np.maximum(p, np.asarray(moved_var, dtype=np.float64)), p)
    return out


def moved_door_gate(config: LocalizeConfig) -> tuple[float, float]:
    """The moved-door gate's settings: ``door_moved_gate_chi2`` and the variance a moved door restarts from,
    ``door_init_sigma_deg``² (rad²)."""
    return config.door_moved_gate_chi2, math.radians(config.door_init_sigma_deg) ** 2


def update_doors(points_base: npt.ArrayLike, particles: ParticleSet, doors: DoorSet, config: LocalizeConfig,
                 max_gap_m: float | None = None, angle_margin_rad: float | None = None,
                 backend: Backend = "auto") -> DoorUpdate:
    """Step 3 of the RBPF for one scan: polygon once, association per particle, Kalman update.

    Args:
        points_base: (M, 2) scan points in base_link, in scan order (non-finite ones are skipped).
        particles: The particle set (poses, door means and variances); not modified.
        doors: D doors.
        config: The DP tolerance, the gates and ``door_angle_sigma_deg``.
        max_gap_m: Polyline break distance (see :func:`douglas_peucker`); None: ``config.dp_max_gap_m``.
        angle_margin_rad: See :func:`associate_segments`; None: ``config.door_angle_margin_deg``.
        backend: ``numba``, ``numpy`` or ``auto`` for the polygon and the association.

    Returns:
        :class:`DoorUpdate` with the new (N, D) means and variances, the observed mask and the measured angles.
    """
    gap = config.dp_max_gap_m if max_gap_m is None else max_gap_m
    margin = math.radians(config.door_angle_margin_deg) if angle_margin_rad is None else angle_margin_rad
    segments = douglas_peucker(points_base, config.dp_epsilon_m, max_gap_m=gap, backend=backend)
    angle, mask = associate_segments(segments, particles.pose, doors, particles.door_mean, config,
                                     angle_margin_rad=margin, backend=backend)
    meas_var = math.radians(config.door_angle_sigma_deg) ** 2
    mean, var = kalman_update(particles.door_mean, particles.door_var, angle, mask, meas_var, *moved_door_gate(config))
    return DoorUpdate(mean, var, mask, angle)
