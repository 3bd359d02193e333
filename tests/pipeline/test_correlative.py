"""Correlative scan matching: large offsets recovered where ICP alone fails; branch and bound is exact."""

from __future__ import annotations

import itertools

import numpy as np
from scanmatch_sim import corridor_segments, room_segments, simulate_scan

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import compose, transform_points
from doorbatch.pipeline.poses.correlative import _block_max, build_likelihood_grid, correlative_match
from doorbatch.pipeline.poses.plicp import plicp, scan_line_reference

P0 = np.array([10.0, 0.0, 0.0])  # in the corridor, between niches


def _errors(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    return float(np.hypot(*(estimate[:2] - truth[:2]))), float(np.rad2deg(abs(wrap_angle(estimate[2] - truth[2]))))


def test_correlative_search_recovers_large_offset_that_plicp_alone_misses() -> None:
    rng = np.random.default_rng(0)
    segments = corridor_segments()
    ref_scan = simulate_scan(segments, P0, rng)
    ref_points = transform_points(P0, ref_scan)
    lines = scan_line_reference(ref_scan, P0)
    grid = build_likelihood_grid(ref_points, resolution_m=0.05, sigma_m=0.05, window_m=1.5)
    for offset in ([1.0, 0.0, 10.0], [0.0, 0.6, 30.0], [1.2, 0.3, 30.0]):
        truth = compose(P0, [offset[0], offset[1], np.deg2rad(offset[2])])
        scan = simulate_scan(segments, truth, rng)
        alone = plicp(lines, scan, P0)
        assert _errors(alone.pose, truth)[0] > 0.05, "the scene must defeat plain ICP for this test to mean anything"
        coarse = correlative_match(grid, scan, P0, window_m=1.5, window_deg=35.0, step_deg=1.0)
        c_xy, c_yaw = _errors(coarse.pose, truth)
        assert c_xy <= 0.05 * np.sqrt(2) and c_yaw <= 0.5 + 1e-9, (c_xy, c_yaw)  # one cell, half a step
        assert coarse.score > 0.5
        fine = plicp(lines, scan, coarse.pose)
        f_xy, f_yaw = _errors(fine.pose, truth)
        assert f_xy < 0.01 and f_yaw < 0.2, (f_xy, f_yaw)


def _brute_force(grid_values: np.ndarray, grid_origin: np.ndarray, res: float, scan: np.ndarray,
                 prior: np.ndarray, n: int, yaws: np.ndarray) -> float:
    """Best mean likelihood over every yaw and every integer cell shift, one at a time."""
    best = -1.0
    h, w = grid_values.shape
    for yaw in yaws:
        pts = transform_points([prior[0], prior[1], yaw], scan)
        cells = np.floor((pts - grid_origin) / res).astype(int)
        for dx, dy in itertools.product(range(-n, n + 1), repeat=2):
            col, row = cells[:, 0] + dx, cells[:, 1] + dy
            ok = (col >= 0) & (col < w) & (row >= 0) & (row < h)
            best = max(best, float(grid_values[row[ok], col[ok]].sum()) / len(scan))
    return best


def test_branch_and_bound_returns_the_exhaustive_optimum() -> None:
    rng = np.random.default_rng(1)
    p0 = np.array([3.0, 2.5, 0.3])
    ref_points = transform_points(p0, simulate_scan(room_segments(), p0, rng))
    truth = compose(p0, [0.13, -0.08, np.deg2rad(3.3)])
    scan = simulate_scan(room_segments(), truth, rng)[::3]
    for coarse_cells in (1, 3, 4):
        grid = build_likelihood_grid(ref_points, resolution_m=0.05, sigma_m=0.05, window_m=0.25,
                                     coarse_cells=coarse_cells)
        result = correlative_match(grid, scan, p0, window_m=0.25, window_deg=4.0, step_deg=2.0)
        yaws = p0[2] + np.deg2rad([-4.0, -2.0, 0.0, 2.0, 4.0])
        expected = _brute_force(grid.values, grid.origin_xy, 0.05, scan, p0, 5, yaws)
        assert abs(result.score - expected) < 1e-5, (coarse_cells, result.score, expected)


def test_block_max_bounds_every_fine_cell_of_its_block() -> None:
    values = np.random.default_rng(2).random((23, 31)).astype(np.float32)
    for r in (1, 2, 4, 5):
        bound = _block_max(values, r)
        padded = np.pad(values, ((0, r - 1), (0, r - 1)))
        windows = np.lib.stride_tricks.sliding_window_view(padded, (r, r))
        assert np.array_equal(bound, windows.max(axis=(2, 3)))


def test_likelihood_is_a_gaussian_of_the_distance_to_the_nearest_point() -> None:
    grid = build_likelihood_grid(np.array([[1.02, 2.02]]), resolution_m=0.05, sigma_m=0.1, window_m=0.2)
    cell = np.floor((np.array([1.02, 2.02]) - grid.origin_xy) / 0.05).astype(int)
    assert grid.values[cell[1], cell[0]] == 1.0
    for k in (1, 2, 4, 6):
        assert np.isclose(grid.values[cell[1], cell[0] + k], np.exp(-0.5 * (0.05 * k / 0.1) ** 2), rtol=1e-6)
    assert grid.values[cell[1], cell[0] + 7] == 0.0  # beyond 3σ
    assert grid.values.sum() < 40.0  # one blob, nothing else


def test_no_information_keeps_the_prior() -> None:
    prior = np.array([1.0, -2.0, 0.5])
    empty = build_likelihood_grid(np.zeros((0, 2)), window_m=0.5)
    result = correlative_match(empty, np.ones((20, 2)), prior)
    assert np.allclose(result.pose, prior) and result.score == 0.0
    grid = build_likelihood_grid(np.array([[0.0, 0.0]]), window_m=0.5)
    assert correlative_match(grid, np.zeros((0, 2)), prior).score == 0.0


def test_along_a_featureless_wall_the_prior_keeps_its_position() -> None:
    """A scan of a long straight wall fixes y and yaw, not x: of the equally good poses the search keeps the one
    nearest the prior (x unchanged), not the first it met at the window's edge."""
    wall = np.column_stack([np.arange(-10.0, 10.0, 0.02), np.ones(1000)])
    grid = build_likelihood_grid(wall, resolution_m=0.05, sigma_m=0.05, window_m=0.5)
    scan = np.column_stack([np.arange(-1.0, 1.0, 0.02), np.ones(100)])  # the wall 1 m to the left, from y = 0
    for prior in ([0.013, 0.1, 0.0], [0.3, -0.2, np.deg2rad(2.0)]):  # yaw on the 1° lattice around the prior
        result = correlative_match(grid, scan, np.array(prior), window_m=0.5, window_deg=5.0)
        np.testing.assert_allclose(result.pose, [prior[0], 0.0, 0.0], atol=1e-9)
        assert result.score == 1.0


def test_branch_and_bound_returns_the_nearest_of_tied_optima_like_an_exhaustive_search() -> None:
    """References and scans on a 0.1 m lattice (so that equal scores are common): the search's pose has the
    exhaustive optimum's score and, of the poses that tie with it, the least squared lattice distance from the
    prior (cells and yaw steps alike)."""
    from doorbatch.pipeline.poses import correlative

    rng = np.random.default_rng(0)
    nx, n_yaw = 10, 3
    for _ in range(80):
        pts = rng.integers(-20, 20, size=(int(rng.integers(3, 40)), 2)) * 0.1
        grid = build_likelihood_grid(pts, resolution_m=0.05, sigma_m=0.05, window_m=0.5, coarse_cells=4)
        scan = rng.integers(-15, 15, size=(int(rng.integers(1, 15)), 2)) * 0.1
        prior = np.array([rng.integers(-3, 3) * 0.05, rng.integers(-3, 3) * 0.05, 0.0])
        result = correlative_match(grid, scan, prior, window_m=0.5, window_deg=3.0, step_deg=1.0)
        yaws = prior[2] + np.deg2rad(np.arange(-n_yaw, n_yaw + 1))
        cells = correlative._flat_cells(grid, scan, prior[:2], yaws)
        shifts = np.arange(-nx, nx + 1)
        fx, fy = (a.ravel()[None, :] for a in np.meshgrid(shifts, shifts))
        scores = correlative._scores(grid.values, cells, np.broadcast_to(fx, (len(yaws), fx.size)),
                                     np.broadcast_to(fy, (len(yaws), fy.size)))
        dist = fx**2 + fy**2 + ((np.arange(len(yaws)) - n_yaw) ** 2)[:, None]
        top = scores.max()
        assert result.score == top
        got = np.round([(result.pose[0] - prior[0]) / 0.05, (result.pose[1] - prior[1]) / 0.05,
                        np.rad2deg(result.pose[2] - prior[2])]).astype(int)
        assert got[0] ** 2 + got[1] ** 2 + got[2] ** 2 == dist[scores == top].min()
