"""Doors a tracked RBPF has not observed yet (``tracking_door_prior``): a corridor whose static map has a
doorway gap at every door, all leaves closed and flush with the wall, as in the sample's closed log."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from mcl_sim import LASER_X, RES, polyline, rasterize, scan_beams, scan_ranges

from doorbatch.config import LocalizeConfig
from doorbatch.maps import DoorSet
from doorbatch.pipeline.localize.door_likelihood import door_log_likelihood_at_poses
from doorbatch.pipeline.localize.door_prior import unobserved_door_variance
from doorbatch.pipeline.localize.likelihood_field import build_distance_field, endpoint_distances
from doorbatch.pipeline.localize.mcl import MclState
from doorbatch.pipeline.localize.particles import ParticleSet
from doorbatch.pipeline.localize.rbpf import condition_doors_on_beams, observed_share, rbpf_step

FloatArray = npt.NDArray[np.float64]
HINGES_X = (3.0, 6.0, 9.0, 12.0)
LEAF = 0.8
RANGE = 12.0


def flush_corridor() -> tuple[FloatArray, FloatArray, DoorSet]:
    """World segments (walls + closed leaves), static segments (walls with a gap per doorway), doors opening
    out of the corridor (range −90°…0°, closed along +x from the hinge)."""
    ends = [-1.0, *(v for h in HINGES_X for v in (h, h + LEAF)), 16.0]
    south = [polyline((a, 0.0), (b, 0.0)) for a, b in zip(ends[::2], ends[1::2], strict=True)]
    static = np.concatenate([polyline((-1.0, 2.4), (16.0, 2.4)), polyline((-1.0, 0.0), (-1.0, 2.4)), *south])
    leaves = np.array([[[h, 0.0], [h + LEAF, 0.0]] for h in HINGES_X])
    d = len(HINGES_X)
    doors = DoorSet(np.array([[h, 0.0] for h in HINGES_X]), np.full(d, LEAF), np.zeros(d),
                    np.full(d, -math.radians(90.0)), np.zeros(d))
    return np.concatenate([static, leaves]), static, doors


def _tracked_step(tracking_door_prior: bool) -> tuple[npt.NDArray[np.bool_], FloatArray, FloatArray]:
    """One tracked update at x = 1 m, every door mid-range (−45°) with the start's 30° std: which doors the
    polygon observed, and the weighted door means and stds (degrees) after it."""
    world, static, doors = flush_corridor()
    field = build_distance_field(rasterize(static, (-1.0, 16.0), (0.0, 2.4), margin=RES * 4), 2.0)
    truth = np.array([1.0, 1.2, 0.0])
    rng = np.random.default_rng(0)
    n, d = 300, len(doors)
    config = LocalizeConfig(max_particles=n, min_particles=n, tracking_door_prior=tracking_door_prior)
    particles = ParticleSet(truth + rng.normal(0.0, [0.02, 0.02, 0.005], (n, 3)), np.full(n, 1.0 / n),
                            np.full((n, d), -math.radians(45.0)),
                            np.full((n, d), math.radians(config.door_init_sigma_deg) ** 2))
    beams = scan_beams(world, truth, max_range=RANGE, rng=rng)
    r, a = scan_ranges(world, truth, max_range=RANGE)
    hit = np.isfinite(r)
    pts = np.stack([LASER_X + r[hit] * np.cos(a[hit]), r[hit] * np.sin(a[hit])], axis=1)
    state, _, observed = rbpf_step(MclState(particles), truth, 0.0, None, beams, pts, field, doors, config,
                                   np.random.default_rng(1), force=True)
    p = state.particles
    mean = np.degrees(np.average(p.door_mean, axis=0, weights=p.weight))
    std = np.degrees(np.sqrt(np.average(p.door_var, axis=0, weights=p.weight)))
    return observed, mean, std


def test_tracking_conditions_a_door_the_polygon_missed_on_the_beams_its_leaf_explains() -> None:
    """The leaf at 6 m is 5 m down the corridor: the Douglas–Peucker update does not associate it, but beams
    end on it. With ``tracking_door_prior`` those beams put it near closed; linearized (the paper's letter) it
    stays at its mid-range prior, so the next scans pay the same wrong leaf again (the closed log's drift)."""
    observed, mean, std = _tracked_step(True)
    assert observed[0] and not observed[1]
    assert abs(mean[0]) < 3.0  # the polygon's own door, either way
    assert abs(mean[1]) < 15.0 and std[1] < 20.0
    _, mean_off, std_off = _tracked_step(False)
    assert abs(mean_off[1] + 45.0) < 1e-6 and abs(std_off[1] - 30.0) < 1e-6


def test_end_points_outside_the_sector_a_leaf_can_sweep_do_not_move_its_door() -> None:
    """A door at (3, 0) (closed along +x, range 0…90° into y > 0, observed: 45° ± 5°) in a doorway the static map
    leaves open up to x = 3.8 m, and clutter the map lacks just behind the hinge (x 2.5–2.9 m, on the wall's
    line): the door's leaf is the nearest model to those end points, but they lie 180° from the closed
    direction, beyond the range and its margin, so they cannot be on the leaf. Combined into the door's angle
    they would drag it towards 180° (found on a simulated log: a door open 100° estimated at −170°)."""
    static = np.concatenate([polyline((3.8, 0.0), (8.0, 0.0)), polyline((-1.0, 2.4), (8.0, 2.4))])
    clutter = polyline((2.5, 0.0), (2.9, 0.0))
    doors = DoorSet(np.array([[3.0, 0.0]]), np.array([LEAF]), np.zeros(1), np.zeros(1), np.array([math.pi / 2]))
    field = build_distance_field(rasterize(static, (-1.0, 8.0), (0.0, 2.4), margin=RES * 4), 2.0)
    truth = np.array([2.7, 0.6, -math.pi / 2])  # facing the clutter from 0.6 m
    beams = scan_beams(np.concatenate([static, clutter]), truth, max_beams=180, max_range=1.5,
                       rng=np.random.default_rng(0))
    config = LocalizeConfig()
    n = 4
    particles = ParticleSet(np.tile(truth, (n, 1)), np.full(n, 1.0 / n), np.full((n, 1), math.radians(45.0)),
                            np.full((n, 1), math.radians(5.0) ** 2))
    dl = door_log_likelihood_at_poses(endpoint_distances(field, particles.pose, beams.points_base), particles.pose,
                                      beams.points_base, doors, particles.door_mean, particles.door_var, config,
                                      beams.range_max_m, unobserved_var=unobserved_door_variance(doors, config))
    assert (dl.association[0] == 0).sum() >= 3  # the clutter's end points are the door's best explanation
    mean, var = condition_doors_on_beams(particles, beams, field, doors, config)
    np.testing.assert_array_equal(mean, particles.door_mean)
    np.testing.assert_array_equal(var, particles.door_var)


def test_a_doors_observed_share_is_the_weight_of_the_particles_that_measured_it() -> None:
    weight = np.array([0.5, 0.3, 0.2])
    observed = np.array([[True, False], [False, False], [True, True]])
    assert np.allclose(observed_share(weight, observed), [0.7, 0.2])
    assert np.allclose(observed_share(2 * weight, observed), [0.7, 0.2])  # weights need not be normalized
    assert np.array_equal(observed_share(np.zeros(3), observed), [0.0, 0.0])  # no weight: nothing measured
    every = np.random.default_rng(3).dirichlet(np.ones(2000))
    assert observed_share(every, np.ones((2000, 1), dtype=bool))[0] <= 1.0  # a share, never above all of it
