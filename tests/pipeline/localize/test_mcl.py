"""MCL (Nav2 AMCL's filter): update thresholds, weighting, resampling decisions, tracking, global localization."""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import numpy.typing as npt
import pytest
from mcl_sim import (
    LASER_TO_BASE,
    asymmetric_room,
    axis_scaled_odometry,
    loop_trajectory,
    polyline,
    rasterize,
    room_map,
    scan_beams,
    scan_ranges,
)

from doorbatch.config import LocalizeConfig
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import compose, relative
from doorbatch.pipeline.localize.likelihood_field import (
    BeamCombination,
    DistanceField,
    FreeCells,
    build_distance_field,
    free_cells,
)
from doorbatch.pipeline.localize.mcl import (
    MclState,
    apply_log_likelihood,
    beams_from_scan,
    finish_step,
    global_particles,
    initial_particles,
    mcl_step,
    resample_if_needed,
    scan_log_likelihood,
    update_thresholds_met,
    weigh,
)
from doorbatch.pipeline.localize.particles import ParticleSet
from doorbatch.pipeline.localize.resampling import RecoveryState
from doorbatch.records import Scan
from doorbatch.sim.motion import OdometryNoise, drift_poses

FloatArray = npt.NDArray[np.float64]
# Drifting wheel odometry: 2 % scale error, 0.6°/m yaw drift, white noise.
DRIFT = OdometryNoise(0.01, 0.005, 0.01, 0.005, scale_error=0.02, yaw_drift_rad_per_m=0.01)


@cache
def room() -> tuple[DistanceField, FreeCells]:
    grid = room_map()
    return build_distance_field(grid, LocalizeConfig().laser_likelihood_max_dist), free_cells(grid)


def run(state: MclState, truth: FloatArray, odom: FloatArray, config: LocalizeConfig, rng: np.random.Generator,
        combination: BeamCombination = BeamCombination.AMCL, free: FreeCells | None = None
        ) -> tuple[MclState, list[tuple[int, FloatArray, int, int]]]:
    """Feed scans ray cast from ``truth`` and the ``odom`` poses; (index, mean, particles, injected) per update."""
    field, _ = room()
    segments = asymmetric_room()
    out = []
    for k in range(truth.shape[0]):
        beams = scan_beams(segments, truth[k], noise_m=0.01, rng=rng)
        state, diag = mcl_step(state, odom[k], beams, field, config, rng, free=free, combination=combination)
        if diag.updated:
            mean, _ = state.particles.mean_and_covariance()
            out.append((k, mean, diag.n_particles, diag.n_random))
    return state, out


def test_update_thresholds_are_amcls_per_axis_test() -> None:
    config = LocalizeConfig(update_min_d=0.1, update_min_a=0.1)
    assert not update_thresholds_met((0, 0, 0), (0.09, -0.09, 0.09), config)
    assert update_thresholds_met((0, 0, 0), (0.11, 0.0, 0.0), config)
    assert update_thresholds_met((0, 0, 0), (0.0, -0.11, 0.0), config)
    assert update_thresholds_met((0, 0, 0), (0.0, 0.0, -0.11), config)
    assert not update_thresholds_met((0, 0, 0), (0.08, 0.08, 0.0), config)  # 0.113 m, but < 0.1 on each axis
    assert not update_thresholds_met((0, 0, 3.1), (0, 0, -3.1), config)  # 0.083 rad across ±π


def test_weighting_is_normalized_and_gives_the_mean_likelihood() -> None:
    field, _ = room()
    config = LocalizeConfig(do_beamskip=False)  # every beam counts (beam skipping: test_beam_skipping_*)
    rng = np.random.default_rng(11)
    particles = initial_particles([4.0, 2.0, 0.3], config, rng, n=500)
    particles.weight = rng.random(500)
    particles.weight /= particles.weight.sum()
    beams = scan_beams(asymmetric_room(), np.array([4.0, 2.0, 0.3]))
    w = weigh(particles, beams, field, config)
    p = np.exp(scan_log_likelihood(particles.pose, beams, field, config))
    assert np.all((p >= 1.0) & (p <= 1.0 + len(beams)))  # AMCL: 1 + Σ pz³ with pz ≤ 1
    posterior = particles.weight * p
    assert np.allclose(np.exp(w.log_weight), posterior / posterior.sum())
    assert w.log_avg_weight == pytest.approx(math.log(posterior.sum()))
    impossible = apply_log_likelihood(particles, np.full(500, -np.inf))  # AMCL's zero total → uniform
    assert np.allclose(np.exp(impossible.log_weight), 1 / 500)


def test_resampling_waits_for_a_low_effective_sample_size() -> None:
    config = LocalizeConfig(min_particles=100, max_particles=100, resample_neff_ratio=0.5)
    rng = np.random.default_rng(12)
    particles = initial_particles([1.0, 1.0, 0.0], config, rng, n=100)
    same, _, injected = resample_if_needed(particles, config, rng)
    assert same is particles and injected == -1
    particles.weight = np.r_[np.full(10, 0.091), np.full(90, 0.0001)]
    particles.weight /= particles.weight.sum()
    assert particles.neff() < 50
    resampled, _, injected = resample_if_needed(particles, config, rng)
    assert injected == 0 and len(resampled) == 100 and np.allclose(resampled.weight, 0.01)
    every = LocalizeConfig(min_particles=100, max_particles=100, resample_neff_ratio=1.0)
    assert resample_if_needed(initial_particles([1, 1, 0], every, rng, n=100), every, rng)[2] == 0



def test_ros1_selective_resampling_injects_no_random_particles_while_neff_is_high() -> None:
    """pf.c (ROS 1, selective_resampling): with Neff above N/2 the set is copied and the function returns before
    its recovery test, so a falling w_fast brings no random particles until the weights also collapse."""
    _, free = room()
    rng = np.random.default_rng(13)
    falling = RecoveryState(log_w_slow=0.0, log_w_fast=math.log(0.5))  # recovery asks for 50 % random particles
    for gated, expected in ((False, True), (True, False)):
        config = LocalizeConfig(min_particles=100, max_particles=100, resample_neff_ratio=0.5,
                                neff_test_gates_recovery=gated)
        particles = initial_particles([1.0, 1.0, 0.0], config, rng, n=100)  # equal weights: Neff = N
        out, _, injected = resample_if_needed(particles, config, rng, falling, free)
        assert (injected > 0) is expected and (out is not particles) is expected

def test_resampling_is_due_on_every_resample_interval_th_update_as_nav2_counts() -> None:
    field, _ = room()
    config = LocalizeConfig(resample_interval=3, resample_neff_ratio=1.0)
    rng = np.random.default_rng(15)
    beams = scan_beams(asymmetric_room(), np.array([4.0, 2.0, 0.0]))
    state = MclState(initial_particles([4.0, 2.0, 0.0], config, rng))
    resampled = []
    for k in range(7):
        state, diag = mcl_step(state, (0.0, 0.0, 0.0), beams, field, config, rng, force=k > 0)
        resampled.append(diag.resampled)
    assert resampled == [False, False, True, False, False, True, False]
    assert state.updates == 7


def test_an_omnidirectional_base_strafing_round_the_room_is_tracked() -> None:
    """A holonomic robot keeps facing +x while it drives the loop (sideways half the time); its odometry
    drifts in the robot frame. The omnidirectional model tracks it within 5 cm on average."""
    truth = loop_trajectory(240)
    truth[:, 2] = 0.0
    rng = np.random.default_rng(16)
    odom = axis_scaled_odometry(truth, rng)
    assert np.hypot(*(odom[-1, :2] - relative(truth[0], truth[-1])[:2])) > 0.2  # the odometry drifts away
    config = LocalizeConfig(robot_model_type="omnidirectional")
    _, updates = run(MclState(initial_particles(truth[0], config, rng)), truth,
                     compose(np.broadcast_to(truth[0], odom.shape), odom), config, rng)
    errors = np.array([np.hypot(*(mean[:2] - truth[k, :2])) for k, mean, _, _ in updates])
    assert len(updates) > 90
    assert errors.mean() < 0.05
    assert errors.max() < 0.15


def test_no_update_below_the_thresholds() -> None:
    field, _ = room()
    config = LocalizeConfig()
    rng = np.random.default_rng(13)
    beams = scan_beams(asymmetric_room(), np.array([4.0, 2.0, 0.0]))
    state, first = mcl_step(MclState(initial_particles([4.0, 2.0, 0.0], config, rng)), (0, 0, 0), beams, field,
                            config, rng)
    assert first.updated and state.odom_at_update is not None
    same, diag = mcl_step(state, (0.05, 0.05, 0.05), beams, field, config, rng)
    assert not diag.updated and same is state
    forced, diag = mcl_step(state, (0.05, 0.05, 0.05), beams, field, config, rng, force=True)
    assert diag.updated and forced.odom_at_update is not None
    assert np.allclose(forced.odom_at_update, (0.05, 0.05, 0.05))


def test_beams_from_a_scan_record_use_the_config() -> None:
    truth = np.array([4.0, 2.0, 0.0])
    ranges, angles = scan_ranges(asymmetric_room(), truth)
    scan = Scan(0, 0, "laser", float(angles[0]), float(angles[1] - angles[0]), 0.05, 12.0, ranges.astype(np.float32))
    beams = beams_from_scan(scan, LASER_TO_BASE, LocalizeConfig(max_beams=30, laser_max_range=3.0))
    assert beams.range_max_m == 3.0 and 0 < len(beams) <= 31
    assert np.all(np.hypot(*(beams.points_base - LASER_TO_BASE[:2, 3]).T) < 3.0)


@pytest.mark.parametrize("combination", list(BeamCombination))
def test_tracking_with_drifting_odometry_stays_within_5_cm(combination: BeamCombination) -> None:
    truth = loop_trajectory(240)  # 12 m loop, 5 cm per scan
    rng = np.random.default_rng(14)
    odom = drift_poses(truth, DRIFT, rng)
    assert np.hypot(*(odom[-1, :2] - truth[-1, :2])) > 0.2  # the odometry alone drifts away
    config = LocalizeConfig()
    _, updates = run(MclState(initial_particles(truth[0], config, rng)), truth, odom, config, rng, combination)
    assert len(updates) > 90
    errors = np.array([np.hypot(*(mean[:2] - truth[k, :2])) for k, mean, _, _ in updates])
    yaw_errors = np.array([abs(float(wrap_angle(mean[2] - truth[k, 2]))) for k, mean, _, _ in updates])
    assert errors.mean() < 0.05
    assert errors.max() < 0.15
    assert yaw_errors.mean() < math.radians(2.0)
    assert all(config.min_particles <= n <= config.max_particles for _, _, n, _ in updates[1:])


def test_global_localization_converges_in_an_asymmetric_room() -> None:
    _, free = room()
    truth = loop_trajectory(240)[:120]
    rng = np.random.default_rng(15)
    odom = drift_poses(truth, DRIFT, rng)
    config = LocalizeConfig()
    state = MclState(global_particles(free, config.global_particles, rng))
    first, _ = state.particles.mean_and_covariance()
    assert np.hypot(*(first[:2] - truth[0, :2])) > 0.5  # starts anywhere
    state, _ = run(state, truth, odom, config, rng)
    mean, cov = state.particles.mean_and_covariance()
    assert np.hypot(*(mean[:2] - truth[-1, :2])) < 0.1
    assert abs(float(wrap_angle(mean[2] - truth[-1, 2]))) < math.radians(3.0)
    assert math.sqrt(max(cov[0, 0], cov[1, 1])) < config.converged_xy_std_m
    assert math.degrees(math.sqrt(cov[2, 2])) < config.converged_yaw_std_deg


def test_kidnapped_robot_gets_random_particles() -> None:
    _, free = room()
    truth = loop_trajectory(240)
    rng = np.random.default_rng(16)
    odom = drift_poses(truth, DRIFT, rng)
    config = LocalizeConfig(recovery_alpha_slow=0.001, recovery_alpha_fast=0.1)
    state, updates = run(MclState(initial_particles(truth[0], config, rng)), truth[:60], odom[:60], config, rng,
                         free=free)
    assert sum(n for _, _, _, n in updates) == 0  # tracking well: w_fast ≈ w_slow, nothing injected
    wrong = ParticleSet(state.particles.pose + np.array([2.0, 1.5, 1.0]), state.particles.weight,
                        state.particles.door_mean, state.particles.door_var)
    state, updates = run(MclState(wrong, state.recovery, state.odom_at_update), truth[60:120], odom[60:120], config,
                         rng, free=free)
    # w_fast falls below w_slow within a few updates: random particles come in, and AMCL then resets both
    # averages (so one injection per drop, not a stream of them)
    injected = [n for _, _, _, n in updates if n > 0]
    assert len(injected) >= 1
    assert state.recovery.random_fraction() < 0.01


def test_amcls_mean_weight_divides_by_the_particles_weighed() -> None:
    """pf_update_sensor: w_avg = Σ wᵢ·pᵢ / N. With KLD shrinking the cloud from 5,000 to 500 particles at the same
    mean likelihood, AMCL's w_avg grows tenfold, w_fast overtakes w_slow and nothing is injected; growing the cloud
    back makes w_fast fall below w_slow (1 − w_fast/w_slow > 0). Without the option the count leaves both alone."""
    rng = np.random.default_rng(0)
    log_p = math.log(0.3)  # the mean likelihood Σ wᵢ·pᵢ of every update here

    def cloud(n: int) -> ParticleSet:
        return initial_particles(np.zeros(3), LocalizeConfig(), rng, n)

    fractions = {}
    for per_particle in (True, False):
        config = LocalizeConfig(recovery_alpha_slow=0.1, recovery_alpha_fast=0.5, resample_interval=1000,
                                recovery_average_per_particle=per_particle)
        state = MclState(cloud(5000))
        state, _ = finish_step(state, state.particles, log_p, np.zeros(3), config, rng, None, None)
        if per_particle:  # the first update initializes both averages to w_avg itself
            assert state.recovery.log_w_slow == pytest.approx(log_p - math.log(5000))
        else:
            assert state.recovery.log_w_slow == pytest.approx(log_p)
        state, _ = finish_step(MclState(cloud(500), state.recovery, np.zeros(3)), cloud(500), log_p, np.zeros(3),
                               config, rng, None, None)
        shrunk = state.recovery.random_fraction()
        for _ in range(4):  # w_fast (α 0.5) forgets the small cloud's large w_avg faster than w_slow (α 0.1)
            state, _ = finish_step(MclState(cloud(5000), state.recovery, np.zeros(3)), cloud(5000), log_p,
                                   np.zeros(3), config, rng, None, None)
        fractions[per_particle] = (shrunk, state.recovery.random_fraction())
    assert max(fractions[False]) < 1e-12
    shrunk, grown = fractions[True]
    # by hand, in units of p/5000: w_slow 1 → 1.9 → 1.81, 1.729, 1.656, 1.590; w_fast 1 → 5.5 → 3.25, 2.125, 1.5625,
    # 1.281; 1 − w_fast/w_slow = 0.194
    assert shrunk == 0.0 and grown == pytest.approx(1 - 1.28125 / 1.59049, rel=1e-9), fractions[True]


def test_same_seed_same_result() -> None:
    truth = loop_trajectory(240)[:40]
    odom = drift_poses(truth, DRIFT, np.random.default_rng(17))
    config = LocalizeConfig()
    results = []
    for _ in range(2):
        rng = np.random.default_rng(18)
        state, _ = run(MclState(initial_particles(truth[0], config, rng)), truth, odom, config, rng)
        results.append(state.particles.pose)
    assert np.array_equal(results[0], results[1])


def test_global_localization_with_the_product_model_needs_the_smoothing() -> None:
    # 2,000 particles over 39 m² and all headings: ~0.2 m and 4° between neighbours, far coarser than the
    # product of 60 sharp beams resolves. Smoothed and tempered (localize/smoothing.py) every run localizes;
    # the plain product collapses on whichever particle happens to fit best (measured: 2 of 6 seeds localize).
    _, free = room()
    truth = loop_trajectory(240)[:120]
    final_errors = {}
    for smoothing in (True, False):
        for seed in range(4):
            rng = np.random.default_rng(seed)
            odom = drift_poses(truth, DRIFT, rng)
            config = LocalizeConfig(global_smoothing=smoothing, global_particles=2000, max_particles=2000)
            state, _ = run(MclState(global_particles(free, 2000, rng)), truth, odom, config, rng,
                           BeamCombination.PRODUCT)
            mean, _ = state.particles.mean_and_covariance()
            final_errors[(smoothing, seed)] = float(np.hypot(*(mean[:2] - truth[-1, :2])))
    assert all(final_errors[(True, s)] < 0.1 for s in range(4)), final_errors
    assert any(final_errors[(False, s)] > 1.0 for s in range(4)), final_errors


def test_global_localization_in_a_long_corridor_keeps_the_hypotheses_along_it() -> None:
    # A 40 m × 2 m corridor whose only feature is a notch at the west end, seen by the 4 m laser during the
    # first 3 m of the drive east: after that every pose along the corridor fits the scans equally. 1,500
    # particles. With one volume factor per pose region (smoothing.pose_volume_log_factor) every seed ends
    # at the truth; with one factor per beam, particles where the cloud happens to be dense outscore the
    # sparse ones near the truth by tens of nats, and the cloud settles on an arbitrary or the mirrored pose
    # (measured: 4 of 8 seeds).
    segments = np.concatenate([polyline((0, 0), (40, 0), (40, 2), (0, 2), (0, 0)),
                               polyline((0.0, 1.2), (0.4, 1.2), (0.4, 0.6))])
    grid = rasterize(segments, (0.0, 40.0), (0.0, 2.0))
    field, free = build_distance_field(grid, LocalizeConfig().laser_likelihood_max_dist), free_cells(grid)
    truth = np.column_stack([np.linspace(1.2, 9.0, 157), np.full(157, 0.8), np.zeros(157)])
    errors = {}
    for volume in ("pose", "per_beam"):
        config = LocalizeConfig(global_particles=1500, max_particles=1500, global_smoothing_volume=volume)
        for seed in range(8):
            rng = np.random.default_rng(seed)
            odom = drift_poses(truth, DRIFT, rng)
            state = MclState(global_particles(free, 1500, rng), global_start=True)
            for k in range(truth.shape[0]):
                beams = scan_beams(segments, truth[k], max_range=4.0, noise_m=0.01, rng=rng)
                state, _ = mcl_step(state, odom[k], beams, field, config, rng, combination=BeamCombination.PRODUCT)
            mean, _ = state.particles.mean_and_covariance()
            errors[(volume, seed)] = float(np.hypot(*(mean[:2] - truth[-1, :2])))
    assert all(errors[("pose", s)] < 0.3 for s in range(8)), errors
    assert sum(errors[("per_beam", s)] > 1.0 for s in range(8)) >= 2, errors


def test_a_global_cloud_keeps_no_particle_off_the_maps_free_space() -> None:
    """The pose prior of a global start is uniform over free space. Regularized resampling moves each copy by its
    source's kernel, which widens with the distance to the other particles, so copies that strayed off the map
    spread further every update (a crowded corridor's global run ended 140 m off a 42 m map, covariance 10⁶ m²).
    A cloud with a fifth of its particles 20 m outside the room: after one update none is drawn from them (the
    default); without the prior their copies are resampled and jittered on out there."""
    field, free = room()
    truth = loop_trajectory(240)[:2]
    far = {}
    for prior in (True, False):
        rng = np.random.default_rng(21)
        config = LocalizeConfig(global_particles=2000, max_particles=2000, global_free_space_prior=prior,
                                resample_neff_ratio=1.0)  # resample at every update, as Nav2 does
        cloud = global_particles(free, 2000, rng)
        cloud.pose[:400, 0] += 20.0
        state = MclState(cloud, odom_at_update=truth[0].copy(), global_start=True)
        beams = scan_beams(asymmetric_room(), truth[1], noise_m=0.01, rng=rng)
        state, diag = mcl_step(state, truth[1], beams, field, config, rng, free=free, force=True)
        assert diag.resampled
        far[prior] = int((state.particles.pose[:, 0] > 12.0).sum())
    assert far[True] == 0 and far[False] > 0, far
