"""RBPF against MCL with partially open doors (paper 000, Figs. 5-7): a corridor whose static map is two plain
walls, so that along its axis only the door leaves (absent from the static map) tell where the robot is."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest
from mcl_sim import LASER_X, RES, polyline, rasterize, scan_beams, scan_ranges

from doorbatch.config import LocalizeConfig
from doorbatch.maps import DoorSet
from doorbatch.pipeline.localize.likelihood_field import (
    BeamCombination,
    beam_skip_mask,
    beam_support_weights,
    build_distance_field,
    drop_beams,
    skip_unexplained,
)
from doorbatch.pipeline.localize.mcl import MclState, initial_particles, mcl_step
from doorbatch.pipeline.localize.particles import ParticleSet
from doorbatch.pipeline.localize.rbpf import rbpf_step
from doorbatch.pipeline.localize.run import initial_door_states
from doorbatch.sim.motion import OdometryNoise, drift_poses

FloatArray = npt.NDArray[np.float64]
HINGES_X = (3.0, 6.0, 9.0, 12.0)
LEAF = 0.8
OPEN = math.radians(50.0)  # partially open, into the corridor
# 5 % scale error: MCL, which has only the walls, drifts along the corridor with the odometry.
DRIFT = OdometryNoise(0.005, 0.002, 0.005, 0.002, scale_error=0.05, yaw_drift_rad_per_m=0.0)
RANGE = 4.0  # the corridor's ends are out of reach most of the way


def corridor() -> tuple[FloatArray, FloatArray, DoorSet]:
    """World segments (walls + leaves), static segments (walls), and the doors (hinges on the wall y = 0)."""
    walls = np.concatenate([polyline((-1.0, 0.0), (16.0, 0.0)), polyline((-1.0, 2.4), (16.0, 2.4)),
                            polyline((-1.0, 0.0), (-1.0, 2.4))])
    leaves = np.array([[[x, 0.0], [x + LEAF * math.cos(OPEN), LEAF * math.sin(OPEN)]] for x in HINGES_X])
    d = len(HINGES_X)
    doors = DoorSet(np.array([[x, 0.0] for x in HINGES_X]), np.full(d, LEAF), np.zeros(d), np.zeros(d),
                    np.full(d, math.radians(90.0)))
    return np.concatenate([walls, leaves]), walls, doors


def track(method: str, seed: int, map_doors: DoorSet | None = None) -> tuple[float, FloatArray]:
    """Mean position error of one run along the corridor, and the RBPF's door angles at its end (rad, weighted
    mean over particles). ``map_doors``: the doors the filter is given (default: the world's, range 0–90°)."""
    world, static, doors = corridor()
    doors = doors if map_doors is None else map_doors
    field = build_distance_field(rasterize(static, (-1.0, 16.0), (0.0, 2.4), margin=RES * 4), 2.0)
    n = 240
    truth = np.stack([np.linspace(1.0, 13.0, n), np.full(n, 1.5), np.zeros(n)], axis=1)
    rng = np.random.default_rng(seed)
    odom = drift_poses(truth, DRIFT, rng)
    config = LocalizeConfig(max_particles=1000, min_particles=300)
    particles = initial_particles(truth[0], config, rng)
    d = len(doors) if method == "rbpf" else 0
    if map_doors is None:
        particles.door_mean = np.full((len(particles), d), math.radians(45.0))
        particles.door_var = np.full((len(particles), d), math.radians(config.door_init_sigma_deg) ** 2)
    else:  # as a run starts them: mid-range
        particles.door_mean, particles.door_var = initial_door_states(doors, len(particles), False, config, rng)
    state = MclState(particles)
    errors: list[float] = []
    last: float | None = None
    for k in range(n):
        beams = scan_beams(world, truth[k], max_range=RANGE, noise_m=0.01, rng=rng)
        if method == "rbpf":
            r, a = scan_ranges(world, truth[k], max_range=RANGE)
            hit = np.isfinite(r)
            pts = np.stack([LASER_X + r[hit] * np.cos(a[hit]), r[hit] * np.sin(a[hit])], axis=1)
            state, diag, _ = rbpf_step(state, odom[k], 0.1 * k, last, beams, pts, field, doors, config, rng,
                                       force=k == 0)
        else:
            state, diag = mcl_step(state, odom[k], beams, field, config, rng, force=k == 0,
                                   combination=BeamCombination(config.beam_combination))
        if diag.updated:
            last = 0.1 * k
            mean, _ = state.particles.mean_and_covariance()
            errors.append(float(np.hypot(*(mean[:2] - truth[k, :2]))))
    door_angles = state.particles.door_estimate()[0] if d else np.zeros(0)
    return float(np.mean(errors)), door_angles


@pytest.mark.parametrize("seed", [3])
def test_rbpf_beats_mcl_with_partially_open_doors(seed: int) -> None:
    mcl, _ = track("mcl", seed)
    rbpf, _ = track("rbpf", seed)
    assert rbpf < 0.08
    assert rbpf < 0.5 * mcl, (rbpf, mcl)


def test_doors_that_never_moved_while_mapping_are_tracked_when_opened(tmp_path: Path) -> None:
    """A map whose doors never moved while mapping (doors.parquet ``moved`` false, the one angle the passes saw:
    closed) and a day on which they stand 50° open. Their range had been that one angle, so the RBPF kept them
    closed and took their leaves for clutter; they now open by ``door_unmoved_swing_deg`` to either side, and
    the filter finds them open."""
    from doorbatch.io.map_server import write_map
    from doorbatch.io.parquet import write_table
    from doorbatch.pipeline.localize.run import load_localization_map

    _, static, doors = corridor()
    n = len(doors)
    write_map(rasterize(static, (-1.0, 16.0), (0.0, 2.4), margin=RES * 4), tmp_path / "map.yaml")
    write_table("doors", {"door_id": np.arange(n, dtype=np.int32), "hinge_x": doors.hinge[:, 0],
                          "hinge_y": doors.hinge[:, 1], "length": doors.length, "closed_yaw": doors.closed_yaw,
                          "angle_min": np.zeros(n), "angle_max": np.zeros(n), "n_observations": np.full(n, 9, np.int32),
                          "source": ["em"] * n, "moved": [False] * n}, tmp_path / "doors.parquet")
    mapped = load_localization_map(tmp_path, LocalizeConfig()).doors
    np.testing.assert_allclose(np.degrees(mapped.angle_min), -90.0)
    np.testing.assert_allclose(np.degrees(mapped.angle_max), 90.0)
    error, door_angles = track("rbpf", 3, mapped)
    assert error < 0.05  # 0.097 m with the leaves as clutter
    # the last door's leaf is seen edge-on from behind as the run ends 1 m past its hinge (19° with a 0–90° range)
    np.testing.assert_allclose(np.degrees(door_angles[:3]), np.degrees(OPEN), atol=5.0)


def test_beam_skipping_leaves_out_beams_most_weight_cannot_explain() -> None:
    explained = np.array([[True, False, True], [True, False, False], [True, True, False]])
    w = np.array([0.5, 0.3, 0.2])
    # beam 1: 0.2 of the weight explains it; beam 2: 0.5 (not below the threshold)
    np.testing.assert_array_equal(beam_skip_mask(explained, w, 0.5, 0.9), [False, True, False])
    # more than the error threshold of the beams would go: the filter is lost, keep them all
    np.testing.assert_array_equal(beam_skip_mask(~explained, w, 0.9, 0.5), [False, False, False])
    pz = np.full((3, 3), 0.5, dtype=np.float32)
    assert np.all(drop_beams(pz, [False, True, False], BeamCombination.PRODUCT)[:, 1] == 1.0)
    assert np.all(drop_beams(pz, [False, True, False], BeamCombination.AMCL)[:, 1] == 0.0)



def test_beam_skipping_keeps_the_corrective_beams_of_a_wide_predicted_cloud() -> None:
    """After a long odometry step only the minority of particles near the true pose (0.3 of the prior weight)
    explains the beams on the wall that pulls the cloud back (beams 4 and 5): under the prior weight they
    would be skipped; under the other beams' posterior they count. Beam 6 (an obstacle the map lacks) is
    explained nowhere and is skipped either way."""
    config = LocalizeConfig()
    floor = config.z_hit * math.exp(-0.5 * (config.beam_skip_distance / config.sigma_hit) ** 2)
    pz = np.full((10, 7), 0.8)
    pz[3:, 4:6] = 0.01  # the majority misses the corrective wall
    pz[:, 6] = 0.01  # nobody explains the obstacle
    explained = pz >= floor
    w = np.full(10, 0.1)
    np.testing.assert_array_equal(beam_skip_mask(explained, w, 0.5, 0.9), [0, 0, 0, 0, 1, 1, 1])
    support = beam_support_weights(pz, w, floor, BeamCombination.PRODUCT)
    np.testing.assert_allclose(support.sum(axis=0), 1.0, rtol=1e-6)  # float32
    np.testing.assert_array_equal(beam_skip_mask(explained, support, 0.5, 0.9), [0, 0, 0, 0, 0, 0, 1])
    # the obstacle's own floor-level pz does not move any particle's support weight
    np.testing.assert_allclose(support[:, 6], beam_support_weights(pz[:, :6], w, floor,
                                                                   BeamCombination.PRODUCT)[:, 0], rtol=1e-6)
    support_amcl = beam_support_weights(pz, w, floor, BeamCombination.AMCL)
    assert np.all(support_amcl[:3, 4].sum() > w[:3].sum())


def test_nav2s_particle_count_skips_the_corrective_beams_the_posterior_keeps() -> None:
    """The wide predicted cloud above through skip_unexplained: ``beam_skip_support: particles`` (nav2_amcl) counts
    7 of 10 particles missing the corrective wall and skips it with the obstacle; the default keeps it."""
    pz = np.full((10, 7), 0.8, dtype=np.float32)
    pz[3:, 4:6] = 0.01
    pz[:, 6] = 0.01
    w, pose = np.full(10, 0.1), np.zeros((10, 3))  # one pose: a converged cloud, so skipping is on
    kept = {rule: skip_unexplained(pz, w, pose, LocalizeConfig(beam_skip_support=rule), 30.0,
                                   BeamCombination.PRODUCT)[1] for rule in ("posterior", "particles")}
    assert kept == {"posterior": 1, "particles": 3}


def _step_with_door_mean(particles_pose: FloatArray, door_deg: float, global_door_term: bool = True,
                         door_std_deg: float = 10.0) -> FloatArray:
    """Poses and weights after one forced RBPF update of the corridor scan at x = 6 m, every particle holding
    each door at ``door_deg`` (std ``door_std_deg``: 10° is an observed door, as a sampled global start's; 30° is
    at the prior, door_prior.unobserved_door_variance)."""
    world, static, doors = corridor()
    field = build_distance_field(rasterize(static, (-1.0, 16.0), (0.0, 2.4), margin=RES * 4), 2.0)
    truth = np.array([6.0, 1.5, 0.0])
    config = LocalizeConfig(max_particles=len(particles_pose), min_particles=len(particles_pose),
                            global_door_term=global_door_term)
    rng = np.random.default_rng(0)
    beams = scan_beams(world, truth, max_range=RANGE, noise_m=0.0, rng=rng)
    r, a = scan_ranges(world, truth, max_range=RANGE)
    hit = np.isfinite(r)
    pts = np.stack([LASER_X + r[hit] * np.cos(a[hit]), r[hit] * np.sin(a[hit])], axis=1)
    n, d = len(particles_pose), len(doors)
    particles = ParticleSet(particles_pose, np.full(n, 1.0 / n), np.full((n, d), math.radians(door_deg)),
                            np.full((n, d), math.radians(door_std_deg) ** 2))
    state, _, _ = rbpf_step(MclState(particles, global_start=True), truth, 0.0, None, beams, pts, field, doors, config,
                            np.random.default_rng(1), force=True)
    return np.column_stack([state.particles.pose, state.particles.weight])  # resampled or not


def test_global_door_term_switch() -> None:
    """With ``global_door_term`` off the weights of a global cloud are the static model's and do not depend on the
    door angles; with it on (eq. (6) over each particle's region), and in a converged cloud either way, they
    do (the leaves at 50° explain beams that a closed-door estimate cannot). A door still at its prior variance is
    weighed and updated under the prior (door_prior.py; in tracking too, ``tracking_door_prior``), so its mean,
    which then says nothing, does not matter."""
    rng = np.random.default_rng(2)
    spread = np.stack([rng.uniform(0.0, 14.0, 400), rng.uniform(0.3, 2.1, 400), rng.uniform(-3.1, 3.1, 400)], axis=1)
    np.testing.assert_array_equal(_step_with_door_mean(spread, 50.0, False), _step_with_door_mean(spread, 0.0, False))
    assert not np.allclose(_step_with_door_mean(spread, 50.0), _step_with_door_mean(spread, 0.0))
    np.testing.assert_array_equal(_step_with_door_mean(spread, 50.0, door_std_deg=30.0),
                                  _step_with_door_mean(spread, 0.0, door_std_deg=30.0))
    tight = np.array([6.0, 1.5, 0.0]) + rng.normal(0.0, [0.03, 0.03, 0.01], (400, 3))
    assert not np.allclose(_step_with_door_mean(tight, 50.0, False), _step_with_door_mean(tight, 0.0, False))
    np.testing.assert_array_equal(_step_with_door_mean(tight, 50.0, False, 30.0),
                                  _step_with_door_mean(tight, 0.0, False, 30.0))


def test_global_start_draws_each_particles_door_angles_from_the_range() -> None:
    _, _, doors = corridor()
    doors = DoorSet(doors.hinge, doors.length, doors.closed_yaw, np.array([0.0, -1.0, 0.0, -1.5]),
                    np.array([1.5, 0.0, 0.5, 0.0]))
    config = LocalizeConfig(door_global_init="sampled")
    mean, var = initial_door_states(doors, 20000, True, config, np.random.default_rng(4))
    assert np.all((mean >= doors.angle_min) & (mean <= doors.angle_max))
    width = doors.angle_max - doors.angle_min
    assert np.all(np.abs(mean.mean(axis=0) - (doors.angle_min + doors.angle_max) / 2) < 0.02 * width)
    np.testing.assert_allclose(mean.std(axis=0), width / math.sqrt(12.0), rtol=0.03)  # uniform over the range
    np.testing.assert_allclose(var, math.radians(config.door_global_init_sigma_deg) ** 2)
    # a tracked start, or door_global_init mid_range: every particle mid-range with the wide prior
    for global_start, cfg in ((False, config), (True, LocalizeConfig(door_global_init="mid_range"))):
        m, v = initial_door_states(doors, 10, global_start, cfg, np.random.default_rng(4))
        np.testing.assert_allclose(m, np.broadcast_to((doors.angle_min + doors.angle_max) / 2, (10, 4)))
        np.testing.assert_allclose(v, math.radians(cfg.door_init_sigma_deg) ** 2)
