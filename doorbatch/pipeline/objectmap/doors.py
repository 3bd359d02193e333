"""Door M-step sub-steps of paper 001 Sec. V: hinge and per-pass angles by gradient descent on eq. (10),
the global width by the segment-length procedure, and the per-pass angle search that initialises a door
proposed in Sec. VI (a pseudo-E-step: the points near the leaf support it, occlusion ignored)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from doorbatch.config import ObjectMapConfig
from doorbatch.pipeline.objectmap.beams import BeamSet
from doorbatch.pipeline.objectmap.model import DOOR, ObjectMap
from doorbatch.pipeline.objectmap.sensor import FirstObjects
from doorbatch.pipeline.objectmap.walls import crossing_gains, first_without

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


def _unit(yaw: FloatArray) -> FloatArray:
    return np.stack([np.cos(yaw), np.sin(yaw)], axis=-1)


def door_objective(hinge: FloatArray, yaws: FloatArray, points: FloatArray, passes: IntArray,
                   weights: FloatArray) -> tuple[float, FloatArray, FloatArray]:
    """Eq. (10): f = Σ e ((−sin ψ_t, cos ψ_t)·(π − h))², with its gradient in h and in each ψ_t."""
    yaw = yaws[passes]
    normal = np.stack([-np.sin(yaw), np.cos(yaw)], axis=1)
    rel = points - hinge
    r = np.sum(normal * rel, axis=1)
    f = float(np.sum(weights * r * r))
    g_h = -2.0 * (weights * r) @ normal
    dr_dyaw = -np.sum(_unit(yaw) * rel, axis=1)  # d/dψ of (−sin ψ, cos ψ)·v = −(cos ψ, sin ψ)·v
    g_y = np.bincount(passes, weights=2.0 * weights * r * dr_dyaw, minlength=yaws.shape[0])
    return f, np.asarray(g_h, dtype=np.float64), np.asarray(g_y, dtype=np.float64)


def fit_hinge_angles(hinge: FloatArray, yaws: FloatArray, points: FloatArray, passes: IntArray,
                     weights: FloatArray, iterations: int) -> tuple[FloatArray, FloatArray]:
    """Gradient descent on eq. (10) over the hinge and the angles of the passes that have points, with a
    backtracking (Armijo) step. Angles are scaled by the mean lever arm so that one step suits both."""
    if points.shape[0] < 2 or float(np.sum(weights)) <= 0.0:
        return hinge, yaws
    lever2 = max(float(np.average(np.sum((points - hinge) ** 2, axis=1), weights=weights)), 1e-4)
    h, y = hinge.copy(), yaws.copy()
    f, g_h, g_y = door_objective(h, y, points, passes, weights)
    step = 0.5 / max(float(np.sum(weights)), 1e-9)
    for _ in range(iterations):
        gnorm2 = float(g_h @ g_h + (g_y @ g_y) / lever2)
        if gnorm2 < 1e-18:
            break
        while step > 1e-12:
            h_new, y_new = h - step * g_h, y - step * g_y / lever2
            f_new, gh_new, gy_new = door_objective(h_new, y_new, points, passes, weights)
            if f_new <= f - 0.5 * step * gnorm2:
                h, y, f, g_h, g_y = h_new, y_new, f_new, gh_new, gy_new
                step *= 2.0
                break
            step *= 0.5
        else:
            break
    return h, np.arctan2(np.sin(y), np.cos(y))


def leaf_support(points: FloatArray, hinge: FloatArray, yaws: FloatArray, width: float, sigma: float
                 ) -> FloatArray:
    """Pseudo-E-step score of candidate leaf directions: Σ exp(−r²/2σ²) over the points whose projection
    falls on the leaf [0, w], r their distance to the leaf line (occlusion ignored). (A,) for A yaws."""
    rel = points - hinge
    along = rel @ _unit(yaws).T  # (P, A)
    across = rel @ np.stack([-np.sin(yaws), np.cos(yaws)], axis=0)
    on = (along >= -sigma) & (along <= width + sigma)
    return np.asarray(np.sum(np.where(on, np.exp(-0.5 * (across / sigma) ** 2), 0.0), axis=0), dtype=np.float64)


def leaf_blocked(origin: FloatArray, end: FloatArray, hinge: FloatArray, yaws: FloatArray, width: float
                 ) -> FloatArray:
    """How many ray pieces origin→end cross the leaf [h, h + w·u(ψ)] for each yaw ψ: (A,) counts."""
    if origin.shape[0] == 0:
        return np.zeros(yaws.shape[0])
    tips = hinge + width * _unit(yaws)  # (A, 2)

    def cross(a: FloatArray, b: FloatArray) -> FloatArray:
        return np.asarray(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0], dtype=np.float64)

    r = end - origin  # (R, 2)
    e = tips - hinge  # (A, 2)
    den = cross(r[:, None, :], e[None, :, :])  # (R, A)
    w = hinge - origin  # (R, 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = cross(w[:, None, :], e[None, :, :]) / den
        u = cross(w, r)[:, None] / den
    hit = (t > 0.0) & (t < 1.0) & (u >= 0.0) & (u <= 1.0)
    return np.asarray(hit.sum(axis=0), dtype=np.float64)


def initial_angles(beams: BeamSet, hinge: FloatArray, width: float, fallback_yaw: float, config: ObjectMapConfig
                   ) -> FloatArray:
    """Per pass, the leaf direction best supported by that pass's points near the hinge (pseudo-E-step)
    less the rays of that pass that would pass through the leaf, within ``max_opening_deg`` of the closed
    direction ``fallback_yaw`` (so the wall behind the hinge is not taken for the leaf); of directions
    within ``angle_tie_share`` of the best, the one nearest the closed direction; ``fallback_yaw`` when no
    direction has support (the leaf was not seen in that pass)."""
    sigma = config.sigma_m
    offsets = np.deg2rad(np.arange(-config.max_opening_deg, config.max_opening_deg + 1e-9,
                                   config.angle_search_step_deg))
    yaws = fallback_yaw + offsets
    out = np.full(beams.n_passes, fallback_yaw)
    pts = beams.points
    reach = np.linalg.norm(pts - hinge, axis=1)
    near_o = rays_near(beams, hinge, width + config.door_wall_margin_m)
    for t in range(beams.n_passes):
        in_pass = beams.pass_index == t
        sel = in_pass & beams.hit & (reach <= width + 3.0 * sigma)
        support = leaf_support(pts[sel], hinge, yaws, width, sigma)
        if support.max() < config.min_leaf_support:
            continue
        # rays of this pass passing by the hinge: their piece up to (range − margin) must not cross the leaf
        rays = in_pass & near_o
        end = beams.origin[rays] + np.maximum(beams.range_m[rays] - config.through_margin_m, 0.0)[:, None] * \
            beams.direction[rays]
        score = support - leaf_blocked(beams.origin[rays], end, hinge, yaws, width)
        good = np.flatnonzero(score >= max(config.min_leaf_support, config.angle_tie_share * float(score.max())))
        if good.size:
            out[t] = yaws[good[np.argmin(np.abs(offsets[good]))]]
    return out


def rays_near(beams: BeamSet, point: FloatArray, radius: float) -> BoolArray:
    """Rays (origin → measured end, the max-range mark for no-return beams) passing within ``radius`` of
    ``point``."""
    rel = point - beams.origin
    along = np.clip(np.sum(rel * beams.direction, axis=1), 0.0, beams.range_m)
    closest = beams.origin + along[:, None] * beams.direction
    return np.asarray(np.linalg.norm(closest - point, axis=1) <= radius, dtype=np.bool_)


def leaf_crossings(beams: BeamSet, hinge: FloatArray, yaws: FloatArray, max_width: float, sigma: float
                   ) -> tuple[IntArray, FloatArray, FloatArray]:
    """Rays of each pass t that cross the leaf line from the hinge in direction ψ_t at leaf coordinate
    u ∈ [0, max_width], before their measured end (+5σ): beam index, t along the ray, u."""
    yaw = yaws[beams.pass_index]
    d = _unit(yaw)
    n = np.stack([-np.sin(yaw), np.cos(yaw)], axis=1)
    denom = np.sum(beams.direction * n, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.sum((hinge - beams.origin) * n, axis=1) / denom
    ok = np.isfinite(t) & (t > 0.0) & (t <= np.minimum(beams.range_m + 5.0 * sigma, beams.dmax))
    idx = np.flatnonzero(ok)
    u = np.sum((beams.origin[idx] + t[idx, None] * beams.direction[idx] - hinge) * d[idx], axis=1)
    keep = (u >= 0.0) & (u <= max_width)
    return idx[keep], t[idx][keep], u[keep]


def width_gains(beams: BeamSet, first: FirstObjects, obj_map: ObjectMap, i: int, max_width: float, lam: float,
                sigma: float) -> tuple[FloatArray, FloatArray]:
    """For door i: leaf coordinates u of the rays crossing its leaf line and the gain Δ of each (as eq. 9:
    the leaf present at u against absent)."""
    door = obj_map.doors[i]
    idx, t, u = leaf_crossings(beams, door.hinge, door.yaws, max_width, sigma)
    if idx.size == 0:
        return np.zeros(0), np.zeros(0)
    delta, kind = first_without(beams, first, idx, obj_map, DOOR, i)
    gain = crossing_gains(beams, idx, t, delta, kind, DOOR, obj_map.classes, lam, sigma)
    return u, gain


def best_width(u: FloatArray, gain: FloatArray, n_doors: int, rho_length_per_m: float, width_min: float,
               width_max: float, current: float) -> float:
    """The width procedure of Sec. V: all doors' rays as crossings of one segment [0, w]; minimise
    −Σ_{u ≤ w} Δ + ρL·w·n_doors over w ∈ the crossing coordinates within [width_min, width_max]."""
    inside = (u >= 0.0) & (u <= width_max)
    if not np.any(inside):
        return current
    order = np.argsort(u[inside])
    us, gs = u[inside][order], gain[inside][order]
    cost = -np.cumsum(gs) + rho_length_per_m * n_doors * us
    ok = us >= width_min
    if not np.any(ok):
        return current
    k = int(np.flatnonzero(ok)[np.argmin(cost[ok])])
    return float(us[k])
