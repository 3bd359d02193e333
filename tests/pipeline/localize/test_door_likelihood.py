"""Eq. (6) of paper 000: door-aware beam likelihood with maximum-likelihood association (static map or a door)."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest

from doorbatch.config import LocalizeConfig
from doorbatch.maps import DoorSet
from doorbatch.pipeline.localize.door_likelihood import (
    door_log_likelihood,
    door_log_likelihood_at_poses,
    numba_available,
)
from doorbatch.pipeline.localize.door_prior import UNIFORM, DoorPrior
from doorbatch.pipeline.localize.likelihood_field import endpoint_points

FloatArray = npt.NDArray[np.float64]
CONFIG = LocalizeConfig(z_hit=0.95, z_rand=0.05)  # a sharp mixture: the ranking margins below are in nats
RANGE_MAX = 10.0
RAND = CONFIG.z_rand / RANGE_MAX
SIGMA = CONFIG.sigma_hit
BACKENDS = ["numpy", pytest.param("numba", marks=pytest.mark.skipif(not numba_available(), reason="no numba"))]

# A wall along y = 0 with a doorway x ∈ [0, 0.9]; the door hinges at (0, 0), closed along +x, opens CCW.
WALLS = np.array([[[-5.0, 0.0], [0.0, 0.0]], [[0.9, 0.0], [5.0, 0.0]]])
DOOR = DoorSet(hinge=np.array([[0.0, 0.0]]), length=np.array([0.9]), closed_yaw=np.array([0.0]),
               angle_min=np.array([0.0]), angle_max=np.array([math.pi / 2]))


def wall_distance(points: FloatArray) -> FloatArray:
    """What the static likelihood field holds: distance to the walls (hinge included), capped."""
    p = points[..., None, :]
    a, e = WALLS[:, 0], WALLS[:, 1] - WALLS[:, 0]
    t = np.clip(np.sum((p - a) * e, axis=-1) / np.sum(e * e, axis=-1), 0.0, 1.0)
    d = np.hypot(*np.moveaxis(p - a - t[..., None] * e, -1, 0)).min(axis=-1)
    return np.asarray(np.minimum(d, CONFIG.laser_likelihood_max_dist), dtype=np.float64)


def static_pz(d: npt.ArrayLike) -> FloatArray:
    return np.asarray(CONFIG.z_hit * np.exp(-np.square(d) / (2 * SIGMA**2)) + RAND, dtype=np.float64)


def door_pz(d: float, jac2: float, var: float) -> float:
    sig2 = SIGMA**2 + jac2 * var
    return CONFIG.z_hit * math.sqrt(SIGMA**2 / sig2) * math.exp(-d * d / (2 * sig2)) + RAND


@pytest.mark.parametrize("backend", BACKENDS)
def test_leaf_beam_goes_to_the_door_and_prefers_the_right_angle_wall_beam_stays_static(backend: str) -> None:
    a60 = math.radians(60.0)
    leaf_hit = 0.5 * np.array([math.cos(a60), math.sin(a60)])
    beams = np.array([leaf_hit, [-1.0, 0.01], [2.0, -0.02]])
    pts = np.broadcast_to(beams, (3, 3, 2))
    mean = np.radians([[60.0], [30.0], [0.0]])  # right angle, wrong angle, closed
    var = np.full((3, 1), 1e-4)
    res = door_log_likelihood(wall_distance(pts), pts, DOOR, mean, var, CONFIG, RANGE_MAX, backend=backend)
    np.testing.assert_array_equal(res.association[:, 1:], -1)  # the wall beams are static for everyone
    assert res.association[0, 0] == 0 and res.association[1, 0] == 0
    assert res.log_likelihood[0] > res.log_likelihood[1] + 3.0 > res.log_likelihood[2] + 3.0
    # The right angle explains the leaf beam perfectly (d = 0, J² = t² on the leaf).
    assert res.beam_likelihood[0, 0] == pytest.approx(door_pz(0.0, 0.25, 1e-4), rel=1e-6)
    total = math.log(door_pz(0.0, 0.25, 1e-4)) + np.sum(np.log(static_pz(wall_distance(beams[1:]))))
    assert res.log_likelihood[0] == pytest.approx(total, rel=1e-6)


@pytest.mark.parametrize("backend", BACKENDS)
def test_hinge_beam_is_counted_once_by_the_likelier_model(backend: str) -> None:
    # Exactly at the hinge: static d = 0 and door d = 0 with J = 0 tie; the static map takes it, once.
    # Just off the hinge along the open leaf: the door is closer than the wall's end and wins, once.
    near = np.array([0.05, 0.03])
    pts = np.array([[[0.0, 0.0], near]])
    mean, var = np.radians([[60.0]]), np.full((1, 1), 1e-4)
    res = door_log_likelihood(wall_distance(pts), pts, DOOR, mean, var, CONFIG, RANGE_MAX, backend=backend)
    np.testing.assert_array_equal(res.association, [[-1, 0]])
    assert res.beam_likelihood[0, 0] == pytest.approx(CONFIG.z_hit + RAND, rel=1e-6)  # not squared, not doubled
    u = np.array([math.cos(mean[0, 0]), math.sin(mean[0, 0])])
    t, s = float(near @ u), float(u[0] * near[1] - u[1] * near[0])
    expected = door_pz(abs(s), t * t, 1e-4)
    assert expected > static_pz(np.hypot(*near))
    assert res.beam_likelihood[0, 1] == pytest.approx(expected, rel=1e-6)
    assert res.log_likelihood[0] == pytest.approx(math.log(CONFIG.z_hit + RAND) + math.log(expected), rel=1e-6)


@pytest.mark.parametrize("backend", BACKENDS)
def test_marginalized_likelihood_follows_the_propagated_variance(backend: str) -> None:
    # Leaf at the mean angle 0 along +x; beams 0.5 m from the hinge, on the leaf and 0.3 m off it.
    # σ² = σ_hit² + t²·var with t = 0.5: on the leaf the likelihood falls with var; 0.3 m off it rises until
    # σ = 0.3 m (the door may well be where the beam says), then falls.
    variances = np.linspace(0.0, 1.0, 201)
    n = variances.size
    for offset in (0.0, 0.3):
        pts = np.broadcast_to(np.array([[0.5, offset]]), (n, 1, 2))
        static = np.full((n, 1), CONFIG.laser_likelihood_max_dist)
        res = door_log_likelihood(static, pts, DOOR, np.zeros((n, 1)), variances[:, None], CONFIG, RANGE_MAX,
                                  backend=backend)
        assert np.all(res.association == 0)
        expected = np.array([door_pz(offset, 0.25, v) for v in variances])
        np.testing.assert_allclose(res.beam_likelihood[:, 0], expected, rtol=1e-5)
        steps = np.diff(res.log_likelihood)
        if offset == 0.0:
            assert np.all(steps < 0)
        else:
            peak = (offset**2 - SIGMA**2) / 0.25  # σ_hit² + t²·var = offset²
            assert np.all(steps[variances[1:] < peak - 0.01] > 0)
            assert np.all(steps[variances[:-1] > peak + 0.01] < 0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_without_doors_it_is_the_static_endpoint_model(backend: str) -> None:
    rng = np.random.default_rng(1)
    dist = rng.uniform(0.0, 2.0, (50, 30)).astype(np.float32)
    pts = rng.uniform(-3, 3, (50, 30, 2))
    no_doors = DoorSet.empty()
    res = door_log_likelihood(dist, pts, no_doors, np.zeros((50, 0)), np.zeros((50, 0)), CONFIG, RANGE_MAX,
                              backend=backend)
    np.testing.assert_allclose(res.log_likelihood, np.log(static_pz(dist.astype(np.float64))).sum(axis=1),
                               rtol=1e-5)
    assert np.all(res.association == -1)


@pytest.mark.parametrize("backend", BACKENDS)
def test_non_finite_beams_are_skipped(backend: str) -> None:
    rng = np.random.default_rng(2)
    pts = rng.uniform(-1, 1, (4, 10, 2))
    dist = wall_distance(pts)
    mean, var = np.full((4, 1), 0.5), np.full((4, 1), 0.05)
    full = door_log_likelihood(dist[:, :8], pts[:, :8], DOOR, mean, var, CONFIG, RANGE_MAX, backend=backend)
    pts[:, 8] = np.nan
    dist[:, 9] = np.nan
    res = door_log_likelihood(dist, pts, DOOR, mean, var, CONFIG, RANGE_MAX, backend=backend)
    np.testing.assert_allclose(res.log_likelihood, full.log_likelihood, rtol=1e-9)
    assert np.all(res.association[:, 8:] == -1) and np.all(np.isnan(res.beam_likelihood[:, 8:]))


def random_case(rng: np.random.Generator, n: int, b: int, d: int
                ) -> tuple[FloatArray, FloatArray, DoorSet, FloatArray, FloatArray]:
    """Doors and end points in a 6 m square: many beams near leaves, wide door variances."""
    doors = DoorSet(hinge=rng.uniform(-3, 3, (d, 2)), length=rng.uniform(0.6, 1.1, d),
                    closed_yaw=rng.uniform(-math.pi, math.pi, d), angle_min=np.zeros(d), angle_max=np.full(d, 1.6))
    pts = rng.uniform(-3.5, 3.5, (n, b, 2))
    static = rng.uniform(0.0, 2.0, (n, b))
    mean = rng.uniform(-0.2, 1.8, (n, d))
    var = rng.uniform(0.0, 0.5, (n, d)) ** 2
    return static, pts, doors, mean, var


@pytest.mark.skipif(not numba_available(), reason="no numba")
def test_numba_kernel_agrees_with_the_numpy_reference() -> None:
    static, pts, doors, mean, var = random_case(np.random.default_rng(4), 500, 60, 10)
    pts[0, :5] = np.nan
    ref = door_log_likelihood(static, pts, doors, mean, var, CONFIG, RANGE_MAX, backend="numpy")
    fast = door_log_likelihood(static, pts, doors, mean, var, CONFIG, RANGE_MAX, backend="numba")
    assert np.mean(ref.association >= 0) > 0.3  # the case exercises the doors
    assert np.mean(fast.association == ref.association) > 0.9999
    np.testing.assert_allclose(fast.log_likelihood, ref.log_likelihood, rtol=1e-5, atol=1e-4)


def test_vectorized_over_particles_matches_a_per_particle_loop() -> None:
    static, pts, doors, mean, var = random_case(np.random.default_rng(5), 1000, 60, 10)
    res = door_log_likelihood(static, pts, doors, mean, var, CONFIG, RANGE_MAX)
    for i in range(1000):
        one = door_log_likelihood(static[i:i + 1], pts[i:i + 1], doors, mean[i:i + 1], var[i:i + 1], CONFIG,
                                  RANGE_MAX)
        np.testing.assert_array_equal(one.association[0], res.association[i])
        assert one.log_likelihood[0] == res.log_likelihood[i]


def test_bad_shapes_and_range_are_errors() -> None:
    pts = np.zeros((2, 3, 2))
    with pytest.raises(ValueError, match="points"):
        door_log_likelihood(np.zeros((2, 4)), pts, DOOR, np.zeros((2, 1)), np.zeros((2, 1)), CONFIG, RANGE_MAX)
    with pytest.raises(ValueError, match="door_mean"):
        door_log_likelihood(np.zeros((2, 3)), pts, DOOR, np.zeros((2, 2)), np.zeros((2, 2)), CONFIG, RANGE_MAX)
    with pytest.raises(ValueError, match="range_max"):
        door_log_likelihood(np.zeros((2, 3)), pts, DOOR, np.zeros((2, 1)), np.zeros((2, 1)), CONFIG, 0.0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_at_poses_equals_the_end_point_form(backend: str) -> None:
    rng = np.random.default_rng(6)
    static, _, doors, mean, var = random_case(rng, 300, 40, 8)
    pose = np.column_stack([rng.uniform(-1, 1, (300, 2)), rng.uniform(-math.pi, math.pi, 300)])
    base = rng.uniform(-3, 3, (40, 2))
    base[3] = np.nan
    c, s = np.cos(pose[:, 2, None]), np.sin(pose[:, 2, None])
    pts = np.stack([pose[:, 0, None] + c * base[:, 0] - s * base[:, 1],
                    pose[:, 1, None] + s * base[:, 0] + c * base[:, 1]], axis=-1)
    ref = door_log_likelihood(static, pts, doors, mean, var, CONFIG, RANGE_MAX, backend=backend)
    res = door_log_likelihood_at_poses(static, pose, base, doors, mean, var, CONFIG, RANGE_MAX, backend=backend)
    assert np.mean(ref.association >= 0) > 0.2
    np.testing.assert_array_equal(res.association, ref.association)
    np.testing.assert_allclose(res.log_likelihood, ref.log_likelihood, rtol=1e-9)
    with pytest.raises(ValueError, match="static_dist"):
        door_log_likelihood_at_poses(static[:, :5], pose, base, doors, mean, var, CONFIG, RANGE_MAX)


def _uniform_prior_pz(point: FloatArray, n_angles: int = 20001) -> float:
    """Quadrature of the endpoint model averaged over the door angle, uniform over DOOR's range."""
    a = np.linspace(float(DOOR.angle_min[0]), float(DOOR.angle_max[0]), n_angles)
    tip = DOOR.length[0] * np.stack([np.cos(a), np.sin(a)], axis=1)
    t = np.clip(tip @ point / DOOR.length[0] ** 2, 0.0, 1.0)
    d = np.hypot(*(point - t[:, None] * tip).T)
    return float(CONFIG.z_hit * np.exp(-d**2 / (2 * SIGMA**2)).mean() + RAND)


@pytest.mark.parametrize("backend", BACKENDS)
def test_unobserved_door_is_weighed_under_its_uniform_prior_not_linearized_at_its_mean(backend: str) -> None:
    # End points on the closed leaf (the range's edge), inside the swept quarter disc, and just beyond the tip;
    # the particle's door mean is mid-range (45°) with the uniform's variance: eq. (6) around 45° would put the
    # closed leaf's beams 4-5 σ away, the uniform prior gives each the fraction of the range that explains it.
    points = np.array([[0.5, 0.0], [0.4 * math.cos(1.0), 0.4 * math.sin(1.0)], [0.0, 1.0]])
    pts = points[None]
    mean = np.array([[math.pi / 4]])
    var = np.array([[(math.pi / 2) ** 2 / 12]])
    dist = wall_distance(pts)
    res = door_log_likelihood_at_poses(dist, np.zeros((1, 3)), points, DOOR, mean, var, CONFIG, RANGE_MAX,
                                       backend=backend, unobserved_var=var[0])
    np.testing.assert_array_equal(res.association[0], [0, 0, 0])
    want = [_uniform_prior_pz(p) for p in points]
    # the quadratic expansion of d(a) around its minimum: within a few percent of the exact average
    np.testing.assert_allclose(res.beam_likelihood[0], want, rtol=0.05)
    old = door_log_likelihood_at_poses(dist, np.zeros((1, 3)), points, DOOR, mean, var, CONFIG, RANGE_MAX,
                                       backend=backend)
    assert old.beam_likelihood[0, 0] < 0.75 * want[0]  # the linearization at 45° undervalues the closed leaf (0.58x)
    # a door below the threshold (observed) keeps eq. (6)
    kept = door_log_likelihood_at_poses(dist, np.zeros((1, 3)), points, DOOR, mean, var, CONFIG, RANGE_MAX,
                                        backend=backend, unobserved_var=2 * var[0])
    np.testing.assert_array_equal(kept.beam_likelihood, old.beam_likelihood)


@pytest.mark.parametrize(("seed", "prior"), [(3, UNIFORM), (4, DoorPrior(0.3, math.radians(3.0) ** 2))])
def test_door_prior_backends_agree(seed: int, prior: DoorPrior) -> None:
    """NumPy and numba agree for doors at the prior (uniform, or the closed/open mixture) and observed ones."""
    if not numba_available():
        pytest.skip("no numba")
    rng = np.random.default_rng(seed)
    pose = np.column_stack([rng.uniform(-0.5, 0.5, (50, 2)), rng.uniform(-0.3, 0.3, 50)])
    base = rng.uniform(-1.5, 1.5, (40, 2))
    dist = wall_distance(endpoint_points(pose, base))
    mean = rng.uniform(0.0, math.pi / 2, (50, 1))
    var = np.where(rng.random((50, 1)) < 0.5, 0.3, 0.01)
    out = [door_log_likelihood_at_poses(dist, pose, base, DOOR, mean, var, CONFIG, RANGE_MAX, backend=b,
                                        unobserved_var=np.array([0.2]), prior=prior) for b in ("numpy", "numba")]
    np.testing.assert_array_equal(out[0].association, out[1].association)
    np.testing.assert_allclose(out[0].log_likelihood, out[1].log_likelihood, rtol=1e-4, atol=1e-4)


def _leaf_pz(point: FloatArray, angles: FloatArray) -> FloatArray:
    """The endpoint model's hit density exp(−d²/2σ²) of the leaf at each angle (DOOR's geometry)."""
    tip = DOOR.length[0] * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    t = np.clip(tip @ point / DOOR.length[0] ** 2, 0.0, 1.0)
    d = np.hypot(*(point - t[:, None] * tip).T)
    return np.asarray(np.exp(-d**2 / (2 * SIGMA**2)), dtype=np.float64)


@pytest.mark.parametrize("backend", BACKENDS)
def test_unobserved_door_under_the_closed_open_mixture_matches_its_quadrature(backend: str) -> None:
    # The global phase's prior (door_prior.py): closed N(0, σ_c²) with p_c, else uniform over [0, 90°]. End points
    # on the closed leaf, on a leaf 3° open, on one 57° open, and beyond the tip: each beam's closed-form density
    # must be the quadrature of the endpoint model over the mixture within a few percent (the quadratic expansion
    # of d(a) is the only approximation), and the closed leaf must gain against the uniform prior.
    prior = DoorPrior(0.5, math.radians(2.0) ** 2)
    points = np.array([[0.5, 0.0], [0.6 * math.cos(0.05), 0.6 * math.sin(0.05)],
                       [0.4 * math.cos(1.0), 0.4 * math.sin(1.0)], [0.0, 1.0]])
    mean = np.array([[math.pi / 4]])
    var = np.array([[(math.pi / 2) ** 2 / 12]])
    dist = wall_distance(points[None])
    res = door_log_likelihood_at_poses(dist, np.zeros((1, 3)), points, DOOR, mean, var, CONFIG, RANGE_MAX,
                                       backend=backend, unobserved_var=var[0], prior=prior)
    np.testing.assert_array_equal(res.association[0], [0, 0, 0, 0])
    sc = math.sqrt(prior.closed_var)
    a_closed = np.linspace(-8 * sc, 8 * sc, 4001)
    w_closed = np.exp(-0.5 * a_closed**2 / prior.closed_var)
    w_closed /= w_closed.sum()
    want = [CONFIG.z_hit * (prior.closed_prob * float(w_closed @ _leaf_pz(p, a_closed))
                            + (1 - prior.closed_prob) * (_uniform_prior_pz(p) - RAND) / CONFIG.z_hit) + RAND
            for p in points]
    np.testing.assert_allclose(res.beam_likelihood[0], want, rtol=0.05)
    uniform = door_log_likelihood_at_poses(dist, np.zeros((1, 3)), points, DOOR, mean, var, CONFIG, RANGE_MAX,
                                           backend=backend, unobserved_var=var[0])
    assert res.beam_likelihood[0, 0] > 2.0 * uniform.beam_likelihood[0, 0]
