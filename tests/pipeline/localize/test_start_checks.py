"""What localize checks before it runs: a holonomic base's odometry (it strafes) takes the omnidirectional model
unless the config names one, and a start pose where the first scan does not fit the map is told."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from mcl_sim import axis_scaled_odometry, loop_trajectory, room_map, room_recording

from doorbatch.config import DoorbatchConfig, load_config
from doorbatch.io.recording import Recording
from doorbatch.maps import DoorSet
from doorbatch.pipeline.localize.run import LocalizationMap, localize_recording, motion_model_for, start_fit_note


def _strafing_recording(differential: bool = False) -> tuple[Recording, np.ndarray]:
    """The room loop driven facing +x all the way (a mecanum base: sideways half the time), or with the heading
    along the path (a differential base); odometry with a 3 % scale error on each axis and white noise."""
    truth = loop_trajectory(240)
    if not differential:
        truth[:, 2] = 0.0
    rng = np.random.default_rng(3)
    odom = axis_scaled_odometry(truth, rng)
    return room_recording(truth, odom, rng), truth


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


def test_a_reference_in_another_frame_than_the_map_is_told_at_the_start() -> None:
    """--init reference where the reference's frame is not the map's (a simulator's world frame against a map from
    scan-matched poses, in the odometry's frame): the first scan does not fit there, and the warning says why."""
    truth = loop_trajectory(60)
    rng = np.random.default_rng(5)
    odom = axis_scaled_odometry(truth, rng)
    shifted = truth + np.array([13.0, -4.0, 0.0])  # the reference's frame 13 m away from the map's
    config = DoorbatchConfig()
    # a scan-matched map with a reference whose start fits (a Stage user's 1 m along a corridor: 0.94 m APE, no word)
    # is told too, without the misfit
    for reference, source, told in ((truth, "reference", False), (shifted, "reference", True),
                                    (shifted, "scanmatch", True), (truth, "scanmatch", True)):
        rec = room_recording(truth, odom, np.random.default_rng(1), reference=reference)
        lmap = LocalizationMap.of(room_map(), DoorSet.empty(), config.localize, pose_source=source)
        note = start_fit_note(rec, lmap, "reference", config.localize)
        assert (note is not None) == told
        if note is not None:
            assert ("odometry frame" in note) == (source == "scanmatch")
            assert ("--init global" in note) == (reference is shifted)  # the misfit's advice
    good = room_recording(truth, odom, np.random.default_rng(1))
    lmap = LocalizationMap.of(room_map(), DoorSet.empty(), config.localize)
    assert start_fit_note(good, lmap, tuple(truth[0]), config.localize) is None
    assert start_fit_note(good, lmap, (truth[0, 0], truth[0, 1], truth[0, 2] + 1.5), config.localize) is not None


def test_a_gap_in_the_scans_is_told_in_the_run(write_log: Callable[..., Path]) -> None:
    """5 s without scans: inspect told it, the run's trajectory just had a hole. The run now says where."""
    from doorbatch.io.recording import load_recording
    from doorbatch.pipeline.localize.run import gap_notes
    from tests.conftest import sample_messages

    messages = sample_messages(30)
    scans = [k for k, msg in enumerate(messages) if msg[0] == "/scan"]
    holed = [msg for k, msg in enumerate(messages) if k not in scans[12:20]]
    assert gap_notes(load_recording(write_log("whole.mcap", messages), DoorbatchConfig()), 5.0) == []
    notes = gap_notes(load_recording(write_log("holed.mcap", holed), DoorbatchConfig()), 5.0)
    assert len(notes) == 1 and notes[0].startswith("1 gap(s) in the scans (") and "no poses there" in notes[0]


def test_a_tracked_start_converges_at_its_first_update_when_odometry_begins_after_the_first_scan() -> None:
    """A 100 Hz odometry whose first pose comes after the first scan: the run's first update is the second scan,
    yet its convergence was dated at the first scan, and evaluate reported time_to_converge_s = -0.100."""
    from dataclasses import replace

    from doorbatch.io.recording import PoseSeries

    truth = loop_trajectory(40)
    rng = np.random.default_rng(2)
    rec = room_recording(truth, axis_scaled_odometry(truth, rng), rng, reference=truth)
    assert rec.odometry is not None
    late = rec.odometry.stamps_ns > rec.scans.stamps_ns[0] + 50_000_000  # no odometry at the first scan
    rec = replace(rec, odometry=PoseSeries(rec.odometry.stamps_ns[late], rec.odometry.poses[late], "odom"))
    config = DoorbatchConfig()
    lmap = LocalizationMap.of(room_map(), DoorSet.empty(), config.localize)
    result = localize_recording(rec, lmap, config, "mcl", "reference")
    assert result.stamps_ns[0] == rec.scans.stamps_ns[1]
    assert result.manifest_extra()["converged_after_s"] == 0.0
