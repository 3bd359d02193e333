"""A holonomic base's log: localize sees the odometry strafe and takes the omnidirectional model, unless the config
names the model (then it warns)."""

from __future__ import annotations

import numpy as np
import pytest
from mcl_sim import LASER_X, asymmetric_room, axis_scaled_odometry, loop_trajectory, room_map, scan_ranges

from doorbatch.config import DoorbatchConfig, load_config
from doorbatch.io.recording import PoseSeries, Recording, ScanSet
from doorbatch.maps import DoorSet
from doorbatch.pipeline.localize.run import LocalizationMap, localize_recording, motion_model_for

PERIOD_NS = 100_000_000


def _strafing_recording(differential: bool = False) -> tuple[Recording, np.ndarray]:
    """The room loop driven facing +x all the way (a mecanum base: sideways half the time), or with the heading
    along the path (a differential base); odometry with a 3 % scale error on each axis and white noise."""
    truth = loop_trajectory(240)
    if not differential:
        truth[:, 2] = 0.0
    rng = np.random.default_rng(3)
    odom = axis_scaled_odometry(truth, rng)
    segments = asymmetric_room()
    ranges, angles = zip(*(scan_ranges(segments, pose, noise_m=0.01, rng=rng) for pose in truth), strict=True)
    n = len(truth)
    stamps = np.arange(n, dtype=np.int64) * PERIOD_NS
    scans = ScanSet(stamps, [r.astype(np.float32) for r in ranges], np.full(n, angles[0][0]),
                    np.full(n, angles[0][1] - angles[0][0]), np.full(n, 0.05), np.full(n, 12.0),
                    np.broadcast_to(np.array([[1.0, 0.0, LASER_X], [0.0, 1.0, 0.0]]), (n, 2, 3)).copy(), "laser")
    return Recording("strafe.mcap", scans, PoseSeries(stamps, odom, "odom"), None), truth


@pytest.mark.parametrize("config_sets_it", [False, True])
def test_a_strafing_base_is_localized_with_the_omnidirectional_model_unless_told(config_sets_it: bool) -> None:
    rec, truth = _strafing_recording()
    config = load_config(None, ["localize.robot_model_type=differential"] if config_sets_it else [])
    lmap = LocalizationMap.of(room_map(), DoorSet.empty(), config.localize)
    result = localize_recording(rec, lmap, config, "mcl", tuple(truth[0]))
    note = [w for w in result.warnings if "sideways" in w]
    assert len(note) == 1
    at = np.searchsorted(rec.scans.stamps_ns, result.stamps_ns)
    error = np.hypot(*(result.pose[:, :2] - truth[at, :2]).T)
    if config_sets_it:
        assert "robot_model_type=omnidirectional" in note[0]  # the fix is named; the model is the one asked for
    else:
        assert "localized with robot_model_type omnidirectional" in note[0]
        assert error.mean() < 0.05 and error.max() < 0.15


def test_a_differential_base_keeps_the_differential_model_without_a_word() -> None:
    rec, _ = _strafing_recording(differential=True)
    assert rec.odometry is not None
    lc = DoorbatchConfig().localize
    assert motion_model_for(rec.odometry, lc) == (lc, None)
    strafing, _ = _strafing_recording()
    assert strafing.odometry is not None
    chosen, note = motion_model_for(strafing.odometry, lc)
    assert chosen.robot_model_type == "omnidirectional" and note is not None
