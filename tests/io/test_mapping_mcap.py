"""The annotated MCAP of a mapping run: several input logs merged, the doors of each pass, poses and map→odom."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader

from doorbatch.io.annotated_mcap import write_annotated_mcap
from doorbatch.io.log_clock import LogClock
from doorbatch.io.mapdir import MappedPass, mapping_annotations
from doorbatch.maps import DoorSet, OccupancyMap
from tests.conftest import T0, sample_messages, write_messages


def _pass(t_first: int, n: int, x0: float, angles: list[float]) -> MappedPass:
    stamps = t_first + 100_000_000 * np.arange(n, dtype=np.int64)
    poses = np.stack([x0 + 0.1 * np.arange(n), np.zeros(n), np.full(n, 0.3)], axis=1)
    odom = poses - [0.5, 0.2, 0.0]  # map→odom is then (0.5, 0.2, 0) for every scan
    return MappedPass(stamps, poses, odom, np.array(angles))


def test_two_passes_keep_every_input_message_and_draw_each_pass_s_leaves(tmp_path: Path) -> None:
    a = write_messages(tmp_path / "a.mcap", sample_messages(4))
    b = write_messages(tmp_path / "b.mcap", sample_messages(3, seed=1))
    doors = DoorSet(np.array([[1.0, 1.0], [3.0, -1.0]]), np.array([0.9, 0.8]), np.array([0.0, math.pi]),
                    np.zeros(2), np.full(2, 1.5))
    occ = OccupancyMap(np.zeros((20, 30), dtype=np.int8), 0.1, -1.0, -1.0)
    passes = [_pass(T0, 12, 0.0, [0.5, math.nan]), _pass(T0 + 5_000_000_000, 7, 2.0, [math.nan, 1.0])]
    out = tmp_path / "annotated.mcap"
    write_annotated_mcap([a, b], out, mapping_annotations(passes, occ, doors, path_every=5))
    counts: dict[str, int] = {}
    with AnyReader([out]) as reader:
        for conn in reader.connections:
            counts[conn.topic] = counts.get(conn.topic, 0) + conn.msgcount
        msgs = [(c.topic, reader.deserialize(raw, c.msgtype)) for c, _, raw in reader.messages()]
    with AnyReader([a, b]) as reader:
        inputs = sum(c.msgcount for c in reader.connections)
    assert sum(counts.values()) == inputs + 1 + 2 + 19 + 19 + (3 + 2)  # map, doors, poses, map→odom, paths
    assert counts["/scan"] == 4 + 3
    door_msgs = [m for t, m in msgs if t == "/doorbatch/doors"]
    leaves = [[k for k in m.markers if k.ns == "leaves"] for m in door_msgs]  # type: ignore[attr-defined]
    assert [[k.id for k in pass_leaves] for pass_leaves in leaves] == [[0], [1]]
    end = leaves[0][0].points[1]
    np.testing.assert_allclose([end.x, end.y], [1.0 + 0.9 * math.cos(0.5), 1.0 + 0.9 * math.sin(0.5)], atol=1e-9)
    end = leaves[1][0].points[1]
    np.testing.assert_allclose([end.x, end.y], [3.0 + 0.8 * math.cos(math.pi + 1.0),
                                                -1.0 + 0.8 * math.sin(math.pi + 1.0)], atol=1e-9)
    map_to_odom = [tf.transforms[0] for t, tf in msgs if t == "/tf"
                   and tf.transforms[0].header.frame_id == "map"]  # type: ignore[attr-defined]
    assert len(map_to_odom) == 19
    for tr in map_to_odom:
        assert tr.child_frame_id == "odom"
        np.testing.assert_allclose([tr.transform.translation.x, tr.transform.translation.y], [0.5, 0.2], atol=1e-9)


def test_passes_on_one_restarted_clock_come_out_in_time_order() -> None:
    """Two logs that each start their (simulated) clock at the same time: the annotations interleave by time,
    as the annotated MCAP's merge with the input messages needs."""
    doors = DoorSet(np.array([[1.0, 1.0]]), np.array([0.9]), np.zeros(1), np.zeros(1), np.full(1, 1.5))
    occ = OccupancyMap(np.zeros((20, 30), dtype=np.int8), 0.1, -1.0, -1.0)
    passes = [_pass(T0, 8, 0.0, [0.2]), _pass(T0 + 50_000_000, 6, 2.0, [0.4])]
    stamps = [a.log_time_ns for a in mapping_annotations(passes, occ, doors)]
    assert stamps == sorted(stamps)
    assert len(stamps) == 1 + 2 + 2 * (8 + 6) + (1 + 1)  # map, doors per pass, pose + map→odom per scan, paths


def test_passes_recorded_on_wall_clock_with_sim_time_stamps_are_logged_on_the_recorders_clock() -> None:
    """Each pass restarts a sim clock at 0.5 s; its recorder logged it an hour apart on wall-clock time
    (Recording.log_clock). The annotations are logged on the recorder's clock, their headers keep the stamps."""
    from dataclasses import replace

    doors = DoorSet(np.array([[1.0, 1.0]]), np.array([0.9]), np.zeros(1), np.zeros(1), np.full(1, 1.5))
    occ = OccupancyMap(np.zeros((20, 30), dtype=np.int8), 0.1, -1.0, -1.0)
    offsets = (T0, T0 + 3600 * 10**9)
    passes = [replace(_pass(500_000_000, 8, 0.0, [0.2]), log_clock=LogClock.constant(offsets[0])),
              replace(_pass(500_000_000, 6, 2.0, [0.4]), log_clock=LogClock.constant(offsets[1]))]
    added = list(mapping_annotations(passes, occ, doors))
    times = [a.log_time_ns for a in added]
    assert times == sorted(times) and times[0] == T0 + 500_000_000
    poses = [a for a in added if a.topic == "/doorbatch/pose"]
    assert [a.log_time_ns - offsets[k >= 8] for k, a in enumerate(poses)] == [
        500_000_000 + 100_000_000 * (k if k < 8 else k - 8) for k in range(14)]
    stamp = poses[-1].msg.header.stamp
    assert stamp.sec * 10**9 + stamp.nanosec == 500_000_000 + 100_000_000 * 5  # the header keeps the sim stamp
