"""Run directory writers: Parquet schemas and values, TUM, and an annotated MCAP readable by rosbags."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader

from doorbatch.io.annotated_mcap import write_annotated_mcap
from doorbatch.io.parquet import read_table
from doorbatch.io.rundir import run_annotations, write_run_tables
from doorbatch.io.tum import read_tum
from doorbatch.maps import DoorSet, OccupancyMap
from doorbatch.pipeline.localize.result import LocalizationResult
from tests.conftest import T0, sample_messages, write_messages


def _result(u: int = 5, d: int = 2) -> LocalizationResult:
    rng = np.random.default_rng(0)
    stamps = T0 + 100_000_000 * (np.arange(u, dtype=np.int64) + 1)
    pose = np.stack([np.arange(u) * 0.1, np.zeros(u), np.full(u, 3.1)], axis=1)
    return LocalizationResult(
        log="a.mcap", method="rbpf", stamps_ns=stamps, pose=pose, cov=np.tile(np.eye(3) * 0.01, (u, 1, 1)),
        odom=pose - [0.5, 0.0, 0.0], n_particles=np.full(u, 100, dtype=np.int32), neff=np.full(u, 50.0),
        door_mean=rng.uniform(0, 1, (u, d)), door_std=np.full((u, d), 0.05),
        door_observed=rng.uniform(size=(u, d)) > 0.5, particles=np.zeros((u, 4, 3)),
    )


def test_tables_follow_the_schema_and_hold_the_values(tmp_path: Path) -> None:
    result = _result()
    write_run_tables(tmp_path, result)
    traj = read_table("trajectory", tmp_path / "trajectory.parquet").to_pydict()
    np.testing.assert_array_equal(traj["stamp_ns"], result.stamps_ns)
    np.testing.assert_allclose(traj["x"], result.pose[:, 0])
    assert set(traj["method"]) == {"rbpf"}
    states = read_table("door_states", tmp_path / "door_states.parquet").to_pydict()
    assert len(states["door_id"]) == 10
    np.testing.assert_allclose(np.reshape(states["angle"], (5, 2)), result.door_mean)
    stamps, x, _, yaw = read_tum(tmp_path / "trajectory.tum")
    np.testing.assert_array_equal(stamps, result.stamps_ns)
    np.testing.assert_allclose(x, result.pose[:, 0])
    np.testing.assert_allclose(yaw, 3.1)


def test_annotated_mcap_reads_back_with_rosbags(tmp_path: Path) -> None:
    log = write_messages(tmp_path / "in.bag", sample_messages(5), fmt="bag")
    occ = OccupancyMap(np.zeros((20, 30), dtype=np.int8), 0.1, -1.0, -1.0)
    doors = DoorSet(np.array([[1.0, 1.0], [2.0, 0.0]]), np.array([0.9, 0.8]), np.zeros(2), np.zeros(2),
                    np.full(2, 1.5))
    out = tmp_path / "annotated.mcap"
    write_annotated_mcap(log, out, run_annotations(_result(), occ, doors, path_every=2))
    with AnyReader([out]) as reader:
        counts: dict[str, int] = {}
        for conn in reader.connections:
            counts[conn.topic] = counts.get(conn.topic, 0) + conn.msgcount
        pose = next(reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()
                    if c.topic == "/doorbatch/pose")
    assert counts["/doorbatch/map"] == 1 and counts["/doorbatch/pose"] == 5
    assert counts["/doorbatch/doors"] == 5 and counts["/doorbatch/path"] == 3
    assert counts["/scan"] == 5 and counts["/tf"] == 5 + 5  # input TF plus map→odom per update
    assert pose.header.frame_id == "map"  # type: ignore[attr-defined]


def test_a_long_path_is_thinned_evenly_keeping_its_first_and_latest_pose() -> None:
    from doorbatch.io.rundir import path_so_far

    k = 10_000
    stamps = T0 + 100_000_000 * np.arange(k, dtype=np.int64)
    poses = np.stack([np.arange(k) * 0.1, np.zeros(k), np.zeros(k)], axis=1)
    msg = path_so_far(int(stamps[-1]), "map", stamps, poses, max_poses=500)
    xs = np.array([p.pose.position.x for p in msg.poses])  # type: ignore[attr-defined]
    assert len(xs) == 500 and xs[0] == 0.0 and xs[-1] == poses[-1, 0]
    gaps = np.diff(xs)
    assert gaps.min() > 0 and gaps.max() - gaps.min() <= 0.1 + 1e-9  # evenly spaced, within one pose
    short = path_so_far(int(stamps[9]), "map", stamps[:10], poses[:10], max_poses=500)
    assert len(short.poses) == 10  # type: ignore[attr-defined]


def test_an_mcl_run_shows_the_maps_doors_without_leaves(tmp_path: Path) -> None:
    """DESIGN's annotated MCAP has /doorbatch/doors for every run; MCL estimates no door angle, so its markers
    are the map's hinges and opening ranges alone, written once at the first update (they had been repeated at every
    update: 74 MB of a 36-minute run's annotated.mcap, hAM)."""
    log = write_messages(tmp_path / "in.bag", sample_messages(5), fmt="bag")
    occ = OccupancyMap(np.zeros((20, 30), dtype=np.int8), 0.1, -1.0, -1.0)
    doors = DoorSet(np.array([[1.0, 1.0], [2.0, 0.0]]), np.array([0.9, 0.8]), np.zeros(2), np.zeros(2),
                    np.full(2, 1.5))
    out = tmp_path / "annotated.mcap"
    mcl = replace(_result(d=0), method="mcl")
    write_annotated_mcap(log, out, run_annotations(mcl, occ, doors, path_every=2))
    with AnyReader([out]) as reader:
        arrays = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()
                  if c.topic == "/doorbatch/doors"]
    assert len(arrays) == 1
    spaces = [m.ns for m in arrays[0].markers]  # type: ignore[attr-defined]
    assert sorted(spaces) == ["hinges", "hinges", "ranges", "ranges"]


def test_the_logs_own_map_to_odom_is_left_out_where_doorbatchs_replaces_it(tmp_path: Path) -> None:
    """A log with another localizer's map→odom on /tf (alone, and in one message with odom→base_link): the copy
    keeps every other transform and only doorbatch's map→odom, so a viewer's map frame does not flip between two."""
    from doorbatch.io import ros_messages as m
    from doorbatch.io.annotated_mcap import Annotation
    from doorbatch.io.reader import open_log

    messages = sample_messages(n_scans=4)
    foreign = [("/tf", "tf2_msgs/msg/TFMessage", T0 + 1, m.tf_message([m.planar_transform(T0 + 1, "map", "odom",
                                                                                           5.0, 0.0, 0.0)])),
               ("/tf", "tf2_msgs/msg/TFMessage", T0 + 2, m.tf_message([
                   m.planar_transform(T0 + 2, "map", "odom", 5.0, 0.0, 0.0),
                   m.planar_transform(T0 + 2, "odom", "base_footprint", 0.0, 0.0, 0.0)]))]
    log = write_messages(tmp_path / "in.mcap", sorted([*messages, *foreign], key=lambda x: x[2]))
    ours = [Annotation("/tf", "tf2_msgs/msg/TFMessage", T0 + 3,
                       m.tf_message([m.planar_transform(T0 + 3, "map", "odom", 1.0, 0.0, 0.0)]))]
    out = tmp_path / "annotated.mcap"
    copy = write_annotated_mcap(log, out, ours, replaced_tf=[("map", "odom")])
    with open_log(out) as reader:
        edges = [(t.header.frame_id, t.child_frame_id, t.transform.translation.x)
                 for raw in reader.raw_messages(["/tf"]) for t in raw.msg.transforms]
    assert copy.replaced_transforms == 2
    assert [e for e in edges if e[:2] == ("map", "odom")] == [("map", "odom", 1.0)]
    assert ("odom", "base_footprint", 0.0) in edges and sum(e[:2] == ("odom", "base_link") for e in edges) == 4
