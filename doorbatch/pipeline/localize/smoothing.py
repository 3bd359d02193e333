"""Density-adaptive likelihood smoothing and regularized resampling for global localization.

Why. A particle set is a sample, and each particle stands for the region of pose space around it that no
other particle covers. With particles uniform over 200 m² of free space and all headings, 10,000 particles
leave ~0.12 m²·rad to each: the particle nearest to the true pose is typically 0.15 m and 3° away. The
endpoint model (σ_hit = 0.1 m, ~60 beams) is far sharper than that: 2° of heading moves an end point 10 m
away by 0.35 m and costs ~16 nats on the sample's first scan, so the weights rank particles by how exactly
they happen to sit on *some* pose that fits, not by how well their region fits; on a corridor the winner
is an arbitrary pose along it, resampling gathers everything there and the filter "converges" on the wrong
pose (docs/results.md, "Localization (issue #5)"). The remedy is the one of Pfaff, Burgard and Fox,
"Robust Monte-Carlo localization using adaptive likelihood models" (EUROS 2006): weigh each particle with
the likelihood averaged over its region, whose size follows the local particle density.

The math. Particle i stands for poses x_i + δ with δ ~ N(0, diag(h_xy², h_xy², h_θ²)). A beam end point b
(base_link, at distance r = |b| from the robot's origin) then moves by δ_xy + h_θ·r in the direction normal to
b, to first order; the end point's distance to the map changes by at most that, so its variance grows by
e = h_xy² + r²·h_θ² (the same first-order error propagation as the door term of paper 000's eq. (6)).
Averaging AMCL's unnormalized hit Gaussian over it gives, exactly for a distance linear in δ,

    ∫ exp(−(d + u)² / (2σ²)) N(u; 0, e) du = σ / √(σ² + e) · exp(−d² / (2(σ² + e))),   σ = σ_hit,

so pz = z_hit·σ/√(σ² + e)·exp(−d²/(2(σ² + e))) + z_rand / range_max. With e = 0 it is Nav2's term.

One volume factor, not one per beam (``global_smoothing_volume`` "pose", the default with the product of the
beams). The factor σ/√(σ² + e) is the share of a beam's offset range that fits; but all beams of a scan move
with the *same* 3-D pose offset δ, so the average of their product is not the product of their averages.
To second order (Laplace), with J_b = ∂d_b/∂pose and the scan's pose information A = Σ_b r_b·J_bᵀJ_b / σ²,

    E_δ[Π_b exp(−(d_b + J_b·δ)² / (2σ²))] ≈ |I + H·A|^(−½) · (peak),   H = diag(h_xy², h_xy², h_θ²),

one factor for the region (:func:`pose_volume_log_factor`), while the peak keeps the per-beam exponents
exp(−d_b²/(2(σ² + e_b))). The per-beam factors instead count the region's size once per beam: at the true pose
of the sample's loc_closed, first scan, a 0.21 m / 4.2° region (10,000 uniform particles) costs 60.9 nats that
way and 5.8 in the Laplace form, a tracked cloud's 0.03 m / 0.5° 4.4 and 1.2 (scripts/localize_region_factor.py),
so the cloud collapsed onto whichever part of a corridor happened to be dense (docs/results.md).

The bandwidth. Each particle stands for the region its neighbours leave to it: with the distance r_k to its
k-th nearest neighbour (k = 8) in (x, y, L·yaw), L = kld_bin_xy_m / kld_bin_yaw (the KLD bins' aspect,
2.9 m/rad), a ball of volume (4/3)·π·r_k³ holds k particles, so a particle's cell has the side
c = ((4/3)·π·r_k³ / k)^(1/3), and the offset of a pose uniform in the cell from its centre has the standard
deviation c/√12: h_xy = c/√12, h_θ = h_xy / L. Uniform over the sample's 196 m² of free space: 1,000
particles 0.49 m and 9.8°, 10,000 0.21 m and 4.2°, 50,000 0.12 m and 2.4°; 700 around a tracked pose 0.03 m
and 0.5°.

Regularized resampling (Musso, Oudjane and Le Gland, "Improving regularised particle filters", 2001). The
copies of a particle drawn by resampling are moved by its kernel N(0, h²), so that they spread over the region
it stood for; without it they would stay on one pose for ever (the motion noise of good odometry is tiny),
the bandwidth would shrink as they pile up in one bin, and a hypothesis 0.1 m and 2° from the truth would be
rejected by the sharpening model before the robot moved far enough to see it.

Tempering (:func:`tempering_exponent`, :func:`doorbatch.pipeline.localize.mcl.tempered_weighting`). A scan's
likelihood is applied in stages L^β₁·L^β₂·… (Σβ = 1), each β the largest that shrinks the effective sample
size at most by ``global_min_neff_ratio``, with resampling and the kernel jitter between stages, so that a
sharp scan refines the cloud instead of collapsing it (adaptive SMC tempering), up to ``global_max_stages``.

All three apply only while the cloud has not converged (:func:`~.likelihood_field.cloud_converged`: weighted
position std > ``converged_xy_std_m`` or yaw std > ``converged_yaw_std_deg``): during global localization, and
when a tracked cloud has spread that far (e.g. after 1 m odometry steps on the CARMEN logs). A converged
filter is the plain MCL / RBPF of the tracking results.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from doorbatch.config import LocalizeConfig
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.pipeline.localize.likelihood_field import (
    BeamCombination,
    DistanceField,
    cloud_converged,
    endpoint_distances,
)

FloatArray = npt.NDArray[np.float64]
Float32Array = npt.NDArray[np.float32]

SQRT12 = math.sqrt(12.0)
# Neighbours of the k-NN density estimate behind the bandwidths (8: a stable estimate, still local).
NEIGHBOURS = 8


class Bandwidth(NamedTuple):
    """Per-particle kernel standard deviations: position h_xy (N,) in m, heading h_yaw (N,) in rad."""

    xy_m: FloatArray
    yaw_rad: FloatArray


def particle_bandwidth(pose: npt.ArrayLike, config: LocalizeConfig, neighbours: int = NEIGHBOURS) -> Bandwidth:
    """Per-particle kernel from the k-nearest-neighbour density (module docstring).

    Distances in (x, y, L·yaw) with L = kld_bin_xy_m / kld_bin_yaw (the KLD bins' aspect, 2.9 m/rad by
    default; yaw periodic): the ball reaching the k-th neighbour holds k particles, so each stands for a cell
    of volume v = (4/3)·π·r_k³ / k, side c = v^(1/3); h_xy = c/√12, h_θ = h_xy / L.
    """
    p = np.asarray(pose, dtype=np.float64).reshape(-1, 3)
    n = p.shape[0]
    scale = config.kld_bin_xy_m / math.radians(config.kld_bin_yaw_deg)
    k = min(neighbours, n - 1)
    if k < 1:
        return Bandwidth(np.zeros(n), np.zeros(n))
    pts = np.empty((n, 3))
    pts[:, :2] = p[:, :2] - p[:, :2].min(axis=0)
    pts[:, 2] = np.mod(p[:, 2], 2.0 * math.pi) * scale
    span = pts[:, :2].max(axis=0) + 1.0  # non-periodic in x, y: a box larger than the cloud
    box = np.array([2.0 * span[0] + 1.0, 2.0 * span[1] + 1.0, 2.0 * math.pi * scale])
    pts[:, 2] = np.minimum(pts[:, 2], np.nextafter(box[2], 0.0))
    tree = cKDTree(pts, boxsize=box)
    dist, _ = tree.query(pts, k=k + 1)  # the first is the particle itself (or a duplicate at 0)
    r_k = np.maximum(dist[:, -1], 1e-9)
    side = np.cbrt(4.0 / 3.0 * math.pi * r_k**3 / k)
    h_xy = side / SQRT12
    return Bandwidth(h_xy, h_xy / scale)


def active_bandwidth(pose: npt.ArrayLike, weight: npt.ArrayLike, config: LocalizeConfig) -> Bandwidth | None:
    """The particles' bandwidths while ``global_smoothing`` is on and the cloud has not converged, else None."""
    if not config.global_smoothing or cloud_converged(weight, pose, config):
        return None
    return particle_bandwidth(pose, config)


def endpoint_variance(bandwidth: Bandwidth, points_base: npt.ArrayLike) -> Float32Array:
    """Extra variance (N, B) of each beam's end-point distance: e = h_xy² + |b|²·h_θ² (module docstring)."""
    b = np.asarray(points_base, dtype=np.float64).reshape(-1, 2)
    r2 = (b * b).sum(axis=1)
    e: Float32Array = (bandwidth.xy_m[:, None] ** 2 + bandwidth.yaw_rad[:, None] ** 2 * r2[None, :]).astype(np.float32)
    return e


def smoothed_beam_likelihood(dist: npt.ArrayLike, extra_var: npt.ArrayLike, z_hit: float, z_rand: float,
                             sigma_hit: float, max_range: float) -> Float32Array:
    """pz = z_hit·σ/√(σ² + e)·exp(−d²/(2(σ² + e))) + z_rand / max_range per beam (N, B), float32.

    With e = 0 it equals :func:`~.likelihood_field.beam_likelihood`.
    """
    d = np.asarray(dist, dtype=np.float32)
    s2 = np.asarray(extra_var, dtype=np.float32) + np.float32(sigma_hit * sigma_hit)
    pz = d * d
    pz /= s2
    pz *= np.float32(-0.5)
    np.exp(pz, out=pz)
    pz *= np.float32(z_hit * sigma_hit) / np.sqrt(s2)
    pz += np.float32(z_rand / max_range)
    return pz


def jitter(pose: npt.ArrayLike, bandwidth: Bandwidth, rng: np.random.Generator,
           index: npt.ArrayLike | None = None) -> FloatArray:
    """Poses (n, 3) moved by kernels N(0, diag(h_xy², h_xy², h_θ²)), yaw wrapped (regularized resampling).

    ``index`` (n,): which particle's bandwidth each pose takes (the resampled copy's source); None: the i-th.
    """
    p = np.array(pose, dtype=np.float64).reshape(-1, 3)
    idx = np.arange(p.shape[0]) if index is None else np.asarray(index, dtype=np.intp).reshape(-1)
    noise = rng.standard_normal(p.shape)
    p[:, 0] += noise[:, 0] * bandwidth.xy_m[idx]
    p[:, 1] += noise[:, 1] * bandwidth.xy_m[idx]
    p[:, 2] = wrap_angle(p[:, 2] + noise[:, 2] * bandwidth.yaw_rad[idx])
    return p


def effective_sample_ratio(log_weight: FloatArray) -> float:
    """Neff / N = (Σw)² / (N·Σw²) of unnormalized log-weights."""
    w = np.exp(log_weight - np.max(log_weight))
    return float(w.sum() ** 2 / (w.size * np.dot(w, w)))


def tempering_exponent(log_prior: npt.ArrayLike, log_likelihood: npt.ArrayLike, min_neff_ratio: float,
                       iterations: int = 30) -> float:
    """The largest β ∈ [0, 1] with Neff(prior · likelihood^β) ≥ min_neff_ratio · Neff(prior) (bisection; 1 when
    β = 1 does).

    Adaptive tempering of sequential Monte Carlo (Jasra et al., "Inference for Lévy-driven stochastic volatility
    models via adaptive sequential Monte Carlo", 2011): the beams of one scan are far from independent (a pose
    error moves them all), and consecutive scans from nearly the same pose repeat one another, so their product
    is overconfident for a sparse cloud; β lets one scan shrink the effective sample size by at most the factor
    ``min_neff_ratio``, which keeps enough of the cloud alive for the regularized resampling to refine it; the
    next scans bring the evidence left out.
    """
    lp = np.asarray(log_prior, dtype=np.float64)
    ll = np.asarray(log_likelihood, dtype=np.float64)
    target = min_neff_ratio * effective_sample_ratio(lp)
    if effective_sample_ratio(lp + ll) >= target:
        return 1.0
    lo, hi = 0.0, 1.0
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        if effective_sample_ratio(lp + mid * ll) >= target:
            lo = mid
        else:
            hi = mid
    return lo


def endpoint_jacobians(field: DistanceField, pose: npt.ArrayLike, points_base: npt.ArrayLike) -> Float32Array:
    """J (N, B, 3): the derivative of each beam's field distance with respect to its particle's pose (x, y, θ).

    ∂d/∂(x, y) is the field's gradient at the end point (central differences, one cell each way, by moving
    the particle); ∂d/∂θ = ∇d · (−r_y, r_x), r = R(θ)·b the end point relative to the particle.
    """
    p = np.asarray(pose, dtype=np.float64).reshape(-1, 3)
    b = np.asarray(points_base, dtype=np.float64).reshape(-1, 2)
    eps = field.resolution_m
    grad = np.empty((p.shape[0], b.shape[0], 2), dtype=np.float32)
    for axis in (0, 1):
        step = np.zeros(3)
        step[axis] = eps
        grad[..., axis] = endpoint_distances(field, p + step, b) - endpoint_distances(field, p - step, b)
    grad /= np.float32(2.0 * eps)
    c, s = np.cos(p[:, 2:3]), np.sin(p[:, 2:3])
    rx = c * b[None, :, 0] - s * b[None, :, 1]
    ry = s * b[None, :, 0] + c * b[None, :, 1]
    jac = np.empty((p.shape[0], b.shape[0], 3), dtype=np.float32)
    jac[..., :2] = grad
    jac[..., 2] = grad[..., 1] * rx - grad[..., 0] * ry
    return jac


def pose_volume_log_factor(jac: npt.ArrayLike, hit_weight: npt.ArrayLike, bandwidth: Bandwidth,
                           sigma_hit: float) -> FloatArray:
    """−½·log det(I + H^½·A·H^½) (N,): the share of a particle's pose region that fits the scan (Laplace).

    The scan likelihood near a pose is Gaussian in the pose offset δ with information A = Σ_b r_b·J_bᵀJ_b / σ_hit²
    (J_b from :func:`endpoint_jacobians`, r_b the beam's probability of being a hit); averaged over the
    particle's kernel δ ~ N(0, H), H = diag(h_xy², h_xy², h_θ²), its peak is scaled by |I + H·A|^(−½). This is the
    one volume factor of the 3-D pose region; the per-beam factors σ/√(σ² + e_b) of
    :func:`smoothed_beam_likelihood` count the same pose uncertainty once per beam (module docstring).
    """
    j = np.asarray(jac, dtype=np.float64)
    r = np.asarray(hit_weight, dtype=np.float64)
    info = np.einsum("nb,nbi,nbj->nij", r, j, j) / (sigma_hit * sigma_hit)
    h = np.stack([bandwidth.xy_m, bandwidth.xy_m, bandwidth.yaw_rad], axis=1)
    m = np.eye(3)[None] + h[:, :, None] * info * h[:, None, :]
    _, logdet = np.linalg.slogdet(m)
    out: FloatArray = -0.5 * logdet
    return out


def pose_volume_applies(config: LocalizeConfig, combination: BeamCombination) -> bool:
    """Whether the region's size enters as one pose volume factor: ``global_smoothing_volume`` "pose" with the
    product of the beams (Nav2's 1 + Σ pz³ is no product of beam likelihoods; there each beam keeps its factor)."""
    return config.global_smoothing_volume == "pose" and combination is BeamCombination.PRODUCT


def region_beam_likelihood(field: DistanceField, pose: npt.ArrayLike, points_base: npt.ArrayLike,
                           dist: npt.ArrayLike, bandwidth: Bandwidth, config: LocalizeConfig, max_range: float,
                           combination: BeamCombination) -> tuple[Float32Array, FloatArray]:
    """Per-beam likelihoods (N, B) smoothed over each particle's region, and a log factor (N,) for the region.

    ``global_smoothing_volume`` "pose": pz_b = z_hit·exp(−d_b²/(2(σ² + e_b))) + z_rand / max_range (the fit of
    beam b within the region; e_b from :func:`endpoint_variance`) and :func:`pose_volume_log_factor`, so that
    log p = Σ_b log pz_b + factor; with e = 0 (a point particle) pz is Nav2's term and the factor 0.
    "per_beam", or the combination "amcl" (:func:`pose_volume_applies`): :func:`smoothed_beam_likelihood` (each
    beam its own factor σ/√(σ² + e_b)) and factor 0.
    """
    extra = endpoint_variance(bandwidth, points_base)
    n = np.asarray(dist).shape[0]
    if not pose_volume_applies(config, combination):
        return (smoothed_beam_likelihood(dist, extra, config.z_hit, config.z_rand, config.sigma_hit, max_range),
                np.zeros(n))
    d = np.asarray(dist, dtype=np.float32)
    sigma2 = np.float32(config.sigma_hit * config.sigma_hit)
    hit = np.exp(np.float32(-0.5) * d * d / (extra + sigma2)) * np.float32(config.z_hit)
    pz: Float32Array = hit + np.float32(config.z_rand / max_range)
    jac = endpoint_jacobians(field, pose, points_base)
    return pz, pose_volume_log_factor(jac, hit / pz, bandwidth, config.sigma_hit)
