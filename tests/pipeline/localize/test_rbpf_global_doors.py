"""The RBPF's door term while the pose is global: the door update's Laplace factor and the beams that condition
a door the polygon has not seen (doorbatch.pipeline.localize.rbpf)."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from mcl_sim import RES, polyline, rasterize, scan_beams

from doorbatch.config import LocalizeConfig
from doorbatch.maps import DoorSet
from doorbatch.pipeline.localize.door_observation import DoorUpdate, kalman_update
from doorbatch.pipeline.localize.likelihood_field import build_distance_field
from doorbatch.pipeline.localize.particles import ParticleSet
from doorbatch.pipeline.localize.rbpf import (
    condition_doors_on_beams,
    door_update_log_factor,
    unobserved_door_variance,
)

FloatArray = npt.NDArray[np.float64]
HINGES_X = (3.0, 6.0, 9.0)
LEAF = 0.8
DOORS = DoorSet(np.array([[x, 0.0] for x in HINGES_X]), np.full(3, LEAF), np.zeros(3), np.zeros(3),
                np.full(3, math.pi / 2))


def _log_normal(x: FloatArray, mean: FloatArray, var: FloatArray) -> FloatArray:
    return np.asarray(-0.5 * (x - mean) ** 2 / var - 0.5 * np.log(2 * math.pi * var), dtype=np.float64)


def test_door_update_factor_gives_the_marginal_likelihood_of_a_linear_gaussian_door() -> None:
    """For a Gaussian prior N(μ, P) and an angle measurement z ~ N(a, R) the marginal is N(z; μ, P + R): the
    factor plus the measurement's likelihood at the posterior mean must equal it (Laplace is exact here)."""
    config = LocalizeConfig()
    rng = np.random.default_rng(0)
    n = 200
    mu = rng.uniform(0.2, 1.2, (n, 3))
    var = rng.uniform(0.001, 0.03, (n, 3))  # below the uniform's (π/2)²/12 = 0.21: Gaussian priors
    z = mu + rng.normal(0.0, 0.3, (n, 3))
    observed = rng.random((n, 3)) < 0.6
    meas_var = math.radians(config.door_angle_sigma_deg) ** 2
    mean, post = kalman_update(mu, var, z, observed, meas_var)
    prior = ParticleSet(np.zeros((n, 3)), np.full(n, 1.0 / n), mu, var)
    factor = door_update_log_factor(prior, DoorUpdate(mean, post, observed), DOORS, config)
    want = np.where(observed, _log_normal(z, mu, var + meas_var) - _log_normal(z, mean, np.full_like(z, meas_var)),
                    0.0).sum(axis=1)
    np.testing.assert_allclose(factor, want, rtol=1e-9, atol=1e-9)
    # a door still at its prior is uniform over its range: the same identity with density 1/Δ
    flat = ParticleSet(np.zeros((n, 3)), np.full(n, 1.0 / n), np.full((n, 3), math.pi / 4),
                       np.full((n, 3), unobserved_door_variance(DOORS, config)))
    z_in = rng.uniform(0.3, 1.2, (n, 3))
    factor = door_update_log_factor(flat, DoorUpdate(z_in, np.full_like(z_in, meas_var), observed), DOORS, config)
    at_post = np.where(observed, _log_normal(z_in, z_in, np.full_like(z_in, meas_var)), 0.0).sum(axis=1)
    np.testing.assert_allclose(factor + at_post, -np.log(math.pi / 2) * observed.sum(axis=1), rtol=1e-9)


def test_beams_on_a_closed_leaf_condition_the_unobserved_door_to_closed() -> None:
    """A wall y = 0 with doorways [x, x + 0.8] whose leaves are closed; the robot at (4.5, 1.2) sees the leaves of
    doors 0 and 1 with a 4 m laser, not door 2 (5.3 m away). Every particle starts each door mid-range with the
    prior's variance: doors 0 and 1 must come out closed (the beams put the angle at ~0) and certain enough to
    leave the uniform model; door 2 (no beam reaches it) and a door the polygon observed in this scan (``skip``)
    are left as they were."""
    config = LocalizeConfig()
    gaps = [(x, x + LEAF) for x in HINGES_X]
    wall = [(-1.0, 3.0), (3.8, 6.0), (6.8, 9.0), (9.8, 12.0)]
    assert [b for _, b in wall[:-1]] == [a for a, _ in gaps]
    walls = np.concatenate([polyline((a, 0.0), (b, 0.0)) for a, b in wall]
                           + [polyline((-1.0, 2.4), (12.0, 2.4)), polyline((-1.0, 0.0), (-1.0, 2.4))])
    leaves = np.array([[[a, 0.0], [b, 0.0]] for a, b in gaps])
    field = build_distance_field(rasterize(walls, (-1.0, 12.0), (0.0, 2.4), margin=RES * 4), 2.0)
    truth = np.array([4.5, 1.2, 0.0])
    beams = scan_beams(np.concatenate([walls, leaves]), truth, max_beams=180, max_range=4.0, noise_m=0.0,
                       rng=np.random.default_rng(0))
    n = 4
    thr = unobserved_door_variance(DOORS, config)
    mean = np.full((n, 3), math.pi / 4)
    var = np.full((n, 3), math.radians(config.door_init_sigma_deg) ** 2)
    skip = np.zeros((n, 3), dtype=bool)
    skip[3, 1] = True  # particle 3's polygon update observed door 1 in this scan
    particles = ParticleSet(np.tile(truth, (n, 1)), np.full(n, 1.0 / n), mean, var)
    new_mean, new_var = condition_doors_on_beams(particles, beams, field, DOORS, config, skip=skip)
    assert np.all(np.abs(new_mean[:3, :2]) < math.radians(5.0))
    assert np.all(new_var[:3, :2] < thr[:2])
    np.testing.assert_array_equal(new_mean[:, 2], mean[:, 2])
    np.testing.assert_array_equal(new_var[:, 2], var[:, 2])
    assert new_mean[3, 1] == mean[3, 1] and new_var[3, 1] == var[3, 1]


def test_observing_a_door_with_a_range_narrower_than_the_measurement_earns_nothing() -> None:
    """A never-moved door (range 0.1°) is as certain before the observation as after: the factor is 0, never the
    density 1/Δ ≈ 570 per rad that would reward every particle that sees it (the built map has such doors)."""
    config = LocalizeConfig()
    narrow = DoorSet(np.array([[0.0, 0.0]]), np.array([0.9]), np.zeros(1), np.zeros(1), np.radians([0.1]))
    prior = ParticleSet(np.zeros((2, 3)), np.full(2, 0.5), np.zeros((2, 1)), np.full((2, 1), 0.27))
    meas_var = math.radians(config.door_angle_sigma_deg) ** 2
    update = DoorUpdate(np.zeros((2, 1)), np.full((2, 1), meas_var), np.array([[True], [False]]))
    np.testing.assert_array_equal(door_update_log_factor(prior, update, narrow, config), [0.0, 0.0])
