"""The compiled kernels agree with their NumPy references on random scans: the grid kernels bit for bit,
the leaf kernels (sums in another order) to 1e-9."""

from __future__ import annotations

import math

import numpy as np
import pytest
from gridmap_sim import cast

from doorbatch.config import DoorDetectionConfig, GridConfig
from doorbatch.pipeline.gridmap.doors import (
    SOURCE_TRANSIENT,
    complete_line,
    complete_line_numpy,
    extract_leaves,
    fit_leaf,
    fit_leaf_numpy,
    scan_leaves,
)
from doorbatch.pipeline.gridmap.dynamic import (
    begin_pass,
    classify_and_integrate,
    classify_scan,
    classify_scan_numpy,
)
from doorbatch.pipeline.gridmap.occupancy import (
    GRID_ARRAYS,
    LogOddsGrid,
    integrate_scan,
    integrate_scan_numpy,
    new_grid,
)


def _random_world(rng: np.random.Generator) -> np.ndarray:
    """A closed room of random size with a few random segments inside (beams in order hit surfaces)."""
    w, h = rng.uniform(3.0, 9.0, 2)
    box = np.array([[0, 0], [w, 0], [w, h], [0, h]])
    segs = [np.stack([box, np.roll(box, -1, axis=0)], axis=1)]
    a = rng.uniform([0.5, 0.5], [w - 0.5, h - 0.5], (4, 2))
    b = a + rng.normal(0.0, 0.6, (4, 2))
    segs.append(np.stack([a, b], axis=1))
    return np.concatenate(segs)


def _scans(seed: int, n: int) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """n scans (origin, hits in beam order, no-return directions, a random dynamic mask) in one world:
    random ranges cut at a random max range (no returns), a few spurious short readings."""
    rng = np.random.default_rng(seed)
    world = _random_world(rng)
    lo, hi = world.reshape(-1, 2).min(axis=0) + 0.3, world.reshape(-1, 2).max(axis=0) - 0.3
    out = []
    for _ in range(n):
        origin = rng.uniform(lo, hi)
        beams = int(rng.integers(90, 400))
        angles = np.sort(rng.uniform(-math.pi, math.pi, beams))
        dirs = np.stack([np.cos(angles), np.sin(angles)], axis=1)
        r = cast(origin, dirs, world) + rng.normal(0.0, 0.01, beams)
        r[rng.random(beams) < 0.02] = rng.uniform(0.05, 1.0)
        hit = r < rng.uniform(2.0, 12.0)
        pts = origin + r[hit, None] * dirs[hit]
        out.append((origin, pts, dirs[~hit], rng.random(pts.shape[0]) < 0.1))
    return out


def _assert_same(a: LogOddsGrid, b: LogOddsGrid) -> None:
    assert (a.shape, a.origin_x_m, a.origin_y_m, a.scan_count) == (b.shape, b.origin_x_m, b.origin_y_m, b.scan_count)
    for name in GRID_ARRAYS:
        if name != "stamp":  # the kernel's scratch
            assert np.array_equal(getattr(a, name), getattr(b, name)), name


CONFIGS = [
    (1, {}),
    (2, {"surface_band_m": 0.0}),
    (3, {"max_range_m": 3.0, "no_return_clear_m": 4.0}),  # beams cut at max range
    (4, {"no_return_clear_m": 0.0, "resolution_m": 0.1, "transient_neighborhood_cells": 1}),
]


@pytest.mark.parametrize(("seed", "update"), CONFIGS)
def test_kernels_match_the_numpy_reference_on_random_scans(seed: int, update: dict[str, float]) -> None:
    cfg = GridConfig(initial_size_m=4.0).model_copy(update=update)  # small: the grid grows on the way
    scans = _scans(seed, 60)
    a = new_grid(cfg, scans[0][0])
    b = new_grid(cfg, scans[0][0])
    for k, (origin, pts, dirs, mask) in enumerate(scans):
        if k % 20 == 0:
            begin_pass(a, cfg)
            begin_pass(b, cfg)
        got = classify_scan(a, pts, cfg)
        want_dynamic, want_support = classify_scan_numpy(b, pts, cfg)
        assert np.array_equal(got.dynamic, want_dynamic) and np.array_equal(got.support, want_support)
        assert got.n_dynamic == int(want_dynamic.sum())
        dynamic = got.dynamic | mask if k % 2 else None  # with and without a mask
        a = integrate_scan(a, origin, pts, dirs, cfg, dynamic)
        b = integrate_scan_numpy(b, origin, pts, dirs, cfg, dynamic)
        _assert_same(a, b)
    assert a.transient.any() and a.seen_occupied.any() and a.free_latch.any()


@pytest.mark.parametrize(("seed", "update"), CONFIGS[:2])
def test_classify_and_integrate_in_one_call_matches_the_numpy_reference(seed: int, update: dict[str, float]) -> None:
    cfg = GridConfig(initial_size_m=4.0).model_copy(update=update)
    scans = _scans(seed + 10, 60)
    a = new_grid(cfg, scans[0][0])
    b = new_grid(cfg, scans[0][0])
    for k, (origin, pts, dirs, _) in enumerate(scans):
        if k % 20 == 0:
            begin_pass(a, cfg)
            begin_pass(b, cfg)
        a, got = classify_and_integrate(a, origin, pts, dirs, cfg)
        want_dynamic, want_support = classify_scan_numpy(b, pts, cfg)
        b = integrate_scan_numpy(b, origin, pts, dirs, cfg, want_dynamic)
        assert np.array_equal(got.dynamic, want_dynamic) and np.array_equal(got.support, want_support)
        _assert_same(a, b)
    assert a.transient.any()


def test_kernels_handle_empty_scans() -> None:
    cfg = GridConfig(initial_size_m=4.0)
    a = new_grid(cfg, (0.0, 0.0))
    b = new_grid(cfg, (0.0, 0.0))
    for pts, dirs in ((np.zeros((0, 2)), np.zeros((0, 2))), (np.zeros((0, 2)), np.array([[1.0, 0.0]])),
                      (np.array([[0.5, 0.5]]), np.zeros((0, 2)))):
        a = integrate_scan(a, (0.0, 0.0), pts, dirs, cfg)
        b = integrate_scan_numpy(b, (0.0, 0.0), pts, dirs, cfg)
        _assert_same(a, b)
        assert classify_scan(a, pts, cfg).dynamic.shape == (pts.shape[0],)


def test_leaf_kernels_match_their_numpy_references_on_random_clusters() -> None:
    """Eq. (2) line objects, line completion, and the whole per-scan leaf extraction (compiled) agree with
    their NumPy versions on noisy random segments, some of them blobs."""
    cfg = DoorDetectionConfig()
    rng = np.random.default_rng(7)
    for _ in range(300):
        parts = []
        for _ in range(int(rng.integers(1, 4))):
            a, length = rng.uniform(0.0, 2 * math.pi), rng.uniform(0.2, 1.4)
            t = np.sort(rng.uniform(0.0, length, int(rng.integers(2, 120))))
            noise = rng.choice([0.005, 0.03, 0.2])
            parts.append(rng.uniform(-3, 3, 2) + np.stack([t * math.cos(a), t * math.sin(a)], axis=1)
                         + rng.normal(0.0, noise, (t.size, 2)))
        pts = np.concatenate(parts)
        dynamic = rng.random(pts.shape[0]) < 0.7
        got, want = fit_leaf(parts[0], cfg), fit_leaf_numpy(parts[0], cfg)
        assert (got is None) == (want is None)
        if got is not None and want is not None:
            np.testing.assert_allclose(got, want, atol=1e-9)
        got_line = complete_line(pts[dynamic][:5], pts[~dynamic], cfg)
        want_line = complete_line_numpy(pts[dynamic][:5], pts[~dynamic], cfg)
        np.testing.assert_allclose(np.sort(got_line, axis=0), np.sort(want_line, axis=0), atol=1e-12)
        fast = scan_leaves(pts[dynamic], pts[~dynamic], cfg, 3, 1)
        slow = extract_leaves(pts[dynamic], cfg, 3, 1, SOURCE_TRANSIENT, pts[~dynamic])
        assert len(fast) == len(slow)
        np.testing.assert_allclose(fast.p0, slow.p0, atol=1e-9)
        np.testing.assert_allclose(fast.p1, slow.p1, atol=1e-9)
