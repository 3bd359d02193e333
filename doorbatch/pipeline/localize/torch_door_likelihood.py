"""The RBPF's door-aware beam likelihood (paper 000, eq. (6); :mod:`.door_likelihood`) on a torch device: the
tracked cloud's weighing with ``localize.backend: torch``, so that its (N, B) arrays never cross to the host.

The arithmetic is :func:`.door_likelihood._numpy_scores`' (the reference the numba kernel equals), in float64 on
the device: each beam end point's static score d₀²/σ² against every door in reach of the scan, the door's leaf
at the particle's mean with the propagated variance σ_k² = σ_hit² + J_k²·P_k, or, for a door the particle has
not observed, its prior over the opening range in closed form; the lowest score wins the beam (the static map
on ties). Then pz = z_hit·exp(−score/2) + z_rand/range_max in float32, beam skipping and the sum as MCL's
(:func:`.torch_field.skip_and_combine`), and the sums of what the beams each leaf explains say of its angle
(:func:`door_beam_information`), which the door conditioning needs. What comes back: N log-likelihoods and those
(N, D) sums; the (N, B) association stays on the device. ``erf``, ``atan2`` and the sums are torch's, so scores
equal NumPy's to rounding, not to the bit (the tests bound both); on a device the results are the same on every
run (no atomic adds).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import numpy.typing as npt

from doorbatch.pipeline.localize.door_geometry import doors_in_reach
from doorbatch.pipeline.localize.door_likelihood import STATIC, BeamModel, beam_model
from doorbatch.pipeline.localize.door_prior import UNIFORM, DoorPrior
from doorbatch.pipeline.localize.rbpf import DoorBeamInformation
from doorbatch.pipeline.localize.torch_field import block_distances, device_blocks, import_torch, skip_and_combine

if TYPE_CHECKING:
    from doorbatch.config import LocalizeConfig
    from doorbatch.maps import DoorSet
    from doorbatch.pipeline.localize.likelihood_field import BeamCombination, DistanceField

FloatArray = npt.NDArray[np.float64]
Int16Array = npt.NDArray[np.int16]
# (particle, beam, door) elements per chunk: float64 temporaries of 64 MB each on the device, whatever N is.
DEVICE_CHUNK_ELEMENTS = 1 << 23


def _door_arrays(doors: DoorSet, index: npt.NDArray[np.intp], device: Any) -> dict[str, Any]:
    """The doors at ``index`` as float64 tensors on ``device``."""
    torch = import_torch()

    def on(values: npt.ArrayLike) -> Any:
        return torch.as_tensor(np.ascontiguousarray(np.asarray(values, dtype=np.float64)[index]), device=device)

    hinge = on(doors.hinge)
    return {"hx": hinge[:, 0], "hy": hinge[:, 1], "length": on(doors.length), "closed_yaw": on(doors.closed_yaw),
            "lo": on(doors.angle_min), "hi": on(doors.angle_max)}


def _uniform_scores(px: Any, py: Any, door: dict[str, Any], s0: float, model: BeamModel, prior: DoorPrior) -> Any:
    """Score −2·log(g_k) of each door under its prior over the opening range, (n, B, D) from end points (n, B, 1)
    (:func:`.door_likelihood._uniform_scores`, the same closed forms)."""
    torch = import_torch()
    vx, vy = px - door["hx"], py - door["hy"]
    r = torch.hypot(vx, vy)
    lo, hi, ln = door["lo"], door["hi"], door["length"]
    mid = (lo + hi) / 2
    phi = mid + torch.remainder(torch.atan2(vy, vx) - door["closed_yaw"] - mid + math.pi, 2 * math.pi) - math.pi
    dmin2 = torch.clamp_min(r - ln, 0.0) ** 2
    sq = torch.sqrt(torch.where(r <= ln, r * r, r * ln) / s0)  # √c / σ
    width = hi - lo
    frac = math.sqrt(math.pi / 2) / (sq * width) * (torch.erf((hi - phi) * sq / math.sqrt(2))
                                                   - torch.erf((lo - phi) * sq / math.sqrt(2)))
    frac = torch.where(sq * width < 1e-9, 1.0, frac)
    if prior.closed_prob > 0.0:
        den = 1.0 + sq**2 * prior.closed_var  # (σ² + c·σ_c²)/σ²
        closed = torch.exp(-0.5 * sq**2 * phi**2 / den) / torch.sqrt(den)
        frac = prior.closed_prob * closed + (1.0 - prior.closed_prob) * frac
    score = dmin2 / s0 + math.log(s0 / model.sigma2) - 2 * torch.log(frac)
    return torch.where((dmin2 < model.max_dist**2) & (frac > 0), score, math.inf)


def door_scores(dist: Any, pts: Any, doors: DoorSet, mean: Any, var: Any, model: BeamModel, unobserved_var: FloatArray,
                prior: DoorPrior = UNIFORM) -> tuple[Any, Any]:
    """(score (N, B) float32, association (N, B) int16) on the device: the chosen model's score −2·log(g/z_hit) per
    beam (NaN for an end point that is not finite) and its door (−1: the static map), as
    :func:`.door_likelihood._numpy_scores` gives them.

    Args:
        dist: (N, B) float32 static field distances. pts: (N, B, 2) float64 map-frame end points.
        doors: the D doors. mean, var: (N, D) float64 door means and variances per particle.
        model: the beam model. unobserved_var: (D,) the variance at which a door is weighed under ``prior``.
    """
    torch = import_torch()
    device = dist.device
    n, b = dist.shape
    valid = torch.isfinite(dist) & torch.isfinite(pts).all(dim=2)
    s0 = model.sigma2  # no pose-region smoothing while tracking: every model's σ² starts at σ_hit²
    score = torch.where(valid, dist.double() ** 2 / s0 + math.log(s0 / model.sigma2), math.nan)
    assoc = torch.full((n, b), STATIC, dtype=torch.int16, device=device)
    finite = pts[valid]
    if not len(doors) or finite.shape[0] == 0:
        return score.float(), assoc
    box = torch.stack([finite.min(dim=0).values, finite.max(dim=0).values]).cpu().numpy()
    active = np.flatnonzero(doors_in_reach(doors, box, model.max_dist))  # the box of the end points: the same doors
    if active.size == 0:
        return score.float(), assoc
    door = _door_arrays(doors, active, device)
    index = torch.as_tensor(active, device=device)
    uni = torch.as_tensor(np.asarray(unobserved_var, dtype=np.float64)[active], device=device)
    any_uniform = bool(np.isfinite(np.asarray(unobserved_var, dtype=np.float64)[active]).any())
    masked = torch.where(valid[:, :, None], pts, 0.0)
    step = max(1, DEVICE_CHUNK_ELEMENTS // (b * active.size))
    for lo in range(0, n, step):  # chunks of particles (device memory)
        sl = slice(lo, min(n, lo + step))
        px, py = masked[sl, :, 0, None], masked[sl, :, 1, None]
        m, v = mean[sl][:, index], var[sl][:, index]
        yaw = door["closed_yaw"] + m
        cx, cy = torch.cos(yaw)[:, None, :], torch.sin(yaw)[:, None, :]
        vx, vy = px - door["hx"], py - door["hy"]
        t_c = torch.minimum(torch.clamp_min(vx * cx + vy * cy, 0.0), door["length"])
        d_k = torch.hypot(vx - t_c * cx, vy - t_c * cy)
        j_k = torch.where(d_k > 0.0, -t_c * (cx * vy - cy * vx) / d_k, -t_c)  # ∂d/∂a (door_geometry)
        sig2 = s0 + j_k**2 * v[:, None, :]
        s_k = d_k**2 / sig2 + torch.log(sig2 / model.sigma2)
        s_k = torch.where((d_k < model.max_dist) & valid[sl, :, None], s_k, math.inf)
        if any_uniform:
            s_u = torch.where(valid[sl, :, None], _uniform_scores(px, py, door, s0, model, prior), math.inf)
            s_k = torch.where(v[:, None, :] >= uni, s_u, s_k)
        s_best, best = s_k.min(dim=2)
        wins = s_best < score[sl]
        score[sl] = torch.where(wins, s_best, score[sl])
        assoc[sl] = torch.where(wins, index[best], STATIC).to(torch.int16)
    return score.float(), assoc


class TrackedWeighing(NamedTuple):
    """The tracked cloud's log-likelihoods (N,), what its beams say of the doors (:func:`.rbpf.door_beam_information`;
    None when not asked for) and the number of beams skipped."""

    log_likelihood: FloatArray
    information: DoorBeamInformation | None
    skipped: int


def door_beam_information(assoc: Any, poses: Any, base: Any, doors: DoorSet, config: LocalizeConfig
                          ) -> DoorBeamInformation:
    """:func:`.rbpf.door_beam_information` of an association (N, B) on the device, summed there; the (N, D) sums
    come back. Each beam's measurement is computed for its associated door, then summed per door with a mask per
    door: plain reductions, the same bits on every run (atomic scatter-adds on a GPU add in any order)."""
    torch = import_torch()
    device = assoc.device
    n, d = poses.shape[0], len(doors)
    info_sum = torch.zeros((n, d), dtype=torch.float64, device=device)
    angle_sum = torch.zeros((n, d), dtype=torch.float64, device=device)
    if n == 0 or d == 0 or assoc.shape[1] == 0:
        return DoorBeamInformation(info_sum.cpu().numpy(), angle_sum.cpu().numpy())
    door = _door_arrays(doors, np.arange(d), device)
    k = assoc.long().clamp_min(0)  # (N, B); a static beam gets door 0's geometry and no weight
    c, s = torch.cos(poses[:, 2, None]), torch.sin(poses[:, 2, None])
    vx = poses[:, 0, None] + c * base[:, 0] - s * base[:, 1] - door["hx"][k]
    vy = poses[:, 1, None] + s * base[:, 0] + c * base[:, 1] - door["hy"][k]
    r = torch.hypot(vx, vy)
    length, lo, hi = door["length"][k], door["lo"][k], door["hi"][k]
    mid = (lo + hi) / 2
    wrapped = torch.remainder(torch.atan2(vy, vx) - door["closed_yaw"][k] - mid + math.pi, 2 * math.pi) - math.pi
    phi = mid + torch.where(wrapped == -math.pi, math.pi, wrapped)  # wrap_angle: (−π, π]
    margin = math.radians(config.door_angle_margin_deg)
    counts = (assoc >= 0) & (phi >= lo - margin) & (phi <= hi + margin)
    info = torch.where(counts, torch.where(r <= length, r * r, r * length), 0.0) / config.sigma_hit**2
    info_angle = info * phi
    for j in range(d):  # a (N, B) mask per door: D reductions of the cloud's beams
        on = assoc == j
        info_sum[:, j] = torch.where(on, info, 0.0).sum(dim=1)
        angle_sum[:, j] = torch.where(on, info_angle, 0.0).sum(dim=1)
    return DoorBeamInformation(np.asarray(info_sum.cpu().numpy()), np.asarray(angle_sum.cpu().numpy()))


def skipped_door_log_likelihood(dist_field: DistanceField, pose: npt.ArrayLike, weight: npt.ArrayLike,
                                points_base: npt.ArrayLike, doors: DoorSet, door_mean: npt.ArrayLike,
                                door_var: npt.ArrayLike, config: LocalizeConfig, range_max_m: float,
                                combination: BeamCombination, unobserved_var: npt.ArrayLike | None = None,
                                with_information: bool = True) -> TrackedWeighing:
    """log p(z | x) (N,) of a tracked RBPF cloud with its doors, what its beams say of the doors and the number
    of beams skipped, every step on the field's ``torch_device``: the static distances
    (:func:`.torch_field.endpoint_distances`' lookup), :func:`door_scores`, the per-beam likelihoods, then beam
    skipping and the sum (:func:`.torch_field.skip_and_combine`), and :func:`door_beam_information` of the
    association where ``with_information`` (the conditioning of the doors on the beams needs it). The host's path
    is :func:`.door_likelihood.door_log_likelihood_at_poses`, :func:`.likelihood_field.skip_unexplained`,
    :func:`.likelihood_field.combine_beams`, :func:`.rbpf.door_beam_information`. The whole cloud is one block
    (beam skipping normalizes over it)."""
    torch = import_torch()
    model = beam_model(config, range_max_m)
    field, grid, cells = device_blocks(dist_field, pose, points_base)
    n, b = grid.shape[0], cells.shape[0]
    if b == 0:
        none = DoorBeamInformation(np.zeros((n, len(doors))), np.zeros((n, len(doors))))
        return TrackedWeighing(np.zeros(n), none if with_information else None, 0)
    device = grid.device
    poses = torch.as_tensor(np.ascontiguousarray(pose, dtype=np.float64).reshape(-1, 3), device=device)
    base = torch.as_tensor(np.ascontiguousarray(points_base, dtype=np.float64).reshape(-1, 2), device=device)
    c, s = torch.cos(poses[:, 2, None]), torch.sin(poses[:, 2, None])
    pts = torch.stack([poses[:, 0, None] + c * base[:, 0] - s * base[:, 1],
                       poses[:, 1, None] + s * base[:, 0] + c * base[:, 1]], dim=-1)
    n_doors = len(doors)
    if n_doors > np.iinfo(np.int16).max:
        raise ValueError(f"{n_doors} doors do not fit the int16 association")
    uni = (np.full(n_doors, np.inf) if unobserved_var is None
           else np.broadcast_to(np.asarray(unobserved_var, dtype=np.float64), (n_doors,)))
    mean = torch.as_tensor(np.ascontiguousarray(door_mean, dtype=np.float64).reshape(n, n_doors), device=device)
    var = torch.as_tensor(np.ascontiguousarray(door_var, dtype=np.float64).reshape(n, n_doors), device=device)
    score, assoc = door_scores(block_distances(field, grid, cells), pts, doors, mean, var, model, uni)
    pz = torch.exp(score * -0.5)  # :func:`.door_likelihood.beam_likelihoods`, in float32
    pz *= float(np.float32(model.z_hit))
    pz += float(np.float32(model.rand_term))
    loglik, skipped = skip_and_combine(pz, pose, weight, config, range_max_m, combination)
    information = door_beam_information(assoc, poses, base, doors, config) if with_information else None
    return TrackedWeighing(np.asarray(loglik.cpu().numpy()), information, skipped)
