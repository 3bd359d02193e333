"""The scan-matching pose source on simulated sequences with drifting odometry (fixed seeds)."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError
from scanmatch_sim import (
    ate_rmse_m,
    corridor_segments,
    corridor_truth,
    drifting_odometry,
    polyline,
    room_segments,
    simulate_scan,
)

from doorbatch.config import DoorbatchConfig, load_config
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import compose, interpolate_poses, relative, transform_points
from doorbatch.io.recording import load_recording
from doorbatch.pipeline.evaluate.trajectory_error import align_first_pose, ate_rmse
from doorbatch.pipeline.mapping import pass_poses
from doorbatch.pipeline.poses import ScanMatchConfig, scan_match_trajectory
from doorbatch.pipeline.poses.free_space import on_seen_surfaces
from doorbatch.pipeline.poses.plicp import GaussianPrior, map_cost, plicp_configured
from doorbatch.pipeline.poses.scanmatch import (
    basin_cost,
    grown_window,
    increment_covariance,
    prediction_covariance,
    propagated_covariance,
    search_window,
    start_submap,
    voxel_downsample,
)
from tests.conftest import REPO

JUMPS = {60: (0.3, 0.0, np.deg2rad(10.0)), 140: (-0.2, 0.1, np.deg2rad(-8.0))}  # wheel slip, a bump


def _corridor_run(n: int = 200, seed: int = 1) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    rng = np.random.default_rng(seed)
    truth = corridor_truth(n)
    scans = [simulate_scan(corridor_segments(), pose, rng) for pose in truth]
    return truth, scans, drifting_odometry(truth, rng, jumps={k: v for k, v in JUMPS.items() if k < n})


def test_scan_matching_removes_odometry_drift_along_a_corridor() -> None:
    truth, scans, odom = _corridor_run()
    result = scan_match_trajectory(scans, odom, ScanMatchConfig())
    assert ate_rmse_m(odom, truth) > 0.3
    assert ate_rmse_m(result.poses, truth) < 0.05
    assert np.allclose(result.poses[0], odom[0])
    assert not result.fallback.any()
    assert 30 < result.keyframe.sum() < 120
    yaw_err = np.abs(np.angle(np.exp(1j * (result.poses[:, 2] - truth[:, 2]))))
    assert np.rad2deg(yaw_err).max() < 0.5
    assert np.all(result.n_inliers[1:] > 100) and np.nanmax(result.residual_m) < 0.02
    std = np.sqrt(np.diagonal(result.covariances[1:], axis1=1, axis2=2))
    assert np.all(np.isfinite(std)) and np.all(std[:, :2] < 0.01)


def test_single_straight_wall_corrects_across_it_and_keeps_odometry_along_it() -> None:
    rng = np.random.default_rng(3)
    wall = polyline([(-50.0, 1.0), (50.0, 1.0)])
    truth = corridor_truth(40)
    scans = [simulate_scan(wall, pose, rng) for pose in truth]
    odom = drifting_odometry(truth, rng)
    result = scan_match_trajectory(scans, odom, ScanMatchConfig())
    assert not result.fallback.any() and result.degenerate[1:].all()
    # Across the wall and in heading the scan wins; along it nothing is invented: the odometry's 3 % scale stays.
    assert np.abs(odom[:, 1] - truth[:, 1]).max() > 0.1 and np.abs(result.poses[:, 1] - truth[:, 1]).max() < 0.005
    assert np.rad2deg(np.abs(wrap_angle(result.poses[:, 2] - truth[:, 2]))).max() < 0.1
    travel = (result.poses[-1, 0] - result.poses[0, 0]) / (truth[-1, 0] - truth[0, 0])
    assert 1.02 < travel < 1.04
    std = np.sqrt(np.diagonal(result.covariances[1:], axis1=1, axis2=2))
    assert np.all(std[:, 0] > 10.0 * std[:, 1])  # the unobservable direction keeps the prior's uncertainty


def test_too_few_points_fall_back_and_matching_resumes_after() -> None:
    truth, scans, odom = _corridor_run(n=60, seed=4)
    scans[20] = scans[20][:10]
    scans[21] = np.zeros((0, 2))
    scans[22] = np.full((50, 2), np.nan)
    result = scan_match_trajectory(scans, odom, ScanMatchConfig())
    assert np.flatnonzero(result.fallback).tolist() == [20, 21, 22]
    assert result.n_inliers[21] == 0 and np.isnan(result.residual_m[21])
    step = relative(result.poses[20], result.poses[21])
    assert np.allclose(step, relative(odom[20], odom[21]), atol=1e-9)
    assert ate_rmse_m(result.poses, truth) < 0.05


def test_result_moves_rigidly_with_the_odometry_frame() -> None:
    _, scans, odom = _corridor_run(n=40, seed=5)
    frame = np.array([-3.0, 7.0, 2.0])
    moved = scan_match_trajectory(scans, compose(frame, odom), ScanMatchConfig())
    base = scan_match_trajectory(scans, odom, ScanMatchConfig())
    expected = compose(frame, base.poses)
    # Equal up to ICP's convergence thresholds (1 mm, 0.05°) and the search lattice, which is map-axis aligned.
    assert np.abs(moved.poses[:, :2] - expected[:, :2]).max() < 0.01
    assert np.abs(np.angle(np.exp(1j * (moved.poses[:, 2] - expected[:, 2])))).max() < np.deg2rad(0.2)


def test_inputs_are_checked() -> None:
    with pytest.raises(ValueError, match=r"\(2, 3\)"):
        scan_match_trajectory([np.zeros((5, 2))] * 2, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="NaN"):
        scan_match_trajectory([np.zeros((5, 2))], np.full((1, 3), np.nan))
    empty = scan_match_trajectory([], np.zeros((0, 3)))
    assert empty.poses.shape == (0, 3) and empty.covariances.shape == (0, 3, 3)


def test_config_is_frozen_and_rejects_unknown_keys() -> None:
    with pytest.raises(ValidationError, match="window_mm"):
        ScanMatchConfig(window_mm=1.0)  # type: ignore[call-arg]
    with pytest.raises(ValidationError):
        ScanMatchConfig(trim_fraction=1.5)
    with pytest.raises(ValidationError, match="correlative_window_min_m must not exceed"):
        ScanMatchConfig(correlative_window_min_m=3.0)
    with pytest.raises(ValidationError, match="loop_window_min_m"):
        ScanMatchConfig(loop_window_min_deg=30.0)
    config = ScanMatchConfig()
    with pytest.raises(ValidationError):
        config.keyframe_min_d_m = 1.0  # type: ignore[misc]


def test_rotation_error_beyond_the_modelled_window_is_found_by_growing_the_window() -> None:
    """An in-place turn whose odometry is 30° off in one step (a tail the α-model's 3σ window leaves out)."""
    rng = np.random.default_rng(11)
    truth = np.array([[3.0, 2.6, np.deg2rad(10.0 * k)] for k in range(12)])
    scans = [simulate_scan(room_segments(), pose, rng) for pose in truth]
    inc = relative(truth[:-1], truth[1:])
    inc[3, 2] += np.deg2rad(30.0)
    odom = np.vstack([truth[:1], compose(truth[0], np.cumsum(inc, axis=0))])  # pure turns: increments add up
    cfg = ScanMatchConfig()
    window_deg = search_window(prediction_covariance(inc[3], odom[3, 2], cfg), cfg)[1]
    assert window_deg < 30.0  # the error lies outside the first window
    result = scan_match_trajectory(scans, odom, cfg)
    assert not result.fallback.any()
    assert np.rad2deg(np.abs(wrap_angle(result.poses[:, 2] - truth[:, 2]))).max() < 0.5
    assert np.abs(result.poses[:, :2] - truth[:, :2]).max() < 0.02


def test_window_grows_on_every_axis_up_to_the_maxima() -> None:
    cfg = ScanMatchConfig(window_growth=2.0, correlative_window_max_m=2.0, correlative_window_max_deg=90.0)
    assert grown_window(((0.25, 0.5), 20.0), cfg) == ((0.5, 1.0), 40.0)
    assert grown_window(((1.5, 0.5), 60.0), cfg) == ((2.0, 1.0), 90.0)  # clipped to the maxima
    assert grown_window(((2.0, 2.0), 90.0), cfg) is None  # nothing left to grow


def test_voxel_downsample_keeps_one_centroid_per_voxel() -> None:
    points = np.array([[0.01, 0.01], [0.03, 0.04], [0.26, 0.0], [-0.01, 0.0]])
    out = voxel_downsample(points, 0.05)
    assert len(out) == 3
    assert any(np.allclose(p, [0.02, 0.025]) for p in out)
    assert any(np.allclose(p, [-0.01, 0.0]) for p in out)


def test_scan_matched_sample_pass_follows_the_ground_truth_not_the_drifting_odometry() -> None:
    """The whole pose source on the bundled sample's first mapping pass (720 beams, people, moving doors)."""
    config = DoorbatchConfig()
    rec = load_recording(REPO / "datasets" / "sample" / "logs" / "map_pass1.mcap", config)
    assert rec.reference is not None and rec.odometry is not None
    matched = pass_poses(rec, "scanmatch", config)
    truth, ok = interpolate_poses(rec.reference.stamps_ns, rec.reference.poses, matched.stamps_ns)
    odom = interpolate_poses(rec.odometry.stamps_ns, rec.odometry.poses, matched.stamps_ns)[0]
    ok &= matched.valid
    assert matched.source == "scanmatch" and ok.sum() > 400
    assert ate_rmse(align_first_pose(odom[ok], truth[ok]), truth[ok]) > 0.3
    assert ate_rmse(align_first_pose(matched.poses[ok], truth[ok]), truth[ok]) < 0.05


def test_prediction_covariance_compounds_the_previous_pose_uncertainty() -> None:
    """First-order x ⊕ u: a heading σ of the previous pose becomes a lateral σ of d·σ after a move of d."""
    cfg = ScanMatchConfig()
    sigma_yaw = np.deg2rad(5.0)
    previous = np.diag([0.0, 0.0, sigma_yaw**2])
    increment = np.array([2.0, 0.0, 0.0])
    own = prediction_covariance(increment, np.pi / 2, cfg)
    cov = propagated_covariance(previous, np.array([1.0, 1.0, np.pi / 2]), increment, cfg)
    # Heading north, moved 2 m north: the heading error moves the pose along −x by 2 m per radian.
    expected = own + sigma_yaw**2 * np.array([[4.0, 0.0, -2.0], [0.0, 0.0, 0.0], [-2.0, 0.0, 1.0]])
    assert np.allclose(cov, expected)
    assert np.allclose(propagated_covariance(np.zeros((3, 3)), np.zeros(3), increment, cfg),
                       prediction_covariance(increment, 0.0, cfg))


def test_a_scan_that_cannot_be_matched_is_no_keyframe_and_its_odometry_error_is_taken_out_by_the_next() -> None:
    """A 20° wheel slip into a scan with too few points: the scan keeps the wrong prediction but does not enter
    the submap, and the next scan, searched in the window of the carried uncertainty, finds the true pose."""
    rng = np.random.default_rng(6)
    truth = corridor_truth(50)
    scans = [simulate_scan(corridor_segments(), pose, rng) for pose in truth]
    odom = drifting_odometry(truth, rng, jumps={30: (0.2, 0.0, np.deg2rad(20.0))})
    scans[30] = scans[30][:20]
    result = scan_match_trajectory(scans, odom, ScanMatchConfig())
    assert np.flatnonzero(result.fallback).tolist() == [30] and not result.keyframe[30]
    assert np.rad2deg(abs(wrap_angle(result.poses[30, 2] - truth[30, 2]))) > 15.0
    yaw_err = np.rad2deg(np.abs(wrap_angle(result.poses[31:, 2] - truth[31:, 2])))
    assert yaw_err.max() < 0.5 and np.abs(result.poses[31:, :2] - truth[31:, :2]).max() < 0.03


def test_a_scan_that_mostly_sees_ground_not_in_the_submap_is_weak_and_still_placed() -> None:
    """Scan 25 keeps 40 % of its corridor hits and gains as many again from a room the submap has never seen:
    the match is accepted (its corridor part fixes the pose) but flagged weak; the run stays accurate."""
    rng = np.random.default_rng(8)
    truth = corridor_truth(40)
    scans = [simulate_scan(corridor_segments(), pose, rng) for pose in truth]
    odom = drifting_odometry(truth, rng)
    own = scans[25][::5]
    unseen = simulate_scan(room_segments(), np.array([4.0, 2.5, 0.0]), rng)[::2] + np.array([0.0, 6.0])
    scans[25] = np.concatenate([own, unseen[: 2 * len(own)]])
    result = scan_match_trajectory(scans, odom, ScanMatchConfig())
    assert np.flatnonzero(result.weak).tolist() == [25] and not result.fallback.any()
    assert ate_rmse_m(result.poses, truth) < 0.05


def test_a_step_backwards_gets_the_prior_of_the_same_step_forwards() -> None:
    """The prior's α-model folds the rotations as the drift model and the localizers do (r = min(|δrot|,
    π − |δrot|)): a 10 cm creep backwards is not given a ±π-sized rotation window."""
    cfg = ScanMatchConfig()
    forward = increment_covariance([0.1, 0.0, 0.02], cfg)
    backward = increment_covariance([-0.1, 0.0, 0.02], cfg)
    np.testing.assert_allclose(np.diag(backward), np.diag(forward), rtol=1e-9)
    np.testing.assert_allclose(np.abs(backward), np.abs(forward), rtol=1e-9, atol=1e-15)  # a start-heading error
    assert np.sqrt(backward[2, 2]) < np.radians(3.0)                    # moves a backward end point the other way



def _front_half(scan: np.ndarray) -> np.ndarray:
    """The hits of a 180° laser facing the heading (x > 0 in the sensor frame)."""
    return scan[scan[:, 0] > 0.0]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_scan_entering_a_corridor_is_not_pulled_back_onto_its_mapped_mouth(seed: int) -> None:
    """A keyframe at the mouth of a 1 m corridor (180° laser facing down it) maps the walls' first 2 m and the end
    wall 10 m away: the walls further down it sees only at grazing angles, too steep for lines. A scan 1 m into
    the corridor fits in two basins: the truth, where its near-wall points run past the mapped mouth and its
    end-wall points sit on the end wall, and about 0.8 m back, where the near-wall points land on the mouth and
    the end-wall points short of the end wall. The plain MAP cost charges the unmapped wall points as misfits and
    prefers the slip (intel at drift seed 1, scans 823-827); the basin cost charges only points that contradict
    the keyframe's view, the end-wall points of the slip where it saw free space, and prefers the truth."""
    rng = np.random.default_rng(seed)
    walls = polyline([(-4, 4), (-4, 0), (-0.5, 0), (-0.5, -10), (0.5, -10), (0.5, 0), (4, 0), (4, 4), (-4, 4)])
    cfg = ScanMatchConfig()
    mouth, truth = np.array([0.0, 0.3, -np.pi / 2]), np.array([0.0, -0.7, -np.pi / 2])
    submap = start_submap(_front_half(simulate_scan(walls, mouth, rng, max_range_m=20.0)), mouth, cfg)
    scan = voxel_downsample(_front_half(simulate_scan(walls, truth, rng, max_range_m=20.0)), cfg.scan_voxel_m)
    prior = GaussianPrior(truth, np.linalg.inv(np.diag([0.4**2, 0.4**2, np.radians(2.0) ** 2])))
    at_truth = plicp_configured(submap.lines, scan, truth, prior, cfg)
    slipped = plicp_configured(submap.lines, scan, mouth, prior, cfg)
    assert abs(at_truth.pose[1] - truth[1]) < 0.05 and slipped.pose[1] - truth[1] > 0.4  # two basins
    sigma_m = min(at_truth.sigma_m, slipped.sigma_m)
    assert map_cost(slipped, sigma_m) < map_cost(at_truth, sigma_m)
    assert basin_cost(submap, scan, at_truth, sigma_m, cfg) < basin_cost(submap, scan, slipped, sigma_m, cfg)
    plain = ScanMatchConfig(free_space_basins=False)
    assert basin_cost(submap, scan, slipped, sigma_m, plain) == map_cost(slipped, sigma_m)
    kf = submap.keyframes[0]
    relieved = {}
    for name, result in (("truth", at_truth), ("slipped", slipped)):
        seen = on_seen_surfaces([kf.profile], kf.pose[None], transform_points(result.pose, scan[result.outside_gate]),
                                cfg.max_correspondence_m)
        relieved[name] = (int(seen.sum()), int(result.outside_gate.sum()))
    assert relieved["truth"][0] >= 10  # the wall points past the mapped mouth
    assert relieved["slipped"][0] < relieved["slipped"][1]  # its end-wall points, seen free, stay charged


def test_without_odometry_scans_are_matched_at_constant_velocity() -> None:
    """A log with no odometry (a handheld lidar): each scan predicted at the last matched velocity. The sample's
    open-door run stays within centimetres; the constant-position prediction it replaced (all-zero odometry: a
    robot that never moves, held there by the odometry floors' tight prior) ran off by metres."""
    config = load_config()
    rec = load_recording(REPO / "datasets" / "sample" / "logs" / "loc_open.mcap", config)
    assert rec.reference is not None
    stamps = rec.scans.stamps_ns
    scans = [pts[hit] for pts, hit in (rec.scans.endpoints_base(i) for i in range(len(stamps)))]
    ref, _ = interpolate_poses(rec.reference.stamps_ns, rec.reference.poses, stamps)
    moving = scan_match_trajectory(scans, None, config.scanmatch, stamps).poses
    standing = scan_match_trajectory(scans, np.zeros((len(stamps), 3)), config.scanmatch).poses
    assert ate_rmse(align_first_pose(moving, ref), ref) < 0.1
    assert ate_rmse(align_first_pose(standing, ref), ref) > 1.0
    with pytest.raises(ValueError, match="stamps"):
        scan_match_trajectory(scans, None, config.scanmatch)


def _laps(n_laps: int) -> np.ndarray:
    """Up the corridor 20 m and back, ``n_laps`` times (0.1 m per scan)."""
    up = corridor_truth(200)
    down = up[::-1].copy()
    down[:, 2] = wrap_angle(down[:, 2] + np.pi)
    return np.concatenate([up, down] * n_laps)


def _local_keyframes(truth: np.ndarray, cfg: ScanMatchConfig, rng: np.random.Generator) -> list[int]:
    """The submap's local keyframe count at the far end of each lap, keyframes placed at the true poses."""
    from doorbatch.pipeline.poses.scanmatch import add_keyframe

    segments = corridor_segments()
    submap = start_submap(simulate_scan(segments, truth[0], rng), truth[0], cfg)
    counts = []
    for k in range(1, truth.shape[0]):
        pose = truth[k]
        last = submap.last_keyframe_pose
        if np.hypot(*(pose[:2] - last[:2])) >= cfg.keyframe_min_d_m or abs(wrap_angle(pose[2] - last[2])) >= np.deg2rad(
                cfg.keyframe_min_a_deg):
            submap = add_keyframe(submap, simulate_scan(segments, pose, rng), pose, cfg)
        if k % 400 == 199:  # the far end, heading up
            counts.append(len(submap.local_profiles))
    return counts


def test_repeated_passes_leave_the_submap_the_size_of_the_first() -> None:
    """A 22.5-minute log of 14 passes had 280 keyframes in its submap, every one matched and voted over for each
    scan, and its scan matching had not finished in 9 minutes. A keyframe that stands within submap_revisit_m and
    _deg of an older one stays out: the third lap holds what the first way up and down did; with submap_revisit_m = 0
    each lap adds its keyframes."""
    cfg = ScanMatchConfig()
    thinned = _local_keyframes(_laps(3), cfg, np.random.default_rng(5))
    every = _local_keyframes(_laps(3), cfg.model_copy(update={"submap_revisit_m": 0.0}), np.random.default_rng(5))
    assert thinned[0] == every[0]  # the first lap has no revisit
    assert thinned[2] == thinned[1]  # the third holds what the first way up and down made (34 + 44)
    assert every[2] > every[1] + 0.8 * (every[1] - every[0])  # each lap adds its 68-odd keyframes


def test_scan_matching_over_repeated_passes_stays_on_the_truth() -> None:
    """Two laps with drifting odometry: the revisits matched against the first lap's keyframes alone."""
    rng = np.random.default_rng(6)
    truth = _laps(2)
    scans = [simulate_scan(corridor_segments(), pose, rng) for pose in truth]
    odom = drifting_odometry(truth, rng)
    result = scan_match_trajectory(scans, odom, ScanMatchConfig())
    assert ate_rmse_m(odom, truth) > 0.5
    assert ate_rmse_m(result.poses, truth) < 0.05 and not result.fallback.any()
