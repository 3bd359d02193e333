"""A driver restart bridged in one pass, carried on to the passes recorded after it in the driver's new frame."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from doorbatch.config import DoorbatchConfig
from doorbatch.io import ros_messages as m
from doorbatch.io.recording import load_recording
from doorbatch.pipeline.mapping import carried_bridges, check_common_frame, odometry_jump
from tests.conftest import T0, sample_messages


def _with_odometry(xs: np.ndarray, t_start: int) -> list:
    """The sample log's scans (and mounts) with /odom driving along x through ``xs`` (one per scan), no /tf odometry,
    stamped from ``t_start``."""
    out = []
    k = 0
    for topic, msgtype, t, msg in sample_messages(n_scans=len(xs)):
        if topic in ("/tf", "/ground_truth"):
            continue
        if topic == "/odom":
            msg = m.odometry(t, "odom", "base_link", float(xs[k]), 0.0, 0.0)
            k += 1
        out.append((topic, msgtype, t, msg))
    shift = t_start - T0
    return [(topic, msgtype, t + shift, msg) for topic, msgtype, t, msg in out]


def test_a_pass_continuing_the_restarted_frame_is_moved_as_the_restart_was_bridged(
        write_log: Callable[..., Path]) -> None:
    """Pass 1 drives x 5.0 → 5.9 m, its driver restarts at 0 (moving on to 0.9 m); pass 2, recorded on, goes on
    from 1.0 m. Bridged, pass 1 ends at 6.8 m: pass 2 lies 5.8 m from it (disjoint frames, before). Carried: pass 2
    starts 0.1 m on from pass 1's bridged end, and the passes share one frame."""
    one = np.concatenate([5.0 + 0.1 * np.arange(10), 0.1 * np.arange(10)])
    two = 1.0 + 0.1 * np.arange(20)
    a = load_recording(write_log("p1.mcap", _with_odometry(one, T0)))
    b = load_recording(write_log("p2.mcap", _with_odometry(two, T0 + 5_000_000_000)))
    config = DoorbatchConfig()
    assert a.odometry is not None and a.odometry_bridge is not None
    np.testing.assert_allclose(a.odometry.poses[-1], [6.8, 0.0, 0.0], atol=1e-9)
    assert odometry_jump(a, b)[0] > 5.0
    passes, notes = carried_bridges([a, b], config)
    assert passes[1].odometry is not None and len(notes) == 1 and "p2.mcap" in notes[0]
    np.testing.assert_allclose(passes[1].odometry.poses[0], [6.9, 0.0, 0.0], atol=1e-9)
    check_common_frame(passes, "odometry", config)  # no error
    assert carried_bridges([b, a], config)[1] == []  # nothing bridged before: nothing carried


def test_every_piece_of_the_moved_log_moves_with_it(write_log: Callable[..., Path]) -> None:
    """Pass 2 cut in two pieces (mapping.pass_duration_s): its second piece continues its first (one log), and
    is moved by the same bridge; it lay 6 m off before, with no error (continues_piece took it as chained)."""
    one = np.concatenate([5.0 + 0.1 * np.arange(10), 0.1 * np.arange(10)])
    two = 1.0 + 0.1 * np.arange(20)
    a = load_recording(write_log("p1.mcap", _with_odometry(one, T0)))
    b = load_recording(write_log("p2.mcap", _with_odometry(two, T0 + 5_000_000_000)))
    pieces = [b.take(0, 10, "p2.mcap [0]", 0), b.take(10, 20, "p2.mcap [1]", 1)]
    passes, _ = carried_bridges([a, *pieces], DoorbatchConfig())
    assert passes[1].odometry is not None and passes[2].odometry is not None
    np.testing.assert_allclose(passes[1].odometry.poses[0, 0], 6.9, atol=1e-9)
    assert passes[2].odometry.poses[0, 0] - passes[1].odometry.poses[-1, 0] < 0.2


def test_the_odometry_drawn_keeps_the_restart_the_filter_is_spared(write_log: Callable[..., Path]) -> None:
    """Bridging moves the odometry the mapper and the filter use, not the log: the odometry a viewer of the log
    draws the robot from (and annotated map→odom is computed against) still jumps back to 0 at the restart."""
    one = np.concatenate([5.0 + 0.1 * np.arange(10), 0.1 * np.arange(10)])
    a = load_recording(write_log("p1.mcap", _with_odometry(one, T0)))
    assert a.odometry is not None and a.drawn_odometry is not None
    np.testing.assert_allclose(a.odometry.poses[:, 0], 5.0 + 0.1 * np.concatenate([np.arange(10), 9 + np.arange(10)]),
                               atol=1e-9)
    np.testing.assert_allclose(a.drawn_odometry.poses[:, 0], one, atol=1e-9)
    moved = carried_bridges([a, load_recording(write_log("p2.mcap", _with_odometry(1.0 + 0.1 * np.arange(20),
                                                                                    T0 + 5_000_000_000)))],
                            DoorbatchConfig())[0][1]
    assert moved.drawn_odometry is not None
    np.testing.assert_allclose(moved.drawn_odometry.poses[:, 0], 1.0 + 0.1 * np.arange(20), atol=1e-9)
