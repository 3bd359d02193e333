"""The Rao-Blackwellized particle filter of paper 000, Sec. IV: poses by particles, door angles by one
Kalman filter per door per particle.

One update, in the paper's order (with MCL's update thresholds, recovery and resampling, so that the two
methods differ only in the map model)::

    1. sampling     poses by the odometry motion model; door angles d_k,t = d_k,t−1 + ε, ε ~ N(0, σ_d²·Δt)
    2. importance   per beam, ML association between the static likelihood field and each door leaf at the
                    particle's door estimate, the door term marginalized to first order (eq. 6); until the
                    cloud converges, the same smoothed over each particle's pose region and applied in
                    tempered stages (:mod:`.smoothing`, mcl.tempered_weighting; ``global_door_term`` false:
                    the static model alone, as MCL; true: each particle's door update of this scan first and
                    the beams under its result, :func:`door_update_log_factor`, a door not yet observed under
                    the closed/open prior of :mod:`.door_prior`); once converged, beams that
                    most of the weight explains by neither are skipped (Nav2's do_beamskip,
                    likelihood_field.skip_unexplained), as MCL does; with ``tracking_door_prior`` a door the
                    particle has not observed is weighed under the uniform prior over its range (global: the
                    closed/open mixture)
    3. door update  one Douglas–Peucker polygon per scan, moved to every particle, associated to doors,
                    Kalman update of the associated doors' angles; while global with the door term, and in
                    tracking with ``tracking_door_prior``, each particle's other doors are also conditioned on
                    the beams their leaves explain (:func:`condition_doors_on_beams`)
    4. resampling   low-variance (KLD-adaptive) when Neff is low
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from doorbatch.config import LocalizeConfig
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.maps import DoorSet
from doorbatch.pipeline.localize.door_likelihood import STATIC, door_log_likelihood_at_poses
from doorbatch.pipeline.localize.door_observation import (
    DoorUpdate,
    gated_prior_variance,
    moved_door_gate,
    predict_doors,
    update_doors,
)
from doorbatch.pipeline.localize.door_prior import (
    UNIFORM,
    DoorPrior,
    evidence_and_posterior,
    log_evidence,
    log_normal,
    posterior,
    unobserved_door_variance,
)
from doorbatch.pipeline.localize.likelihood_field import (
    BeamCombination,
    BeamSet,
    DistanceField,
    FreeCells,
    combine_beams,
    endpoint_distances,
    skip_unexplained,
    skipped_field_log_likelihood,
)
from doorbatch.pipeline.localize.mcl import (
    MclState,
    StepDiagnostics,
    apply_log_likelihood,
    finish_step,
    predict,
    region_log_likelihood,
    spread_cloud_config,
    tempered_weighting,
    update_thresholds_met,
    with_log_weights,
)
from doorbatch.pipeline.localize.particles import ParticleSet
from doorbatch.pipeline.localize.smoothing import (
    Bandwidth,
    active_bandwidth,
    endpoint_jacobians,
    endpoint_variance,
    pose_volume_applies,
    pose_volume_log_factor,
)


def rbpf_step(state: MclState, odom_now: npt.ArrayLike, stamp_s: float, last_stamp_s: float | None,
              beams: BeamSet, scan_points_base: npt.ArrayLike, field: DistanceField, doors: DoorSet,
              config: LocalizeConfig, rng: np.random.Generator, free: FreeCells | None = None,
              force: bool = False) -> tuple[MclState, StepDiagnostics, npt.NDArray[np.float64]]:
    """One RBPF update.

    Args:
        state: the filter state after the previous update (particles with (N, D) door arrays).
        odom_now: (3,) odometry pose at the scan's time.
        stamp_s, last_stamp_s: this scan's time and the previous update's (for the door random walk).
        beams: the max_beams subsample used by the importance weights.
        scan_points_base: (M, 2) all hit end points of the scan in base_link, in scan order (the polygon).
        field: the static map's distance field. doors: the D doors of the map.
        free: free cells for random-particle recovery (None: none).
        force: update although the update thresholds are not met.

    Returns:
        The new state, the step's diagnostics, and (D,) each door's observed share: the weight of the particles
        that took a measurement of it (:func:`observed_share`; 0 for all without a door update).
    """
    odom = np.asarray(odom_now, dtype=np.float64).reshape(3)
    particles = state.particles
    n_doors = particles.n_doors
    none = np.zeros(n_doors, dtype=np.float64)
    if state.odom_at_update is not None:
        if not (force or update_thresholds_met(state.odom_at_update, odom, config)):
            if not (config.door_update_when_still and n_doors and last_stamp_s is not None
                    and standing_still(state.odom_at_update, odom, config)
                    and active_bandwidth(particles.pose, particles.weight, config) is None):
                return state, StepDiagnostics(False, False, particles.neff(), len(particles), 0.0, 0, math.nan), none
            particles, observed = doors_updated_still(particles, stamp_s - last_stamp_s, scan_points_base, doors,
                                                      config)
            return (replace(state, particles=particles),
                    StepDiagnostics(False, False, particles.neff(), len(particles), 0.0, 0, math.nan, True), observed)
        particles = predict(particles, state.odom_at_update, odom, config, rng)
    if last_stamp_s is not None and n_doors:
        particles = walked_doors(particles, stamp_s - last_stamp_s, config)

    bandwidth = active_bandwidth(particles.pose, particles.weight, config)
    combination = BeamCombination(config.beam_combination)
    # While the cloud is global each particle is weighed with its pose region's likelihood, in tempered stages
    # (mcl.tempered_weighting); with ``global_door_term`` that likelihood is eq. (6) (door_region_log_likelihood),
    # else MCL's static model.
    global_phase = bandwidth is not None and len(beams.points_base) > 0
    spread = spread_cloud_config(config, state.global_start) if global_phase else config
    evidence = None  # the tracked weighting's beams on the doors, which the beam conditioning reuses
    if global_phase:

        def region(p: ParticleSet, h: Bandwidth) -> npt.NDArray[np.float64]:
            if n_doors and spread.global_door_term:
                return global_door_log_likelihood(p, h, beams, scan_points_base, field, doors, spread, combination)
            return region_log_likelihood(p, h, beams, field, spread, combination)

        particles, log_avg, bandwidth = tempered_weighting(particles, region, spread, rng)
    else:
        log_likelihood, evidence = tracked_log_likelihood(particles, beams, field, doors, config, combination)
        weighting = apply_log_likelihood(particles, log_likelihood)
        particles, log_avg = with_log_weights(particles, weighting.log_weight), weighting.log_avg_weight

    observed = none
    if n_doors:
        if global_phase and spread.global_door_term:
            update = global_door_update(scan_points_base, particles, doors, config)
        else:
            update = update_doors(scan_points_base, particles, doors, config)
        particles = replace(particles, door_mean=update.mean, door_var=update.var)
        observed = observed_share(particles.weight, update.observed)
        if spread.global_door_term if global_phase else config.tracking_door_prior:
            prior = DoorPrior.from_config(config) if global_phase else None
            mean, var = condition_doors_on_beams(particles, beams, field, doors, config, prior,
                                                 skip=update.observed, evidence=evidence)
            particles = replace(particles, door_mean=mean, door_var=var)

    new_state, diag = finish_step(state, particles, log_avg, odom, config, rng, free, bandwidth)
    return new_state, diag, observed


def observed_share(weight: npt.ArrayLike, observed: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """(D,) per door the share of the weight (N,) held by the particles that observed it (``observed`` (N, D)):
    Σᵢ wᵢ·[door d observed from particle i] / Σᵢ wᵢ."""
    w = np.asarray(weight, dtype=np.float64)
    seen = np.asarray(observed, dtype=np.float64).reshape(w.shape[0], -1)
    total = float(w.sum())
    if not total > 0.0:  # no particle, or none with weight: no door measured
        return np.zeros(seen.shape[1], dtype=np.float64)
    return np.asarray(np.clip(w @ seen / total, 0.0, 1.0), dtype=np.float64)


def walked_doors(particles: ParticleSet, dt_s: float, config: LocalizeConfig) -> ParticleSet:
    """The particles with their door variances grown by the random walk over ``dt_s`` (var += σ_d²·dt, capped at
    ``door_init_sigma_deg``²: a door left unobserved is as uncertain as a new one, no more)."""
    cap = math.radians(config.door_init_sigma_deg) ** 2
    return replace(particles, door_var=predict_doors(particles.door_var, max(dt_s, 0.0),
                                                     config.door_sigma_rad_per_sqrt_s, max_var=cap))


def standing_still(odom_at_update: npt.ArrayLike, odom_now: npt.ArrayLike, config: LocalizeConfig) -> bool:
    """Whether the odometry has moved the robot by at most ``door_update_still_m`` and ``door_update_still_deg``
    since the last pose update (the held pose is where the robot is)."""
    return bool(within_of(odom_at_update, odom_now, config.door_update_still_m, config.door_update_still_deg).all())


def within_of(poses: npt.ArrayLike, pose: npt.ArrayLike, max_m: float, max_deg: float) -> npt.NDArray[np.bool_]:
    """(K,) whether each of ``poses`` (K, 3) (or one (3,)) lies within ``max_m`` and ``max_deg`` of ``pose``
    (distance, and heading along the shorter arc)."""
    a = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    b = np.asarray(pose, dtype=np.float64).reshape(3)
    step = np.hypot(a[:, 0] - b[0], a[:, 1] - b[1])
    turn = np.abs(wrap_angle(a[:, 2] - b[2]))
    return np.asarray((step <= max_m) & (turn <= math.radians(max_deg)), dtype=np.bool_)


def doors_updated_still(particles: ParticleSet, dt_s: float, scan_points_base: npt.ArrayLike, doors: DoorSet,
                        config: LocalizeConfig) -> tuple[ParticleSet, npt.NDArray[np.float64]]:
    """The door half of an RBPF update for a robot that stands still (``door_update_when_still``): each particle's
    door Gaussians walk for ``dt_s`` and take the scan's polygon measurements (Kalman update, as in
    :func:`rbpf_step`); poses and weights are left as they are (AMCL's update thresholds hold the pose: a standing
    robot's scans are one view again, but a door moving in it is news). Returns the particles and (D,) each
    door's observed share (:func:`observed_share`)."""
    update = update_doors(scan_points_base, walked_doors(particles, dt_s, config), doors, config)
    return (replace(particles, door_mean=update.mean, door_var=update.var),
            observed_share(particles.weight, update.observed))


def tracked_log_likelihood(particles: ParticleSet, beams: BeamSet, field: DistanceField, doors: DoorSet,
                           config: LocalizeConfig, combination: BeamCombination
                           ) -> tuple[npt.NDArray[np.float64], DoorEvidence | None]:
    """log p(z | x) (N,) of a tracked cloud, eq. (6) with ML association between the static map and each door
    leaf (:mod:`.door_likelihood`; a door not observed yet under its prior with ``tracking_door_prior``), beams
    skipped as MCL skips them (:func:`~.likelihood_field.skip_unexplained`); and the beams' evidence on the doors
    (None without doors: MCL's weighing): their (N, B) association on the host, what they say of each door's angle
    (:func:`door_beam_information`, summed there) on a field with a ``torch_device``, where every step runs
    (:func:`.torch_door_likelihood.skipped_door_log_likelihood`)."""
    if not len(doors):
        log_likelihood, _ = skipped_field_log_likelihood(field, particles.pose, particles.weight, beams.points_base,
                                                         config, beams.range_max_m, combination)
        return log_likelihood, None
    unobserved = unobserved_door_variance(doors, config) if config.tracking_door_prior else None
    if field.torch_device is not None:
        from doorbatch.pipeline.localize.torch_door_likelihood import skipped_door_log_likelihood

        weighed = skipped_door_log_likelihood(field, particles.pose, particles.weight, beams.points_base, doors,
                                              particles.door_mean, particles.door_var, config, beams.range_max_m,
                                              combination, unobserved, with_information=config.tracking_door_prior)
        return weighed.log_likelihood, weighed.information
    static = endpoint_distances(field, particles.pose, beams.points_base)
    dl = door_log_likelihood_at_poses(static, particles.pose, beams.points_base, doors, particles.door_mean,
                                      particles.door_var, config, beams.range_max_m, unobserved_var=unobserved)
    pz, _ = skip_unexplained(dl.beam_likelihood, particles.weight, particles.pose, config, beams.range_max_m,
                             combination)
    return combine_beams(pz, combination), dl.association


def global_door_log_likelihood(particles: ParticleSet, bandwidth: Bandwidth, beams: BeamSet,
                               scan_points_base: npt.ArrayLike, field: DistanceField, doors: DoorSet,
                               config: LocalizeConfig, combination: BeamCombination) -> npt.NDArray[np.float64]:
    """log p(z | region) (N,) of a global cloud with the door term (``global_door_term``): the door update of this
    scan first, under the doors' prior (:func:`global_door_update`), then the beams under the updated doors
    (:func:`door_region_log_likelihood`) plus the update's evidence factor (:func:`door_update_log_factor`)."""
    update = global_door_update(scan_points_base, particles, doors, config)
    posterior = replace(particles, door_mean=update.mean, door_var=update.var)
    out: npt.NDArray[np.float64] = (door_region_log_likelihood(posterior, bandwidth, beams, field, doors, config,
                                                               combination)
                                    + door_update_log_factor(particles, update, doors, config))
    return out


def door_region_log_likelihood(particles: ParticleSet, bandwidth: Bandwidth, beams: BeamSet, field: DistanceField,
                               doors: DoorSet, config: LocalizeConfig, combination: BeamCombination
                               ) -> npt.NDArray[np.float64]:
    """log p(z | region) (N,): eq. (6) with ML association, smoothed over each particle's pose region.

    Every model's σ² of beam b grows by the region's e_b (:func:`~.smoothing.endpoint_variance`, the kernel's
    ``extra_var``). With ``global_smoothing_volume`` "pose" the per-beam factor √(σ_hit²/(σ_hit² + e_b)) is taken
    out again (the door's own factor √((σ_hit² + e_b)/σ_k²) stays) and the pose region's one volume factor
    (:func:`~.smoothing.pose_volume_log_factor`) is added, from the beams the static map explains (a beam on a
    door leaf is left out of the pose information: expert choice, its Jacobian is not at hand; this errs on the
    side of a wider region). A door the particle has not observed (:func:`~.door_prior.unobserved_door_variance`)
    is weighed under its prior (:mod:`.door_prior`: closed or uniformly open), not linearized at its mean
    (:mod:`.door_likelihood`).
    """
    extra = endpoint_variance(bandwidth, beams.points_base)
    static = endpoint_distances(field, particles.pose, beams.points_base)
    dl = door_log_likelihood_at_poses(static, particles.pose, beams.points_base, doors, particles.door_mean,
                                      particles.door_var, config, beams.range_max_m, extra_var=extra,
                                      unobserved_var=unobserved_door_variance(doors, config),
                                      prior=DoorPrior.from_config(config))
    if not pose_volume_applies(config, combination):
        return combine_beams(dl.beam_likelihood, combination)
    rand = np.float32(config.z_rand / beams.range_max_m)
    hit = (dl.beam_likelihood - rand) * np.sqrt(1.0 + extra / np.float32(config.sigma_hit**2))
    pz = hit + rand
    weight = np.where(dl.association == STATIC, hit / pz, np.float32(0.0))
    jac = endpoint_jacobians(field, particles.pose, beams.points_base)
    out: npt.NDArray[np.float64] = combine_beams(pz, combination) + pose_volume_log_factor(
        jac, weight, bandwidth, config.sigma_hit)
    return out


def global_door_update(points_base: npt.ArrayLike, particles: ParticleSet, doors: DoorSet, config: LocalizeConfig
                       ) -> DoorUpdate:
    """The polygon's door update (:func:`~.door_observation.update_doors`) with each door a particle has not yet
    observed updated under the global phase's prior (:mod:`.door_prior`: closed or uniformly open; the posterior
    component picked by its evidence and moment-matched into the particle's Gaussian) instead of under the
    particle's mid-range Gaussian; doors already observed keep their Kalman update."""
    update = update_doors(points_base, particles, doors, config)
    at_prior = update.observed & (particles.door_var >= unobserved_door_variance(doors, config))
    if not at_prior.any():
        return update
    i, k = np.nonzero(at_prior)
    meas_var = math.radians(config.door_angle_sigma_deg) ** 2
    mean, var = update.mean.copy(), update.var.copy()
    evidence = np.full_like(mean, np.nan)
    evidence[i, k], mean[i, k], var[i, k] = evidence_and_posterior(
        update.angle[i, k], meas_var, doors.angle_min[k], doors.angle_max[k], DoorPrior.from_config(config))
    return update._replace(mean=mean, var=var, log_evidence=evidence)


def door_update_log_factor(prior: ParticleSet, update: DoorUpdate, doors: DoorSet, config: LocalizeConfig
                           ) -> npt.NDArray[np.float64]:
    """(N,) the log-factor that turns the beams' likelihood under the door posterior into the marginal one.

    The importance weight is p(z | x) = ∫ p(z | x, a) p(a) da over the door angles a. Weighing the beams at the
    prior (FastSLAM's order, eq. (6)) marginalizes every beam on a leaf separately, so K beams on one leaf pay
    the prior's spread K times; while the pose is global each particle's prior is the whole opening range and
    the true pose pays for every closed leaf it has not yet observed. Counted once instead: the beams are
    weighed under the updated doors (a⁺, P⁺), which stand in for the measurement's likelihood at the posterior
    mean N(z; a⁺, R), and each door the update observed adds log p(z) − log N(z; a⁺, R), p(z) the measurement's
    evidence under the door's prior. For a door at a Gaussian prior N(μ, P) that is the Laplace identity,
    exact here: log N(a⁺; μ, P) + ½·log(2π·P⁺) = −½·(a⁺ − μ)²/P + ½·log(P⁺/P). For a door still at its prior
    (:func:`~.door_prior.unobserved_door_variance`) p(z) is the closed/open mixture's evidence
    (:func:`~.door_prior.log_evidence`; a⁺ its moment-matched posterior mean, :func:`global_door_update`); p(z)
    is at most N(z; z, R), and for ranges of 0.1° to 100° and measurements within the association's ±10° gate
    the factor stays ≤ −0.08 nats, so a door whose range is narrower than the measurement (the built map's
    never-moved doors) earns nothing. A door not observed adds nothing (a⁺ = μ, P⁺ = P). A door the moved-door gate
    restarted (:func:`~.door_observation.gated_prior_variance`) was updated from N(μ, P_moved), so that is its prior
    here too.
    """
    mu, var = prior.door_mean, prior.door_var
    post_var = np.maximum(update.var, 1e-12)
    meas_var = math.radians(config.door_angle_sigma_deg) ** 2
    gated = gated_prior_variance(mu, var, update.angle, update.observed, meas_var, *moved_door_gate(config))
    gaussian = -0.5 * (update.mean - mu) ** 2 / gated + 0.5 * np.log(post_var / gated)
    at_prior = update.observed & (var >= unobserved_door_variance(doors, config))
    term = np.where(update.observed, gaussian, 0.0)
    if at_prior.any():
        i, k = np.nonzero(at_prior)
        z = update.angle[i, k]
        evidence = (log_evidence(z, meas_var, doors.angle_min[k], doors.angle_max[k], DoorPrior.from_config(config))
                    if update.log_evidence is None else update.log_evidence[i, k])  # global_door_update's
        at_post = log_normal(z, update.mean[i, k], meas_var)
        term[i, k] = evidence - at_post
    out: npt.NDArray[np.float64] = term.sum(axis=1)
    return out


class DoorBeamInformation(NamedTuple):
    """What the beams each door's leaf explains say of its angle, per particle and door (N, D): the information
    Σ c_b/σ_hit² and the information-weighted angle Σ c_b·φ_b/σ_hit² (:func:`condition_doors_on_beams`)."""

    info: npt.NDArray[np.float64]
    info_angle: npt.NDArray[np.float64]


def door_beam_information(association: npt.NDArray[np.int16], pose: npt.ArrayLike, points_base: npt.ArrayLike,
                          doors: DoorSet, config: LocalizeConfig, keep: npt.NDArray[np.bool_] | None = None
                          ) -> DoorBeamInformation:
    """The angle measurements of the beams associated with doors (:func:`condition_doors_on_beams`), summed per
    particle and door: a beam b of particle i on door k, its end point at distance r from the hinge in direction
    φ_b (relative to closed_yaw, unwrapped about the range's middle), carries c_b/σ_hit², c = r² on the leaf's disc
    and r·L beyond it, when φ_b lies in the sector the leaf can sweep (the range ± ``door_angle_margin_deg``: the
    door update's gate; an end point beside the hinge on the far side would put the angle outside the range), else
    nothing. ``association`` (N, B): −1 static, k ≥ 0 door k (:mod:`.door_likelihood`); ``keep`` (N, D): the
    particles' doors to sum (others 0; all when None). A torch device computes the same where the association
    lies (:func:`.torch_door_likelihood.skipped_door_log_likelihood`)."""
    poses = np.asarray(pose, dtype=np.float64).reshape(-1, 3)
    base = np.asarray(points_base, dtype=np.float64).reshape(-1, 2)
    n, d = poses.shape[0], len(doors)
    i, b = np.nonzero(association >= 0)
    k = association[i, b].astype(np.intp)
    if keep is not None:
        kept = keep[i, k]
        i, b, k = i[kept], b[kept], k[kept]
    p = poses[i]
    c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
    vx = p[:, 0] + c * base[b, 0] - s * base[b, 1] - doors.hinge[k, 0]
    vy = p[:, 1] + s * base[b, 0] + c * base[b, 1] - doors.hinge[k, 1]
    r = np.hypot(vx, vy)
    length = doors.length[k]
    mid = (doors.angle_min[k] + doors.angle_max[k]) / 2
    phi = mid + wrap_angle(np.arctan2(vy, vx) - doors.closed_yaw[k] - mid)
    margin = math.radians(config.door_angle_margin_deg)
    inside = (phi >= doors.angle_min[k] - margin) & (phi <= doors.angle_max[k] + margin)
    info = np.where(inside, np.where(r <= length, r * r, r * length), 0.0) / config.sigma_hit**2
    flat = i * d + k
    sums = [np.asarray(np.bincount(flat, weights=w, minlength=n * d), dtype=np.float64).reshape(n, d)
            for w in (info, info * phi)]
    return DoorBeamInformation(*sums)


# The beams' evidence on the doors that the tracked weighting leaves to the conditioning: their association (N, B),
# or what they say of each door's angle, summed (a torch device sums where the association lies).
DoorEvidence = npt.NDArray[np.int16] | DoorBeamInformation


def condition_doors_on_beams(particles: ParticleSet, beams: BeamSet, field: DistanceField, doors: DoorSet,
                             config: LocalizeConfig, prior: DoorPrior | None = None,
                             skip: npt.NDArray[np.bool_] | None = None,
                             evidence: DoorEvidence | None = None
                             ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Each particle's doors conditioned on the beams that their leaves explain (global phase with the door term;
    tracking with ``tracking_door_prior``).

    A beam explained by door k (:mod:`.door_likelihood`: under the door prior while the door is unobserved,
    eq. (6) after) says where the leaf is: its end point at distance r from the hinge, in direction φ, puts the
    angle at φ with variance σ_hit²/c (c = r² on the leaf's disc, r·L beyond it; the quadratic that the prior's
    marginal integrates). Without this, a door the Douglas–Peucker update cannot see (a closed leaf 10 m down
    a corridor is a few sparse points) is marginalized afresh at every scan and its beams pay the prior's
    spread again and again, which the joint likelihood p(z_1..t | x) does not (expert choice; the paper's
    door update uses the polygon only). The beams were weighed under the prior (FastSLAM's order), so this is
    the matching posterior. The beams of a door combine by information into one measurement z = Σ c_b·φ_b / Σ c_b
    with variance σ_hit²/Σ c_b (through the same moved-door gate as the polygon's update); with a ``prior`` (the
    global phase's closed/open mixture) a door still at its
    prior (:func:`~.door_prior.unobserved_door_variance`) takes it under that prior (:func:`~.door_prior.posterior`,
    moment-matched), every other door under its Gaussian (product of Gaussians). Without one (tracking,
    ``tracking_door_prior``) every door takes it under its Gaussian: moment-matching the uniform prior's posterior,
    a Gaussian truncated at the closed end of the range, would put a closed door's mean a fraction of the
    measurement's std open, and the linearized model would then draw its leaf there (measured: closed-log
    tracking 0.060-0.068 m against 0.039-0.056 m). Doors in ``skip`` (N, D) (the polygon's update of this scan
    observed them) are left alone. ``evidence``: this scan's weighting's (:func:`tracked_log_likelihood`), whose
    doors outside ``skip`` are unchanged since (tracking; saves a second door likelihood).

    Returns:
        (N, D) means and variances.
    """
    thr = unobserved_door_variance(doors, config)
    mean, var = particles.door_mean.copy(), particles.door_var.copy()
    unobserved = np.ones_like(var, dtype=bool) if skip is None else ~skip
    if not unobserved.any():
        return mean, var
    if evidence is None:
        static = endpoint_distances(field, particles.pose, beams.points_base)
        evidence = door_log_likelihood_at_poses(static, particles.pose, beams.points_base, doors, mean, var,
                                                config, beams.range_max_m, unobserved_var=thr,
                                                prior=UNIFORM if prior is None else prior).association
    if not isinstance(evidence, DoorBeamInformation):  # an association: the doors left alone need no sums
        evidence = door_beam_information(evidence, particles.pose, beams.points_base, doors, config, unobserved)
    info_sum = np.where(unobserved, evidence.info, 0.0)
    phi_sum = np.where(unobserved, evidence.info_angle, 0.0)
    hit = info_sum > 0
    if not hit.any():
        return mean, var
    z = np.where(hit, phi_sum / np.where(hit, info_sum, 1.0), mean)
    meas_var = np.where(hit, 1.0 / np.where(hit, info_sum, 1.0), 1.0)
    # a door the beams put far from its estimate was moved: the polygon update's gate (kalman_update)
    var = gated_prior_variance(mean, var, z, hit, meas_var, *moved_door_gate(config))
    post_var = np.where(hit, 1.0 / (1.0 / var + info_sum), var)
    post_mean = np.where(hit, post_var * (mean / var + phi_sum), mean)
    if prior is not None and (at_prior := hit & (var >= thr)).any():
        i, k = np.nonzero(at_prior)
        post_mean[i, k], post_var[i, k] = posterior(phi_sum[i, k] / info_sum[i, k], 1.0 / info_sum[i, k],
                                                    doors.angle_min[k], doors.angle_max[k], prior)
    return post_mean, post_var
