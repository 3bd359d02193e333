"""Ray casting against a brute-force reference: exact ranges and indices, joints, circles."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.sim.raycast import RayBuffers, cast_rays, cast_rays_circles


def brute_force(origins: np.ndarray, dirs: np.ndarray, segs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One ray and one segment at a time, solving p + t·d = a + u·e with numpy.linalg.solve."""
    rng = np.full(dirs.shape[0], np.inf)
    idx = np.full(dirs.shape[0], -1)
    for b in range(dirs.shape[0]):
        for j, (a, c) in enumerate(segs):
            m = np.column_stack([dirs[b], a - c])
            if abs(np.linalg.det(m)) < 1e-12:
                continue
            t, u = np.linalg.solve(m, a - origins[b])
            if t > 0 and 0 <= u <= 1 and t < rng[b]:
                rng[b], idx[b] = t, j
    return rng, idx


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), shared=st.booleans())
def test_cast_rays_matches_brute_force(seed: int, shared: bool) -> None:
    gen = np.random.default_rng(seed)
    segs = gen.uniform(-5, 5, (int(gen.integers(1, 15)), 2, 2))
    n = int(gen.integers(1, 25))
    dirs = gen.normal(size=(n, 2))
    origins = np.repeat(gen.uniform(-5, 5, (1, 2)), n, axis=0) if shared else gen.uniform(-5, 5, (n, 2))
    rng, idx = cast_rays(origins[0] if shared else origins, dirs, segs, RayBuffers())
    ref_rng, ref_idx = brute_force(origins, dirs, segs)
    np.testing.assert_array_equal(idx, ref_idx)
    np.testing.assert_allclose(rng, ref_rng, rtol=1e-9)


def test_rays_through_polygon_vertices_never_slip_through() -> None:
    # a closed 36-gon around the origin, rays aimed exactly at its vertices (and between them)
    k = np.arange(36)
    ring = np.stack([np.cos(k * np.pi / 18), np.sin(k * np.pi / 18)], axis=1) * 3.0
    segs = np.stack([ring, np.roll(ring, -1, axis=0)], axis=1)
    angles = np.linspace(0, 2 * np.pi, 3600, endpoint=False)
    dirs = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    for origin in (np.zeros(2), np.array([0.3, -0.7])):
        rng, idx = cast_rays(origin, dirs, segs)
        assert np.all(np.isfinite(rng)) and np.all(idx >= 0)


def test_shared_and_per_ray_origins_agree_and_misses_are_inf() -> None:
    gen = np.random.default_rng(1)
    segs = gen.uniform(-10, 10, (50, 2, 2))
    angles = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    dirs = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    shared = cast_rays(np.array([0.5, 0.5]), dirs, segs)
    per_ray = cast_rays(np.tile([0.5, 0.5], (720, 1)) + np.array([[1e-300, 0.0]] * 720), dirs, segs)
    np.testing.assert_array_equal(shared[1], per_ray[1])
    np.testing.assert_allclose(shared[0], per_ray[0], rtol=1e-12)
    away = cast_rays(np.array([100.0, 100.0]), np.array([[1.0, 0.0]]), segs)
    assert np.isinf(away[0][0]) and away[1][0] == -1


def test_range_is_depth_for_unnormalized_camera_directions() -> None:
    wall = np.array([[[4.0, -10.0], [4.0, 10.0]]])
    rng, _ = cast_rays(np.zeros(2), np.array([[1.0, 0.0], [1.0, 0.5], [1.0, -2.0]]), wall)
    np.testing.assert_allclose(rng, [4.0, 4.0, 4.0])


def test_circles_match_closed_form_and_absent_people_are_skipped() -> None:
    centers = np.array([[5.0, 0.0], [np.nan, np.nan], [2.0, 2.0]])
    radii = np.array([0.5, 0.5, 0.25])
    dirs = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [-1.0, 0.0], [1.0, 0.1]])
    rng, idx = cast_rays_circles(np.zeros(2), dirs, centers, radii)
    assert rng[0] == 4.5 and idx[0] == 0
    assert np.isinf(rng[1]) and idx[1] == -1
    # along (1, 1) (not unit): t·|d| = |c| − r
    assert np.isclose(rng[2] * np.sqrt(2), np.hypot(2, 2) - 0.25, rtol=1e-12)
    assert idx[2] == 2
    assert np.isinf(rng[3])
    # chord: t = d·c − sqrt(r² − (perpendicular distance)²), unit direction
    d = np.array([1.0, 0.1]) / np.hypot(1.0, 0.1)
    perp = abs(5.0 * d[1])
    expected = (5.0 * d[0] - np.sqrt(0.25 - perp**2)) / np.hypot(1.0, 0.1)
    assert np.isclose(rng[4], expected, rtol=1e-12)
    inside = cast_rays_circles(np.array([5.0, 0.0]), np.array([[1.0, 0.0]]), centers[:1], radii[:1])
    assert inside[0][0] == 0.5
