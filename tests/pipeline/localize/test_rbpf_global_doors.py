"""The RBPF's door term while the pose is global: the door update's Laplace factor and the beams that condition
a door the polygon has not seen (doorbatch.pipeline.localize.rbpf)."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest
from mcl_sim import LASER_X, RES, polyline, rasterize, scan_beams, scan_ranges

from doorbatch.config import LocalizeConfig
from doorbatch.maps import DoorSet
from doorbatch.pipeline.localize.door_observation import DoorUpdate, gated_prior_variance, kalman_update
from doorbatch.pipeline.localize.door_prior import UNIFORM, DoorPrior, log_evidence, posterior, unobserved_door_variance
from doorbatch.pipeline.localize.likelihood_field import BeamCombination, build_distance_field
from doorbatch.pipeline.localize.particles import ParticleSet
from doorbatch.pipeline.localize.rbpf import (
    condition_doors_on_beams,
    door_update_log_factor,
    global_door_log_likelihood,
)
from doorbatch.pipeline.localize.smoothing import Bandwidth

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
    moved_var = math.radians(config.door_init_sigma_deg) ** 2  # as update_doors: a door 0.3 rad off may be "moved"
    mean, post = kalman_update(mu, var, z, observed, meas_var, config.door_moved_gate_chi2, moved_var)
    prior = ParticleSet(np.zeros((n, 3)), np.full(n, 1.0 / n), mu, var)
    factor = door_update_log_factor(prior, DoorUpdate(mean, post, observed, z), DOORS, config)
    used = gated_prior_variance(mu, var, z, observed, meas_var, config.door_moved_gate_chi2, moved_var)
    assert np.any(used > var) and np.any(observed & (used == var))  # both kinds of door occur
    want = np.where(observed, _log_normal(z, mu, used + meas_var) - _log_normal(z, mean, np.full_like(z, meas_var)),
                    0.0).sum(axis=1)
    np.testing.assert_allclose(factor, want, rtol=1e-9, atol=1e-9)


def _mixture_evidence_by_quadrature(z: float, meas_var: float, prior: DoorPrior, lo: float, hi: float) -> float:
    """∫ N(z; a, R)·p(a) da over the closed/open mixture, on a fine grid."""
    a = np.linspace(lo - 1.0, hi + 1.0, 200001)
    closed = np.exp(-0.5 * a**2 / max(prior.closed_var, 1e-12)) / math.sqrt(2 * math.pi * max(prior.closed_var, 1e-12))
    density = prior.closed_prob * closed + (1 - prior.closed_prob) * ((a >= lo) & (a <= hi)) / (hi - lo)
    lik = np.exp(-0.5 * (z - a) ** 2 / meas_var) / math.sqrt(2 * math.pi * meas_var)
    return float(np.sum(density * lik) * (a[1] - a[0]))


def test_door_update_factor_of_a_door_at_its_prior_is_the_mixture_evidence() -> None:
    """A door still at its prior (closed with p_c, else uniform over [0, 90°]) measured at z ~ N(a, R): the
    factor plus the measurement's likelihood at the posterior mean must be the exact evidence of z under the
    mixture, whether z says closed, ajar, open or a little outside the range; with p_c = 0 the uniform's."""
    config = LocalizeConfig(global_door_closed_prob=0.5, global_door_closed_sigma_deg=2.0)
    prior = DoorPrior.from_config(config)
    meas_var = math.radians(config.door_angle_sigma_deg) ** 2
    z = np.radians([[0.0, 2.0, -4.0], [8.0, 45.0, 95.0]])
    observed = np.array([[True, True, True], [True, True, False]])
    flat = ParticleSet(np.zeros((2, 3)), np.full(2, 0.5), np.full((2, 3), math.pi / 4),
                       np.full((2, 3), unobserved_door_variance(DOORS, config)))
    for p in (prior, UNIFORM):
        cfg = config.model_copy(update={"global_door_closed_prob": p.closed_prob})
        mean, var = posterior(z, meas_var, 0.0, math.pi / 2, p)
        factor = door_update_log_factor(flat, DoorUpdate(mean, var, observed, z), DOORS, cfg)
        at_post = np.where(observed, _log_normal(z, mean, np.full_like(z, meas_var)), 0.0).sum(axis=1)
        want = [sum(math.log(_mixture_evidence_by_quadrature(float(zz), meas_var, p, 0.0, math.pi / 2))
                    for zz, o in zip(row, obs, strict=True) if o) for row, obs in zip(z, observed, strict=True)]
        np.testing.assert_allclose(factor + at_post, want, rtol=1e-4)
    # observing a door closed costs about log 2 under the mixture (−0.83 nats), ~2 nats more under the uniform
    only_closed = np.array([[True, False, False]] * 2)
    cost = [door_update_log_factor(flat, DoorUpdate(*posterior(z, meas_var, 0.0, math.pi / 2, p), only_closed, z),
                                   DOORS, config.model_copy(update={"global_door_closed_prob": p.closed_prob}))[0]
            for p in (prior, UNIFORM)]
    assert -1.0 < cost[0] < -0.5 and cost[1] < cost[0] - 1.5


def test_mixture_posterior_picks_the_component_by_its_evidence() -> None:
    """Moment-matched posterior of the mixture against quadrature: a closed measurement lands near 0 with about
    the closed component's narrowed variance, an open one at the measurement with about R."""
    prior = DoorPrior(0.5, math.radians(2.0) ** 2)
    meas_var = math.radians(3.0) ** 2
    a = np.linspace(-1.0, 2.6, 360001)
    for z in np.radians([-3.0, 0.0, 1.0, 6.0, 12.0, 45.0, 88.0]):
        closed = np.exp(-0.5 * a**2 / prior.closed_var) / math.sqrt(2 * math.pi * prior.closed_var)
        density = (prior.closed_prob * closed + (1 - prior.closed_prob) * ((a >= 0) & (a <= math.pi / 2))
                   / (math.pi / 2)) * np.exp(-0.5 * (z - a) ** 2 / meas_var)
        m = float(np.sum(a * density) / np.sum(density))
        v = float(np.sum((a - m) ** 2 * density) / np.sum(density))
        mean, var = posterior(z, meas_var, 0.0, math.pi / 2, prior)
        assert abs(float(mean) - m) < 1e-4 and float(var) == pytest.approx(v, rel=1e-3)
        np.testing.assert_allclose(float(log_evidence(z, meas_var, 0.0, math.pi / 2, prior)),
                                   math.log(_mixture_evidence_by_quadrature(float(z), meas_var, prior, 0.0,
                                                                            math.pi / 2)), atol=1e-4)
    mean, var = posterior(0.0, meas_var, 0.0, math.pi / 2, prior)
    assert abs(float(mean)) < math.radians(0.5) and float(var) < meas_var


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
    new_mean, new_var = condition_doors_on_beams(particles, beams, field, DOORS, config, DoorPrior.from_config(config),
                                                 skip=skip)
    assert np.all(np.abs(new_mean[:3, :2]) < math.radians(5.0))
    assert np.all(new_var[:3, :2] < thr[:2])
    np.testing.assert_array_equal(new_mean[:, 2], mean[:, 2])
    # tracking (no prior: each door's own Gaussian) puts the closed leaves near closed as well
    own_mean, own_var = condition_doors_on_beams(particles, beams, field, DOORS, config, skip=skip)
    assert np.all(np.abs(own_mean[:3, :2]) < math.radians(5.0))
    assert np.all(own_var[:3, :2] < thr[:2])
    np.testing.assert_array_equal(new_var[:, 2], var[:, 2])
    assert new_mean[3, 1] == mean[3, 1] and new_var[3, 1] == var[3, 1]


def test_observing_a_door_with_a_range_narrower_than_the_measurement_earns_nothing() -> None:
    """A never-moved door (range 0.1°) is as certain before the observation as after: the factor is never the
    density 1/Δ ≈ 570 per rad that would reward every particle that sees it (the built map has such doors). The
    mixture's exact evidence is at most the likelihood at the posterior mean: no reward for any measurement,
    almost no cost (−0.09 nats: the closed component's σ_c) for one at the door's angle."""
    config = LocalizeConfig()
    narrow = DoorSet(np.array([[0.0, 0.0]]), np.array([0.9]), np.zeros(1), np.zeros(1), np.radians([0.1]))
    prior = ParticleSet(np.zeros((2, 3)), np.full(2, 0.5), np.zeros((2, 1)), np.full((2, 1), 0.27))
    meas_var = math.radians(config.door_angle_sigma_deg) ** 2
    for z in np.radians([-8.0, -2.0, 0.0, 0.05, 3.0, 9.0]):
        mean, var = posterior(np.full((2, 1), z), meas_var, 0.0, math.radians(0.1), DoorPrior.from_config(config))
        update = DoorUpdate(mean, var, np.array([[True], [False]]), np.full((2, 1), z))
        factor = door_update_log_factor(prior, update, narrow, config)
        assert factor[1] == 0.0 and factor[0] <= 0.0
        if abs(z) < math.radians(0.1):
            assert factor[0] > -0.2


def test_a_pose_that_sees_closed_doors_pays_about_the_closed_prior_not_the_uniform_price() -> None:
    """A 31 m corridor with doorways at x = 3, 6, 9 on the wall y = 0, all leaves closed (flush with the wall);
    the static map has the doorways open. From (6.4, 1.2) the 4 m laser sees the three closed leaves; from
    (20.4, 1.2) it sees plain walls, and the same scan fits both poses perfectly. Weighed as the global RBPF
    weighs a particle (door update under the prior, beams under the result, evidence factor), the pose among
    the doors must pay at most −log p_c per closed door with the closed/open mixture, and clearly more with the
    uniform prior (the loc5 diagnosis: ~2.3 nats per door observed closed, so that in an all-closed corridor
    the poses that see fewer doorways win)."""
    walls = np.concatenate([polyline((-1.0, 0.0), (3.0, 0.0)), polyline((3.8, 0.0), (6.0, 0.0)),
                            polyline((6.8, 0.0), (9.0, 0.0)), polyline((9.8, 0.0), (30.0, 0.0)),
                            polyline((-1.0, 2.4), (30.0, 2.4))])
    leaves = np.array([[[x, 0.0], [x + LEAF, 0.0]] for x in HINGES_X])
    world = np.concatenate([walls, leaves])
    field = build_distance_field(rasterize(walls, (-1.0, 30.0), (0.0, 2.4), margin=RES * 4), 2.0)
    among_doors, plain = np.array([6.4, 1.2, 0.0]), np.array([20.4, 1.2, 0.0])
    beams = scan_beams(world, among_doors, max_beams=60, max_range=4.0)
    r, a = scan_ranges(world, among_doors, max_range=4.0)
    hit = np.isfinite(r)
    points = np.stack([LASER_X + r[hit] * np.cos(a[hit]), r[hit] * np.sin(a[hit])], axis=1)
    cost = {}
    for closed_prob in (0.5, 0.0):
        config = LocalizeConfig(global_door_term=True, global_door_closed_prob=closed_prob)
        prior = ParticleSet(np.stack([among_doors, plain]), np.full(2, 0.5), np.full((2, 3), math.pi / 4),
                            np.tile(unobserved_door_variance(DOORS, config), (2, 1)))
        region = Bandwidth(np.full(2, 0.02), np.full(2, math.radians(0.5)))
        loglik = global_door_log_likelihood(prior, region, beams, points, field, DOORS, config,
                                            BeamCombination.PRODUCT)
        cost[closed_prob] = loglik[1] - loglik[0]
    assert 0.0 < cost[0.5] < len(HINGES_X) * math.log(2.0)
    assert cost[0.0] > cost[0.5] + 2.0
