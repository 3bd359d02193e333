"""Monte Carlo localization with Nav2 AMCL's models and parameters (the baseline of issue #5).

One filter update, as nav2_amcl ``AmclNode::laserReceived`` composes it:

1. ``update_thresholds_met``: the odometry moved more than ``update_min_d`` along x or along y, or turned more
   than ``update_min_a``, since the last update (AMCL tests |Δx|, |Δy| and |Δθ| separately, in the odom
   frame). Otherwise nothing happens and the odometry pose of the last update is kept.
2. ``predict``: the odometry motion model (:mod:`.motion_model`).
3. ``weigh``: the likelihood-field endpoint model (:mod:`.likelihood_field`) over all particles × beams,
   combined with the prior weights and normalized in log space; the mean weight feeds the recovery averages.
   Until the cloud has converged (global localization) the model is smoothed over each particle's region,
   applied in tempered stages with resampling in between, and resampled copies are jittered by the region
   (:mod:`.smoothing`, :func:`tempered_weighting`; not in nav2_amcl).
4. ``resample_if_needed``: KLD-adaptive low-variance resampling with random-particle injection
   (:mod:`.resampling`) on every ``resample_interval``-th update (AMCL's rule), when Neff <
   ``resample_neff_ratio``·N (not in AMCL; ratio 1.0 resamples on every due update), and whenever recovery asks
   for random particles (else a kidnapped filter whose particles are all equally wrong would never inject any).

The first update after initialization weighs and resamples without motion (AMCL's ``pf_init_``).

Reuse by the RBPF: ``predict`` and ``resample_if_needed`` work on any :class:`ParticleSet` (door arrays are
carried along: ``predict`` leaves them, resampling copies them with the particles; injected random particles
copy the door state of the particle drawn in their place, see :class:`~.resampling.KldDraw`). The RBPF's
importance weight replaces :func:`scan_log_likelihood`: it takes the same static-map distances
(:func:`~.likelihood_field.endpoint_distances`), the distances to the door leaves, keeps the smaller per
beam, and feeds them to :func:`~.likelihood_field.endpoint_log_likelihood`; then :func:`apply_log_likelihood`
normalizes exactly as MCL does.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from doorbatch.config import LocalizeConfig
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.pipeline.localize.likelihood_field import (
    CHUNK_PARTICLES,
    BeamCombination,
    BeamSet,
    DistanceField,
    FreeCells,
    combine_beams,
    endpoint_distances,
    field_log_likelihood,
    select_beams,
    skipped_field_log_likelihood,
)
from doorbatch.pipeline.localize.motion_model import sample_motion_model_odometry, sample_motion_model_omni
from doorbatch.pipeline.localize.particles import ParticleSet
from doorbatch.pipeline.localize.resampling import RecoveryState, kld_resample, low_variance_resample
from doorbatch.pipeline.localize.smoothing import (
    Bandwidth,
    active_bandwidth,
    jitter,
    particle_bandwidth,
    region_beam_likelihood,
    tempering_exponent,
)
from doorbatch.records import Scan

FloatArray = npt.NDArray[np.float64]


class Weighting(NamedTuple):
    """Normalized log-weights (N,) (their log-sum-exp is 0) and log w_avg = log Σᵢ wᵢ·pᵢ (recovery's average)."""

    log_weight: FloatArray
    log_avg_weight: float


@dataclass(frozen=True)
class MclState:
    """Everything one update needs from the previous one.

    Attributes:
        particles: the particle set.
        recovery: AMCL's w_slow / w_fast.
        odom_at_update: odometry pose (3,) at the last filter update; None before the first.
        global_start: the run started from a uniform cloud (``--init global``); see :func:`spread_cloud_config`.
        updates: filter updates so far (resampling is due on every ``resample_interval``-th, as Nav2 counts).
    """

    particles: ParticleSet
    recovery: RecoveryState = dataclasses.field(default_factory=RecoveryState)
    odom_at_update: FloatArray | None = None
    global_start: bool = False
    updates: int = 0


def spread_cloud_config(config: LocalizeConfig, global_start: bool) -> LocalizeConfig:
    """The settings that weigh a cloud that has not converged.

    Global localization (``global_start``) uses them as configured. A tracked cloud that has spread (the
    CARMEN logs' 1 m odometry steps) keeps one tempered stage, per-beam factors and, in the RBPF, eq. (6) only
    once converged: measured on aces, ATE 0.14 m that way and 34 m with the pose volume factor, whose per-beam
    peak term exp(−d_b²/(2(σ² + e_b))) lets each beam of a wide region pick its own offset, which a cluttered
    map rewards (docs/results.md, "Global localization: keeping the hypotheses").
    """
    if global_start:
        return config
    return config.model_copy(update={"global_max_stages": 1, "global_smoothing_volume": "per_beam",
                                     "global_door_term": False})


@dataclass(frozen=True)
class StepDiagnostics:
    """What one :func:`mcl_step` did."""

    updated: bool  # the update thresholds were met (or forced, or first update)
    resampled: bool
    neff: float  # effective sample size after weighting, before resampling
    n_particles: int  # after the step
    random_fraction: float  # recovery's injection probability at this step
    n_random: int  # random particles injected
    log_avg_weight: float  # log w_avg of the weighting (nan without update)
    doors_updated: bool = False  # RBPF: the pose held (not updated), the doors updated from this scan




def update_thresholds_met(odom_prev: npt.ArrayLike, odom_now: npt.ArrayLike, config: LocalizeConfig) -> bool:
    """AMCL's ``shouldUpdateFilter``: |Δx| > update_min_d or |Δy| > update_min_d or |Δθ| > update_min_a."""
    a = np.asarray(odom_prev, dtype=np.float64)
    b = np.asarray(odom_now, dtype=np.float64)
    dyaw = float(wrap_angle(b[2] - a[2]))
    return bool(abs(b[0] - a[0]) > config.update_min_d or abs(b[1] - a[1]) > config.update_min_d
                or abs(dyaw) > config.update_min_a)


def predict(particles: ParticleSet, odom_prev: npt.ArrayLike, odom_now: npt.ArrayLike, config: LocalizeConfig,
            rng: np.random.Generator) -> ParticleSet:
    """Particles moved by the odometry motion model of ``robot_model_type`` (weights and door arrays unchanged)."""
    c = config
    if c.robot_model_type == "omnidirectional":
        pose = sample_motion_model_omni(particles.pose, odom_prev, odom_now,
                                        (c.alpha1, c.alpha2, c.alpha3, c.alpha4, c.alpha5), rng, c.alpha_sums_as_std)
    else:
        pose = sample_motion_model_odometry(particles.pose, odom_prev, odom_now,
                                            (c.alpha1, c.alpha2, c.alpha3, c.alpha4), rng, c.alpha_sums_as_std)
    return replace(particles, pose=pose)


def beams_from_scan(scan: Scan, laser_to_base: npt.ArrayLike, config: LocalizeConfig) -> BeamSet:
    """The beams of a scan the endpoint model uses (AMCL's rules: max_beams, laser_min/max_range)."""
    return select_beams(scan.ranges, scan.angles, scan.range_min, scan.range_max, laser_to_base, config.max_beams,
                        config.laser_min_range, config.laser_max_range, config.laser_max_range_fallback)


def scan_log_likelihood(pose: npt.ArrayLike, beams: BeamSet, field: DistanceField, config: LocalizeConfig,
                        combination: BeamCombination = BeamCombination.AMCL, chunk: int = CHUNK_PARTICLES
                        ) -> FloatArray:
    """log p(z | x) (N,) of every particle pose under the likelihood-field endpoint model.

    Every beam end point of every particle is moved at once ((chunk, B) float32 blocks), looked up in the
    distance field, and combined as AMCL does (or as a product, see :class:`BeamCombination`).
    """
    return field_log_likelihood(field, pose, beams.points_base, config.z_hit, config.z_rand, config.sigma_hit,
                                beams.range_max_m, combination, chunk)


def apply_log_likelihood(particles: ParticleSet, log_likelihood: npt.ArrayLike) -> Weighting:
    """Posterior log-weights log wᵢ + log pᵢ, normalized by log-sum-exp, and log w_avg (for recovery).

    w_avg = Σᵢ wᵢ·pᵢ with the prior weights normalized: the mean likelihood of Probabilistic Robotics Table 8.3
    ((1/M)·Σ pᵢ right after a resampling). AMCL's ``pf_update_sensor`` divides this once more by the particle
    count; with KLD changing the count between updates that factor alone moves w_fast away from w_slow, so
    it is left out here and applied by :func:`finish_step` only with ``recovery_average_per_particle`` (in a
    steady particle count the ratio w_fast / w_slow is the same).
    """
    ll = np.asarray(log_likelihood, dtype=np.float64)
    with np.errstate(divide="ignore"):
        log_w = np.log(particles.weight) + ll
    top = float(np.max(log_w))
    if not math.isfinite(top):  # every particle impossible: AMCL's "zero total" resets to uniform
        n = len(particles)
        return Weighting(np.full(n, -math.log(n)), -math.inf)
    log_total = top + math.log(float(np.sum(np.exp(log_w - top))))
    return Weighting(log_w - log_total, log_total)


def region_log_likelihood(particles: ParticleSet, bandwidth: Bandwidth, beams: BeamSet, field: DistanceField,
                          config: LocalizeConfig, combination: BeamCombination) -> FloatArray:
    """log p(z | region) (N,) of each particle's pose region (:func:`~.smoothing.region_beam_likelihood`)."""
    dist = endpoint_distances(field, particles.pose, beams.points_base)
    pz, log_region = region_beam_likelihood(field, particles.pose, beams.points_base, dist, bandwidth, config,
                                            beams.range_max_m, combination)
    out: FloatArray = combine_beams(pz, combination) + log_region
    return out


def tempered_weighting(particles: ParticleSet, log_likelihood: Callable[[ParticleSet, Bandwidth], FloatArray],
                       config: LocalizeConfig, rng: np.random.Generator) -> tuple[ParticleSet, float, Bandwidth]:
    """A scan applied in tempered stages with rejuvenation (adaptive SMC tempering, Jasra et al. 2011).

    The scan's likelihood L goes in as L^β₁·L^β₂·… with Σβ_s = 1: each β_s is the largest that shrinks Neff at most
    by ``global_min_neff_ratio`` (:func:`~.smoothing.tempering_exponent`); between stages the particles are
    resampled (low variance, same count), moved by their kernels (:func:`~.smoothing.jitter`) and L is evaluated
    afresh at the moved poses (with their new bandwidths). So a sharp scan refines the cloud step by step
    instead of collapsing it, and none of its evidence is lost: with one stage the rest 1 − β₁ was dropped,
    and a cue seen only briefly (a corridor's end wall in the first 2 s) never counted in full. After
    ``global_max_stages`` stages what remains is left out.

    Args:
        particles: the weighted particles before the scan.
        log_likelihood: log L (N,) of a particle set given its bandwidths.

    Returns:
        The particles with their final weights, log Ẑ = Σ_s log Σᵢ wᵢ·Lᵢ^β_s (the scan's mean likelihood, for
        recovery), and the bandwidths of the final poses.
    """
    remaining = 1.0
    log_z = 0.0
    stage = 0
    while True:
        bandwidth = particle_bandwidth(particles.pose, config)
        ll = log_likelihood(particles, bandwidth)
        with np.errstate(divide="ignore"):
            log_prior = np.log(particles.weight)
        beta = remaining * tempering_exponent(log_prior, remaining * ll, config.global_min_neff_ratio)
        weighting = apply_log_likelihood(particles, beta * ll)
        log_z += weighting.log_avg_weight
        particles = with_log_weights(particles, weighting.log_weight)
        remaining -= beta
        stage += 1
        if remaining <= 1e-9 or stage >= config.global_max_stages:
            return particles, log_z, bandwidth
        index = low_variance_resample(particles.weight, len(particles), rng)
        moved = particles.take(index)
        moved.pose = jitter(particles.pose[index], bandwidth, rng, index)
        particles = moved


def weigh(particles: ParticleSet, beams: BeamSet, field: DistanceField, config: LocalizeConfig,
          combination: BeamCombination = BeamCombination.AMCL) -> Weighting:
    """Weigh the particles of a converged cloud with a scan: normalized log-weights and the recovery's mean weight.

    With ``do_beamskip`` the per-beam likelihoods are formed first and the beams most particles cannot explain
    are left out (:func:`~.likelihood_field.beam_skip_mask`); otherwise the fused chunked path runs. (A cloud
    that has not converged goes through :func:`tempered_weighting` instead.)
    """
    if config.do_beamskip and len(beams.points_base):
        ll, _ = skipped_field_log_likelihood(field, particles.pose, particles.weight, beams.points_base, config,
                                             beams.range_max_m, combination)
    else:
        ll = scan_log_likelihood(particles.pose, beams, field, config, combination)
    return apply_log_likelihood(particles, ll)


def with_log_weights(particles: ParticleSet, log_weight: npt.ArrayLike) -> ParticleSet:
    """The particles with weights exp(log_weight), renormalized against rounding."""
    w = np.exp(np.asarray(log_weight, dtype=np.float64))
    return replace(particles, weight=w / w.sum())


def resample_if_needed(particles: ParticleSet, config: LocalizeConfig, rng: np.random.Generator,
                       recovery: RecoveryState | None = None, free: FreeCells | None = None,
                       bandwidth: Bandwidth | None = None) -> tuple[ParticleSet, RecoveryState, int]:
    """KLD-adaptive low-variance resampling when Neff < resample_neff_ratio·N or recovery injects (unless
    ``neff_test_gates_recovery``: ROS 1 amcl's selective resampling injects only when the Neff test resamples).

    With a ``bandwidth`` (global localization) each drawn copy is moved by its source particle's kernel
    (regularized resampling, :func:`~.smoothing.jitter`); injected random particles are not.

    Returns:
        The particles (the same object when not resampled), the recovery state (reset after an injection,
        as AMCL), and the number of random particles injected (−1: not resampled).
    """
    n = len(particles)
    recovery = recovery or RecoveryState()
    fraction = recovery.random_fraction() if free is not None else 0.0
    neff_says = config.resample_neff_ratio >= 1.0 or particles.neff() < config.resample_neff_ratio * n
    if not (neff_says or (fraction > 0.0 and not config.neff_test_gates_recovery)):
        return particles, recovery, -1
    draw = kld_resample(particles.pose, particles.weight, rng, min_particles=config.min_particles,
                        max_particles=config.max_particles, pf_err=config.pf_err, pf_z=config.pf_z,
                        bin_xy_m=config.kld_bin_xy_m, bin_yaw_rad=math.radians(config.kld_bin_yaw_deg),
                        random_fraction=fraction, free=free)
    out = particles.take(draw.index)
    out.pose = draw.pose
    if bandwidth is not None:
        kept = ~draw.random
        out.pose[kept] = jitter(draw.pose[kept], bandwidth, rng, draw.index[kept])
    if fraction > 0.0:
        recovery = RecoveryState()
    return out, recovery, int(draw.random.sum())


def mcl_step(state: MclState, odom_now: npt.ArrayLike, beams: BeamSet, field: DistanceField,
             config: LocalizeConfig, rng: np.random.Generator, free: FreeCells | None = None,
             force: bool = False, combination: BeamCombination = BeamCombination.AMCL
             ) -> tuple[MclState, StepDiagnostics]:
    """One AMCL update: thresholds → motion → weight → recovery averages → resample.

    Args:
        state: the filter state after the previous step.
        odom_now: (3,) odometry pose at the scan's time.
        beams: the scan's beams (:func:`beams_from_scan`).
        field: the map's distance field.
        config: the ``localize`` section.
        rng: random generator.
        free: the map's free cells, for random-particle recovery (None: no injection).
        force: update even if the thresholds are not met (AMCL's ``request_nomotion_update``).
        combination: how beams combine (AMCL's 1 + Σ pz³ by default; see :class:`BeamCombination`).
    """
    odom = np.asarray(odom_now, dtype=np.float64).reshape(3)
    particles = state.particles
    if state.odom_at_update is not None:
        if not (force or update_thresholds_met(state.odom_at_update, odom, config)):
            return state, StepDiagnostics(False, False, particles.neff(), len(particles), 0.0, 0, math.nan)
        particles = predict(particles, state.odom_at_update, odom, config, rng)
    bandwidth = active_bandwidth(particles.pose, particles.weight, config)
    if bandwidth is not None and len(beams.points_base):
        spread = spread_cloud_config(config, state.global_start)

        def region(p: ParticleSet, h: Bandwidth) -> FloatArray:
            return region_log_likelihood(p, h, beams, field, spread, combination)

        particles, log_avg, bandwidth = tempered_weighting(particles, region, spread, rng)
    else:
        weighting = weigh(particles, beams, field, config, combination)
        particles, log_avg = with_log_weights(particles, weighting.log_weight), weighting.log_avg_weight
    return finish_step(state, particles, log_avg, odom, config, rng, free, bandwidth)


def finish_step(state: MclState, particles: ParticleSet, log_avg_weight: float, odom: FloatArray,
                config: LocalizeConfig, rng: np.random.Generator, free: FreeCells | None,
                bandwidth: Bandwidth | None) -> tuple[MclState, StepDiagnostics]:
    """The end of an update that MCL and the RBPF share once the particles are weighed: the recovery averages
    (from the scan's mean weight; divided by the particle count with ``recovery_average_per_particle``),
    resampling with random-particle injection, the new state and diagnostics."""
    if config.recovery_average_per_particle:  # AMCL's w_avg /= set->sample_count (the count weighed)
        log_avg_weight -= math.log(len(particles))
    if bandwidth is not None and free is not None and config.global_free_space_prior:
        particles = in_free_space(particles, free)
    recovery = state.recovery.update(log_avg_weight, config.recovery_alpha_slow, config.recovery_alpha_fast)
    fraction = recovery.random_fraction() if free is not None else 0.0
    neff = particles.neff()
    updates = state.updates + 1
    n_random = -1
    if updates % config.resample_interval == 0:
        particles, recovery, n_random = resample_if_needed(particles, config, rng, recovery, free, bandwidth)
    diag = StepDiagnostics(True, n_random >= 0, neff, len(particles), fraction, max(n_random, 0), log_avg_weight)
    return MclState(particles, recovery, odom.copy(), state.global_start, updates), diag


def in_free_space(particles: ParticleSet, free: FreeCells) -> ParticleSet:
    """The particles with the pose prior of a global start, uniform over the map's free cells: weight 0 off them
    (unchanged if that would leave none). Regularized resampling moves each copy by its source's kernel, and the
    kernel of a particle far from the others is wide: without the prior, copies that strayed outside the map in a
    scan that fits nowhere (a crowd) spread further each update, to covariances of 10⁶ m²."""
    off = ~free.holds(particles.pose[:, :2])
    if not off.any() or off.all():
        return particles
    w = np.where(off, 0.0, particles.weight)
    return replace(particles, weight=w / w.sum())


def initial_particles(mean: npt.ArrayLike, config: LocalizeConfig, rng: np.random.Generator,
                      n: int | None = None) -> ParticleSet:
    """Particles around a known pose (``init_sigma_xy_m``, ``init_sigma_yaw_deg``); max_particles by default."""
    sigma = (config.init_sigma_xy_m, config.init_sigma_xy_m, math.radians(config.init_sigma_yaw_deg))
    return ParticleSet.gaussian(mean, sigma, n or config.max_particles, rng)


def global_particles(free: FreeCells, n: int, rng: np.random.Generator) -> ParticleSet:
    """n particles uniform over the map's free space (AMCL's global localization)."""
    return ParticleSet(free.sample_poses(n, rng), np.full(n, 1.0 / n), np.zeros((n, 0)), np.zeros((n, 0)))
