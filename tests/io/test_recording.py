"""load_recording: arrays equal what was written; laser→base from TF; missing TF is a clear error."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from doorbatch.config import DoorbatchConfig, IoConfig, load_config
from doorbatch.errors import LogContentError
from doorbatch.io import ros_messages as m
from doorbatch.io.recording import load_recording, unset_stamps
from tests.conftest import T0, sample_messages


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


def test_a_lidar_cloud_taken_for_colours_by_its_type_is_left_out_with_a_warning(
        write_log: Callable[..., Path]) -> None:
    """A 3D lidar's /velodyne_points (x, y, z, intensity) beside the scan: the only PointCloud2, so taken for beam
    colours, where it has no rgb. It had made `doorbatch map` refuse the log; now the log is read without colours,
    with a warning. Named as the colour topic in the config, it is still an error."""
    from dataclasses import replace as with_field

    messages = []
    for topic, msgtype, t, msg in sample_messages(n_scans=6, beams=91):
        if topic.startswith("/camera"):  # no camera: the cloud is the only source of colours there is
            continue
        if topic == "/scan_colors":
            topic = "/velodyne_points"
            msg.fields = [with_field(f, name="intensity") if f.name == "rgb" else f for f in msg.fields]
        messages.append((topic, msgtype, t, msg))
    path = write_log("lidar.mcap", messages)
    rec = load_recording(path, with_colors=True)
    assert rec.colors is None and len(rec.scans) == 6
    assert any("/velodyne_points" in w and "no colour cloud" in w for w in rec.warnings)
    with pytest.raises(LogContentError, match="rgb"):
        load_recording(path, load_config(overrides=["topics.colors=/velodyne_points"]), with_colors=True)


def test_missing_laser_transform_is_an_error_unless_assumed(write_log: Callable[..., Path]) -> None:
    path = write_log("notf.mcap", [m for m in sample_messages(3) if m[0] != "/tf_static"])
    with pytest.raises(LogContentError, match="laser"):
        load_recording(path)
    rec = load_recording(path, DoorbatchConfig(io=IoConfig(assume_identity_laser_tf=True)))
    np.testing.assert_allclose(rec.scans.laser_to_base[0], [[1, 0, 0], [0, 1, 0]])


def test_a_laser_mount_given_in_the_config_stands_in_for_a_missing_tf_static(write_log: Callable[..., Path]) -> None:
    """A recording started after /tf_static was latched: io.laser_mount (x y z roll pitch yaw) gives the mount the
    log lacks (upside down: roll π mirrors the fan), with a warning; the log's own TF wins where it has one."""
    with_tf = load_recording(write_log("tf.mcap", sample_messages(3)))
    path = write_log("notf.mcap", [m for m in sample_messages(3) if m[0] != "/tf_static"])
    mounted = load_recording(path, load_config(None, ["io.laser_mount=[0.2,0,0.3,0,0,0]"]))
    np.testing.assert_allclose(mounted.scans.laser_to_base, with_tf.scans.laser_to_base, atol=1e-12)
    assert any("io.laser_mount" in w for w in mounted.warnings)
    flipped = load_recording(path, load_config(None, [f"io.laser_mount=[0.2,0,0.3,{math.pi},0,0]"]))
    np.testing.assert_allclose(flipped.scans.laser_to_base[0], [[1, 0, 0.2], [0, -1, 0]], atol=1e-12)
    ignored = load_recording(write_log("tf2.mcap", sample_messages(3)),
                             load_config(None, [f"io.laser_mount=[0,0,0,{math.pi},0,0]"]))
    np.testing.assert_allclose(ignored.scans.laser_to_base, with_tf.scans.laser_to_base, atol=1e-12)


@pytest.mark.parametrize(("sweep_s", "deskew", "told"), [(0.09, False, True), (0.05, False, False),
                                                         (0.0, False, False), (0.09, True, False)])
def test_a_laser_that_sweeps_while_the_robot_moves_is_told_unless_deskewed(write_log: Callable[..., Path],
                                                                           sweep_s: float, deskew: bool,
                                                                           told: bool) -> None:
    """The sample robot drives 1.02 m/s turning 0.1 rad/s, a scan every 0.1 s: a 0.09 s sweep moves a beam end at
    5 m by (1.02 + 0.1·5)·0.09 = 0.14 m; with io.deskew off that is a warning; 0.05 s moves it 0.08 m (below the
    0.1 m of io.sweep_smear_warn_m); a driver that leaves time_increment 0 tells nothing. Deskewed (the default),
    the scans change and nothing is told."""
    path = write_log("sweep.mcap", _swept(sample_messages(10), sweep_s))
    rec = load_recording(path, load_config(None, [f"io.deskew={str(deskew).lower()}"]))
    note = [w for w in rec.warnings if "per sweep" in w]
    assert bool(note) == told
    if told:
        assert "90 ms per sweep" in note[0] and "moves 0.14 m" in note[0] and "io.deskew is off" in note[0]
    still = load_recording(path, load_config(None, ["io.deskew=false"]))
    changed = any(not np.array_equal(a, b, equal_nan=True) for a, b in zip(rec.scans.ranges, still.scans.ranges,
                                                                            strict=True))
    assert changed == (deskew and sweep_s > 0)


def _swept(messages: list[tuple[str, str, int, object]], sweep_s: float) -> list[tuple[str, str, int, object]]:
    for topic, _, _, msg in messages:
        if topic == "/scan":
            msg.time_increment = sweep_s / (len(msg.ranges) - 1)  # type: ignore[attr-defined]
    return messages


@pytest.mark.parametrize(("lag_ms", "offset_s", "told"), [(5, 0.0, True), (5, -0.09, False), (95, 0.0, False),
                                                          (0, 0.0, False)])
def test_scans_recorded_sooner_than_their_sweep_lasts_name_the_end_of_sweep_offset(
        write_log: Callable[..., Path], lag_ms: int, offset_s: float, told: bool) -> None:
    """A 90 ms sweep whose scans reach the log 5 ms after their stamp: the driver stamps the sweep's end (a scan
    stamped at its first beam cannot be logged before its last), and the warning names the offset that moves the
    stamps there; given it, nothing is told. 95 ms after (a start stamp) or log times equal to the stamps (a
    converter's) tell nothing."""
    messages = _swept(sample_messages(10), 0.09)
    for topic, _, t, msg in messages:
        if topic == "/scan":
            msg.header.stamp = m.header(t - lag_ms * 1_000_000, "laser").stamp  # type: ignore[attr-defined]
    rec = load_recording(write_log("end.mcap", messages), load_config(None, [f"io.scan_time_offset_s={offset_s}"]))
    note = [w for w in rec.warnings if "end of each sweep" in w]
    assert bool(note) == told
    if told:
        assert "5 ms after their stamps" in note[0] and "io.scan_time_offset_s=-0.090" in note[0]


def test_a_sweep_longer_than_the_scan_period_is_not_deskewed(write_log: Callable[..., Path]) -> None:
    """time_increment × beams = 0.3 s on a laser that scans every 0.1 s is no sweep (a driver that wrote the scan time
    or a per-beam period in another unit there): the scans are read as measured, with a warning."""
    path = write_log("bogus.mcap", _swept(sample_messages(10), 0.3))
    rec = load_recording(path)
    still = load_recording(path, load_config(None, ["io.deskew=false"]))
    assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(rec.scans.ranges, still.scans.ranges, strict=True))
    assert any("300 ms, longer than the scan period (100 ms)" in w for w in rec.warnings)


def _footprint_robot(odom_topic: bool) -> list[tuple[str, str, int, object]]:
    """The sample messages re-framed as a TurtleBot-like robot: odom → base_footprint (dynamic; the /odom
    topic's child frame, or TF only) and base_footprint → base_link static, 0.1 m ahead and turned 0.2 rad;
    plus a second dynamic child of odom (a tracked cart) that is not the robot."""
    out: list[tuple[str, str, int, object]] = []
    for topic, msgtype, t, msg in sample_messages(n_scans=8):
        if topic == "/ground_truth" or (topic == "/odom" and not odom_topic):
            continue
        if topic == "/odom":
            msg.child_frame_id = "base_footprint"
        if topic == "/tf":
            msg.transforms[0].child_frame_id = "base_footprint"
            msg.transforms.append(m.planar_transform(t, "odom", "cart", 5.0, 5.0, 1.0))
        if topic == "/tf_static":
            msg.transforms.append(m.planar_transform(t, "base_footprint", "base_link", 0.1, 0.0, 0.2))
        out.append((topic, msgtype, t, msg))
    return out


@pytest.mark.parametrize("odom_topic", [True, False])
def test_odometry_of_a_footprint_frame_is_moved_to_base_link(write_log: Callable[..., Path],
                                                             odom_topic: bool) -> None:
    # before: a TF-only log with odom → base_footprint → base_link had no odometry at all (only a direct
    # odom → base_link edge counted), and an /odom topic's base_footprint pose was taken as base_link's
    rec = load_recording(write_log("tb.mcap", _footprint_robot(odom_topic)))
    assert rec.odometry is not None and rec.odometry.poses.shape == (8, 3)
    i = np.arange(8)
    x, y, yaw = 0.1 * i, 0.02 * i, 0.01 * i  # the footprint's poses, as sample_messages writes them
    np.testing.assert_allclose(rec.odometry.poses[:, 0], x + 0.1 * np.cos(yaw), atol=1e-9)
    np.testing.assert_allclose(rec.odometry.poses[:, 1], y + 0.1 * np.sin(yaw), atol=1e-9)
    np.testing.assert_allclose(rec.odometry.poses[:, 2], yaw + 0.2, atol=1e-9)


def _pr2_messages(footprint: bool) -> list[tuple[str, str, int, object]]:
    """Six scans of a PR2-style tree: odom_combined → base_link (``footprint``: odom_combined → base_footprint
    moving and base_footprint → base_link fixed, both on /tf), no odom frame, no /odom topic, no reference."""
    msgs = []
    for topic, msgtype, t, msg in sample_messages(n_scans=6):
        if topic in ("/odom", "/ground_truth"):
            continue
        if topic == "/tf":
            msg.transforms[0].header.frame_id = "odom_combined"
            if footprint:
                msg.transforms[0].child_frame_id = "base_footprint"
                msg.transforms.append(m.planar_transform(t, "base_footprint", "base_link", 0.0, 0.0, 0.0))
        msgs.append((topic, msgtype, t, msg))
    return msgs


def test_tf_odometry_in_an_odometry_frame_of_another_name(write_log: Callable[..., Path]) -> None:
    rec = load_recording(write_log("pr2.mcap", _pr2_messages(footprint=False)))
    assert rec.odometry is not None and rec.odometry.frame_id == "odom_combined"
    np.testing.assert_allclose(rec.odometry.poses[:, 0], 0.1 * np.arange(6), atol=1e-12)
    assert any("odom_combined" in w and "frames.odom" in w for w in rec.warnings)


def test_a_fixed_mount_republished_on_tf_is_not_taken_for_the_odometry(write_log: Callable[..., Path]) -> None:
    """The Stata Center's PR2 tree: odom_combined → base_footprint moving, base_footprint → base_link fixed but
    republished on /tf (robot_state_publisher), no odom frame, no /odom topic. Before, the fixed edge was the
    first dynamic one above base_link and its parent, base_footprint, the odometry frame: a robot that never
    moved. The odometry is read in odom_combined, the parent of the first edge that moves."""
    rec = load_recording(write_log("pr2_mount.mcap", _pr2_messages(footprint=True)))
    assert rec.odometry is not None and rec.odometry.frame_id == "odom_combined"
    np.testing.assert_allclose(rec.odometry.poses[:, 0], 0.1 * np.arange(6), atol=1e-12)


def test_a_tree_without_base_link_takes_the_child_of_odom(write_log: Callable[..., Path]) -> None:
    msgs = []
    for topic, msgtype, t, msg in sample_messages(n_scans=4):
        if topic == "/tf":
            msg.transforms[0].child_frame_id = "base_footprint"
        if topic == "/tf_static":
            for tr in msg.transforms:
                tr.header.frame_id = "base_footprint"
        msgs.append((topic, msgtype, t, msg))
    path = write_log("nobase.mcap", msgs)
    guessed = load_recording(path)  # the child of odom is the robot's base, with a warning
    assert any("no frame 'base_link'" in w and "'base_footprint'" in w for w in guessed.warnings)
    rec = load_recording(path, DoorbatchConfig.model_validate({"frames": {"base_link": "base_footprint"}}))
    np.testing.assert_allclose(rec.scans.laser_to_base[0], [[1, 0, 0.2], [0, 1, 0]], atol=1e-12)
    np.testing.assert_array_equal(guessed.scans.laser_to_base, rec.scans.laser_to_base)
    assert not any("no frame" in w for w in rec.warnings)


def _split_recording(write_log: Callable[..., Path], static_in: int) -> list[Path]:
    """sample_messages with an upside-down laser mount (roll π, 0.2 m ahead) as one recording split in three
    pieces of 4 scans, /tf_static only in piece ``static_in`` (as a split recording keeps the latched message in
    its first piece)."""
    msgs = sample_messages(n_scans=12)
    static = msgs[0]
    assert static[0] == "/tf_static"
    static[3].transforms[0] = m.transform_stamped(T0, "base_link", "laser", (0.2, 0.0, 0.3), (1.0, 0.0, 0.0, 0.0))
    rest = msgs[1:]
    cut = [t for topic, _, t, _ in rest if topic == "/scan"][4::4]
    pieces: list[list[tuple[str, str, int, object]]] = [[], [], []]
    for msg in rest:
        pieces[sum(msg[2] >= c for c in cut)].append(msg)
    pieces[static_in].insert(0, static)
    return [write_log(f"piece{k}.mcap", piece) for k, piece in enumerate(pieces)]


@pytest.mark.parametrize("static_in", [0, 2])
def test_pieces_of_a_split_recording_borrow_the_mount_of_the_piece_that_has_it(
        write_log: Callable[..., Path], static_in: int) -> None:
    """The later pieces name no laser mount: alone, each is the missing-transform error (whose hint had pointed
    only at io.assume_identity_laser_tf, which mirrors an upside-down laser). As passes of one map, they take the
    mount of the piece that has it, first piece or last, with a warning."""
    from doorbatch.errors import LaserMountError
    from doorbatch.io.recording import load_passes

    paths = _split_recording(write_log, static_in)
    bare = paths[1]
    with pytest.raises(LaserMountError, match="split in pieces"):
        load_recording(bare)
    recs = load_passes(paths, DoorbatchConfig())
    for k, rec in enumerate(recs):
        assert len(rec.scans) == 4
        np.testing.assert_allclose(rec.scans.laser_to_base, np.broadcast_to([[1, 0, 0.2], [0, -1, 0]], (4, 2, 3)),
                                   atol=1e-12)
        assert any("static transforms of another pass" in w and "base_link→laser" in w
                   for w in rec.warnings) == (k != static_in)


def test_a_lent_mount_wins_over_the_identity_whatever_the_order(write_log: Callable[..., Path]) -> None:
    """With io.assume_identity_laser_tf a pass without a mount read the identity (its upside-down scans mirrored)
    whenever the pass with the mount came after it; the identity is only for a pass no pass lends a mount."""
    from doorbatch.io.recording import load_passes

    identity = DoorbatchConfig(io=IoConfig(assume_identity_laser_tf=True))
    for rec in load_passes(_split_recording(write_log, 2), identity):
        np.testing.assert_allclose(rec.scans.laser_to_base[0], [[1, 0, 0.2], [0, -1, 0]], atol=1e-12)
    alone = load_passes(_split_recording(write_log, 2)[:2], identity)  # no pass has it: the identity, as asked
    np.testing.assert_allclose(alone[0].scans.laser_to_base[0], [[1, 0, 0], [0, 1, 0]], atol=1e-12)


def test_passes_share_the_no_return_code_of_their_laser(write_log: Callable[..., Path]) -> None:
    """One laser, two passes that state no range_max: the first writes its 8 m code in a fifth of its beams, the
    second in 10 beams only, too few to tell in that pass alone (its 10 beams would be hits at 8 m). Read together,
    both take the code; and the warnings no longer say "every finite reading a hit" beside the code."""
    from doorbatch.io.recording import load_passes

    messages = sample_messages(n_scans=12, beams=91)
    scans = [msg for topic, _, _, msg in messages if topic == "/scan"]
    for k, scan in enumerate(scans):
        scan.range_max = 0.0
        scan.ranges = np.minimum(scan.ranges, 7.9).astype(np.float32)
        if k < 6:
            scan.ranges[np.isinf(scans[k].ranges) | (np.arange(91) % 5 == 0)] = 8.0
    scans[8].ranges[:10] = 8.0
    cut = next(t for topic, _, t, msg in messages if msg is scans[6])
    paths = [write_log("a.mcap", [x for x in messages if x[2] < cut]),
             write_log("b.mcap", [messages[0], *(x for x in messages if x[2] >= cut)])]
    assert np.isposinf(load_recording(paths[1]).scans.range_max).all()  # alone: no code
    recs = load_passes(paths, DoorbatchConfig())
    for rec in recs:
        np.testing.assert_array_equal(rec.scans.range_max, 8.0)
        assert any("read as the laser's no-return code" in w and "the 2 passes together: 12 of 12 scans" in w
                   for w in rec.warnings)  # the count is the passes', said so (hAL F6)
        assert not any("every finite reading" in w for w in rec.warnings)
    assert not recs[1].scans.endpoints_base(2)[1][:10].any()  # scan 8's code beams: no hits


def test_pieces_without_any_mount_stay_an_error(write_log: Callable[..., Path]) -> None:
    from doorbatch.errors import LaserMountError
    from doorbatch.io.recording import load_passes

    paths = _split_recording(write_log, 1)
    with pytest.raises(LaserMountError, match="piece0"):
        load_passes([paths[0], paths[2]], DoorbatchConfig())


def test_a_range_max_of_zero_or_nan_is_no_stated_maximum(write_log: Callable[..., Path]) -> None:
    """Drivers that leave range_max 0 (or NaN): read as it was, every reading would be a no-return and the map
    empty. It becomes +inf (every finite reading a hit), with a warning; a good range_max is kept."""
    messages = sample_messages(n_scans=4)
    scans = [msg for topic, _, _, msg in messages if topic == "/scan"]
    good = float(scans[0].range_max)
    scans[0].range_max, scans[1].range_max, scans[2].range_min = 0.0, float("nan"), float("nan")
    rec = load_recording(write_log("zero_max.mcap", messages), DoorbatchConfig())
    np.testing.assert_array_equal(rec.scans.range_max, [np.inf, np.inf, good, good])
    assert rec.scans.range_min[2] == 0.001  # a NaN range_min: the 1 mm floor, so a 0.0 reading is no hit
    assert any("range_max" in w and "2 of 4" in w for w in rec.warnings)
    assert all(rec.scans.endpoints_base(i)[1].any() for i in range(4))  # hits in every scan


@pytest.mark.parametrize("code", [8.0, 30.0])
def test_a_no_return_code_of_a_laser_that_states_no_range_max(write_log: Callable[..., Path], code: float) -> None:
    """A laser that states no range_max (0 here, as some drivers leave it) and writes its maximum range in every
    beam without an echo: read as every finite reading a hit, those beams were a ring of walls at that range
    around every pose. The repeated largest value is read as the no-return code and range_max."""
    messages = sample_messages(n_scans=6, beams=91)
    scans = [msg for topic, _, _, msg in messages if topic == "/scan"]
    for scan in scans:
        scan.range_max = 0.0
        scan.ranges[np.isinf(scan.ranges) | (scan.ranges > 7.5)] = code  # 21 % of the beams: no echo
    rec = load_recording(write_log("clamped.mcap", messages), DoorbatchConfig())
    np.testing.assert_array_equal(rec.scans.range_max, code)
    for i, scan in enumerate(scans):
        hit = rec.scans.endpoints_base(i)[1]
        np.testing.assert_array_equal(hit, np.isfinite(scan.ranges) & (scan.ranges < code))
    assert any("no-return code" in w and f"{code:g} m" in w for w in rec.warnings)


def test_a_largest_reading_that_does_not_repeat_is_no_code(write_log: Callable[..., Path]) -> None:
    """Without a stated range_max, noisy readings whose largest value occurs once (a far wall) stay hits; so do
    the readings of a laser that states its range_max, however often they repeat below it."""
    messages = sample_messages(n_scans=6, beams=91)
    scans = [msg for topic, _, _, msg in messages if topic == "/scan"]
    for scan in scans[:3]:
        scan.range_max = float("nan")
    for scan in scans[3:]:
        scan.ranges[::4] = 9.5  # below the stated 30 m
    rec = load_recording(write_log("noisy.mcap", messages), DoorbatchConfig())
    np.testing.assert_array_equal(rec.scans.range_max, [np.inf] * 3 + [30.0] * 3)
    assert not any("read as the laser's no-return code" in w for w in rec.warnings)
    assert any("no finite reading repeats as a no-return code" in w and "every finite reading is a hit" in w
               for w in rec.warnings)
    # the same scans with fewer repeats of their largest value than io.no_return_code_min_readings asks
    for scan in scans[:3]:
        scan.ranges[:3] = 12.0
    rec = load_recording(write_log("few.mcap", messages), DoorbatchConfig())
    assert np.isposinf(rec.scans.range_max[:3]).all()
    strict = DoorbatchConfig.model_validate({"io": {"no_return_code_min_readings": 9}})
    np.testing.assert_array_equal(load_recording(write_log("few9.mcap", messages), strict).scans.range_max[:3], 12.0)


def test_a_zero_reading_is_no_hit_even_with_range_min_zero(write_log: Callable[..., Path]) -> None:
    """Some drivers publish 0.0 for "no data" with range_min 0: as a hit, it would mark the laser's own cell
    occupied along the whole path."""
    messages = sample_messages(n_scans=2)
    scan = next(msg for topic, _, _, msg in messages if topic == "/scan")
    scan.range_min = 0.0
    scan.ranges[:5] = 0.0
    rec = load_recording(write_log("zeros.mcap", messages), DoorbatchConfig())
    _, hit = rec.scans.endpoints_base(0)
    assert not hit[:5].any() and hit[5:].any()


def _restamped(messages: list, topic: str, stamp: Callable[[int, int], int]) -> list:
    """The messages with the header stamp of each message on ``topic`` set to stamp(index, log time)."""
    out, k = [], 0
    for name, msgtype, t, msg in messages:
        if name == topic:
            msg.header = m.header(stamp(k, t), msg.header.frame_id)
            k += 1
        out.append((name, msgtype, t, msg))
    return out


def test_unset_scan_stamps_are_their_log_times(write_log: Callable[..., Path]) -> None:
    messages = _restamped(sample_messages(6), "/scan", lambda k, t: 0)
    rec = load_recording(write_log("zero.mcap", messages))
    log_times = [t for name, _, t, _ in messages if name == "/scan"]
    np.testing.assert_array_equal(rec.scans.stamps_ns, log_times)
    assert any("6 of 6 scans have header stamp 0" in w for w in rec.warnings)
    assert rec.odometry is not None and len(rec.odometry.stamps_ns) == 6



@pytest.mark.parametrize(("stamps_s", "unset"), [
    ([0.0, 0.2, 0.4, 0.6], [False, False, False, False]),  # Gazebo's sim time starts at 0 s
    ([0.0, 0.0, 0.0], [True, True, True]),  # a driver that never sets the stamp
    ([1.7e9, 0.0, 1.7e9 + 0.2], [False, True, False]),  # one unset stamp among wall-clock ones
    ([100.0, 100.2, 0.0, 100.6], [False, False, True, False]),  # an unset one in the middle of a sim run
    ([0.0, 5.0, 5.2, 5.4], [True, False, False, False]),  # sim time, but its next stamp is 25 intervals later
    ([0.0, 0.0, 0.2, 0.4], [True, False, False, False]),  # two before the first /clock: only the last can start it
    ([0.1, 0.3, 0.0, 0.7], [False, False, True, False]),  # a 0 within the first second, but mid-run
])
def test_a_zero_stamp_is_unset_unless_the_clock_starts_there(stamps_s: list[float], unset: list[bool]) -> None:
    stamps = [round(t * 1e9) for t in stamps_s]
    assert unset_stamps(stamps).tolist() == unset


def test_a_sim_time_log_whose_clock_starts_at_zero_keeps_its_stamps(write_log: Callable[..., Path]) -> None:
    """Header stamps in sim time from 0 s, log times on the recorder's wall clock: the first scan's stamp 0 is
    the clock's start, not an unset stamp (before: it took its 2023 log time and ended the run)."""
    messages = sample_messages(6)
    t0 = next(t for name, _, t, _ in messages if name == "/scan")
    for topic in ("/scan", "/odom"):
        messages = _restamped(messages, topic, lambda k, t: t - t0)
    rec = load_recording(write_log("sim0.mcap", messages))
    assert rec.scans.stamps_ns[0] == 0 and np.all(np.diff(rec.scans.stamps_ns) > 0)
    assert not any("stamp 0" in w for w in rec.warnings)

def test_scans_stamped_by_a_device_clock_are_timed_by_the_log(write_log: Callable[..., Path]) -> None:
    # the laser driver stamps from its own power-on (0 s), odometry and TF carry ROS time
    messages = _restamped(sample_messages(6), "/scan", lambda k, t: 5_000_000 + 100_000_000 * k)
    rec = load_recording(write_log("device.mcap", messages))
    log_times = [t for name, _, t, _ in messages if name == "/scan"]
    np.testing.assert_array_equal(rec.scans.stamps_ns, log_times)
    assert any("different clocks" in w for w in rec.warnings)
    same = load_recording(write_log("same.mcap", sample_messages(6)))
    assert not any("clock" in w for w in same.warnings)
    np.testing.assert_array_equal(same.scans.stamps_ns, log_times)


def test_scans_on_a_device_clock_with_odometry_from_tf_only_are_timed_by_the_log(
        write_log: Callable[..., Path]) -> None:
    """A TF-only log (no /odom: odometry from odom → base_link) whose laser stamps from its own clock. Before,
    the clock check saw no odometry topic and kept the scans' stamps: no scan had odometry within reach and
    `doorbatch map --pose-source odometry` stopped with "no scan has a pose"; now the transforms' log times
    reveal the two clocks and both sides are timed by the log, as with an odometry topic."""
    messages = [msg for msg in _restamped(sample_messages(6), "/scan", lambda k, t: 5_000_000 + 100_000_000 * k)
                if msg[0] != "/odom"]
    rec = load_recording(write_log("device_tf.mcap", messages))
    log_times = [t for name, _, t, _ in messages if name == "/scan"]
    np.testing.assert_array_equal(rec.scans.stamps_ns, log_times)
    assert any("different clocks" in w for w in rec.warnings)
    assert rec.odometry is not None
    np.testing.assert_array_equal(rec.odometry.stamps_ns, log_times)  # TF written with each scan
    np.testing.assert_allclose(rec.odometry.poses[:, 0], 0.1 * np.arange(6), atol=1e-12)


def test_scans_logged_out_of_stamp_order_are_sorted(write_log: Callable[..., Path]) -> None:
    messages = sample_messages(6)
    scans = [msg for name, _, _, msg in messages if name == "/scan"]
    scans[3].header.stamp, scans[2].header.stamp = scans[2].header.stamp, scans[3].header.stamp
    rec = load_recording(write_log("back.mcap", messages))
    assert np.all(np.diff(rec.scans.stamps_ns) > 0)
    np.testing.assert_array_equal(rec.scans.ranges[2], scans[3].ranges)  # the ranges follow their stamp
    assert any("go backwards 1 time(s)" in w for w in rec.warnings)


def test_unstamped_colours_go_to_the_unstamped_scan_logged_with_them(write_log: Callable[..., Path]) -> None:
    messages = _restamped(_restamped(sample_messages(6, beams=91), "/scan", lambda k, t: 0),
                          "/scan_colors", lambda k, t: 0)
    rec = load_recording(write_log("zero_colours.mcap", messages), with_colors=True)
    clouds = [msg for name, _, _, msg in messages if name == "/scan_colors"]
    stamped = load_recording(write_log("stamped.mcap", sample_messages(6, beams=91)), with_colors=True)
    assert rec.colors is not None and stamped.colors is not None and len(clouds) == 6
    for k in range(6):  # the same colours as when every message carries its stamp, not the last cloud's
        np.testing.assert_array_equal(rec.colors[k], stamped.colors[k])
    assert not np.array_equal(rec.colors[0], rec.colors[5])


def test_a_copy_printed_to_six_digits_far_from_the_origin_is_still_a_copy() -> None:
    """A raw CARMEN log 150 m from its origin prints poses to 6 significant digits, a millimetre there; its laser
    poses, rounded apart from its odometry fields, are still its odometry (a reviewer's case: 1.3 mm apart)."""
    from doorbatch.io.recording import PoseSeries, odometry_to_reference

    k = np.arange(200)
    stamps = (k * 100_000_000).astype(np.int64)
    odometry = np.stack([150.0 + 0.05 * k, 120.0 + 0.01 * k, 0.3 + 0.001 * k], axis=1)
    laser = odometry + np.array([0.2 * np.cos(odometry[:, 2]), 0.2 * np.sin(odometry[:, 2]), 0 * k]).T
    printed = np.array([[float(f"{v:.6g}") for v in row] for row in laser])
    reference = printed - np.array([0.2 * np.cos(printed[:, 2]), 0.2 * np.sin(printed[:, 2]), 0 * k]).T
    rounded_odometry = np.array([[float(f"{v:.6g}") for v in row] for row in odometry])
    args = (PoseSeries(stamps, reference, "map"), PoseSeries(stamps, rounded_odometry, "odom"), stamps,
            DoorbatchConfig())
    assert odometry_to_reference(*args) is not None
    drifted = PoseSeries(stamps, rounded_odometry * np.array([1.0005, 1.0, 1.0]), "odom")  # 0.05 % scale in x
    assert odometry_to_reference(args[0], drifted, stamps, DoorbatchConfig()) is None


def test_a_nan_odometry_pose_neither_makes_a_copy_nor_spoils_the_motion() -> None:
    """A NaN odometry message (a driver's glitch) says nothing: an independent reference stays independent, and a
    copy's motion comes from finite poses (a reviewer's case: one NaN made a 5 % drift "a copy")."""
    from doorbatch.io.recording import PoseSeries, odometry_to_reference

    stamps = (np.arange(200) * 100_000_000).astype(np.int64)
    s = np.linspace(0.0, 20.0, 200)
    truth = np.column_stack([s, np.sin(s), np.zeros(200)])
    drifted = truth * np.array([1.05, 1.0, 1.0])
    copy = truth + np.array([1.0, -2.0, 0.0])
    for i in (0, 50):
        drifted[i] = copy[i] = np.nan
        got = [odometry_to_reference(PoseSeries(stamps, truth, "map"), PoseSeries(stamps, odo, "odom"), stamps,
                                     DoorbatchConfig()) for odo in (drifted, copy)]
        assert got[0] is None
        assert got[1] is not None
        np.testing.assert_allclose(got[1], [-1.0, 2.0, 0.0], atol=1e-9)


def _turtlebot_without_tf_static(messages: list) -> list:
    """The messages as a TurtleBot's recording that started after /tf_static was latched: its base is
    base_footprint (odom → base_footprint on /tf, Odometry child frames), and no transform names the laser."""
    out = []
    for name, msgtype, t, msg in messages:
        if name == "/tf_static":
            continue
        for x in getattr(msg, "transforms", []):
            x.child_frame_id = "base_footprint"
        if hasattr(msg, "child_frame_id"):
            msg.child_frame_id = "base_footprint"
        out.append((name, msgtype, t, msg))
    return out


def test_a_log_without_base_link_and_tf_static_needs_one_setting(write_log: Callable[..., Path]) -> None:
    """The base frame is the child of odom when the tree has no base_link (a warning says so), and the error for
    the laser names the one setting that reads the log (before: it named frames.base_link, whose next error then
    named the setting, and the reference was dropped on the way)."""
    path = write_log("tb3.mcap", _turtlebot_without_tf_static(sample_messages(6)))
    with pytest.raises(LogContentError, match="assume_identity_laser_tf=true") as err:
        load_recording(path, DoorbatchConfig())
    assert "frames.base_link" not in str(err.value)
    rec = load_recording(path, DoorbatchConfig(io=IoConfig(assume_identity_laser_tf=True)))
    assert rec.odometry is not None and rec.reference is not None
    assert any("taken to be 'base_footprint'" in w for w in rec.warnings)


def _with_model_states(messages: list, names: list[str]) -> list:
    """The messages with /ground_truth (Odometry) replaced by Gazebo's /gazebo/model_states: every model's pose,
    the robot's at the ground truth's, and no header."""
    from rosbags.typesys import get_types_from_msg

    from doorbatch.io.typestore import new_ros2_typestore

    store = new_ros2_typestore()
    store.register(get_types_from_msg("string[] name\ngeometry_msgs/Pose[] pose\ngeometry_msgs/Twist[] twist",
                                      "gazebo_msgs/msg/ModelStates"))
    types = store.types
    pose_t, point_t, quat_t = (types[f"geometry_msgs/msg/{n}"] for n in ("Pose", "Point", "Quaternion"))
    twist_t, vec_t = types["geometry_msgs/msg/Twist"], types["geometry_msgs/msg/Vector3"]
    out = []
    for name, msgtype, t, msg in messages:
        if name != "/ground_truth":
            out.append((name, msgtype, t, msg))
            continue
        still = pose_t(position=point_t(x=-3.0, y=4.0, z=0.0), orientation=quat_t(x=0.0, y=0.0, z=0.0, w=1.0))
        poses = [msg.pose.pose if "burger" in n else still for n in names]
        twists = [twist_t(linear=vec_t(x=0.0, y=0.0, z=0.0), angular=vec_t(x=0.0, y=0.0, z=0.0)) for _ in names]
        states = types["gazebo_msgs/msg/ModelStates"](name=names, pose=poses, twist=twists)
        out.append(("/gazebo/model_states", "gazebo_msgs/msg/ModelStates", t, (states, store)))
    return out


def test_gazebos_model_states_are_the_reference(tmp_path: Path) -> None:
    """A Gazebo recording's ground truth: the robot's model among the world's (no header: timed by log time)."""
    from doorbatch.io.log_writer import LogWriter

    def write(path: Path, names: list[str], sim_time: bool = False, real_time_factor: float = 1.0) -> Path:
        messages = sample_messages(8)
        if sim_time:  # header stamps from 0.5 s, log times on the recorder's wall clock
            t0 = next(t for name, _, t, _ in messages if name == "/scan")
            for topic in ("/scan", "/odom"):
                messages = _restamped(messages, topic,
                                      lambda k, t: 500_000_000 + round((t - t0) * real_time_factor))
        with LogWriter(path) as writer:
            for name, msgtype, t, msg in _with_model_states(messages, names):
                msg, store = msg if isinstance(msg, tuple) else (msg, None)
                writer.write(name, msgtype, t, msg, store)
        return path

    truth = load_recording(_gt_log(tmp_path))
    gz = load_recording(write(tmp_path / "gz.mcap", ["ground_plane", "turtlebot3_world", "turtlebot3_burger"]))
    assert truth.reference is not None and gz.reference is not None
    np.testing.assert_allclose(gz.reference.poses, truth.reference.poses, atol=1e-9)
    # sim time: the log times stand in, moved onto the scans' clock
    sim = load_recording(write(tmp_path / "sim.mcap", ["ground_plane", "turtlebot3_burger"], sim_time=True))
    assert sim.reference is not None and sim.log_clock.offset_ns > 10**9
    np.testing.assert_array_equal(sim.reference.stamps_ns, truth.reference.stamps_ns - sim.log_clock.offset_ns)
    np.testing.assert_allclose(sim.reference.poses, truth.reference.poses, atol=1e-9)
    # Gazebo slower than real time: the offset grows; each log time is put on the scans' clock where it is
    slow = load_recording(write(tmp_path / "slow.mcap", ["ground_plane", "turtlebot3_burger"], True, 0.8))
    assert slow.reference is not None
    t0 = int(truth.scans.stamps_ns[0])
    inside = (truth.reference.stamps_ns >= t0) & (truth.reference.stamps_ns <= truth.scans.stamps_ns[-1])
    expected = 500_000_000 + (truth.reference.stamps_ns[inside] - t0) * 0.8
    np.testing.assert_allclose(slow.reference.stamps_ns[inside], expected, atol=1000)
    two = write(tmp_path / "two.mcap", ["ground_plane", "turtlebot3_burger", "jackal"])
    ambiguous = load_recording(two)  # two robots: no reference, and a warning that says how to choose
    assert ambiguous.reference is None
    assert any("topics.reference_model" in w and "jackal" in w for w in ambiguous.warnings)
    with pytest.raises(LogContentError, match="no model 'husky'"):
        load_recording(two, DoorbatchConfig.model_validate({"topics": {"reference_model": "husky"}}))
    chosen = load_recording(two, DoorbatchConfig.model_validate({"topics": {"reference_model": "turtlebot3_burger"}}))
    assert chosen.reference is not None
    np.testing.assert_allclose(chosen.reference.poses, truth.reference.poses, atol=1e-9)


def _gt_log(tmp_path: Path) -> Path:
    from tests.conftest import write_messages

    return write_messages(tmp_path / "gt.mcap", sample_messages(8), "mcap")


def _localized_robot(n_scans: int, map_to_odom: Callable[[int], tuple[float, float, float]],
                     static: bool = False) -> list[tuple[str, str, int, object]]:
    """sample_messages without /ground_truth, with a localizer's map → odom on /tf (AMCL republishes it with
    every scan), or one static map → odom."""
    msgs = []
    for topic, msgtype, t, msg in sample_messages(n_scans=n_scans):
        if topic == "/ground_truth":
            continue
        msgs.append((topic, msgtype, t, msg))
        if topic == "/tf" and not static:
            k = (t - msgs[0][2]) // 100_000_000 - 1
            msgs.append(("/tf", msgtype, t, m.tf_message([m.planar_transform(t, "map", "odom", *map_to_odom(k))])))
    if static:
        msgs.insert(1, ("/tf_static", "tf2_msgs/msg/TFMessage", msgs[0][2],
                        m.tf_message([m.planar_transform(msgs[0][2], "map", "odom", *map_to_odom(0))])))
    return msgs


def test_a_localizers_map_to_odom_on_tf_is_the_reference_of_a_log_without_one(
        write_log: Callable[..., Path]) -> None:
    """base_link in map = (map → odom) ∘ (odom → base_link) at each stamp, by hand; said in a warning. A static
    map → odom is no reference (it is the odometry moved rigidly), and a reference topic wins over TF."""
    def correction(k: int) -> tuple[float, float, float]:
        return 2.0 + 0.01 * k, -1.0, 0.5 + 0.002 * k

    rec = load_recording(write_log("amcl.mcap", _localized_robot(8, correction)))
    assert rec.reference is not None and rec.reference.poses.shape == (8, 3)
    k = np.arange(8)
    x, y, yaw = 0.1 * k, 0.02 * k, 0.01 * k  # odom → base_link as sample_messages writes it
    cx, cy, cyaw = 2.0 + 0.01 * k, -1.0, 0.5 + 0.002 * k
    np.testing.assert_allclose(rec.reference.poses[:, 0], cx + np.cos(cyaw) * x - np.sin(cyaw) * y, atol=1e-9)
    np.testing.assert_allclose(rec.reference.poses[:, 1], cy + np.sin(cyaw) * x + np.cos(cyaw) * y, atol=1e-9)
    np.testing.assert_allclose(rec.reference.poses[:, 2], cyaw + yaw, atol=1e-9)
    assert any("reference poses from TF map→base_link" in w for w in rec.warnings)
    assert not rec.reference_is_odometry
    still = load_recording(write_log("static.mcap", _localized_robot(8, correction, static=True)))
    assert still.reference is None
    truth = load_recording(write_log("truth.mcap", [*sample_messages(n_scans=8),
                                                    *_localized_robot(8, correction)[-1:]]))
    assert truth.reference is not None
    np.testing.assert_allclose(truth.reference.poses[:, 0], 0.1 * k + 1, atol=1e-9)  # /ground_truth's


def test_a_localizer_that_started_late_gives_no_reference_before_it_started(write_log: Callable[..., Path]) -> None:
    """A map → odom that never changes (a localizer that held its correction) is no mount: before its first
    transform the reference has no pose (only the 100 ms extrapolation limit reaches back), however constant."""
    msgs = [x for x in _localized_robot(20, lambda k: (2.0, -1.0, 0.5))
            if not (x[0] == "/tf" and x[3].transforms[0].header.frame_id == "map" and x[2] < T0 + 1_100_000_000)]
    first = min(x[2] for x in msgs if x[0] == "/tf" and x[3].transforms[0].header.frame_id == "map")
    rec = load_recording(write_log("late.mcap", msgs))
    assert rec.reference is not None
    assert rec.reference.stamps_ns.min() >= first - 100_000_000 and len(rec.reference) == 11


def test_only_an_edge_whose_every_stamp_is_unset_is_timed_by_log_time() -> None:
    """All zero: the log time is the edge's only time. Some set (a simulator's first transforms before /clock): the
    edge keeps its own clock, so that no lookup mixes the two."""
    from doorbatch.io.recording import buffered_transforms
    from doorbatch.records import Transform

    def tf(child: str, stamp: int, log: int, x: float) -> Transform:
        return Transform(stamp, "odom", child, np.array([x, 0.0, 0.0]), np.array([0.0, 0.0, 0.0, 1.0]), False, log)

    unset = [tf("base_link", 0, T0 + k * 100_000_000, 0.1 * k) for k in range(5)]
    mixed = [tf("other", 0, T0, 9.0), *(tf("other", 2_000_000_000 + k * 100_000_000, T0 + k, 0.1 * k)
                                        for k in range(1, 5))]
    buf, note = buffered_transforms([*unset, *mixed], [], DoorbatchConfig())
    assert buf.stamps("base_link") == [T0 + k * 100_000_000 for k in range(5)]
    np.testing.assert_allclose(buf.lookup("odom", "base_link", T0 + 250_000_000)[0, 3], 0.25)
    assert buf.stamps("other") == [0, *(2_000_000_000 + k * 100_000_000 for k in range(1, 5))]
    assert note is not None and "odom→base_link (5 of 5)" in note and "other" not in note


def test_scans_recorded_twice_are_read_once(write_log: Callable[..., Path]) -> None:
    """Bags merged with a copy of /scan: each scan twice, at its stamp. The map had integrated both copies (385
    cells of the sample turned from unknown to free, 4 doors for 2 from odometry poses); the copies are dropped,
    with a note, and the recording equals the clean one. A scan at the same stamp with other ranges is kept."""
    messages = sample_messages(8)
    doubled = sorted([*messages, *[msg for msg in messages if msg[0] == "/scan"][:5]], key=lambda msg: msg[2])
    clean = load_recording(write_log("clean.mcap", messages), DoorbatchConfig())
    rec = load_recording(write_log("doubled.mcap", doubled), DoorbatchConfig())
    assert np.array_equal(rec.scans.stamps_ns, clean.scans.stamps_ns)
    assert any("5 of 13 scans repeat the one before them" in w for w in rec.warnings), rec.warnings
    topic, kind, at, scan = next(msg for msg in messages if msg[0] == "/scan")
    other = m.laser_scan(scan.header.stamp.sec * 10**9 + scan.header.stamp.nanosec, scan.header.frame_id,
                         scan.angle_min, scan.angle_increment, scan.range_min, scan.range_max,
                         np.asarray(scan.ranges) + 0.5)
    twin = load_recording(write_log("twin.mcap", sorted([*messages, (topic, kind, at, other)], key=lambda x: x[2])),
                          DoorbatchConfig())
    assert len(twin.scans.stamps_ns) == len(clean.scans.stamps_ns) + 1


def test_a_laser_stamped_late_is_moved_back_by_the_configured_offset(write_log: Callable[..., Path]) -> None:
    """io.scan_time_offset_s moves every scan's stamp (a driver stamping on arrival, 80 ms late: a run scored 0.064
    m mean against 0.022 m); the odometry stays where it was."""
    path = write_log("late.mcap", sample_messages(6))
    clean = load_recording(path, DoorbatchConfig())
    moved = load_recording(path, load_config(overrides=["io.scan_time_offset_s=-0.08"]))
    np.testing.assert_array_equal(moved.scans.stamps_ns, clean.scans.stamps_ns - 80_000_000)
    assert clean.odometry is not None and moved.odometry is not None
    np.testing.assert_array_equal(moved.odometry.stamps_ns, clean.odometry.stamps_ns)


def _twist_only(messages: list, keep_tf: bool) -> list:
    """The sample log with /odom's pose left at 0 (a base that fills only twist: 1 m/s, 0.1 rad/s) and, unless
    ``keep_tf``, no TF odom→base_link."""
    out = []
    for topic, msgtype, t, msg in messages:
        if topic == "/odom":
            msg = m.odometry(t, "odom", "base_link", 0.0, 0.0, 0.0, 1.0, 0.1)
        if topic == "/tf" and not keep_tf:
            continue
        out.append((topic, msgtype, t, msg))
    return out


def test_an_odometry_topic_with_only_its_twist_set_is_read_from_tf_or_integrated(
        write_log: Callable[..., Path]) -> None:
    """Its pose never moves while its twist does: with a moving TF odom→base_link, the odometry is that TF; without
    one, the twist integrated from the first message, an arc of radius v/w = 10 m. Each with a warning."""
    messages = sample_messages(n_scans=20)
    from_tf = load_recording(write_log("tf.mcap", _twist_only(messages, keep_tf=True)))
    plain = load_recording(write_log("plain.mcap", messages))
    assert from_tf.odometry is not None and plain.odometry is not None
    np.testing.assert_allclose(from_tf.odometry.poses, plain.odometry.poses, atol=1e-9)
    assert any("fills only twist" in w and "TF odom→base_link instead" in w for w in from_tf.warnings)

    rec = load_recording(write_log("twist.mcap", _twist_only(messages, keep_tf=False)))
    assert rec.odometry is not None and any("twist integrated" in w for w in rec.warnings)
    t = (rec.odometry.stamps_ns - T0 - 100_000_000) * 1e-9
    arc = np.column_stack([10.0 * np.sin(0.1 * t), 10.0 * (1 - np.cos(0.1 * t)), 0.1 * t])
    np.testing.assert_allclose(rec.odometry.poses, arc, atol=1e-4)  # the midpoint rule's chord: O(dt³)
