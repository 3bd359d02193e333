"""load_recording: arrays equal what was written; laser→base from TF; missing TF is a clear error."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from doorbatch.config import DoorbatchConfig, IoConfig
from doorbatch.errors import LogContentError
from doorbatch.io.recording import load_recording
from tests.conftest import sample_messages


def test_recording_holds_scans_poses_and_colors(write_log: Callable[..., Path]) -> None:
    messages = sample_messages(n_scans=6, beams=91)
    rec = load_recording(write_log("a.bag", messages, fmt="bag"), with_colors=True)
    scans = [msg for topic, _, _, msg in messages if topic == "/scan"]
    assert len(rec.scans) == 6
    for i, msg in enumerate(scans):
        np.testing.assert_array_equal(rec.scans.ranges[i], msg.ranges)
    np.testing.assert_allclose(rec.scans.laser_to_base[0], [[1, 0, 0.2], [0, 1, 0]], atol=1e-12)
    assert rec.odometry is not None and rec.reference is not None
    np.testing.assert_allclose(rec.reference.poses[:, 0] - rec.odometry.poses[:, 0], 1.0)
    assert rec.colors is not None and rec.colors[0].shape == (91, 3)
    pts, hit = rec.scans.endpoints_base(0)
    r = scans[0].ranges.astype(float)
    ang = scans[0].angle_min + scans[0].angle_increment * np.arange(91)
    np.testing.assert_allclose(pts[hit], np.stack([r * np.cos(ang) + 0.2, r * np.sin(ang)], 1)[hit], atol=1e-6)


def test_missing_laser_transform_is_an_error_unless_assumed(write_log: Callable[..., Path]) -> None:
    path = write_log("notf.mcap", [m for m in sample_messages(3) if m[0] != "/tf_static"])
    with pytest.raises(LogContentError, match="laser"):
        load_recording(path)
    rec = load_recording(path, DoorbatchConfig(io=IoConfig(assume_identity_laser_tf=True)))
    np.testing.assert_allclose(rec.scans.laser_to_base[0], [[1, 0, 0], [0, 1, 0]])
