"""Loop closure: the loop search on known geometry, and a simulated log that returns to its start."""

from __future__ import annotations

import numpy as np
from scanmatch_sim import (
    ate_rmse_m,
    drifting_odometry,
    polyline,
    ring_segments,
    ring_truth,
    room_segments,
    simulate_scan,
)

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.pipeline.poses import ScanMatchConfig, scan_match_trajectory
from doorbatch.pipeline.poses.loop_closure import loop_candidates, match_loop, one_pass
from doorbatch.pipeline.poses.plicp import placed, scan_lines
from doorbatch.pipeline.poses.scanmatch import voxel_downsample


def _old_samples(segments: np.ndarray, poses: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Line samples and normals (map frame) of scans taken at ``poses`` (the old keyframes)."""
    lines = [placed(scan_lines(simulate_scan(segments, p, rng)), p) for p in poses]
    return np.concatenate([ln.points for ln in lines]), np.concatenate([ln.normals for ln in lines])


def test_loop_search_finds_a_revisited_place_from_a_drifted_estimate() -> None:
    """Back in the room after a long loop, estimate 0.6 m and 6° off: the search within 3σ of the accumulated
    uncertainty finds the true pose, with a unique basin and most of the scan on old lines."""
    rng = np.random.default_rng(21)
    points, normals = _old_samples(room_segments(), np.array([[2.0, 2.0, 0.3], [5.5, 3.5, 2.0]]), rng)
    truth = np.array([3.5, 2.8, -1.0])
    scan = voxel_downsample(simulate_scan(room_segments(), truth, rng), 0.05)
    estimate = truth + np.array([0.6, -0.4, np.deg2rad(6.0)])
    uncertainty = np.diag([0.3**2, 0.3**2, np.deg2rad(3.0) ** 2])
    match = match_loop(points, normals, scan, estimate, uncertainty, ScanMatchConfig())
    assert match is not None
    assert np.hypot(*(match.pose[:2] - truth[:2])) < 0.02
    assert np.rad2deg(abs(wrap_angle(match.pose[2] - truth[2]))) < 0.3
    assert match.overlap_fraction > 0.9 and match.ambiguity < 0.85


def test_loop_search_rejects_a_place_it_cannot_tell_apart() -> None:
    """A long featureless corridor: every position along it looks the same, so no loop is claimed, although a
    pose that fits the walls perfectly exists in the window."""
    rng = np.random.default_rng(22)
    corridor = np.concatenate([polyline([(-60.0, -1.0), (60.0, -1.0)]), polyline([(-60.0, 1.0), (60.0, 1.0)])])
    points, normals = _old_samples(corridor, np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0]]), rng)
    truth = np.array([1.5, 0.1, 0.05])
    scan = voxel_downsample(simulate_scan(corridor, truth, rng), 0.05)
    uncertainty = np.diag([0.5**2, 0.5**2, np.deg2rad(3.0) ** 2])
    assert match_loop(points, normals, scan, truth + np.array([0.5, 0.0, 0.0]), uncertainty,
                      ScanMatchConfig()) is None


def test_loop_candidates_are_old_near_keyframes_within_the_accumulated_uncertainty() -> None:
    cfg = ScanMatchConfig(loop_min_travel_m=10.0, loop_search_radius_m=2.0, loop_search_sigmas=3.0,
                          submap_keyframes=2)
    poses = np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0], [9.0, 0.0, 0.0], [5.0, 4.0, 0.0], [1.0, 4.0, 0.0],
                      [0.0, 3.0, 0.0]])
    path = np.array([0.0, 5.0, 9.0, 13.0, 17.0, 18.0, 20.0])  # the new keyframe last
    estimate = np.array([0.0, 1.0, 0.0])
    assert loop_candidates(poses, path, estimate, np.zeros((3, 3)), cfg).tolist() == [0]
    # 1 m of accumulated σ widens the radius to 5 m: keyframe 1 (5.1 m away) stays out, keyframes 4 and 5 are
    # the front end's (the last two), keyframe 3 passed 7 m ago.
    wide = loop_candidates(poses, path, estimate, np.diag([1.0, 1.0, 0.0]), cfg)
    assert wide.tolist() == [0]
    wider = loop_candidates(poses, path, estimate, np.diag([1.5**2, 0.1, 0.0]), cfg)
    assert wider.tolist() == [0, 1]


def test_the_loop_submap_comes_from_one_pass() -> None:
    """Keyframes 0–4 and 40–44 pass the same place; the estimate is nearest keyframe 42: only its pass is used."""
    poses = np.zeros((50, 3))
    poses[:, 0] = 100.0
    poses[0:5, 0] = np.arange(5.0)
    poses[40:45, 0] = np.arange(5.0) + 0.1
    candidates = np.r_[np.arange(0, 5), np.arange(40, 45)]
    assert one_pass(candidates, poses, np.array([2.09, 0.0, 0.0]), span=10).tolist() == [40, 41, 42, 43, 44]
    assert one_pass(candidates, poses, np.array([1.9, 0.0, 0.0]), span=50).tolist() == candidates.tolist()


def test_a_log_that_returns_to_its_start_closes_the_loop_and_takes_out_the_drift() -> None:
    """Once around a ring corridor whose south side is plain (the scan fixes nothing along it, so the front end
    keeps the odometry's 3 % scale error there), then along the start again: the loop closes only on the
    return, every kept loop puts its keyframe where the truth is, and the drift leaves the whole trajectory."""
    rng = np.random.default_rng(1)
    truth = ring_truth()
    scans = [simulate_scan(ring_segments(), pose, rng, max_range_m=6.0) for pose in truth]
    odom = drifting_odometry(truth, rng)
    open_loop = scan_match_trajectory(scans, odom, ScanMatchConfig(loop_closure=False))
    closed = scan_match_trajectory(scans, odom, ScanMatchConfig())
    assert not open_loop.loop_closure.any()
    loops = np.flatnonzero(closed.loop_closure)
    first_return = int(np.flatnonzero(np.hypot(*truth[200:, :2].T) < 1.0)[0]) + 200  # back at (0, 0)
    assert loops.size >= 2 and loops.min() >= first_return - 10
    assert np.hypot(*(closed.poses[loops, :2] - truth[loops, :2]).T).max() < 0.03
    end = slice(first_return, None)
    assert np.hypot(*(open_loop.poses[end, :2] - truth[end, :2]).T).min() > 0.1
    assert np.hypot(*(closed.poses[end, :2] - truth[end, :2]).T).max() < 0.03
    assert ate_rmse_m(closed.poses, truth) < 0.6 * ate_rmse_m(open_loop.poses, truth)
