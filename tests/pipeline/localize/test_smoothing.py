"""Global localization's smoothed likelihood, bandwidths, tempering and regularized resampling."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.config import LocalizeConfig
from doorbatch.maps import DoorSet, OccupancyMap
from doorbatch.pipeline.localize.door_likelihood import door_log_likelihood_at_poses
from doorbatch.pipeline.localize.likelihood_field import beam_likelihood, build_distance_field, endpoint_distances
from doorbatch.pipeline.localize.mcl import tempered_weighting
from doorbatch.pipeline.localize.particles import ParticleSet
from doorbatch.pipeline.localize.smoothing import (
    Bandwidth,
    active_bandwidth,
    effective_sample_ratio,
    endpoint_jacobians,
    endpoint_variance,
    jitter,
    particle_bandwidth,
    pose_volume_log_factor,
    smoothed_beam_likelihood,
    tempering_exponent,
)


def test_no_extra_variance_is_the_plain_endpoint_model() -> None:
    d = np.linspace(0.0, 2.0, 41, dtype=np.float32)[None, :]
    plain = beam_likelihood(d, 0.8, 0.2, 0.1, 20.0)
    assert np.allclose(smoothed_beam_likelihood(d, np.zeros_like(d), 0.8, 0.2, 0.1, 20.0), plain, rtol=1e-6)


@pytest.mark.parametrize(("d", "e"), [(0.0, 0.01), (0.15, 0.04), (0.4, 0.09), (1.0, 0.25)])
def test_smoothing_is_the_average_over_the_offsets(d: float, e: float) -> None:
    # a distance that moves by u ~ N(0, e): the mean of exp(−(d + u)²/2σ²) by quadrature
    u = np.linspace(-8 * math.sqrt(e), 8 * math.sqrt(e), 20001)
    density = np.exp(-0.5 * u**2 / e) / math.sqrt(2 * math.pi * e)
    hit = np.trapezoid(np.exp(-0.5 * (d + u) ** 2 / 0.01) * density, u)
    expected = 0.8 * hit + 0.2 / 20.0
    got = smoothed_beam_likelihood(np.array([[d]], np.float32), np.array([[e]], np.float32), 0.8, 0.2, 0.1, 20.0)
    assert got[0, 0] == pytest.approx(expected, rel=1e-4)


def test_endpoint_variance_grows_with_the_square_of_the_range() -> None:
    bw = Bandwidth(np.array([0.1, 0.0]), np.array([0.0, 0.02]))
    e = endpoint_variance(bw, np.array([[3.0, 4.0], [0.0, 0.0]]))
    assert np.allclose(e, [[0.01, 0.01], [0.02**2 * 25.0, 0.0]], atol=1e-7)


def test_bandwidth_of_uniform_particles_is_their_spacing() -> None:
    # N particles uniform in a 10 m × 10 m × 2π box: each stands for V/N; h_xy = (V/N)^(1/3) / √12 in the
    # (x, y, L·yaw) metric, L = 0.5 m / 10°
    config = LocalizeConfig()
    scale = config.kld_bin_xy_m / math.radians(config.kld_bin_yaw_deg)
    rng = np.random.default_rng(0)
    n = 20000
    pose = np.column_stack([rng.uniform(0, 10, n), rng.uniform(0, 10, n), rng.uniform(-math.pi, math.pi, n)])
    bw = particle_bandwidth(pose, config)
    side = (100.0 * 2 * math.pi * scale / n) ** (1 / 3)
    assert np.median(bw.xy_m) == pytest.approx(side / math.sqrt(12), rel=0.15)
    assert np.allclose(bw.yaw_rad, bw.xy_m / scale)
    dense = particle_bandwidth(pose[:, :] * np.array([0.01, 0.01, 0.01]), config)  # same count, 100× tighter
    assert np.median(dense.xy_m) < 0.1 * np.median(bw.xy_m)


def test_bandwidth_only_before_convergence() -> None:
    config = LocalizeConfig()
    rng = np.random.default_rng(1)
    tight = np.array([5.0, 2.0, 0.3]) + rng.normal(0, [0.05, 0.05, 0.02], (500, 3))
    spread = np.column_stack([rng.uniform(0, 20, 500), rng.uniform(0, 5, 500), rng.uniform(-3, 3, 500)])
    w = np.full(500, 1 / 500)
    assert active_bandwidth(tight, w, config) is None
    assert active_bandwidth(spread, w, config) is not None
    assert active_bandwidth(spread, w, LocalizeConfig(global_smoothing=False)) is None


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), target=st.floats(0.05, 0.9), sharpness=st.floats(1.0, 300.0))
def test_tempering_keeps_the_effective_sample_size(seed: int, target: float, sharpness: float) -> None:
    rng = np.random.default_rng(seed)
    log_prior = np.log(rng.dirichlet(np.ones(300)))
    ll = -sharpness * rng.random(300)
    beta = tempering_exponent(log_prior, ll, target)
    assert 0.0 <= beta <= 1.0
    floor = target * effective_sample_ratio(log_prior)  # one scan shrinks Neff at most by the factor target
    assert effective_sample_ratio(log_prior + beta * ll) >= floor - 1e-9
    if beta < 1.0:  # the largest such β: a little more falls below the floor
        assert effective_sample_ratio(log_prior + min(1.0, beta + 1e-6 + 1e-3 * beta) * ll) < floor + 1e-3


def test_jitter_spreads_copies_by_their_source_bandwidth() -> None:
    rng = np.random.default_rng(2)
    bw = Bandwidth(np.array([0.0, 0.2]), np.array([0.0, 0.05]))
    pose = np.tile([1.0, 2.0, 3.1], (40000, 1))
    source = np.repeat([0, 1], 20000)
    out = jitter(pose, bw, rng, source)
    assert np.allclose(out[:20000], pose[:20000], rtol=0, atol=1e-12)  # zero bandwidth: unchanged
    assert np.std(out[20000:, 0]) == pytest.approx(0.2, rel=0.03)
    yaw_off = np.angle(np.exp(1j * (out[20000:, 2] - 3.1)))
    assert np.std(yaw_off) == pytest.approx(0.05, rel=0.03)
    assert np.all(np.abs(out[:, 2]) <= math.pi)  # wrapped across ±π


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_door_kernel_with_extra_variance_matches_the_static_smoothing(backend: str) -> None:
    # a door far from every end point: every beam is static, and its pz is the smoothed static model
    pytest.importorskip("numba") if backend == "numba" else None
    config = LocalizeConfig()
    rng = np.random.default_rng(3)
    n, b = 50, 30
    pose = np.column_stack([rng.uniform(0, 2, n), rng.uniform(0, 2, n), rng.uniform(-3, 3, n)])
    base = rng.uniform(-3, 3, (b, 2))
    dist = rng.uniform(0, 2, (n, b)).astype(np.float32)
    extra = rng.uniform(0, 0.3, (n, b)).astype(np.float32)
    doors = DoorSet(np.array([[100.0, 100.0]]), np.array([0.9]), np.array([0.0]), np.array([0.0]), np.array([1.5]))
    dl = door_log_likelihood_at_poses(dist, pose, base, doors, np.zeros((n, 1)), np.full((n, 1), 0.1), config, 20.0,
                                      backend=backend, extra_var=extra)  # type: ignore[arg-type]
    expected = smoothed_beam_likelihood(dist, extra, config.z_hit, config.z_rand, config.sigma_hit, 20.0)
    assert np.allclose(dl.beam_likelihood, expected, rtol=1e-5)
    assert np.all(dl.association == -1)


def test_door_kernel_extra_variance_numba_agrees_with_numpy() -> None:
    pytest.importorskip("numba")
    config = LocalizeConfig()
    rng = np.random.default_rng(4)
    n, b = 80, 40
    doors = DoorSet(np.array([[1.0, 1.0], [3.0, 0.0]]), np.array([0.9, 0.8]), np.array([0.0, math.pi / 2]),
                    np.array([0.0, 0.0]), np.array([1.5, 1.5]))
    pose = np.column_stack([rng.uniform(0, 3, n), rng.uniform(-1, 1, n), rng.uniform(-3, 3, n)])
    base = rng.uniform(-2, 2, (b, 2))
    dist = rng.uniform(0, 1, (n, b)).astype(np.float32)
    extra = rng.uniform(0, 0.2, (n, b)).astype(np.float32)
    mean, var = rng.uniform(0, 1.5, (n, 2)), rng.uniform(0.001, 0.2, (n, 2))
    a = door_log_likelihood_at_poses(dist, pose, base, doors, mean, var, config, 20.0, backend="numba", extra_var=extra)
    c = door_log_likelihood_at_poses(dist, pose, base, doors, mean, var, config, 20.0, backend="numpy", extra_var=extra)
    assert np.array_equal(a.association, c.association)
    assert np.allclose(a.log_likelihood, c.log_likelihood, rtol=1e-5)
    assert (a.association >= 0).any()  # some beams do go to a door


def test_pose_volume_factor_counts_a_shared_offset_once() -> None:
    # B beams that all measure the same x offset δ ~ N(0, h²): the exact average of Π_b exp(−δ²/(2σ²)) is
    # (1 + B·h²/σ²)^(−1/2); one factor per beam would give (1 + h²/σ²)^(−B/2), ~42 nats lower here.
    sigma, h, b = 0.1, 0.2, 60
    jac = np.zeros((1, b, 3))
    jac[..., 0] = 1.0
    got = pose_volume_log_factor(jac, np.ones((1, b)), Bandwidth(np.array([h]), np.array([0.0])), sigma)
    assert got[0] == pytest.approx(-0.5 * math.log(1.0 + b * h * h / sigma**2), rel=1e-9)
    delta = np.random.default_rng(0).normal(0.0, h, 400_000)
    assert got[0] == pytest.approx(math.log(np.mean(np.exp(-b * delta**2 / (2 * sigma**2)))), abs=0.02)
    # a direction the beams do not measure (yaw here) adds nothing
    wide = pose_volume_log_factor(jac, np.ones((1, b)), Bandwidth(np.array([h]), np.array([1.0])), sigma)
    assert wide[0] == pytest.approx(got[0], rel=1e-9)


@pytest.mark.parametrize("stages", [1, 30])
def test_tempered_stages_apply_the_whole_likelihood(stages: int) -> None:
    # particles uniform on x ∈ [−5, 5], likelihood N(x; 0, s²): the posterior has variance s², the evidence
    # Z = s·√(2π) / 10. One stage applies only the power β that keeps a quarter of Neff and drops the rest.
    s = 0.3
    rng = np.random.default_rng(5)
    n = 4000
    pose = np.column_stack([rng.uniform(-5, 5, n), np.zeros(n), np.zeros(n)])
    particles = ParticleSet(pose, np.full(n, 1.0 / n), np.zeros((n, 0)), np.zeros((n, 0)))

    def gaussian(p: ParticleSet, h: Bandwidth) -> np.ndarray:
        return -0.5 * p.pose[:, 0] ** 2 / s**2

    config = LocalizeConfig(global_max_stages=stages, global_min_neff_ratio=0.25)
    out, log_z, _ = tempered_weighting(particles, gaussian, config, rng)
    var = float(out.weight @ out.pose[:, 0] ** 2)
    if stages == 1:
        assert var > 2.0 * s**2
    else:
        assert var == pytest.approx(s**2, rel=0.25)
        assert log_z == pytest.approx(math.log(s * math.sqrt(2 * math.pi) / 10.0), abs=0.15)


def test_endpoint_jacobians_match_finite_differences_of_the_field() -> None:
    """A wall y = 1 (the field's distance falls by 1 m per m going up, 0 along x); a particle at the origin turned
    by θ with end points ahead of it: ∂d/∂(x, y) = (0, −1), ∂d/∂θ = ∇d · (−r_y, r_x) = −r_x, as central
    differences of the field itself give."""
    occ = np.zeros((60, 100), dtype=np.int8)
    occ[39, :] = 100  # cell centres y = 0.975: the wall 2.5 cm below y = 1 (origin −1, −1, 5 cm cells)
    field = build_distance_field(OccupancyMap(occ, 0.05, -1.0, -1.0), 2.0)
    pose = np.array([[0.0, 0.0, 0.1], [0.5, -0.3, -0.2]])
    base = np.array([[2.0, 0.3], [1.5, -0.2], [2.5, 0.1]])  # end points 0.3–0.9 m below the wall
    jac = endpoint_jacobians(field, pose, base)
    np.testing.assert_allclose(jac[..., 0], 0.0, atol=0.05)
    np.testing.assert_allclose(jac[..., 1], -1.0, atol=0.05)
    eps = 0.1  # rad: end points 15–25 cm off (several cells: the field is exact only at cell centres), below the wall
    turned = [endpoint_distances(field, pose + np.array([0.0, 0.0, e]), base) for e in (eps, -eps)]
    finite = (turned[0] - turned[1]) / (2 * eps)
    r_x = np.cos(pose[:, 2:3]) * base[:, 0] - np.sin(pose[:, 2:3]) * base[:, 1]
    np.testing.assert_allclose(jac[..., 2], -r_x, atol=0.05)
    np.testing.assert_allclose(jac[..., 2], finite, atol=0.3)  # the field steps by a cell: 0.25 per 5 cm here
