"""The QoS a written log records for each topic: ``ros2 bag play`` replays /tf_static and the map latched only
when the bag says their publishers offered transient local durability."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.interfaces import QosDurability
from rosbags.rosbag2.metadata import parse_qos

from doorbatch.io import ros_messages
from doorbatch.io.log_writer import LogFormat, LogWriter

LATCHED = {"/tf_static": True, "/doorbatch/map": True, "/scan_like_grid": False}


def _write(path: Path, fmt: LogFormat) -> None:
    grid = ros_messages.occupancy_grid(1, "map", np.zeros((2, 2), dtype=np.int8), 0.1, 0.0, 0.0)
    mount = ros_messages.transform_stamped(1, "base_link", "laser", (0.2, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    tf = ros_messages.tf_message([mount])
    with LogWriter(path, fmt) as writer:
        writer.write("/tf_static", "tf2_msgs/msg/TFMessage", 1, tf)
        writer.write("/doorbatch/map", "nav_msgs/msg/OccupancyGrid", 2, grid)
        writer.write("/scan_like_grid", "nav_msgs/msg/OccupancyGrid", 3, grid)


def test_an_mcap_records_tf_static_and_the_map_as_latched(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    _write(path, LogFormat.MCAP)
    with path.open("rb") as f:
        channels = make_reader(f).get_summary().channels.values()
    durability = {c.topic: parse_qos(c.metadata["offered_qos_profiles"])[0].durability for c in channels}
    assert durability == {t: QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE
                          for t, latched in LATCHED.items()}


@pytest.mark.parametrize("fmt", [LogFormat.ROSBAG2, LogFormat.ROSBAG2_MCAP])
def test_a_ros2_bag_records_tf_static_and_the_map_as_latched(tmp_path: Path, fmt: LogFormat) -> None:
    path = tmp_path / "bag"
    _write(path, fmt)
    with AnyReader([path]) as reader:
        durability = {c.topic: c.ext.offered_qos_profiles[0].durability for c in reader.connections}
    assert durability == {t: QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE
                          for t, latched in LATCHED.items()}
