"""Shared fixtures: small logs written by the real writers into tmp_path (STYLE.md, convention 11)."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from doorbatch.io import ros_messages as m
from doorbatch.io.log_writer import LogWriter

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
CARMEN_DIR = SHARED / "datasets" / "carmen"

Message = tuple[str, str, int, Any]  # topic, msgtype, log_time_ns, ROS 2 message object
T0 = 1_700_000_000_000_000_000


def sample_messages(n_scans: int = 20, beams: int = 181, seed: int = 0) -> list[Message]:
    """A small log with every role: static and dynamic TF, scans, odometry, ground truth, colors, camera,
    detections. Messages are in log-time order."""
    rng = np.random.default_rng(seed)
    msgs: list[Message] = [
        ("/tf_static", "tf2_msgs/msg/TFMessage", T0,
         m.tf_message([m.planar_transform(T0, "base_link", "laser", 0.2, 0.0, 0.0, z=0.3),
                       m.transform_stamped(T0, "base_link", "camera_optical", (0.1, 0.0, 1.0),
                                           (-0.5, 0.5, -0.5, 0.5))])),
        ("/camera/camera_info", "sensor_msgs/msg/CameraInfo", T0,
         m.camera_info(T0, "camera_optical", 64, 48, [[50.0, 0, 32], [0, 50.0, 24], [0, 0, 1]])),
    ]
    for i in range(n_scans):
        t = T0 + 100_000_000 * (i + 1)
        x, y, yaw = 0.1 * i, 0.02 * i, 0.01 * i
        ranges = rng.uniform(0.5, 10.0, beams).astype(np.float32)
        ranges[::17] = np.nan
        ranges[::23] = np.inf
        msgs += [
            ("/tf", "tf2_msgs/msg/TFMessage", t, m.tf_message([m.planar_transform(t, "odom", "base_link", x, y, yaw)])),
            ("/odom", "nav_msgs/msg/Odometry", t, m.odometry(t, "odom", "base_link", x, y, yaw, 1.0, 0.1)),
            ("/ground_truth", "nav_msgs/msg/Odometry", t, m.odometry(t, "map", "base_link", x + 1, y, yaw)),
            ("/scan", "sensor_msgs/msg/LaserScan", t,
             m.laser_scan(t, "laser", -np.pi / 2, np.pi / (beams - 1), 0.1, 30.0, ranges)),
            ("/scan_colors", "sensor_msgs/msg/PointCloud2", t,
             m.pointcloud_xyzrgb(t, "laser", rng.normal(size=(beams, 3)), rng.integers(0, 256, (beams, 3)))),
            ("/camera/image_raw", "sensor_msgs/msg/Image", t,
             m.image_rgb8(t, "camera_optical", rng.integers(0, 256, (48, 64, 3), dtype=np.uint8))),
            ("/detections", "vision_msgs/msg/Detection2DArray", t,
             m.detection_array(t, "camera_optical", [("door", 0.9, 30.0, 20.0, 10.0, 30.0),
                                                     ("handle", 0.7, 33.0, 25.0, 2.0, 2.0)])),
        ]
    return msgs


def write_messages(path: Path, messages: Iterable[Message], fmt: str = "mcap") -> Path:
    """Write messages with doorbatch's LogWriter (rosbags/mcap underneath)."""
    with LogWriter(path, fmt) as writer:
        for topic, msgtype, t, msg in messages:
            writer.write(topic, msgtype, t, msg)
    return path


@pytest.fixture
def write_log(tmp_path: Path) -> Callable[..., Path]:
    """``write_log(name, messages, fmt)`` → path of a log in tmp_path."""

    def make(name: str, messages: Iterable[Message] | None = None, fmt: str = "mcap") -> Path:
        return write_messages(tmp_path / name, sample_messages() if messages is None else messages, fmt)

    return make


def carmen_log(name: str) -> Path:
    """Path of a real CARMEN log in ../shared, skipping the test when the dataset is absent."""
    path = CARMEN_DIR / f"{name}-corrected.log.gz"
    if not path.exists():
        pytest.skip(f"{path} is absent")
    return path
