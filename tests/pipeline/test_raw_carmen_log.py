"""A raw CARMEN log, whose laser poses are its odometry, is mapped from scan matching, not from those poses.

Radish's raw logs hold the robot's odometry in every FLASER line twice, as the laser pose and as the odometry;
only a corrected log has other poses there (and then its odometry was replaced by them too). The reader cannot
tell the two apart, so it offers the laser poses as a reference either way. A raw log is made here from the real
orebro log: every pose field replaced by one drifting odometry (the simulator's drift model, a fixed seed).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from doorbatch.config import DoorbatchConfig
from doorbatch.io.carmen_rewrite import rewrite_carmen_poses
from doorbatch.io.recording import load_recording
from doorbatch.pipeline.evaluate.trajectory_error import align_first_pose, position_errors
from doorbatch.pipeline.mapping import build_map
from doorbatch.sim.scenario import load_scenario
from doorbatch.sim.simulate import scenario_drift
from tests.conftest import carmen_log


def _raw_log(corrected: Path, out: Path, seed: int) -> Path:
    """``corrected`` with its FLASER laser poses, FLASER odometry and ODOM lines all one drifted odometry."""
    rng = np.random.default_rng(seed)
    rewrite_carmen_poses(corrected, out, lambda poses: scenario_drift(poses, load_scenario(None), rng))
    return out


def test_a_raw_carmen_log_is_mapped_from_scan_matching(tmp_path: Path) -> None:
    corrected = carmen_log("orebro")
    raw = _raw_log(corrected, tmp_path / "orebro-raw.log", seed=7)
    config = DoorbatchConfig()
    door_map = build_map([raw], config)
    assert door_map.pose_source == "scanmatch"
    assert any("the odometry again" in w for w in door_map.warnings)

    truth = load_recording(corrected, config).reference
    odometry = load_recording(raw, config).odometry
    assert truth is not None and odometry is not None
    mapped = door_map.passes[0]
    assert np.array_equal(truth.stamps_ns, mapped.stamps_ns) and mapped.valid.all()
    matched = position_errors(align_first_pose(mapped.poses, truth.poses), truth.poses)
    dead_reckoned = position_errors(align_first_pose(odometry.poses[np.isin(odometry.stamps_ns, truth.stamps_ns)],
                                                     truth.poses), truth.poses)
    # what the raw log's own poses would have drawn the map from, and what scan matching gives (the orebro figures
    # of docs/results.md: 0.25 m first-pose ATE over drift seeds, against the corrected poses)
    assert np.sqrt(np.mean(dead_reckoned**2)) > 3.0
    assert np.sqrt(np.mean(matched**2)) < 0.5
