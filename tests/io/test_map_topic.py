"""A map from a log's OccupancyGrid topic: the last message, cells outside -1..100 unknown, bad sizes refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from doorbatch.errors import InputDataError, UsageError
from doorbatch.io import ros_messages
from doorbatch.io.log_writer import LogWriter
from doorbatch.io.map_topic import read_map_topic

GRID = "nav_msgs/msg/OccupancyGrid"


def _log(path: Path, *grids: tuple[str, object]) -> Path:
    with LogWriter(path) as writer:
        for t, (topic, msg) in enumerate(grids, start=1):
            writer.write(topic, GRID, t, msg)
    return path


def test_the_only_grid_topic_is_the_map_and_foreign_values_are_unknown(tmp_path: Path) -> None:
    cells = np.array([[0, 100, -1], [50, 120, -100]], dtype=np.int8)
    log = _log(tmp_path / "a.mcap", ("/slam/map", ros_messages.occupancy_grid(1, "map", cells, 0.1, 1.0, 2.0, 0.5)))
    occ = read_map_topic(log)
    np.testing.assert_array_equal(occ.occupancy, [[0, 100, -1], [50, -1, -1]])
    assert (occ.origin_x_m, occ.origin_y_m) == (1.0, 2.0) and occ.origin_yaw_rad == pytest.approx(0.5)


def test_several_grid_topics_without_map_need_one_named(tmp_path: Path) -> None:
    cells = np.zeros((2, 2), dtype=np.int8)
    msg = ros_messages.occupancy_grid(1, "map", cells, 0.1, 0.0, 0.0)
    log = _log(tmp_path / "b.mcap", ("/a", msg), ("/b", msg))
    with pytest.raises(UsageError, match="/a, /b"):
        read_map_topic(log)
    assert read_map_topic(log, "/b").occupancy.shape == (2, 2)


def test_data_that_does_not_fill_the_grid_is_bad_input(tmp_path: Path) -> None:
    msg = ros_messages.occupancy_grid(1, "map", np.zeros((2, 2), dtype=np.int8), 0.1, 0.0, 0.0)
    msg.info.width = 3
    with pytest.raises(InputDataError, match="4 cells for 3 x 2"):
        read_map_topic(_log(tmp_path / "c.mcap", ("/map", msg)))
