"""The door-aware beam likelihood of the RBPF (paper 000, Sec. IV, eq. (6)).

Each beam end point p (map frame, at the particle's pose) is explained either by the static map or by one
door leaf. Both are endpoint models of the same quantity, a distance:

* static: d₀ = the likelihood field's distance from p to the nearest occupied cell (capped at
  ``laser_likelihood_max_dist``), variance σ₀² = σ_hit²;
* door k: d_k = the distance from p to the leaf at the particle's door mean μ_k (:mod:`door_geometry`). The
  door angle is uncertain, a_k ~ N(μ_k, P_k), so eq. (6) integrates the endpoint Gaussian over it. With the
  first-order Taylor expansion d_k(a) ≈ d_k(μ_k) + J_k·(a − μ_k), J_k = ∂d_k/∂a, the integral is again a
  Gaussian in d_k(μ_k) with the propagated variance σ_k² = σ_hit² + J_k²·P_k.

The per-model density, scaled so that the static one is exactly Nav2's likelihood-field term, is

    g_k = (σ_hit / σ_k) · exp(−d_k² / (2 σ_k²))          (g₀ = exp(−d₀² / (2 σ_hit²)))

(the same constant factor √(2π)·σ_hit times the normalized Gaussian for every model, so comparisons
between models are comparisons of densities). Maximum-likelihood association picks, per beam, the model
with the largest g (the static map wins ties); the beam's likelihood is the same mixture as the static
model, p = z_hit·g + z_rand / range_max, and a particle's log-likelihood is Σ_beams log p (eq. (5); the
per-beam p are returned too, for Nav2's log(1 + Σ p³) combination). A door whose
leaf is at least ``laser_likelihood_max_dist`` away from the end point (the static field's cap) is not a
candidate for that beam.

A door the particle has not observed yet (its variance at least ``unobserved_var``, the door prior's) is
weighed under its prior, uniform over the opening range [lo, hi] (width Δ), instead of a linearization at its
mean: the endpoint density averaged over the angle, g_k = (σ_hit/σ)·(1/Δ)∫ exp(−d_k(a)²/(2σ²)) da. With r the end
point's distance from the hinge and φ its direction (relative to closed_yaw), d_k(a)² ≈ d_min² + c·(a − φ)²,
d_min = max(r − L, 0), c = r² on the leaf's disc (r ≤ L, d = r·|sin(a − φ)|) and c = r·L beyond it, so

    g_k = (σ_hit/σ)·exp(−d_min²/(2σ²))·A,   A = √(π/2)·σ/(√c·Δ)·[erf(√c(hi − φ)/(√2σ)) − erf(√c(lo − φ)/(√2σ))]

(A ≤ 1, the fraction of the range whose leaf passes the end point). Under the global phase's mixture prior
(:mod:`.door_prior`: closed, N(0, σ_c²), with probability p_c, else uniform) the same quadratic integrates the
closed component in closed form too, A_c = √(σ²/(σ² + c·σ_c²))·exp(−c·φ²/(2(σ² + c·σ_c²))), and A becomes
p_c·A_c + (1 − p_c)·A (p_c = 0: the uniform prior). This is eq. (6)'s marginalization done
over the prior the particle actually has (expert choice: with a prior std of tens of degrees the first-order
expansion around a mean that is wrong by most of the range is poor, and one closed leaf far away costs the
true pose the beam floor every scan until the door update has seen it).

The hinge is counted once. Mapping keeps the hinge cells occupied in the static grid, and the hinge is
also an end point of the leaf, so a beam ending at a hinge is close to both models. A product of both
factors, or a sum over them, would use that beam twice (and reward particles near hinges twice);
maximum-likelihood association picks exactly one of them per beam. Near the hinge J ≈ 0 (the hinge does not
move with the angle), so σ_k ≈ σ_hit and the two models tie or nearly so; the choice is then immaterial to
the weight, and the tie goes to the static map.

Two implementations give the same result: a numba kernel fused over particles × beams × doors (no
(N, B, D) array; per particle it keeps the doors in reach of its end points, and per (door, beam) it first
applies a cheap exact bound, see :func:`_score_kernel`), and a NumPy reference in chunks of particles. The
end points come either as (N, B, 2) map-frame points (:func:`door_log_likelihood`) or as poses and base_link
points (:func:`door_log_likelihood_at_poses`, which moves them inside the kernel).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, NamedTuple

import numpy as np
import numpy.typing as npt

from doorbatch.config import LocalizeConfig
from doorbatch.maps import DoorSet
from doorbatch.pipeline.localize.door_geometry import (
    CHUNK_ELEMENTS,
    doors_in_reach,
    jit_kernel,
    point_to_leaf_distance,
    subset_doors,
)
from doorbatch.pipeline.localize.door_prior import UNIFORM, DoorPrior

FloatArray = npt.NDArray[np.float64]
Int16Array = npt.NDArray[np.int16]
Backend = Literal["auto", "numba", "numpy"]

STATIC = -1  # association code of a beam explained by the static map (or skipped)


@dataclass(frozen=True)
class DoorLikelihood:
    """Per-beam association (N, B) int16 (−1 static, k ≥ 0 door k) and per-beam likelihoods pz (N, B) float32
    (NaN for skipped beams), which the filters combine with beam skipping (``likelihood_field.skip_unexplained``,
    ``combine_beams``); and, computed when asked for, the product model's per-particle log-likelihood."""

    association: Int16Array
    beam_likelihood: npt.NDArray[np.float32]

    @property
    def log_likelihood(self) -> FloatArray:
        """Σ_beams log pz (N,) float64, a skipped beam counting 0: float32 per beam (SIMD log), float64 sums (the
        error is ~1e-7 relative per beam, far below what the weights resolve)."""
        log_pz = np.log(self.beam_likelihood)
        log_pz[np.isnan(self.beam_likelihood)] = 0.0
        return np.asarray(log_pz.sum(axis=1, dtype=np.float64), dtype=np.float64)


class BeamModel(NamedTuple):
    """The beam model's constants as the door likelihood uses them."""

    z_hit: float
    rand_term: float  # z_rand / range_max
    sigma2: float  # σ_hit²
    max_dist: float


def beam_model(config: LocalizeConfig, range_max_m: float) -> BeamModel:
    """The config's beam model for a laser of ``range_max_m``.

    Raises:
        ValueError: range_max_m not positive and finite.
    """
    if not (math.isfinite(range_max_m) and range_max_m > 0.0):
        raise ValueError(f"range_max_m must be positive and finite, got {range_max_m}")
    return BeamModel(config.z_hit, config.z_rand / range_max_m, config.sigma_hit**2, config.laser_likelihood_max_dist)


def door_log_likelihood(static_dist: npt.ArrayLike, points: npt.ArrayLike, doors: DoorSet,
                        door_mean: npt.ArrayLike, door_var: npt.ArrayLike, config: LocalizeConfig,
                        range_max_m: float, backend: Backend = "auto") -> DoorLikelihood:
    """Eq. (6): per-particle log-likelihood of a scan with maximum-likelihood association to map or doors.

    Args:
        static_dist: (N, B) static likelihood-field distance of each beam end point (m, capped; float32
            like ``likelihood_field.endpoint_distances``). A NaN here or a non-finite end point skips the beam
            (no factor, association −1, pz NaN).
        points: (N, B, 2) beam end points in the map frame at each particle's pose.
        doors: D doors of the map.
        door_mean: (N, D) door angle means per particle (rad, relative to closed_yaw, CCW positive).
        door_var: (N, D) door angle variances (rad²).
        config: ``z_hit``, ``z_rand``, ``sigma_hit``, ``laser_likelihood_max_dist``.
        range_max_m: The laser's maximum range (z_rand's uniform density is 1 / range_max).
        backend: ``numba`` (fused kernel), ``numpy`` (reference), ``auto`` (numba when installed).

    Returns:
        :class:`DoorLikelihood`: log-likelihood (N,) float64 (the product of the beams, eq. (5)),
        association (N, B) int16 (−1 static, k door k of ``doors``), per-beam pz (N, B) float32.

    Raises:
        ValueError: Shapes disagree, more than 32767 doors, range_max_m not positive, or ``numba`` asked
            for without numba.
    """
    dist = np.ascontiguousarray(static_dist, dtype=np.float32)
    pts = np.ascontiguousarray(points, dtype=np.float64)
    if pts.shape != (*dist.shape, 2) or dist.ndim != 2:
        raise ValueError(f"points {pts.shape} must be static_dist's shape {dist.shape} plus (2,)")
    return _door_log_likelihood(dist, pts, None, None, doors, door_mean, door_var, config, range_max_m, backend)


def door_log_likelihood_at_poses(static_dist: npt.ArrayLike, pose: npt.ArrayLike, points_base: npt.ArrayLike,
                                 doors: DoorSet, door_mean: npt.ArrayLike, door_var: npt.ArrayLike,
                                 config: LocalizeConfig, range_max_m: float, backend: Backend = "auto",
                                 extra_var: npt.ArrayLike | None = None,
                                 unobserved_var: npt.ArrayLike | None = None,
                                 prior: DoorPrior = UNIFORM) -> DoorLikelihood:
    """:func:`door_log_likelihood` with the end points given as poses (N, 3) and base_link points (B, 2).

    The numba kernel moves the points itself, particle by particle, so no (N, B, 2) array is made (saves
    ~20 MB and ~25 ms at 10,000 particles × 60 beams); the result equals :func:`door_log_likelihood` of
    ``likelihood_field.endpoint_points(pose, points_base)``.

    ``extra_var`` (N, B): a variance (m²) added to every model's σ² for that beam of that particle (global
    localization's smoothing over the particle's pose region, :mod:`.smoothing`): σ₀² = σ_hit² + e and
    σ_k² = σ_hit² + e + J_k²·P_k, each density keeping its factor σ_hit / σ.

    ``unobserved_var`` (D,): a door whose variance for a particle is at least this is weighed under ``prior`` over
    its range (module docstring: the uniform prior, or the closed/open mixture of :mod:`.door_prior`); None (or
    +inf): eq. (6) for every door.

    Raises:
        ValueError: As :func:`door_log_likelihood`.
    """
    dist = np.ascontiguousarray(static_dist, dtype=np.float32)
    poses = np.ascontiguousarray(pose, dtype=np.float64).reshape(-1, 3)
    base = np.ascontiguousarray(points_base, dtype=np.float64).reshape(-1, 2)
    if dist.shape != (poses.shape[0], base.shape[0]):
        raise ValueError(f"static_dist {dist.shape} must be (N, B) = ({poses.shape[0]}, {base.shape[0]})")
    extra = None if extra_var is None else np.ascontiguousarray(extra_var, dtype=np.float32)
    if extra is not None and extra.shape != dist.shape:
        raise ValueError(f"extra_var {extra.shape} must be (N, B) = {dist.shape}")
    return _door_log_likelihood(dist, None, poses, base, doors, door_mean, door_var, config, range_max_m, backend,
                                extra, unobserved_var, prior)


def _door_log_likelihood(dist: npt.NDArray[np.float32], pts: FloatArray | None, poses: FloatArray | None,
                         base: FloatArray | None, doors: DoorSet, door_mean: npt.ArrayLike, door_var: npt.ArrayLike,
                         config: LocalizeConfig, range_max_m: float, backend: Backend,
                         extra: npt.NDArray[np.float32] | None = None,
                         unobserved_var: npt.ArrayLike | None = None, prior: DoorPrior = UNIFORM) -> DoorLikelihood:
    """Checks, then the kernel or the reference, then the beam likelihoods."""
    model = beam_model(config, range_max_m)
    uni = np.full(len(doors), np.inf) if unobserved_var is None else np.ascontiguousarray(
        np.broadcast_to(np.asarray(unobserved_var, dtype=np.float64), (len(doors),)))
    mean = np.ascontiguousarray(door_mean, dtype=np.float64)
    var = np.ascontiguousarray(door_var, dtype=np.float64)
    n_doors = len(doors)
    if n_doors > np.iinfo(np.int16).max:
        raise ValueError(f"{n_doors} doors do not fit the int16 association")
    if mean.shape != (dist.shape[0], n_doors) or var.shape != mean.shape:
        raise ValueError(f"door_mean {mean.shape} and door_var {var.shape} must be (N, D) = "
                         f"({dist.shape[0]}, {n_doors})")
    kernel = jit_kernel(_score_kernel) if backend in ("auto", "numba") else None
    if kernel is None and backend == "numba":
        raise ValueError("backend 'numba' asked for but numba is not installed (pip install numba)")
    if kernel is not None:
        score = np.empty(dist.shape, dtype=np.float32)
        assoc = np.empty(dist.shape, dtype=np.int16)
        from_pose = pts is None
        kernel(dist, np.zeros((0, 0, 2)) if pts is None else pts, np.zeros((0, 3)) if poses is None else poses,
               np.zeros((0, 2)) if base is None else base, from_pose,
               np.ascontiguousarray(doors.hinge, dtype=np.float64).reshape(-1, 2),
               np.ascontiguousarray(doors.length, dtype=np.float64),
               np.ascontiguousarray(doors.closed_yaw, dtype=np.float64), mean, var, model.sigma2, model.max_dist,
               np.zeros((0, 0), dtype=np.float32) if extra is None else extra, extra is not None,
               uni, np.ascontiguousarray(doors.angle_min, dtype=np.float64),
               np.ascontiguousarray(doors.angle_max, dtype=np.float64), prior.closed_prob, prior.closed_var,
               score, assoc)
    else:
        if pts is None:
            assert poses is not None and base is not None
            c, s = np.cos(poses[:, 2, None]), np.sin(poses[:, 2, None])
            pts = np.stack([poses[:, 0, None] + c * base[:, 0] - s * base[:, 1],
                            poses[:, 1, None] + s * base[:, 0] + c * base[:, 1]], axis=-1)
        score, assoc = _numpy_scores(dist, pts, doors, mean, var, model, extra, uni, prior)
    return DoorLikelihood(assoc, beam_likelihoods(score, model))


def beam_likelihoods(score: npt.NDArray[np.float32], model: BeamModel) -> npt.NDArray[np.float32]:
    """pz = z_hit·exp(−score/2) + z_rand/range_max per beam, float32 (NaN where the score is: a skipped beam)."""
    pz: npt.NDArray[np.float32] = np.exp(np.float32(-0.5) * score)
    pz *= np.float32(model.z_hit)
    pz += np.float32(model.rand_term)
    return pz


def _numpy_scores(dist: npt.NDArray[np.float32], pts: FloatArray, doors: DoorSet, mean: FloatArray, var: FloatArray,
                  model: BeamModel, extra: npt.NDArray[np.float32] | None = None, uni: FloatArray | None = None,
                  prior: DoorPrior = UNIFORM) -> tuple[npt.NDArray[np.float32], Int16Array]:
    """NumPy reference: score −2·log(g/z_hit) of the chosen model and the association, per particle chunk."""
    n, b = dist.shape
    valid = np.isfinite(dist) & np.isfinite(pts).all(axis=2)
    e = np.zeros((n, b)) if extra is None else extra.astype(np.float64)
    s0 = model.sigma2 + e
    score = np.where(valid, dist.astype(np.float64) ** 2 / s0 + np.log(s0 / model.sigma2), np.nan)  # static
    assoc = np.full((n, b), STATIC, dtype=np.int16)
    active = np.flatnonzero(doors_in_reach(doors, pts, model.max_dist)) if len(doors) else np.zeros(0, np.intp)
    if active.size:
        sub = subset_doors(doors, active)
        step = max(1, CHUNK_ELEMENTS // (b * active.size))
        for lo in range(0, n, step):  # chunks of particles (memory), not a per-particle loop
            sl = slice(lo, min(n, lo + step))
            d_k, j_k = point_to_leaf_distance(np.where(valid[sl, :, None], pts[sl], 0.0), sub,
                                              mean[sl][:, active], dtype=np.float64)
            sig2 = s0[sl, :, None] + j_k**2 * var[sl][:, None, active]
            s_k = d_k**2 / sig2 + np.log(sig2 / model.sigma2)
            s_k = np.where((d_k < model.max_dist) & valid[sl, :, None], s_k, np.inf)
            if uni is not None and np.isfinite(uni[active]).any():
                s_u = _uniform_scores(np.where(valid[sl, :, None], pts[sl], 0.0)[:, :, None, :], sub,
                                      s0[sl, :, None], model, prior)
                s_u = np.where(valid[sl, :, None], s_u, np.inf)
                s_k = np.where((var[sl][:, None, active] >= uni[active]), s_u, s_k)
            best = np.argmin(s_k, axis=2)
            s_best = np.take_along_axis(s_k, best[:, :, None], axis=2)[:, :, 0]
            wins = s_best < score[sl]
            score[sl] = np.where(wins, s_best, score[sl])
            assoc[sl] = np.where(wins, active[best], STATIC).astype(np.int16)
    return score.astype(np.float32), assoc


def _uniform_scores(pts: FloatArray, doors: DoorSet, s0: FloatArray, model: BeamModel, prior: DoorPrior = UNIFORM
                    ) -> FloatArray:
    """Score −2·log(g_k) of each door under its prior over the range (module docstring: uniform, or the closed /
    open mixture), (..., D).

    ``pts`` (..., 1, 2) end points, ``s0`` (..., 1) each beam's σ² (σ_hit² + e); inf where the leaf cannot come
    within the distance cap.
    """
    vx = pts[..., 0] - doors.hinge[:, 0]
    vy = pts[..., 1] - doors.hinge[:, 1]
    r = np.hypot(vx, vy)
    lo, hi, ln = doors.angle_min, doors.angle_max, doors.length
    mid = (lo + hi) / 2
    phi = mid + np.mod(np.arctan2(vy, vx) - doors.closed_yaw - mid + np.pi, 2 * np.pi) - np.pi
    dmin2 = np.maximum(r - ln, 0.0) ** 2
    sq = np.sqrt(np.where(r <= ln, r * r, r * ln) / s0)  # √c / σ
    width = hi - lo
    with np.errstate(divide="ignore", invalid="ignore"):
        u_hi, u_lo = (hi - phi) * sq / np.sqrt(2), (lo - phi) * sq / np.sqrt(2)
        frac = np.sqrt(np.pi / 2) / (sq * width) * (_erf(u_hi) - _erf(u_lo))
        frac = np.where(sq * width < 1e-9, 1.0, frac)
        if prior.closed_prob > 0.0:
            den = 1.0 + sq**2 * prior.closed_var  # (σ² + c·σ_c²)/σ²
            closed = np.exp(-0.5 * sq**2 * phi**2 / den) / np.sqrt(den)
            frac = prior.closed_prob * closed + (1.0 - prior.closed_prob) * frac
        score = dmin2 / s0 + np.log(s0 / model.sigma2) - 2 * np.log(frac)
    return np.where((dmin2 < model.max_dist**2) & (frac > 0), score, np.inf)


_erf = np.vectorize(math.erf, otypes=[np.float64])


def _score_kernel(dist: npt.NDArray[np.float32], pts: FloatArray, poses: FloatArray, base: FloatArray,
                  from_pose: bool, hinge: FloatArray, length: FloatArray, closed_yaw: FloatArray, mean: FloatArray,
                  var: FloatArray, sigma2: float, max_dist: float, extra: npt.NDArray[np.float32], has_extra: bool,
                  uni: FloatArray, lo: FloatArray, hi: FloatArray, closed_prob: float, closed_var: float,
                  score: npt.NDArray[np.float32], assoc: Int16Array) -> None:  # pragma: no cover - numba
    """Numba kernel: per particle, its end points (from ``pts``, or ``poses`` ⊕ ``base``), the doors in reach of
    their bounding box, and per beam the model with the lowest score (static on ties; doors in index order).

    A door cannot win a beam whose end point p has |p − h| ≥ L + d₀·√(1 + L²P/σ_hit²): |J| ≤ L gives
    d_k ≥ |p − h| − L and σ_k² ≤ σ_hit² + L²P, so d_k²/σ_k² ≥ d₀²/σ_hit². That test runs door by door over all
    beams in a branch-free loop (vectorizable); only the flagged pairs get the distance, and the logarithm
    only if d_k²/σ_k² alone does not already lose. With ``has_extra`` every model's σ² of beam m also gets
    ``extra[i, m]`` (the bound above stays valid: it only grows σ₀², and the log term it adds to the static
    score is at most the door's). A door with ``var[i, k] ≥ uni[k]`` takes the prior's score instead (module docstring:
    uniform, or the mixture with ``closed_prob`` > 0); the same bound holds for it (d_min ≥ |p − h| − L, and
    −2·log A ≥ 0: A ≤ 1 for either component).
    """
    n, b = dist.shape
    n_doors = length.shape[0]
    px = np.empty(b)
    py = np.empty(b)
    d0 = np.empty(b)
    best = np.empty(b)
    best_k = np.empty(b, dtype=np.int16)
    s0 = np.empty(b)
    near = np.empty(b, dtype=np.bool_)
    max_d2 = max_dist * max_dist
    for i in range(n):
        if from_pose:
            c = math.cos(poses[i, 2])
            s = math.sin(poses[i, 2])
            for m in range(b):
                px[m] = poses[i, 0] + c * base[m, 0] - s * base[m, 1]
                py[m] = poses[i, 1] + s * base[m, 0] + c * base[m, 1]
        else:
            for m in range(b):
                px[m] = pts[i, m, 0]
                py[m] = pts[i, m, 1]
        lo_x = lo_y = math.inf
        hi_x = hi_y = -math.inf
        for m in range(b):
            d0[m] = dist[i, m]
            best_k[m] = -1
            s0[m] = sigma2 + extra[i, m] if has_extra else sigma2
            if math.isfinite(px[m]) and math.isfinite(py[m]) and math.isfinite(d0[m]):
                best[m] = d0[m] * d0[m] / s0[m] + (math.log(s0[m] / sigma2) if has_extra else 0.0)
                lo_x = min(lo_x, px[m])
                hi_x = max(hi_x, px[m])
                lo_y = min(lo_y, py[m])
                hi_y = max(hi_y, py[m])
            else:
                best[m] = math.nan
                d0[m] = math.nan  # fails every reach test below
        for k in range(n_doors):
            hx = hinge[k, 0]
            hy = hinge[k, 1]
            ln = length[k]
            gx = max(lo_x - hx, hx - hi_x, 0.0)
            gy = max(lo_y - hy, hy - hi_y, 0.0)
            if gx * gx + gy * gy > (ln + max_dist) ** 2:
                continue
            phi = closed_yaw[k] + mean[i, k]
            ux = math.cos(phi)
            uy = math.sin(phi)
            pv = var[i, k]
            gain = math.sqrt(1.0 + ln * ln * max(pv, 0.0) / sigma2)
            any_near = False
            for m in range(b):
                vx = px[m] - hx
                vy = py[m] - hy
                reach = ln + min(d0[m] * gain, max_dist)
                near[m] = vx * vx + vy * vy < reach * reach
                any_near |= near[m]
            if not any_near:
                continue
            if pv >= uni[k]:  # unobserved: the door prior over [lo, hi] (uniform, or the closed/open mixture)
                mid = 0.5 * (lo[k] + hi[k])
                width = hi[k] - lo[k]
                for m in range(b):
                    if not near[m]:
                        continue
                    vx = px[m] - hx
                    vy = py[m] - hy
                    r = math.sqrt(vx * vx + vy * vy)
                    dm = max(r - ln, 0.0)
                    d2 = dm * dm
                    if d2 >= max_d2:
                        continue
                    ratio = d2 / s0[m]
                    if ratio >= best[m]:
                        continue
                    phi = math.atan2(vy, vx) - closed_yaw[k] - mid
                    phi = mid + (phi + math.pi) % (2.0 * math.pi) - math.pi
                    sq = math.sqrt((r * r if r <= ln else r * ln) / s0[m])
                    if sq * width < 1e-9:
                        frac = 1.0
                    else:
                        u_hi = (hi[k] - phi) * sq / math.sqrt(2.0)
                        u_lo = (lo[k] - phi) * sq / math.sqrt(2.0)
                        frac = math.sqrt(math.pi / 2.0) / (sq * width) * (math.erf(u_hi) - math.erf(u_lo))
                    if closed_prob > 0.0:
                        den = 1.0 + sq * sq * closed_var
                        frac = (closed_prob * math.exp(-0.5 * sq * sq * phi * phi / den) / math.sqrt(den)
                                + (1.0 - closed_prob) * frac)
                    if frac <= 0.0:
                        continue
                    cand = ratio + math.log(s0[m] / sigma2) - 2.0 * math.log(frac)
                    if cand < best[m]:
                        best[m] = cand
                        best_k[m] = k
                continue
            for m in range(b):
                if not near[m]:
                    continue
                vx = px[m] - hx
                vy = py[m] - hy
                t_c = min(max(vx * ux + vy * uy, 0.0), ln)
                ex = vx - t_c * ux
                ey = vy - t_c * uy
                d2 = ex * ex + ey * ey
                if d2 >= max_d2:
                    continue
                jac2 = t_c * t_c  # J² = t_c² s² / d², t_c² on the leaf (d = 0)
                if d2 > 0.0:
                    s_k = ux * vy - uy * vx
                    jac2 = jac2 * s_k * s_k / d2
                sig2 = s0[m] + jac2 * pv
                ratio = d2 / sig2
                if ratio >= best[m]:  # log(σ_k²/σ_hit²) ≥ 0 can only add to it
                    continue
                cand = ratio + math.log(sig2 / sigma2)
                if cand < best[m]:
                    best[m] = cand
                    best_k[m] = k
        for m in range(b):
            score[i, m] = best[m]
            assoc[i, m] = best_k[m]


def numba_available() -> bool:
    """Whether the fused numba kernels can be used."""
    return jit_kernel(_score_kernel) is not None
