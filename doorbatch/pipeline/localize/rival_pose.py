"""Whether the scans a global localization converged on fit as well somewhere else on the map (DESIGN: symmetric
corridors).

A cloud converges on one pose by the evidence and by chance: in a world symmetric under a rigid motion T (a
corridor turned by 180°, rooms repeating every few metres) the scans fit at T·x as well as at x, and resampling
keeps one of the two. The cloud then looks tight and unimodal, and only the map can tell that a rival exists.

The test: the scans of the converged span, placed by the run's estimates into the frame of its last estimate x,
are one rigid cloud P (one point per ``rival_resolution_m`` cell). Its score at a pose q is the mean likelihood of its
points,

    s(q) = (1/N) Σ_i L(q ⊕ p_i),    L(c) = exp(−d(c)² / 2σ²),

d the map's distance field (the likelihood field's, Thrun et al. 2005, Sec. 6.4).

1. **Search.** Every pose of the map whose position is a free cell and which lies at least ``ambiguity_radius_m`` or
   ``ambiguity_yaw_deg`` from x is searched for one where a subset of P scores at least ``rival_search_ratio`` of x's
   own score, L pooled to cells of ``rival_resolution_m`` by their best value. Both scores are taken on the same
   lattice (x's as the best within one step of it), so that quantization costs each alike. Branch and bound over
   max-pooled grids (Hess et al., "Real-time loop closure in 2D LIDAR SLAM", ICRA 2016, Sec. V-C, Algorithm 3): at
   height h a candidate stands for the 2^h × 2^h translations of a block, and its score over M_h(c) = max of L over
   the block at c bounds every translation inside. The bound decides rather than optimizes (every candidate under
   the bar is dropped, level by level), so the search is breadth first and vectorized over candidates × points. The
   yaw step is Hess et al.'s, the angle that moves the cloud's far points (95th percentile range) by one cell.
2. **Verification.** A mean score dilutes evidence: a niche the robot saw is a few percent of a long corridor's
   points, yet no rotation explains it. So each candidate (the best ``max_rivals``, mutually distinct) and x are
   refined on a lattice four times finer, and the whole cloud at the two is compared point by point: the wall
   length (points × cell) that fits within 2σ at x and not at the candidate is the evidence against it. Under
   ``rival_min_evidence_m`` the candidate is a rival: the scans cannot tell it from x, or, when as much wall fits
   only at the candidate, they prefer it (x is the wrong one of two similar places).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import compose, inverse, transform_points
from doorbatch.pipeline.localize.likelihood_field import DistanceField, endpoint_distances
from doorbatch.pipeline.poses.correlative import thinned

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

# Gathered floats per vectorized block of candidates × points (memory bound of one step).
GATHER_BLOCK = 4_000_000
# Search survivors looked at, best first, for max_rivals mutually distinct ones.
NMS_MAX = 20_000
# Candidates per yaw at the top of the search (the top height is the smallest that leaves at most this many).
TOP_BLOCKS = 16


@dataclass(frozen=True)
class RivalSearch:
    """Settings of the rival test (``localize.rival_*`` and ``localize.ambiguity_*``)."""

    resolution_m: float
    sigma_m: float
    search_ratio: float
    search_points: int
    min_evidence_m: float
    max_candidates: int
    radius_m: float
    yaw_rad: float
    max_rivals: int = 5


@dataclass(frozen=True)
class Rival:
    """A pose away from the estimate (map frame), both refined, their scores over the whole cloud, the length of wall
    (m) the scans see that fits at the estimate and not at the rival (``evidence_m``), and the converse
    (``counter_m``: a rival the scans prefer says the estimate is the wrong one of two similar places)."""

    pose: FloatArray
    score: float
    own_score: float
    evidence_m: float
    counter_m: float = 0.0

    @property
    def ratio(self) -> float:
        return self.score / self.own_score if self.own_score > 0.0 else math.inf


@dataclass(frozen=True)
class RivalOutcome:
    """What the test found: ``rival``, the first candidate the scans do not refute (None: every candidate is refuted
    or none came near); ``nearest``, the candidate with the least evidence against it (for reports);
    ``undecided`` when the search outgrew ``max_candidates`` (a map too self-similar to tell, at this cost)."""

    rival: Rival | None
    nearest: Rival | None = None
    undecided: bool = False
    points: int = 0


def scan_cloud(poses: npt.ArrayLike, hits_base: list[FloatArray], frame: npt.ArrayLike, cell_m: float,
               max_points: int) -> FloatArray:
    """The hits of several scans, each placed by its pose (map frame), in the frame of ``frame``: one point per
    ``cell_m`` cell (the first), then every k-th in cell order for at most ``max_points``."""
    to_frame = inverse(np.asarray(frame, dtype=np.float64))
    parts = [transform_points(compose(to_frame, p), h) for p, h in zip(np.asarray(poses).reshape(-1, 3), hits_base,
                                                                         strict=True) if len(h)]
    if not parts:
        return np.zeros((0, 2))
    pts = np.concatenate(parts)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    _, first = np.unique(np.floor(pts / cell_m).astype(np.int64), axis=0, return_index=True)
    pts = pts[np.sort(first)]
    return thinned(pts, max_points)


def _pooled(values: npt.NDArray[np.float32], f: int) -> npt.NDArray[np.float32]:
    """Block maximum over f × f cells (the last blocks padded with zeros)."""
    h, w = values.shape
    padded = np.zeros((-(-h // f) * f, -(-w // f) * f), dtype=values.dtype)
    padded[:h, :w] = values
    out: npt.NDArray[np.float32] = padded.reshape(padded.shape[0] // f, f, padded.shape[1] // f, f).max(axis=(1, 3))
    return out


def _levels(grid: npt.NDArray[np.float32], top: int) -> list[npt.NDArray[np.float32]]:
    """M_0 = grid, M_h[i, j] = max M_{h−1} over (i, j) and its shifts by 2^(h−1) along each axis (zero beyond)."""
    out = [grid]
    for h in range(1, top + 1):
        prev, s = out[-1], 1 << (h - 1)
        cur = prev.copy()
        np.maximum(cur[:-s], prev[s:], out=cur[:-s])
        tmp = cur.copy()
        np.maximum(tmp[:, :-s], cur[:, s:], out=tmp[:, :-s])
        out.append(tmp)
    return out


def find_rival(field: DistanceField, free_mask: npt.NDArray[np.bool_], estimate: npt.ArrayLike,
               cloud: npt.ArrayLike, settings: RivalSearch) -> RivalOutcome:
    """Search the map for a pose away from ``estimate`` where ``cloud`` ((N, 2), the estimate's frame, one point per
    ``resolution_m`` cell: :func:`scan_cloud`) fits as well (module docstring); ``free_mask`` (the field's cells) says
    where a robot may stand."""
    pts = np.asarray(cloud, dtype=np.float64).reshape(-1, 2)
    if pts.shape[0] == 0:
        return RivalOutcome(None)
    est = np.asarray(estimate, dtype=np.float64).reshape(3)
    found = _candidates(field, free_mask, est, thinned(pts, settings.search_points), settings)
    if found is None:
        return RivalOutcome(None, undecided=True, points=pts.shape[0])
    candidates, step = found
    own = _refined(field, est, pts, settings.resolution_m, step, settings.sigma_m)
    nearest: Rival | None = None
    for pose in candidates:
        rival = _verified(field, own, _refined(field, pose, pts, settings.resolution_m, step, settings.sigma_m), pts,
                          settings)
        if rival.evidence_m < settings.min_evidence_m:
            return RivalOutcome(rival, rival, points=pts.shape[0])
        nearest = rival if nearest is None or rival.evidence_m < nearest.evidence_m else nearest
    return RivalOutcome(None, nearest, points=pts.shape[0])


def _likelihood(field: DistanceField, poses: FloatArray, pts: FloatArray, sigma_m: float) -> FloatArray:
    """(P, N) exp(−d²/2σ²) of every point at every pose, d from the (full-resolution) field."""
    d = endpoint_distances(field, poses, pts).astype(np.float64)
    out: FloatArray = np.exp(-0.5 * (d / sigma_m) ** 2)
    return out


def _refined(field: DistanceField, pose: FloatArray, pts: FloatArray, cell_m: float, step_rad: float,
             sigma_m: float) -> FloatArray:
    """The best-scoring pose within one search cell and one yaw step of ``pose``, on a lattice four times finer."""
    f = np.linspace(-1.0, 1.0, 9)
    dx, dy, dyaw = (a.ravel() for a in np.meshgrid(f * cell_m, f * cell_m, f * step_rad, indexing="ij"))
    poses = pose + np.stack([dx, dy, dyaw], axis=1)
    best: FloatArray = poses[int(np.argmax(_likelihood(field, poses, pts, sigma_m).mean(axis=1)))]
    return best


def _verified(field: DistanceField, own: FloatArray, pose: FloatArray, pts: FloatArray, settings: RivalSearch) -> Rival:
    """The candidate against the estimate over the whole cloud: the length of wall (points × cell, the cloud holding
    one point per cell) that fits within 2σ at the estimate and not at the candidate, and the converse."""
    like = _likelihood(field, np.stack([own, pose]), pts, settings.sigma_m)
    fit = like >= math.exp(-2.0)  # d ≤ 2σ
    evidence = float(np.count_nonzero(fit[0] & ~fit[1])) * settings.resolution_m
    counter = float(np.count_nonzero(fit[1] & ~fit[0])) * settings.resolution_m
    return Rival(pose, float(like[1].mean()), float(like[0].mean()), evidence, counter)


def _candidates(field: DistanceField, free_mask: npt.NDArray[np.bool_], estimate: FloatArray, pts: FloatArray,
                settings: RivalSearch) -> tuple[list[FloatArray], float] | None:
    """Poses (map frame) away from ``estimate`` where ``pts`` score at least ``search_ratio`` of the estimate's score on
    the search lattice, best first, at most ``max_rivals`` mutually apart by ``radius_m`` or ``yaw_rad``, and the
    lattice's yaw step; None when the search outgrew ``max_candidates``."""
    f = max(1, round(settings.resolution_m / field.resolution_m))
    res = f * field.resolution_m
    like = _pooled(np.exp(-0.5 * (field.dist / settings.sigma_m) ** 2).astype(np.float32), f)
    free = _pooled(free_mask.astype(np.float32), f)
    rows, cols = like.shape
    g = field.to_grid(estimate)
    g[:2] *= field.resolution_m / res  # coarse cells
    far = float(np.quantile(np.hypot(pts[:, 0], pts[:, 1]), 0.95))
    step = min(math.acos(max(-1.0, 1.0 - res * res / (2.0 * max(far, res) ** 2))), math.radians(5.0))
    n_yaw = math.ceil(2.0 * math.pi / step)
    yaws = g[2] + (2.0 * math.pi / n_yaw) * np.arange(n_yaw)
    c, s = np.cos(yaws)[:, None], np.sin(yaws)[:, None]
    u = (c * pts[:, 0] - s * pts[:, 1]) / res + g[0]  # (Y, N) columns with the robot at the estimate's position
    v = (s * pts[:, 0] + c * pts[:, 1]) / res + g[1]
    gx, gy = math.floor(g[0]), math.floor(g[1])
    span = (np.arange(-gx, cols - gx), np.arange(-gy, rows - gy))  # shifts that keep the robot on the map
    top = 0
    while max(span[0].size, span[1].size) > TOP_BLOCKS * (1 << top) and top < 12:
        top += 1
    reach = math.ceil(max(float(np.abs(u - g[0]).max()), float(np.abs(v - g[1]).max()))) + 2
    pad = reach + (1 << top) + 2  # every shifted point of a robot on the map indexes inside; zeros beyond the map
    padded = np.zeros((rows + 2 * pad, cols + 2 * pad), dtype=np.float32)
    padded[pad : pad + rows, pad : pad + cols] = like
    free_padded = np.zeros_like(padded)
    free_padded[pad : pad + rows, pad : pad + cols] = free
    grids, frees = _levels(padded, top), _levels(free_padded, top)
    width = padded.shape[1]
    flat_cells = (np.floor(v).astype(np.int64) + pad) * width + np.floor(u).astype(np.int64) + pad
    robot_cell = (gy + pad) * width + gx + pad

    def scores(h: int, k: IntArray, dx: IntArray, dy: IntArray) -> FloatArray:
        out = np.empty(k.size)
        table = grids[h].ravel()
        block = max(1, GATHER_BLOCK // pts.shape[0])
        for a in range(0, k.size, block):
            b = slice(a, a + block)
            out[b] = np.take(table, flat_cells[k[b]] + (dy[b] * width + dx[b])[:, None]).mean(axis=1)
        return out

    near = np.arange(-1, 2)
    kk, xx, yy = (a.ravel() for a in np.meshgrid(near % n_yaw, near, near, indexing="ij"))
    bar = settings.search_ratio * float(scores(0, kk, xx, yy).max())  # the estimate's best within one lattice step
    yaw_off = np.abs(wrap_angle(yaws - g[2]))
    radius_cells = settings.radius_m / res
    x0, y0 = span[0][:: 1 << top], span[1][:: 1 << top]
    k = np.repeat(np.arange(n_yaw), x0.size * y0.size)
    dx0, dy0 = np.meshgrid(x0, y0, indexing="ij")
    dx, dy = np.tile(dx0.ravel(), n_yaw), np.tile(dy0.ravel(), n_yaw)
    sc = np.zeros(0)
    for h in range(top, -1, -1):
        size = 1 << h
        far_x = np.maximum(np.abs(dx), np.abs(dx + size - 1))
        far_y = np.maximum(np.abs(dy), np.abs(dy + size - 1))
        inside = (yaw_off[k] <= settings.yaw_rad) & (np.hypot(far_x, far_y) <= radius_cells)  # wholly near it
        standing = frees[h].ravel()[robot_cell + dy * width + dx] > 0.0
        keep = ~inside & standing
        k, dx, dy = k[keep], dx[keep], dy[keep]
        sc = scores(h, k, dx, dy)
        keep = sc >= bar
        k, dx, dy, sc = k[keep], dx[keep], dy[keep], sc[keep]
        if h == 0 or not k.size:
            break
        half = size >> 1
        k = np.repeat(k, 4)
        dx = np.repeat(dx, 4) + np.tile([0, half, 0, half], dx.size)
        dy = np.repeat(dy, 4) + np.tile([0, 0, half, half], dy.size)
        within = (dx <= span[0][-1]) & (dy <= span[1][-1])
        k, dx, dy = k[within], dx[within], dy[within]
        if k.size > settings.max_candidates:
            return None
    origin = np.array([field.origin_x_m, field.origin_y_m, field.origin_yaw_rad])
    picked: list[FloatArray] = []
    for i in np.argsort(-sc, kind="stable")[:NMS_MAX]:
        grid_pose = np.array([(g[0] + dx[i]) * res, (g[1] + dy[i]) * res, yaws[k[i]]])
        pose = compose(origin, grid_pose)
        if all(np.hypot(*(pose[:2] - q[:2])) > settings.radius_m or abs(float(wrap_angle(pose[2] - q[2])))
               > settings.yaw_rad for q in picked):
            picked.append(pose)
            if len(picked) == settings.max_rivals:
                break
    return picked, step
