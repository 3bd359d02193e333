"""An odometry whose pose is set from outside mid-log (an EKF's set_pose): the jump is taken out, with a warning."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from doorbatch.io import ros_messages as m
from doorbatch.io.recording import load_recording
from tests.conftest import sample_messages


def test_a_set_pose_mid_log_is_bridged_and_said(write_log: Callable[..., Path]) -> None:
    """/odom drives along x at 0.1 m a message; at message 10 it is set to (−6, 4, 100°) (7.98 m from 0.9 m) and
    drives on along its heading. Read, the odometry goes on along x from 0.9 m (the step across the set pose is no
    motion) to 1.8 m, and a warning names the jump."""
    messages, k = [], 0
    for topic, msgtype, t, msg in sample_messages(n_scans=20):
        if topic in ("/tf", "/ground_truth"):
            continue
        if topic == "/odom":
            heading = np.radians(100.0)
            x, y, yaw = ((0.1 * k, 0.0, 0.0) if k < 10 else
                         (-6.0 + 0.1 * (k - 10) * np.cos(heading), 4.0 + 0.1 * (k - 10) * np.sin(heading), heading))
            msg = m.odometry(t, "odom", "base_link", x, y, yaw)
            k += 1
        messages.append((topic, msgtype, t, msg))
    rec = load_recording(write_log("set_pose.mcap", messages))
    assert rec.odometry is not None
    steps = np.hypot(*np.diff(rec.odometry.poses[:, :2], axis=0).T)
    np.testing.assert_allclose(steps, [0.1] * 9 + [0.0] + [0.1] * 9, atol=1e-9)
    np.testing.assert_allclose(rec.odometry.poses[-1], [1.8, 0.0, 0.0], atol=1e-9)
    said = [w for w in rec.warnings if "set_pose" in w]
    assert len(said) == 1 and "1 time(s)" in said[0] and "7.98 m, 100°" in said[0]
