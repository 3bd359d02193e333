"""Exact, vectorized 2D ray casting against line segments and circles (float64, all rays × all obstacles).

Ray i: p_i + t·d_i, t ≥ 0. Segment j: a_j + u·e_j with e_j = b_j − a_j, u ∈ [0, 1]. With the 2D cross
product c(v, w) = v_x w_y − v_y w_x, solving p + t·d = a + u·e gives

    t = c(a − p, e) / c(d, e),        u = c(a − p, d) / c(d, e).

A ray hits the segment when c(d, e) ≠ 0, t > 0 and 0 ≤ u ≤ 1; parallel rays (c(d, e) = 0, including the
degenerate collinear overlap) never hit. The range returned is t, in units of |d|: the Euclidean distance
for unit directions, the depth along a camera's optical axis for directions (1, x_n) in its frame.

The denominator and the u numerator are bilinear in d, so for all B rays × S segments they are
(B, 2) @ (2, S) matrix products plus per-ray and per-segment terms; no Python loop over beams.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

# Segments are stretched by this fraction of their length at both ends, so that rays through the shared
# end point of two joined segments never slip through the joint because of rounding.
U_TOLERANCE = 1e-12
_MISS = 1e300  # stands for "no hit" inside the reduction
_BIG = 1e250  # non-hits get t = −slack·_BIG (slack < 0); small enough that −BIG·U cannot overflow
_MISS_BELOW = 1e100  # any t at least this large is a miss (real ranges are far below)
_SWAP = np.array([-1.0, 1.0])  # (x, y)·_SWAP, transposed and row-reversed: rows (y, −x)
_SWAP_NEG = np.array([1.0, -1.0])  # rows (−y, x)


class RayBuffers:
    """Reusable scratch arrays for :func:`cast_rays`.

    Fresh (B, S) float64 arrays of a few hundred kB each are returned to the OS by malloc on every free
    and page-faulted back on the next call, which costs more than the arithmetic (measured: 3×). A caller
    that casts many scans keeps one ``RayBuffers`` and passes it to every call. Not thread-safe: one per
    thread. Results do not depend on it.
    """

    def __init__(self) -> None:
        self._arrays: dict[tuple[str, tuple[int, ...]], npt.NDArray[Any]] = {}

    def get(self, name: str, shape: tuple[int, ...], dtype: type = np.float64) -> npt.NDArray[Any]:
        """A scratch array (uninitialized) of this name and shape."""
        key = (name, shape)
        arr = self._arrays.get(key)
        if arr is None or arr.dtype != dtype:
            arr = np.empty(shape, dtype=dtype)
            self._arrays[key] = arr
        return arr


def cast_rays(origins: npt.ArrayLike, directions: npt.ArrayLike, segments: npt.ArrayLike,
              buffers: RayBuffers | None = None) -> tuple[FloatArray, IntArray]:
    """First hit of each ray among the segments.

    Args:
        origins: (B, 2) ray origins, or (2,) for one origin shared by all rays (a laser, a camera).
        directions: (B, 2) ray directions (need not be unit).
        segments: (S, 2, 2) segments [[x0, y0], [x1, y1]].
        buffers: scratch arrays to reuse between calls (faster; see :class:`RayBuffers`).

    Returns:
        ``(range, index)``: (B,) t of the nearest hit (+inf on a miss) and (B,) index of the segment hit
        (−1 on a miss). Ties go to the lowest segment index.
    """
    d = np.ascontiguousarray(directions, dtype=np.float64).reshape(-1, 2)
    segs = np.asarray(segments, dtype=np.float64).reshape(-1, 2, 2)
    p = np.asarray(origins, dtype=np.float64)
    n_rays, n_segs = d.shape[0], segs.shape[0]
    if n_segs == 0 or n_rays == 0:
        return np.full(n_rays, np.inf), np.full(n_rays, -1, dtype=np.int64)
    buf = buffers or RayBuffers()
    a = segs[:, 0, :] - U_TOLERANCE * (segs[:, 1, :] - segs[:, 0, :])  # ends stretched by U_TOLERANCE
    e = (1.0 + 2.0 * U_TOLERANCE) * (segs[:, 1, :] - segs[:, 0, :])
    p2 = p.reshape(-1, 2)
    if p2.shape[0] == 1 or bool(np.all(p2 == p2[0])):
        return _cast_shared(p2[0], d, a, e, buf)
    return _cast_general(p2, d, a, e, buf)


def _cast_shared(p: FloatArray, d: FloatArray, a: FloatArray, e: FloatArray, buf: RayBuffers
                 ) -> tuple[FloatArray, IntArray]:
    """One origin for all rays (a laser, a camera): segments are oriented so that c(w, e) > 0, w = a − p
    (by multiplying D = c(d, e) and U = c(w, d) by the sign of c(w, e), which leaves t and u unchanged).

    Then t = c(w, e)/D > 0 ⇔ D = c(d, e) > 0, and u = U/D ∈ [0, 1] ⇔ 0 ≤ U ≤ D with U = c(w, d): the hit
    test needs no division, only the slack min(U, D − U) ≥ 0 (which also implies D ≥ 0; D = 0 would need
    the origin on the segment's line, whose segments are dropped). Non-hits get t = −slack·_BIG via
    fmax, a huge positive number, so that argmin skips them. The scale −_BIG is folded into the matrix
    products, so the whole test is three products and three element-wise passes, each into a buffer.
    """
    w = a - p
    t_num = w[:, 0] * e[:, 1] - w[:, 1] * e[:, 0]  # c(w, e), (S,)
    sign = np.where(t_num < 0.0, -1.0, 1.0)  # orienting a segment = multiplying D and U by sign(c(w, e))
    t_num = np.abs(t_num)
    t_num[t_num == 0.0] = np.inf  # origin on the segment's line: never a hit
    shape = (d.shape[0], a.shape[0])
    rows = np.empty((6, a.shape[0]))
    rows[0], rows[1], rows[2], rows[3] = e[:, 1], -e[:, 0], -w[:, 1], w[:, 0]
    rows[:4] *= sign
    rows[4:] = rows[:2] - rows[2:4]
    rows[2:] *= -_BIG
    # three (B, 2) @ (2, S) products: D, −BIG·U and −BIG·(D − U); then −BIG·slack = max of the last two
    den = np.matmul(d, rows[:2], out=buf.get("t", shape))
    neg_u = np.matmul(d, rows[2:4], out=buf.get("u", shape))
    neg_slack = np.matmul(d, rows[4:], out=buf.get("s", shape))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        np.fmax(neg_slack, neg_u, out=neg_slack)
        t = np.divide(t_num, den, out=den)
        np.fmax(t, neg_slack, out=t)
    return _pick(t)


def _cast_general(p: FloatArray, d: FloatArray, a: FloatArray, e: FloatArray, buf: RayBuffers
                  ) -> tuple[FloatArray, IntArray]:
    """One origin per ray: t and u from the formulas of the module docstring, misses pushed to _MISS."""
    shape = (d.shape[0], a.shape[0])
    e_mat = (e * _SWAP).T[::-1]  # rows (e_y, −e_x)
    t = np.matmul(d, e_mat, out=buf.get("t", shape))  # c(d, e), then 1/c(d, e), then t
    u = np.matmul(d, (a * _SWAP_NEG).T[::-1], out=buf.get("u", shape))  # c(a, d)
    # c(a − p, d) = c(a, d) − c(p, d);  c(a − p, e) = c(a, e) − c(p, e)
    np.subtract(u, (p[:, 0] * d[:, 1] - p[:, 1] * d[:, 0])[:, None], out=u)
    t_num = (a[:, 0] * e[:, 1] - a[:, 1] * e[:, 0])[None, :] - p @ e_mat
    ok = buf.get("ok", shape, np.bool_)
    tmp = buf.get("tmp", shape, np.bool_)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        np.divide(1.0, t, out=t)
        np.multiply(u, t, out=u)
        np.multiply(t, t_num, out=t)
        np.greater_equal(u, 0.0, out=ok)
        np.less_equal(u, 1.0, out=tmp)
        np.logical_and(ok, tmp, out=ok)
        np.greater(t, 0.0, out=tmp)
        np.logical_and(ok, tmp, out=ok)
        np.logical_not(ok, out=ok)
        np.multiply(ok, _MISS, out=u)
        np.fmax(t, u, out=t)  # misses (and NaN from 0/0) become _MISS
    return _pick(t)


def _pick(t: FloatArray) -> tuple[FloatArray, IntArray]:
    """Nearest entry per row; values ≥ _MISS_BELOW are misses (range +inf, index −1)."""
    index = np.argmin(t, axis=1)
    rng = t[np.arange(t.shape[0]), index]
    miss = rng >= _MISS_BELOW
    rng[miss] = np.inf
    index[miss] = -1
    return rng, index.astype(np.int64, copy=False)


def cast_rays_circles(origins: npt.ArrayLike, directions: npt.ArrayLike, centers: npt.ArrayLike,
                      radii: npt.ArrayLike) -> tuple[FloatArray, IntArray]:
    """First hit of each ray among circles (people's legs and bodies seen by a planar laser).

    |p + t·d − c|² = r² is the quadratic |d|² t² − 2 d·(c − p) t + |c − p|² − r² = 0; the hit is the
    smaller positive root (the larger one when the origin is inside the circle). Circles whose centre has
    a NaN coordinate are absent.

    Returns:
        ``(range, index)`` as :func:`cast_rays`, index into the circles.
    """
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 2)
    c_all = np.asarray(centers, dtype=np.float64).reshape(-1, 2)
    r_all = np.asarray(radii, dtype=np.float64).reshape(-1)
    n_rays = d.shape[0]
    present = np.nonzero(np.isfinite(c_all).all(axis=1))[0]
    if present.size == 0 or n_rays == 0:
        return np.full(n_rays, np.inf), np.full(n_rays, -1, dtype=np.int64)
    c, r = c_all[present], r_all[present]
    p = np.asarray(origins, dtype=np.float64).reshape(-1, 2)
    qa = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]  # |d|², (B,)
    # (C, B) layout: few circles, many rays; reductions over axis 0 are cheap there.
    if p.shape[0] == 1:  # shared origin: one small matrix product
        w = c - p[0]  # (C, 2) origin → centre
        qb = w @ d.T  # d·(c − p)
        qc = (w[:, 0] ** 2 + w[:, 1] ** 2 - r**2)[:, None]
    else:
        wb = c[:, None, :] - p[None, :, :]  # (C, B, 2)
        qb = np.einsum("bi,cbi->cb", d, wb)
        qc = np.einsum("cbi,cbi->cb", wb, wb) - r[:, None] ** 2
    # |d|² t² − 2 d·(c − p) t + |c − p|² − r² = 0  →  t = (d·(c − p) ∓ √disc) / |d|²
    disc = qb * qb - qa * qc
    # Only the few (circle, ray) pairs with disc ≥ 0 can hit: solve those, then keep the nearest per ray.
    ci, bi = np.nonzero(disc >= 0.0)
    rng = np.full(n_rays, np.inf)
    index = np.full(n_rays, -1, dtype=np.int64)
    if ci.size == 0:
        return rng, index
    qb_k, root, qa_k = qb[ci, bi], np.sqrt(disc[ci, bi]), qa[bi]
    t_near = (qb_k - root) / qa_k
    t = np.where(t_near > 0.0, t_near, (qb_k + root) / qa_k)
    hit = t > 0.0
    ci, bi, t = ci[hit], bi[hit], t[hit]
    order = np.lexsort((-t, bi))  # per ray, farthest first, so that the nearest is written last
    last = np.ones(order.size, dtype=bool)
    last[:-1] = bi[order][1:] != bi[order][:-1]
    keep = order[last]
    rng[bi[keep]] = t[keep]
    index[bi[keep]] = present[ci[keep]]
    return rng, index


def nearest(first: tuple[FloatArray, IntArray], second: tuple[FloatArray, IntArray], offset: int
            ) -> tuple[FloatArray, IntArray]:
    """Merge two hit results; indices of ``second`` are shifted by ``offset`` (its place in a joint table)."""
    r1, i1 = first
    r2, i2 = second
    take = r2 < r1
    return np.where(take, r2, r1), np.where(take, np.where(i2 >= 0, i2 + offset, -1), i1)
