"""Point-to-line ICP on scans ray-cast in known geometry (1 cm range noise, fixed seeds)."""

from __future__ import annotations

import numpy as np
from scanmatch_sim import polyline, room_segments, simulate_scan

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import compose
from doorbatch.pipeline.poses.plicp import GaussianPrior, LineReference, line_reference, plicp, scan_line_reference

P0 = np.array([3.0, 2.5, 0.3])


def _reference(segments: np.ndarray, pose: np.ndarray, seed: int) -> LineReference:
    rng = np.random.default_rng(seed)
    return scan_line_reference(simulate_scan(segments, pose, rng), pose)


def _errors(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    return float(np.hypot(*(estimate[:2] - truth[:2]))), float(np.rad2deg(abs(wrap_angle(estimate[2] - truth[2]))))


def test_plicp_recovers_known_offset_in_room() -> None:
    ref = _reference(room_segments(), P0, seed=0)
    truth = compose(P0, [0.15, -0.13, np.deg2rad(5.0)])  # 0.2 m, 5°
    scan = simulate_scan(room_segments(), truth, np.random.default_rng(1))
    result = plicp(ref, scan, P0)
    d_xy, d_yaw = _errors(result.pose, truth)
    assert d_xy < 0.01 and d_yaw < 0.2, (d_xy, d_yaw)
    assert result.converged and result.iterations < 15
    assert result.n_inliers > 0.8 * len(scan)
    assert 0.003 < result.residual_m < 0.015  # the two scans' 1 cm noise, not a misfit
    assert result.degeneracy > 0.05
    std = np.sqrt(np.diag(result.covariance))
    assert np.all(np.linalg.eigvalsh(result.covariance) > 0) and np.all(std[:2] < 0.005) and std[2] < 0.002


def test_plicp_covariance_matches_spread_over_noise_draws() -> None:
    truth = compose(P0, [0.1, 0.05, np.deg2rad(2.0)])
    estimates, predicted = [], []
    for seed in range(20):
        rng = np.random.default_rng(100 + seed)
        ref = scan_line_reference(simulate_scan(room_segments(), P0, rng), P0)
        result = plicp(ref, simulate_scan(room_segments(), truth, rng), P0, min_step_m=1e-5, min_step_rad=1e-5)
        estimates.append(result.pose - truth)
        predicted.append(np.sqrt(np.diag(result.covariance)))
    spread = np.std(np.asarray(estimates), axis=0)
    ratio = spread / np.mean(predicted, axis=0)
    # Censi's covariance is that of the new scan's noise alone; here the reference is a scan just as noisy, so
    # the spread is √2 times it. 20 draws estimate a std to ~16 %: a band of about ±2 of those around √2.
    assert np.all((ratio > 0.95) & (ratio < 1.9)), ratio


def test_plicp_rejects_clutter_by_gating_and_trimming() -> None:
    ref = _reference(room_segments(), P0, seed=0)
    truth = compose(P0, [0.1, 0.1, np.deg2rad(-4.0)])
    rng = np.random.default_rng(2)
    scan = simulate_scan(room_segments(), truth, rng)
    clutter = rng.uniform(-3.0, 3.0, (len(scan) // 4, 2))  # people, chairs: not in the reference
    result = plicp(ref, np.concatenate([scan, clutter]), P0)
    d_xy, d_yaw = _errors(result.pose, truth)
    assert d_xy < 0.01 and d_yaw < 0.2, (d_xy, d_yaw)


def test_plicp_single_wall_is_degenerate_along_the_wall() -> None:
    wall = polyline([(-20.0, 1.0), (20.0, 1.0)])
    pose = np.array([0.0, 0.0, 0.0])
    ref = _reference(wall, pose, seed=3)
    result = plicp(ref, simulate_scan(wall, pose, np.random.default_rng(4)), [0.2, 0.0, 0.0])
    assert result.degeneracy < 0.02
    # The across-wall direction is still fixed: y and yaw come back, x is whatever the start said.
    assert abs(result.pose[1]) < 0.01 and abs(result.pose[0] - 0.2) < 0.05


def test_plicp_without_reference_or_points_reports_no_inliers() -> None:
    empty = line_reference(np.zeros((0, 2)), np.zeros((0, 2)))
    result = plicp(empty, np.ones((10, 2)), P0)
    assert result.n_inliers == 0 and np.isnan(result.residual_m) and np.all(np.isinf(result.covariance))
    assert np.allclose(result.pose, P0, atol=1e-12)
    ref = _reference(room_segments(), P0, seed=0)
    assert plicp(ref, np.zeros((0, 2)), P0).n_inliers == 0


def test_line_reference_normals_are_perpendicular_to_the_walls() -> None:
    square = polyline([(0, 0), (4, 0), (4, 3), (0, 3), (0, 0)])
    pose = np.array([1.5, 1.2, 0.0])
    ref = _reference(square, pose, seed=5)
    corners = np.array([(0, 0), (4, 0), (4, 3), (0, 3)])
    away = np.min(np.linalg.norm(ref.points[:, None] - corners[None], axis=2), axis=1) > 0.3
    on_horizontal = away & ((np.abs(ref.points[:, 1]) < 0.05) | (np.abs(ref.points[:, 1] - 3) < 0.05))
    on_vertical = away & ((np.abs(ref.points[:, 0]) < 0.05) | (np.abs(ref.points[:, 0] - 4) < 0.05))
    assert on_horizontal.sum() > 100 and on_vertical.sum() > 50
    assert np.all(np.abs(ref.normals[on_horizontal, 1]) > 0.99)
    assert np.all(np.abs(ref.normals[on_vertical, 0]) > 0.99)
    assert np.allclose(np.linalg.norm(ref.normals, axis=1), 1.0)


def test_plicp_prior_fixes_only_the_direction_the_scan_leaves_open() -> None:
    wall = polyline([(-20.0, 1.0), (20.0, 1.0)])
    pose = np.array([0.0, 0.0, 0.0])
    ref = _reference(wall, pose, seed=3)
    scan = simulate_scan(wall, pose, np.random.default_rng(4))
    prior = GaussianPrior(np.array([0.2, 0.1, np.deg2rad(2.0)]), np.diag([1.0 / 0.05**2, 1.0 / 0.05**2, 1.0 / 0.05**2]))
    result = plicp(ref, scan, prior.mean, prior=prior)
    # Along the wall the prior's 0.2 m stands; across it and in heading the scan overrules the prior.
    assert abs(result.pose[0] - 0.2) < 0.005 and abs(result.pose[1]) < 0.005 and abs(result.pose[2]) < np.deg2rad(0.1)
    std = np.sqrt(np.diag(result.covariance))
    assert std[0] <= 0.05 and std[1] < 0.005 and std[0] > 5.0 * std[1]  # the prior still carries x
