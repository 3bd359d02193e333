"""Compiled kernels of the grid stage (numba): scan integration and end-point classification.

Each kernel does, cell for cell and bit for bit, what its NumPy reference does
(:func:`doorbatch.pipeline.gridmap.occupancy.integrate_scan_numpy`,
:func:`doorbatch.pipeline.gridmap.dynamic.classify_scan_numpy`); tests check that both agree on random
scans. NumPy needs a flat index array of every cell of every beam, several passes over it and a
gather–scatter for "one update per cell per scan"; a loop does one pass and marks the cells it updated
in a per-cell stamp (``LogOddsGrid.stamp``), about four times faster on one core.

Float32 arithmetic is kept where the reference uses it (DDA sample positions, log-odds), and numba does
not contract a·b + c into a fused multiply–add without ``fastmath``, so the rounding is the same.
"""

from __future__ import annotations

import math

import numba  # type: ignore[import-untyped]
import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


@numba.njit(cache=True)  # type: ignore[misc]
def scan_bounds(pts: FloatArray, dirs: FloatArray, ox: float, oy: float, clear: float
                ) -> tuple[float, float, float, float]:  # pragma: no cover - compiled
    """(min x, min y, max x, max y) over the origin, the hits and o + clear·u of each no-return direction u
    (none when clear is 0): what :func:`doorbatch.pipeline.gridmap.occupancy.beam_ends` spans."""
    lox, loy, hix, hiy = ox, oy, ox, oy
    for i in range(pts.shape[0]):
        lox, hix = min(lox, pts[i, 0]), max(hix, pts[i, 0])
        loy, hiy = min(loy, pts[i, 1]), max(hiy, pts[i, 1])
    if clear > 0.0:
        for i in range(dirs.shape[0]):
            x = clear * dirs[i, 0] + ox
            y = clear * dirs[i, 1] + oy
            lox, hix = min(lox, x), max(hix, x)
            loy, hiy = min(loy, y), max(hiy, y)
    return lox, loy, hix, hiy


@numba.njit(cache=True)  # type: ignore[misc]
def _free_fraction(pts: FloatArray, i: int, ox: float, oy: float, band_m: float) -> float:  # pragma: no cover
    """:func:`doorbatch.pipeline.gridmap.occupancy.free_fraction` of hit i."""
    n = pts.shape[0]
    bx = pts[i, 0] - ox
    by = pts[i, 1] - oy
    if n < 2:
        return min(1.0, max(0.0, 1.0 - band_m / max(math.sqrt(bx * bx + by * by), 1e-12)))
    prev2 = np.inf
    next2 = np.inf
    if i > 0:
        px = pts[i, 0] - pts[i - 1, 0]
        py = pts[i, 1] - pts[i - 1, 1]
        prev2 = px * px + py * py
    if i < n - 1:
        qx = pts[i + 1, 0] - pts[i, 0]
        qy = pts[i + 1, 1] - pts[i, 1]
        next2 = qx * qx + qy * qy
    if next2 <= prev2:
        tx = pts[i + 1, 0] - pts[i, 0]
        ty = pts[i + 1, 1] - pts[i, 1]
        t2 = next2
    else:
        tx = pts[i, 0] - pts[i - 1, 0]
        ty = pts[i, 1] - pts[i - 1, 1]
        t2 = prev2
    r_sin = float(abs(bx * ty - by * tx) / max(math.sqrt(t2), 1e-12))
    return min(1.0, max(0.0, 1.0 - band_m / max(r_sin, 1e-12)))


@numba.njit(cache=True)  # type: ignore[misc]
def integrate_kernel(log_odds2: npt.NDArray[np.float32], hits2: npt.NDArray[np.int32],
                     hit_sum2: npt.NDArray[np.complex64], free_latch2: npt.NDArray[np.bool_],
                     seen_occupied2: npt.NDArray[np.bool_], last_hit_scan2: npt.NDArray[np.int32],
                     stamp2: npt.NDArray[np.int32], gx: float, gy: float, res: float,
                     ox: float, oy: float, pts: FloatArray, dirs: FloatArray, dynamic: npt.NDArray[np.bool_],
                     clear: float, band_m: float, cut: bool, max_range_m: float, scan: int,
                     levels: FloatArray) -> None:  # pragma: no cover - compiled
    """One scan (map frame) on the (H, W) arrays of a grid with outer corner (gx, gy) and cell ``res``, as
    :func:`doorbatch.pipeline.gridmap.occupancy.integrate_scan_numpy` (the same float64 steps per beam,
    the same float32 DDA samples). ``dynamic``: hits not to integrate (length 0: none); ``clear``: how far
    no-return beams clear (0: not at all); ``cut``: some beam may exceed ``max_range_m`` (cut it, do not
    mark its end); ``levels``: l_free, l_min, l_occ, l_max, l_low, l_high.

    Stamps: 2·scan + 1 marks a cell freed in this scan, 2·scan + 2 one made occupied (so 0 is never a
    valid stamp and a fresh grid needs no reset). The free pass is branch-free (it always stores, the old
    value for a cell already freed): the stamp test is a coin flip near the robot, where beams overlap.
    """
    width = log_odds2.shape[1]
    log_odds = log_odds2.reshape(log_odds2.size)
    hits = hits2.reshape(hits2.size)
    hit_sum = hit_sum2.reshape(hit_sum2.size)
    free_latch = free_latch2.reshape(free_latch2.size)
    seen_occupied = seen_occupied2.reshape(seen_occupied2.size)
    last_hit_scan = last_hit_scan2.reshape(last_hit_scan2.size)
    stamp = stamp2.reshape(stamp2.size)
    f_free = np.float32(levels[0])
    f_min = np.float32(levels[1])
    f_occ = np.float32(levels[2])
    f_max = np.float32(levels[3])
    l_low = levels[4]
    l_high = levels[5]
    free_mark = np.int32(2 * scan + 1)
    occ_mark = np.int32(2 * scan + 2)
    inv = 1.0 / res
    ocx = (ox - gx) * inv
    ocy = (oy - gy) * inv
    ox32 = np.float32(ocx)
    oy32 = np.float32(ocy)
    lim = max_range_m * inv
    n_hits = pts.shape[0]
    n_dirs = dirs.shape[0] if clear > 0.0 else 0
    keep_hit = np.ones(n_hits, dtype=np.bool_)
    if dynamic.shape[0] == n_hits:
        for i in range(n_hits):
            keep_hit[i] = not dynamic[i]
    before = np.empty(n_hits, dtype=np.float32)
    cell = np.empty(n_hits, dtype=np.int64)
    hx = np.empty(n_hits)
    hy = np.empty(n_hits)
    for i in range(n_hits):  # end cells and their log-odds before the scan (read before any free update)
        hx[i] = (pts[i, 0] - gx) * inv
        hy[i] = (pts[i, 1] - gy) * inv
        c = np.int64(int(hy[i])) * width + np.int64(int(hx[i]))
        cell[i] = c
        before[i] = log_odds[c]
    for b in range(n_hits + n_dirs):
        if b < n_hits:
            dx = hx[b] - ocx
            dy = hy[b] - ocy
        else:
            dx = ((clear * dirs[b - n_hits, 0] + ox) - gx) * inv - ocx
            dy = ((clear * dirs[b - n_hits, 1] + oy) - gy) * inv - ocy
        r2 = dx * dx + dy * dy
        if band_m > 0.0 and b < n_hits:
            f = _free_fraction(pts, b, ox, oy, band_m)
            dx = dx * f
            dy = dy * f
        if cut:
            if b < n_hits and not r2 <= lim * lim:
                keep_hit[b] = False
            f = min(1.0, lim / math.sqrt(max(dx * dx + dy * dy, 1e-300)))
            dx = dx * f
            dy = dy * f
        n = math.ceil(max(abs(dx), abs(dy)))
        if n < 1.0:
            n = 1.0
        sx = np.float32(dx / n)
        sy = np.float32(dy / n)
        for k in range(int(n)):
            kf = np.float32(k)
            x = sx * kf + ox32
            y = sy * kf + oy32
            c = np.int64(np.int32(y)) * width + np.int64(np.int32(x))
            old = log_odds[c]
            v = old + f_free
            v = max(v, f_min)
            fresh = stamp[c] != free_mark
            stamp[c] = free_mark
            log_odds[c] = v if fresh else old
    for i in range(n_hits - 1, -1, -1):  # the last hit of a cell in beam order gives its offset
        if not keep_hit[i]:
            continue
        c = cell[i]
        if stamp[c] == occ_mark:
            continue
        stamp[c] = occ_mark
        after = before[i] + f_occ
        if after > f_max:
            after = f_max
        log_odds[c] = after
        if before[i] < l_low:
            free_latch[c] = True
        if after > l_high:
            seen_occupied[c] = True
        last_hit_scan[c] = scan
        hits[c] += 1
        hit_sum[c] += np.complex64(complex(hx[i] - int(hx[i]), hy[i] - int(hy[i])))


@numba.njit(cache=True)  # type: ignore[misc]
def classify_kernel(log_odds2: npt.NDArray[np.float32], free_latch2: npt.NDArray[np.bool_],
                    transient2: npt.NDArray[np.bool_], occupied_before2: npt.NDArray[np.bool_],
                    pass_start2: npt.NDArray[np.float32], later_pass: bool, gx: float, gy: float, inv: float,
                    pts: FloatArray, r: int, l_low: float, reach: float, dynamic: npt.NDArray[np.bool_],
                    support: npt.NDArray[np.bool_]) -> tuple[int, int, float]:  # pragma: no cover - compiled
    """:func:`doorbatch.pipeline.gridmap.dynamic.classify_scan_numpy` on the (H, W) arrays: for each end
    point (map frame; its cell clamped onto the grid, whose outer corner is (gx, gy) and cell 1 / inv)
    whether it is a dynamic measurement (transient, no cell seen occupied before the pass within r cells),
    setting the transient flag where it newly holds, and whether it may complete a line (seen free, or in a
    ``later_pass`` unseen when the pass began, its ``pass_start`` log-odds 0; not occupied before the pass). Returns
    the number of dynamic points,
    of non-dynamic support points within ``reach`` of the dynamic points' bounding box, and the squared
    diagonal of that box."""
    height, width = log_odds2.shape
    log_odds = log_odds2.reshape(log_odds2.size)
    free_latch = free_latch2.reshape(free_latch2.size)
    transient = transient2.reshape(transient2.size)
    occupied_before = occupied_before2.reshape(occupied_before2.size)
    pass_start = pass_start2.reshape(pass_start2.size)
    low = np.float32(l_low)
    n_dynamic = 0
    n_support = 0
    lox, loy, hix, hiy = np.inf, np.inf, -np.inf, -np.inf
    for i in range(pts.shape[0]):
        j = min(max(math.floor((pts[i, 0] - gx) * inv), 0.0), width - 1.0)
        k = min(max(math.floor((pts[i, 1] - gy) * inv), 0.0), height - 1.0)
        c = int(k) * width + int(j)
        is_transient = transient[c]
        if not is_transient and log_odds[c] < low:
            ok = True
            for di in range(-r, r + 1):
                for dj in range(-r, r + 1):
                    n = c + di * width + dj
                    if not (log_odds[n] < low or free_latch[n]):
                        ok = False
                        break
                if not ok:
                    break
            if ok:
                transient[c] = True
                is_transient = True
        if is_transient:  # no structure known before the pass within the neighbourhood
            for di in range(-r, r + 1):
                for dj in range(-r, r + 1):
                    if occupied_before[c + di * width + dj]:
                        is_transient = False
        dynamic[i] = is_transient
        support[i] = (log_odds[c] < low or free_latch[c] or (later_pass and pass_start[c] == 0.0)) and (
            not occupied_before[c])
        if dynamic[i]:
            n_dynamic += 1
            lox, hix = min(lox, pts[i, 0]), max(hix, pts[i, 0])
            loy, hiy = min(loy, pts[i, 1]), max(hiy, pts[i, 1])
    if n_dynamic:
        for i in range(pts.shape[0]):
            if support[i] and not dynamic[i] and lox - reach <= pts[i, 0] <= hix + reach and (
                    loy - reach <= pts[i, 1] <= hiy + reach):
                n_support += 1
    span2 = (hix - lox) ** 2 + (hiy - loy) ** 2 if n_dynamic else 0.0
    return n_dynamic, n_support, span2


@numba.njit(cache=True)  # type: ignore[misc]
def cluster_kernel(pts: FloatArray, eps: float) -> npt.NDArray[np.int64]:  # pragma: no cover - compiled
    """Eq. (1) single-linkage clusters of a few hundred points: union–find over all pairs closer than ε.
    Labels 0 … C − 1, numbered in the order of each cluster's first point."""
    n = pts.shape[0]
    parent = np.arange(n)
    eps2 = eps * eps
    for i in range(n):
        for j in range(i + 1, n):
            dx = pts[i, 0] - pts[j, 0]
            dy = pts[i, 1] - pts[j, 1]
            if dx * dx + dy * dy < eps2:
                a = i
                while parent[a] != a:
                    parent[a] = parent[parent[a]]
                    a = parent[a]
                b = j
                while parent[b] != b:
                    parent[b] = parent[parent[b]]
                    b = parent[b]
                if a != b:
                    if a < b:
                        parent[b] = a
                    else:
                        parent[a] = b
    labels = np.empty(n, dtype=np.int64)
    root_label = np.full(n, -1, dtype=np.int64)
    count = 0
    for i in range(n):
        a = i
        while parent[a] != a:
            a = parent[a]
        if root_label[a] < 0:
            root_label[a] = count
            count += 1
        labels[i] = root_label[a]
    return labels


@numba.njit(cache=True)  # type: ignore[misc]
def fit_leaf_kernel(pts: FloatArray, delta: float, max_angle: float, out: FloatArray) -> bool:  # pragma: no cover
    """:func:`doorbatch.pipeline.gridmap.doors.fit_leaf_numpy` (eq. (2)) into ``out`` (2, 2); False for no
    line. The span of the 2θ is their range about their circular mean instead of 2π less the largest gap
    (no sort): the two agree whenever the span is below π, and both exceed 2·max_angle ≤ π otherwise (the
    range is never below the span). Sums run in another order: equal to ~1e-12."""
    n = pts.shape[0]
    two = np.empty(n * (n - 1) // 2)
    s_sin = 0.0
    s_cos = 0.0
    k = 0
    best = -1.0
    bi = 0
    bj = 0
    d2min = delta * delta
    for i in range(n):
        for j in range(i + 1, n):
            dx = pts[j, 0] - pts[i, 0]
            dy = pts[j, 1] - pts[i, 1]
            l2 = dx * dx + dy * dy
            if l2 > d2min:
                t = 2.0 * math.atan2(dy, dx)
                two[k] = t
                s_sin += math.sin(t)
                s_cos += math.cos(t)
                k += 1
                if l2 > best:
                    best = l2
                    bi = i
                    bj = j
    if k == 0:
        return False
    mean2 = math.atan2(s_sin, s_cos)
    lo = 0.0
    hi = 0.0
    for q in range(k):
        dev = two[q] - mean2
        dev -= 2.0 * math.pi * math.floor(dev / (2.0 * math.pi) + 0.5)
        lo = min(lo, dev)
        hi = max(hi, dev)
    if (hi - lo) / 2.0 > max_angle:
        return False
    mean = 0.5 * mean2
    ux = math.cos(mean)
    uy = math.sin(mean)
    cx = 0.0
    cy = 0.0
    for i in range(n):
        cx += pts[i, 0]
        cy += pts[i, 1]
    cx /= n
    cy /= n
    along = ((pts[bi, 0] + pts[bj, 0]) / 2 - cx) * ux + ((pts[bi, 1] + pts[bj, 1]) / 2 - cy) * uy
    mx = cx + along * ux
    my = cy + along * uy
    half = 0.5 * math.sqrt(best)
    out[0, 0] = mx - half * ux
    out[0, 1] = my - half * uy
    out[1, 0] = mx + half * ux
    out[1, 1] = my + half * uy
    return True


@numba.njit(cache=True)  # type: ignore[misc]
def complete_kernel(cluster: FloatArray, support: FloatArray, tol: float, eps: float, reach: float,
                    join: npt.NDArray[np.bool_]) -> int:  # pragma: no cover - compiled
    """:func:`doorbatch.pipeline.gridmap.doors.complete_line_numpy`: marks in ``join`` the support points
    that join the cluster along its principal axis; returns how many."""
    k = cluster.shape[0]
    m = support.shape[0]
    cx = 0.0
    cy = 0.0
    for i in range(k):
        cx += cluster[i, 0]
        cy += cluster[i, 1]
    cx /= k
    cy /= k
    sxx = 0.0
    syy = 0.0
    sxy = 0.0
    for i in range(k):
        ex = cluster[i, 0] - cx
        ey = cluster[i, 1] - cy
        sxx += ex * ex
        syy += ey * ey
        sxy += ex * ey
    theta = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
    ux = math.cos(theta)
    uy = math.sin(theta)
    lo = np.inf
    hi = -np.inf
    for i in range(k):
        t = (cluster[i, 0] - cx) * ux + (cluster[i, 1] - cy) * uy
        lo = min(lo, t)
        hi = max(hi, t)
    dist = np.full(m, np.inf)  # beyond its end of the cluster, signed by the end: − before lo, + after hi
    for i in range(m):
        join[i] = False
        rx = support[i, 0] - cx
        ry = support[i, 1] - cy
        t = rx * ux + ry * uy
        if abs(ry * ux - rx * uy) > tol or t < lo - reach or t > hi + reach:
            continue
        if t < lo:
            dist[i] = -(lo - t)
        elif t > hi:
            dist[i] = t - hi
    count = 0
    for sign in range(2):  # grow outwards from each end while the gaps along the line stay below eps
        reached = 0.0
        grown = True
        while grown:
            grown = False
            for i in range(m):
                d = -dist[i] if sign == 0 else dist[i]
                if not join[i] and 0.0 < d < np.inf and d - reached < eps:
                    join[i] = True
                    count += 1
                    grown = True
            if grown:
                for i in range(m):
                    d = -dist[i] if sign == 0 else dist[i]
                    if join[i] and 0.0 < d < np.inf:
                        reached = max(reached, d)
    return count


@numba.njit(cache=True)  # type: ignore[misc]
def scan_leaves_kernel(dyn: FloatArray, support: FloatArray, eps: float, tol: float, delta: float,
                       max_angle: float, shortest: float, longest: float, max_points: int, segs: FloatArray
                       ) -> int:  # pragma: no cover - compiled
    """:func:`doorbatch.pipeline.gridmap.doors.extract_leaves` of one scan's dynamic points in one call:
    eq. (1) clusters, each completed along its line by ``support`` points, eq. (2) line objects with a
    length in [shortest, longest]. Writes the segments into ``segs`` (at least one row per point) and
    returns their number."""
    labels = cluster_kernel(dyn, eps)
    n = dyn.shape[0]
    m = support.shape[0]
    n_clusters = 0
    for i in range(n):
        n_clusters = max(n_clusters, labels[i] + 1)
    grown = np.empty((n + m, 2))
    sub = np.empty((max(max_points, 2), 2))
    join = np.empty(m, dtype=np.bool_)
    out = np.empty((2, 2))
    count = 0
    for c in range(n_clusters):
        size = 0
        for i in range(n):  # the cluster's points, in scan order
            if labels[i] == c:
                grown[size, 0] = dyn[i, 0]
                grown[size, 1] = dyn[i, 1]
                size += 1
        if size < 2:
            continue
        total = size
        if m > 0 and complete_kernel(grown[:size], support, tol, eps, longest, join) > 0:
            for i in range(m):
                if join[i]:
                    grown[total, 0] = support[i, 0]
                    grown[total, 1] = support[i, 1]
                    total += 1
        lox = hix = grown[0, 0]
        loy = hiy = grown[0, 1]
        for q in range(1, total):
            lox, hix = min(lox, grown[q, 0]), max(hix, grown[q, 0])
            loy, hiy = min(loy, grown[q, 1]), max(hiy, grown[q, 1])
        if (hix - lox) ** 2 + (hiy - loy) ** 2 < shortest * shortest:
            continue  # no pair as long as a leaf (a person, a chair): its line would be too short anyway
        pts = grown[:total]
        if total > max_points:  # evenly subsampled as np.linspace(0, n - 1, max_points).astype(int) does
            step = (total - 1) / (max_points - 1)
            for q in range(max_points - 1):
                k = int(q * step)
                sub[q, 0] = grown[k, 0]
                sub[q, 1] = grown[k, 1]
            sub[max_points - 1, 0] = grown[total - 1, 0]
            sub[max_points - 1, 1] = grown[total - 1, 1]
            pts = sub[:max_points]
        if not fit_leaf_kernel(pts, delta, max_angle, out):
            continue
        length = math.sqrt((out[1, 0] - out[0, 0]) ** 2 + (out[1, 1] - out[0, 1]) ** 2)
        if shortest <= length <= longest:
            segs[count, 0, 0] = out[0, 0]
            segs[count, 0, 1] = out[0, 1]
            segs[count, 1, 0] = out[1, 0]
            segs[count, 1, 1] = out[1, 1]
            count += 1
    return count


@numba.njit(cache=True)  # type: ignore[misc]
def classify_integrate_kernel(log_odds2: npt.NDArray[np.float32], hits2: npt.NDArray[np.int32],
                              hit_sum2: npt.NDArray[np.complex64], free_latch2: npt.NDArray[np.bool_],
                              seen_occupied2: npt.NDArray[np.bool_], last_hit_scan2: npt.NDArray[np.int32],
                              stamp2: npt.NDArray[np.int32], transient2: npt.NDArray[np.bool_],
                              occupied_before2: npt.NDArray[np.bool_], pass_start2: npt.NDArray[np.float32],
                              later_pass: bool, gx: float, gy: float, res: float, ox: float,
                              oy: float, pts: FloatArray, dirs: FloatArray, clear: float, band_m: float, cut: bool,
                              max_range_m: float, scan: int, levels: FloatArray, r: int, reach: float,
                              dynamic: npt.NDArray[np.bool_], support: npt.NDArray[np.bool_]
                              ) -> tuple[int, int, float]:  # pragma: no cover - compiled
    """:func:`classify_kernel` of the scan's end points, then :func:`integrate_kernel` without the dynamic
    ones: one call per scan."""
    counts = classify_kernel(log_odds2, free_latch2, transient2, occupied_before2, pass_start2, later_pass, gx, gy,
                             1.0 / res, pts, r, levels[4], reach, dynamic, support)
    integrate_kernel(log_odds2, hits2, hit_sum2, free_latch2, seen_occupied2, last_hit_scan2, stamp2, gx, gy, res,
                     ox, oy, pts, dirs, dynamic, clear, band_m, cut, max_range_m, scan, levels)
    return counts


@numba.njit(cache=True)  # type: ignore[misc]
def ray_fraction_kernel(mask2: npt.NDArray[np.bool_], gx: float, gy: float, inv: float, sx: float, sy: float,
                        yaws: FloatArray, s: FloatArray, out: FloatArray) -> None:  # pragma: no cover - compiled
    """:func:`doorbatch.pipeline.gridmap.doors._ray_fraction`: for each direction, the fraction of the
    samples at distances ``s`` from (sx, sy) that fall into True cells of ``mask2`` (outside: False)."""
    h, w = mask2.shape
    for k in range(yaws.shape[0]):
        c = math.cos(yaws[k])
        d = math.sin(yaws[k])
        hit = 0
        for q in range(s.shape[0]):
            j = math.floor(((sx - gx) + c * s[q]) * inv)
            i = math.floor(((sy - gy) + d * s[q]) * inv)
            if 0 <= j < w and 0 <= i < h and mask2[int(i), int(j)]:
                hit += 1
        out[k] = hit / s.shape[0]


@numba.njit(cache=True)  # type: ignore[misc]
def band_line_kernel(log_odds2: npt.NDArray[np.float32], hits2: npt.NDArray[np.int32],
                     hit_sum2: npt.NDArray[np.complex64], threshold: float, min_hits: int, hinge_x: float,
                     hinge_y: float, gx: float, gy: float, res: float, phi: float, reach: float, gap: float,
                     within: bool,
                     lo: float, hi: float, out: FloatArray
                     ) -> tuple[int, float, float, float, float]:  # pragma: no cover - compiled
    """:func:`doorbatch.pipeline.gridmap.doors._band_line`: the mean end points of the occupied cells (log-odds above
    ``threshold``, hit in at least ``min_hits`` scans) within
    two cells of the ray from the hinge along φ (s ∈ [2 cells, reach]), refitted to those within a cell of
    their principal axis, re-centred on the fitted direction (at most twice) while it lies in [lo, hi]
    (``within``). Writes the inliers (relative to the hinge) into ``out`` and returns (their number, mean x,
    mean y, direction x, direction y); 0 inliers: no line along φ."""
    h, w = log_odds2.shape
    cx = (hinge_x - gx) / res
    cy = (hinge_y - gy) / res
    j0 = max(0, math.floor(cx - reach / res))
    i0 = max(0, math.floor(cy - reach / res))
    j1 = min(w - 1, math.floor(cx + reach / res))
    i1 = min(h - 1, math.floor(cy + reach / res))
    if j1 < j0 or i1 < i0:
        return 0, 0.0, 0.0, 0.0, 0.0
    thr = np.float32(threshold)
    n_cells = 0
    rx = np.empty((i1 - i0 + 1) * (j1 - j0 + 1))
    ry = np.empty_like(rx)
    for i in range(i0, i1 + 1):
        for j in range(j0, j1 + 1):
            if log_odds2[i, j] > thr and hits2[i, j] >= min_hits:
                n = hits2[i, j]
                if n > 0:
                    fx = hit_sum2[i, j].real / n
                    fy = hit_sum2[i, j].imag / n
                else:
                    fx = 0.5
                    fy = 0.5
                rx[n_cells] = (j + fx - cx) * res
                ry[n_cells] = (i + fy - cy) * res
                n_cells += 1
    px = np.empty(n_cells)
    py = np.empty(n_cells)
    for _ in range(3):
        ux = math.cos(phi)
        uy = math.sin(phi)
        m = 0
        for q in range(n_cells):
            along = rx[q] * ux + ry[q] * uy
            if abs(ry[q] * ux - rx[q] * uy) <= 2 * res and 2 * res <= along <= reach:
                px[m] = rx[q]
                py[m] = ry[q]
                m += 1
        if m < 3:
            return 0, 0.0, 0.0, 0.0, 0.0
        mx = my = dx = dy = 0.0
        for _ in range(3):  # refit to the cells within a cell of the line (drops a neighbour's cells)
            mx = 0.0
            my = 0.0
            for q in range(m):
                mx += px[q]
                my += py[q]
            mx /= m
            my /= m
            sxx = 0.0
            syy = 0.0
            sxy = 0.0
            for q in range(m):
                ex = px[q] - mx
                ey = py[q] - my
                sxx += ex * ex
                syy += ey * ey
                sxy += ex * ey
            theta = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
            dx = math.cos(theta)
            dy = math.sin(theta)
            if dx * ux + dy * uy < 0.0:
                dx = -dx
                dy = -dy
            k = 0
            for q in range(m):
                if abs((px[q] - mx) * dy - (py[q] - my) * dx) <= res:
                    k += 1
            if k == m or k < 3:
                break
            k = 0
            for q in range(m):
                if abs((px[q] - mx) * dy - (py[q] - my) * dx) <= res:
                    px[k] = px[q]
                    py[k] = py[q]
                    k += 1
            m = k
        turn = math.atan2(dy, dx) - phi
        turn -= 2.0 * math.pi * math.floor(turn / (2.0 * math.pi) + 0.5)  # wrapped to [−π, π)
        if abs(turn) <= gap:
            for q in range(m):
                out[q, 0] = px[q]
                out[q, 1] = py[q]
            return m, mx, my, dx, dy
        if not within or not lo - gap <= phi + turn <= hi + gap:
            return 0, 0.0, 0.0, 0.0, 0.0
        phi += turn
    return 0, 0.0, 0.0, 0.0, 0.0
