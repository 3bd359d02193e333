"""The Rao-Blackwellized particle filter of paper 000, Sec. IV: poses by particles, door angles by one
Kalman filter per door per particle.

One update, in the paper's order (with MCL's update thresholds, recovery and resampling, so that the two
methods differ only in the map model)::

    1. sampling     poses by the odometry motion model; door angles d_k,t = d_k,t−1 + ε, ε ~ N(0, σ_d²·Δt)
    2. importance   per beam, ML association between the static likelihood field and each door leaf at the
                    particle's door estimate, the door term marginalized to first order (eq. 6); until the
                    cloud converges, the static model alone (as MCL; door angles not yet tied to a pose),
                    smoothed over each particle's pose region and tempered (:mod:`.smoothing`); once
                    converged, beams that most of the weight explains by neither are skipped (Nav2's
                    do_beamskip, likelihood_field.skip_unexplained), as MCL does
    3. door update  one Douglas–Peucker polygon per scan, moved to every particle, associated to doors,
                    Kalman update of the associated doors' angles
    4. resampling   low-variance (KLD-adaptive) when Neff is low
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import numpy.typing as npt

from doorbatch.config import LocalizeConfig
from doorbatch.maps import DoorSet
from doorbatch.pipeline.localize.door_likelihood import door_log_likelihood_at_poses
from doorbatch.pipeline.localize.door_observation import predict_doors, update_doors
from doorbatch.pipeline.localize.likelihood_field import (
    BeamCombination,
    BeamSet,
    DistanceField,
    FreeCells,
    beam_likelihood,
    combine_beams,
    endpoint_distances,
    skip_unexplained,
)
from doorbatch.pipeline.localize.mcl import (
    MclState,
    StepDiagnostics,
    apply_log_likelihood,
    predict,
    resample_if_needed,
    update_thresholds_met,
    with_log_weights,
)
from doorbatch.pipeline.localize.smoothing import (
    active_bandwidth,
    endpoint_variance,
    smoothed_beam_likelihood,
    tempering_exponent,
)


def rbpf_step(state: MclState, odom_now: npt.ArrayLike, stamp_s: float, last_stamp_s: float | None,
              beams: BeamSet, scan_points_base: npt.ArrayLike, field: DistanceField, doors: DoorSet,
              config: LocalizeConfig, rng: np.random.Generator, free: FreeCells | None = None,
              force: bool = False) -> tuple[MclState, StepDiagnostics, npt.NDArray[np.bool_]]:
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
        The new state, the step's diagnostics, and (D,) whether each door was observed by any particle.
    """
    odom = np.asarray(odom_now, dtype=np.float64).reshape(3)
    particles = state.particles
    n_doors = particles.n_doors
    none = np.zeros(n_doors, dtype=bool)
    if state.odom_at_update is not None:
        if not (force or update_thresholds_met(state.odom_at_update, odom, config)):
            return state, StepDiagnostics(False, False, particles.neff(), len(particles), 0.0, 0, math.nan), none
        particles = predict(particles, state.odom_at_update, odom, config, rng)
    if last_stamp_s is not None and n_doors:
        cap = math.radians(config.door_init_sigma_deg) ** 2
        var = predict_doors(particles.door_var, max(stamp_s - last_stamp_s, 0.0), config.door_sigma_rad_per_sqrt_s,
                            max_var=cap)
        particles = replace(particles, door_var=var)

    bandwidth = active_bandwidth(particles.pose, particles.weight, config)
    extra = None if bandwidth is None else endpoint_variance(bandwidth, beams.points_base)
    static = endpoint_distances(field, particles.pose, beams.points_base)
    # Eq. (6) only once the cloud has converged: a particle's door angles are then conditioned on its own
    # (tracked) pose; while the cloud is global they are the 30° prior, and ML association turns every door's
    # swept disc into a region that explains any stray beam, which pulls the cloud onto wrong
    # poses near many doors (docs/results.md, "What does not meet issue #5 yet"); until then, MCL's static model.
    if n_doors and bandwidth is None:
        dl = door_log_likelihood_at_poses(static, particles.pose, beams.points_base, doors, particles.door_mean,
                                          particles.door_var, config, beams.range_max_m)
        pz = dl.beam_likelihood
    elif extra is not None:
        pz = smoothed_beam_likelihood(static, extra, config.z_hit, config.z_rand, config.sigma_hit,
                                      beams.range_max_m)
    else:
        pz = beam_likelihood(static, config.z_hit, config.z_rand, config.sigma_hit, beams.range_max_m)
    combination = BeamCombination(config.beam_combination)
    pz, _ = skip_unexplained(pz, particles.weight, particles.pose, config, beams.range_max_m, combination)
    loglik = combine_beams(pz, combination)
    if bandwidth is not None:
        with np.errstate(divide="ignore"):
            loglik = loglik * tempering_exponent(np.log(particles.weight), loglik, config.global_min_neff_ratio)
    weighting = apply_log_likelihood(particles, loglik)
    particles = with_log_weights(particles, weighting.log_weight)

    observed = none
    if n_doors:
        update = update_doors(scan_points_base, particles, doors, config)
        particles = replace(particles, door_mean=update.mean, door_var=update.var)
        observed = np.asarray(update.observed.any(axis=0), dtype=bool)

    recovery = state.recovery.update(weighting.log_avg_weight, config.recovery_alpha_slow, config.recovery_alpha_fast)
    fraction = recovery.random_fraction() if free is not None else 0.0
    neff = particles.neff()
    particles, recovery, n_random = resample_if_needed(particles, config, rng, recovery, free, bandwidth)
    diag = StepDiagnostics(True, n_random >= 0, neff, len(particles), fraction, max(n_random, 0),
                           weighting.log_avg_weight)
    return MclState(particles, recovery, odom.copy()), diag, observed
