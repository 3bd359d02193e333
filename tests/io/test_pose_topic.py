"""A start pose from a log's pose topic: the first message, its stamp and its covariance."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from doorbatch.errors import UsageError
from doorbatch.io import ros_messages
from doorbatch.io.pose_topic import read_pose_topic, read_start_pose
from tests.conftest import sample_messages

RVIZ_COVARIANCE = np.diag([0.25, 0.25, 0.0, 0.0, 0.0, 0.06853891945200942])  # RViz's 2D Pose Estimate


def test_the_first_initialpose_gives_pose_stamp_and_spread(write_log: Callable[..., Path]) -> None:
    t0 = sample_messages()[0][2]
    first = ros_messages.pose_with_covariance_stamped(t0 + 5, "map", 1.0, -2.0, 0.5, RVIZ_COVARIANCE)
    second = ros_messages.pose_with_covariance_stamped(t0 + 9, "map", 7.0, 7.0, 0.0, RVIZ_COVARIANCE)
    msgtype = "geometry_msgs/msg/PoseWithCovarianceStamped"
    log = write_log("a.mcap", [*sample_messages(), ("/initialpose", msgtype, t0 + 6, first),
                               ("/initialpose", msgtype, t0 + 10, second)])
    start = read_start_pose(log, "/initialpose")
    assert (start.stamp_ns, start.log_time_ns, start.frame_id) == (t0 + 5, t0 + 6, "map")
    np.testing.assert_allclose(start.pose, [1.0, -2.0, 0.5])
    assert start.sigma is not None
    np.testing.assert_allclose(start.sigma, [0.5, 0.5, math.sqrt(0.06853891945200942)])


def test_a_pose_without_a_usable_covariance_has_no_spread(write_log: Callable[..., Path]) -> None:
    t0 = sample_messages()[0][2]
    zero = ros_messages.pose_with_covariance_stamped(t0, "map", 1.0, 2.0, 0.0, np.zeros((6, 6)))
    log = write_log("b.mcap", [*sample_messages(), ("/initialpose", "geometry_msgs/msg/PoseWithCovarianceStamped",
                                                    t0, zero)])
    # localize then spreads the cloud by init_sigma_*; AMCL would put every particle on the one pose
    assert read_start_pose(log, "/initialpose").sigma is None


@pytest.mark.parametrize(("topic", "message"), [("/nope", "no such topic"), ("/scan", "not a pose")])
def test_a_topic_that_gives_no_pose_is_a_usage_error(write_log: Callable[..., Path], topic: str,
                                                      message: str) -> None:
    with pytest.raises(UsageError, match=message):
        read_start_pose(write_log("c.mcap"), topic)


def test_a_pose_topic_reads_as_a_trajectory_in_stamp_order(write_log: Callable[..., Path]) -> None:
    """/amcl_pose as a trajectory: every message, ordered by header stamp (logged out of order here)."""
    t0 = sample_messages()[0][2]
    msgtype = "geometry_msgs/msg/PoseWithCovarianceStamped"
    poses = [(t0 + 20, 2.0), (t0 + 10, 1.0), (t0 + 30, 3.0)]
    log = write_log("amcl.mcap", [*sample_messages(), *[
        ("/amcl_pose", msgtype, t0 + k, ros_messages.pose_with_covariance_stamped(t, "map", x, 0.0, 0.0, np.eye(6)))
        for k, (t, x) in enumerate(poses)]])
    stamps, xyz = read_pose_topic(log, "/amcl_pose")
    np.testing.assert_array_equal(stamps, [t0 + 10, t0 + 20, t0 + 30])
    np.testing.assert_allclose(xyz[:, 0], [1.0, 2.0, 3.0])
