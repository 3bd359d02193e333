"""CARMEN text logs: synthetic topics, scan geometry, max range, stamp repair, errors, and the real logs."""

from __future__ import annotations

import gzip
import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from doorbatch.config import DoorbatchConfig, FramesConfig, IoConfig
from doorbatch.errors import LogReadError
from doorbatch.io.carmen import (
    CarmenReader,
    base_from_laser,
    carmen_scan_geometry,
    heaviest_nondecreasing,
    parse_stamp_ns,
    repair_stamps,
)
from doorbatch.io.reader import open_log
from doorbatch.io.recording import load_recording
from doorbatch.io.typestore import ros2_typestore
from doorbatch.records import Pose2D, Role, RoleMessage, Scan, Transform

DATASETS = Path(__file__).resolve().parents[2].parent / "shared/datasets/carmen"
REAL_LOGS = ["aces-corrected.log.gz", "intel-corrected.log.gz", "orebro-corrected.log.gz"]


def _wrap(angle: float) -> float:
    return math.atan2(math.sin(angle), math.cos(angle))


def flaser(ranges: list[float], pose: tuple[float, float, float], stamp: str,
           odom: tuple[float, float, float] | None = None, host: bool = True) -> str:
    odom = pose if odom is None else odom
    fields = ["FLASER", str(len(ranges)), *(f"{r:g}" for r in ranges), *(f"{v:g}" for v in (*pose, *odom)), stamp]
    if host:
        fields += ["host", stamp]
    return " ".join(fields)


def odom_line(pose: tuple[float, float, float], stamp: str, tv: float = 0.0, rv: float = 0.0) -> str:
    return f"ODOM {pose[0]:g} {pose[1]:g} {pose[2]:g} {tv:g} {rv:g} 0 {stamp} host {stamp}"


def write_log(path: Path, lines: list[str]) -> Path:
    text = "\n".join(lines) + "\n"
    if path.suffix == ".gz":
        with gzip.open(path, "wt") as f:
            f.write(text)
    else:
        path.write_text(text)
    return path


def simple_log(n_scans: int = 5, n_readings: int = 180, period: float = 0.2, t0: float = 100.0,
               params: tuple[str, ...] = ()) -> list[str]:
    """Scans on a straight line with an ODOM line between consecutive scans."""
    lines = ["# message formats defined: PARAM SYNC ODOM FLASER", *params]
    for k in range(n_scans):
        t = t0 + k * period
        ranges = [1.0 + 0.01 * i for i in range(n_readings)]
        ranges[0] = 50.0
        lines.append(flaser(ranges, (0.1 * k, 0.0, 0.05 * k), f"{t:.6f}"))
        lines.append(odom_line((0.1 * k + 0.05, 0.0, 0.05 * k), f"{t + period / 2:.6f}", tv=0.5, rv=0.1))
    return lines


R = TypeVar("R")


def read_all(path: Path, roles: list[Role] | None = None, **kwargs: Any) -> list[RoleMessage]:
    with CarmenReader(path, **kwargs) as reader:
        return list(reader.messages(roles))


def only(kind: type[R], messages: Iterable[RoleMessage], role: Role | None = None) -> list[R]:
    """The records of one type (and role) among role messages."""
    return [m.record for m in messages if isinstance(m.record, kind) and role in (None, m.role)]


def scans_of(path: Path, **kwargs: Any) -> list[Scan]:
    return only(Scan, read_all(path, [Role.SCAN], **kwargs))


# ---- scan geometry


def test_geometry_180_readings_span_minus_90_to_plus_89_at_one_degree() -> None:
    angle_min, inc = carmen_scan_geometry(180, 180.0)
    assert angle_min == pytest.approx(math.radians(-90.0))
    assert inc == pytest.approx(math.radians(1.0))
    assert angle_min + 179 * inc == pytest.approx(math.radians(89.0))


def test_geometry_181_readings_span_minus_90_to_plus_90() -> None:
    angle_min, inc = carmen_scan_geometry(181, 180.0)
    assert angle_min == pytest.approx(-math.pi / 2)
    assert angle_min + 180 * inc == pytest.approx(math.pi / 2)


@pytest.mark.parametrize(("n", "last_deg"), [(361, 90.0), (360, 89.5)])
def test_geometry_360_and_361_readings_are_half_degree_steps(n: int, last_deg: float) -> None:
    angle_min, inc = carmen_scan_geometry(n, 180.0)
    assert angle_min == pytest.approx(-math.pi / 2)
    assert inc == pytest.approx(math.radians(0.5))
    assert angle_min + (n - 1) * inc == pytest.approx(math.radians(last_deg))


def test_geometry_rejects_no_readings_and_empty_field_of_view() -> None:
    with pytest.raises(ValueError, match="reading"):
        carmen_scan_geometry(0, 180.0)
    with pytest.raises(ValueError, match="field of view"):
        carmen_scan_geometry(180, 0.0)


def test_scan_message_carries_the_geometry_of_its_reading_count(tmp_path: Path) -> None:
    for n in (180, 181, 361):
        path = write_log(tmp_path / f"n{n}.log", simple_log(n_scans=2, n_readings=n))
        scan = scans_of(path)[0]
        expected_min, expected_inc = carmen_scan_geometry(n, 180.0)
        assert scan.frame_id == "laser"
        assert scan.ranges.dtype == np.float32 and scan.ranges.shape == (n,)
        assert scan.angles[0] == pytest.approx(expected_min, abs=1e-6)
        assert scan.angle_increment == pytest.approx(expected_inc, abs=1e-7)
        assert scan.range_min == 0.0


def test_fov_from_config_applies_to_180_readings(tmp_path: Path) -> None:
    path = write_log(tmp_path / "a.log", simple_log(n_scans=2))
    scans = scans_of(path, config=DoorbatchConfig(io=IoConfig(carmen_fov_deg=100.0)))
    assert scans[0].angle_increment == pytest.approx(math.radians(100.0 / 180))


def test_resolution_param_sets_the_flaser_increment(tmp_path: Path) -> None:
    path = write_log(tmp_path / "a.log", simple_log(n_scans=2, n_readings=181,
                                                     params=("PARAM laser_front_laser_resolution 0.5",)))
    scan = scans_of(path)[0]
    assert scan.angle_increment == pytest.approx(math.radians(0.5))
    assert scan.angles[0] == pytest.approx(math.radians(-45.0))


def test_fov_param_sets_the_flaser_angles_and_a_count_without_one_is_warned(tmp_path: Path) -> None:
    """A 541-beam 270° laser written as FLASER with ``PARAM laser_front_laser_fov 270`` (carmen.ini, degrees):
    before, the PARAM was ignored and the beams squeezed into 180° without a word. Without any field-of-view
    PARAM such a count is warned about."""
    path = write_log(tmp_path / "fov.log", simple_log(n_scans=2, n_readings=541,
                                                      params=("PARAM laser_front_laser_fov 270",)))
    scan = scans_of(path)[0]
    assert scan.angle_increment == pytest.approx(math.radians(0.5))
    assert scan.angles[0] == pytest.approx(math.radians(-135.0))
    with CarmenReader(path) as reader:
        assert not any("laser_front_laser_fov" in w for w in reader.warnings)
    bare = write_log(tmp_path / "bare.log", simple_log(n_scans=2, n_readings=541))
    with CarmenReader(bare) as reader:
        assert any("541 readings" in w and "io.carmen_fov_deg" in w for w in reader.warnings)
    with CarmenReader(write_log(tmp_path / "sick.log", simple_log(n_scans=2, n_readings=181))) as reader:
        assert not any("readings and no" in w for w in reader.warnings)


# ---- max range


def test_max_range_is_the_largest_reading_when_the_log_gives_none(tmp_path: Path) -> None:
    path = write_log(tmp_path / "a.log", simple_log())
    with CarmenReader(path) as reader:
        assert reader.range_max_m == pytest.approx(50.0)
        assert "largest reading" in reader.range_max_source
        scans = only(Scan, reader.messages([Role.SCAN]))
    assert all(s.range_max == pytest.approx(50.0) for s in scans)
    assert all(s.ranges[0] >= s.range_max for s in scans)  # the 50 m beam reads as "no return"
    assert all(np.all(s.ranges[1:] < s.range_max) for s in scans)


def test_readings_just_below_the_largest_are_no_return_codes_too(tmp_path: Path) -> None:
    lines = simple_log(n_scans=2)
    ranges = [5.0] * 180
    ranges[:3] = [32.767, 32.763, 32.759]
    ranges[3] = 32.5  # a real far wall, more than 1 cm below
    lines.append(flaser(ranges, (0.0, 0.0, 0.0), "101.0"))
    lines = [line.replace(" 50 ", " 5 ") for line in lines]
    with CarmenReader(write_log(tmp_path / "a.log", lines)) as reader:
        assert reader.range_max_m == pytest.approx(32.759, abs=1e-5)


def test_max_range_param_wins_over_the_readings(tmp_path: Path) -> None:
    path = write_log(tmp_path / "a.log", simple_log(params=("PARAM robot_front_laser_max 30.0 nohost 0",)))
    scans = scans_of(path)
    assert scans[0].range_max == pytest.approx(30.0)


def test_max_range_falls_back_to_the_config_without_positive_readings(tmp_path: Path) -> None:
    lines = [flaser([0.0] * 180, (0.0, 0.0, 0.0), f"{t:.1f}") for t in (1.0, 1.2)]
    with CarmenReader(write_log(tmp_path / "a.log", lines),
                      config=DoorbatchConfig(io=IoConfig(carmen_default_max_range_m=12.0))) as reader:
        assert reader.range_max_m == 12.0


# ---- topics, poses, transforms


def test_topics_counts_and_roles(tmp_path: Path) -> None:
    with open_log(write_log(tmp_path / "a.log", simple_log(n_scans=4))) as reader:
        assert reader.storage == "carmen"
        counts = {name: info.count for name, info in reader.topics.items()}
        assert counts == {"/scan": 4, "/odom": 8, "/ground_truth": 4, "/tf": 8, "/tf_static": 1}
        assert {info.encoding for info in reader.topics.values()} == {"carmen"}
        roles = reader.roles
        assert roles.topic(Role.SCAN) == "/scan"
        assert roles.topic(Role.ODOMETRY) == "/odom"
        assert roles.topic(Role.REFERENCE) == "/ground_truth"
        assert set(roles.topics[Role.TRANSFORMS]) == {"/tf", "/tf_static"}


def test_odometry_interleaves_flaser_and_odom_lines_in_file_order(tmp_path: Path) -> None:
    path = write_log(tmp_path / "a.log", simple_log(n_scans=3))
    odom = only(Pose2D, read_all(path, [Role.ODOMETRY]))
    assert [round(p.x, 3) for p in odom] == [0.0, 0.05, 0.1, 0.15, 0.2, 0.25]
    assert all(p.frame_id == "odom" and p.child_frame_id == "base_link" for p in odom)
    assert [p.stamp_ns for p in odom] == sorted(p.stamp_ns for p in odom)


def test_odom_line_velocities_go_into_the_twist(tmp_path: Path) -> None:
    path = write_log(tmp_path / "a.log", simple_log(n_scans=2))
    with CarmenReader(path) as reader:
        raws = [r for r in reader.raw_messages(["/odom"]) if r.msg.twist.twist.linear.x != 0.0]
    assert raws and raws[0].msg.twist.twist.linear.x == pytest.approx(0.5)
    assert raws[0].msg.twist.twist.angular.z == pytest.approx(0.1)


def test_frames_come_from_the_config(tmp_path: Path) -> None:
    path = write_log(tmp_path / "a.log", simple_log(n_scans=2))
    frames = FramesConfig(map="world", odom="odo", base_link="base")
    records = read_all(path, None, config=DoorbatchConfig(frames=frames))
    reference = only(Pose2D, records, Role.REFERENCE)
    assert reference[0].frame_id == "world" and reference[0].child_frame_id == "base"
    tfs = [t for t in only(Transform, records) if not t.static]
    assert {(t.parent, t.child) for t in tfs} == {("odo", "base")}


def test_laser_offset_gives_tf_static_and_moves_the_reference_back(tmp_path: Path) -> None:
    lines = ["PARAM robot_frontlaser_offset 0.25 nohost 0",
             flaser([1.0] * 180, (1.0, 2.0, math.pi / 2), "5.0"),
             flaser([1.0] * 180, (1.0, 3.0, math.pi / 2), "5.2")]
    records = read_all(write_log(tmp_path / "a.log", lines))
    static = [t for t in only(Transform, records) if t.static]
    assert len(static) == 1
    assert (static[0].parent, static[0].child) == ("base_link", "laser")
    np.testing.assert_allclose(static[0].translation, [0.25, 0.0, 0.0])
    assert static[0].stamp_ns == 5_000_000_000
    reference = only(Pose2D, records, Role.REFERENCE)
    # the log prints pi/2 as 1.5708 (%g), hence the tolerances
    assert reference[0].x == pytest.approx(1.0, abs=1e-5)
    assert reference[0].y == pytest.approx(1.75, abs=1e-9)
    assert reference[0].yaw == pytest.approx(math.pi / 2, abs=1e-5)


def _static_yaw(records: list[RoleMessage]) -> float:
    (static,) = [t for t in only(Transform, records) if t.static]
    x, y, z, w = static.rotation_xyzw
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def test_angular_offset_param_is_in_radians(tmp_path: Path) -> None:
    """CARMEN adds robot_frontlaser_angular_offset to the heading as it is (carmen.ini: a rear laser is
    3.1415923); only the laser's field of view and resolution PARAMs are degrees."""
    lines = ["PARAM robot_frontlaser_angular_offset 0.1 nohost 0",
             flaser([1.0] * 180, (1.0, 2.0, 0.3), "5.0"), flaser([1.0] * 180, (1.0, 3.0, 0.3), "5.2")]
    records = read_all(write_log(tmp_path / "a.log", lines))
    assert _static_yaw(records) == pytest.approx(0.1)
    assert only(Pose2D, records, Role.REFERENCE)[0].yaw == pytest.approx(0.2)


def robotlaser1(laser: tuple[float, float, float], robot: tuple[float, float, float], t: float, n: int = 5) -> str:
    readings = " ".join(["1.0"] * n)
    poses = " ".join(f"{v:.9f}" for v in (*laser, *robot))
    return f"ROBOTLASER1 0 -1.0 2.0 0.5 20.0 0.01 0 {n} {readings} 0 {poses} 0.3 0.05 0 0 0 {t} host {t}"


def test_robotlaser1_angles_in_degrees_are_refused(tmp_path: Path) -> None:
    """A ROBOTLASER1 written with start −135, fov 270, resolution 0.5 (degrees, not CARMEN's radians) was read as a
    270-rad fan: 15 false doors, walls 9 m off. Such a line is malformed, named by its line."""
    lines = [robotlaser1((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 3.0 + 0.1 * k, n=541).replace(
        "ROBOTLASER1 0 -1.0 2.0 0.5", "ROBOTLASER1 0 -135 270 0.5") for k in range(3)]
    with pytest.raises(LogReadError, match=r"line 1: .*radians"):
        read_all(write_log(tmp_path / "deg.clf", lines))


def _mounted(robot: tuple[float, float, float], mount: tuple[float, float, float]) -> tuple[float, float, float]:
    c, s = math.cos(robot[2]), math.sin(robot[2])
    return (robot[0] + c * mount[0] - s * mount[1], robot[1] + s * mount[0] + c * mount[1], robot[2] + mount[2])


@pytest.mark.parametrize("mount", [
    (0.2, -0.05, math.pi),  # a laser looking backwards: its yaw wraps at ±π from line to line
    (0.2, -0.05, 0.3),  # turned otherwise: a mount read the wrong way round (laser in robot, not robot in laser)
])
def test_robotlaser1_without_offset_params_takes_the_mount_from_its_two_poses(tmp_path: Path,
                                                                             mount: tuple[float, float, float]) -> None:
    robots = [(0.1 * k, 0.05 * k * k, 0.5 * k - 2.9) for k in range(12)]  # turning through ±π
    lines = [robotlaser1(_mounted(r, mount), r, 3.0 + 0.1 * k) for k, r in enumerate(robots)]
    records = read_all(write_log(tmp_path / "a.clf", lines))
    few = read_all(write_log(tmp_path / "few.clf", lines[:3]))  # three lines prove no rigid mount
    np.testing.assert_allclose(next(t for t in only(Transform, few) if t.static).translation, 0.0)
    (static,) = [t for t in only(Transform, records) if t.static]
    np.testing.assert_allclose(static.translation, [mount[0], mount[1], 0.0], atol=1e-6)
    assert abs(_wrap(_static_yaw(records) - mount[2])) < 1e-6
    for ref, robot in zip(only(Pose2D, records, Role.REFERENCE), robots, strict=True):
        assert (ref.x, ref.y) == pytest.approx(robot[:2], abs=1e-6) and abs(_wrap(ref.yaw - robot[2])) < 1e-6


def test_robotlaser1_whose_laser_pose_was_corrected_keeps_a_zero_mount(tmp_path: Path) -> None:
    # A corrected log: the laser pose is the corrected one, the robot pose the odometry; no fixed mount.
    lines = [robotlaser1((0.1 * k, 0.0, 0.1 * k), (0.09 * k, 0.005 * k, 0.098 * k), 3.0 + 0.1 * k) for k in range(12)]
    records = read_all(write_log(tmp_path / "a.clf", lines))
    (static,) = [t for t in only(Transform, records) if t.static]
    np.testing.assert_allclose(static.translation, 0.0)
    assert only(Pose2D, records, Role.REFERENCE)[10].x == pytest.approx(1.0)


def rawlaser1(t: float, n: int = 5) -> str:
    readings = " ".join(["2.0"] * n)
    return f"RAWLASER1 0 -1.0 2.0 0.5 30.0 0.01 0 {n} {readings} 0 {t} host {t}"


def test_rawlaser1_lines_are_the_scans_of_a_log_without_flaser_or_robotlaser1(tmp_path: Path) -> None:
    lines = ["PARAM robot_frontlaser_offset 0.25 nohost 0"]
    for k in range(3):
        lines += [odom_line((0.1 * k, 0.0, 0.0), f"{10.0 + 0.2 * k:.6f}"), rawlaser1(10.1 + 0.2 * k)]
    # an ODOM line on a raw scan's stamp is the only odometry there: kept, not moved off it
    lines += [odom_line((0.3, 0.0, 0.0), "10.500000"), rawlaser1(10.5), odom_line((0.35, 0.0, 0.0), "10.6")]
    with CarmenReader(write_log(tmp_path / "raw.log", lines)) as reader:
        assert set(reader.topics) == {"/scan", "/odom", "/tf", "/tf_static"}  # no reference: no poses
        assert reader.topics["/scan"].count == 4 and reader.topics["/odom"].count == 5
        assert any("RAWLASER1" in w for w in reader.warnings)
        records = list(reader.messages())
    scans = only(Scan, records)
    assert [s.stamp_ns for s in scans] == [10_100_000_000, 10_300_000_000, 10_500_000_000, 10_500_000_000]
    assert scans[0].angle_min == pytest.approx(-1.0) and scans[0].range_max == pytest.approx(30.0)
    assert [p.x for p in only(Pose2D, records, Role.ODOMETRY)] == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.35])


def test_rawlaser1_lines_beside_flaser_lines_are_ignored_and_counted(tmp_path: Path) -> None:
    lines = [*simple_log(n_scans=2), rawlaser1(100.05), rawlaser1(100.25), rawlaser1(100.35)[:40]]  # one cut off
    with CarmenReader(write_log(tmp_path / "a.log", lines)) as reader:
        assert reader.ignored_lines == {"RAWLASER1": 3}
        assert reader.topics["/scan"].count == 2
        assert len(only(Scan, reader.messages([Role.SCAN]))) == 2


def test_base_from_laser_inverts_the_mounting() -> None:
    base = (2.0, -1.0, 0.7)
    offset = (0.3, 0.1, 0.2)
    c, s = math.cos(base[2]), math.sin(base[2])
    laser = (base[0] + c * offset[0] - s * offset[1], base[1] + s * offset[0] + c * offset[1], base[2] + offset[2])
    np.testing.assert_allclose(base_from_laser(laser, offset), base, atol=1e-12)


def test_messages_serialize_as_ros2_cdr(tmp_path: Path) -> None:
    store = ros2_typestore()
    path = write_log(tmp_path / "a.log", simple_log(n_scans=2))
    with CarmenReader(path) as reader:
        raws = list(reader.raw_messages())
    assert {r.topic for r in raws} == {"/scan", "/odom", "/ground_truth", "/tf", "/tf_static"}
    for raw in raws:
        assert raw.ros1 is False
        back = store.deserialize_cdr(store.serialize_cdr(raw.msg, raw.msgtype), raw.msgtype)
        assert type(back) is type(raw.msg)


def test_time_window_selects_messages(tmp_path: Path) -> None:
    path = write_log(tmp_path / "a.log", simple_log(n_scans=5, t0=10.0))
    with CarmenReader(path) as reader:
        start, stop = 10_200_000_000, 10_600_000_000
        raws = list(reader.raw_messages(["/scan", "/tf_static"], start, stop))
    assert [r.log_time_ns for r in raws] == [10_200_000_000, 10_400_000_000]


def test_gzipped_and_plain_logs_read_the_same(tmp_path: Path) -> None:
    lines = simple_log(n_scans=3)
    plain = read_all(write_log(tmp_path / "a.log", lines), [Role.REFERENCE])
    zipped = read_all(write_log(tmp_path / "a.log.gz", lines), [Role.REFERENCE])
    assert [m.record for m in plain] == [m.record for m in zipped]


def test_old_format_lines_without_hostname(tmp_path: Path) -> None:
    lines = [flaser([1.0] * 181, (0.0, 0.0, 0.0), f"{t:.1f}", host=False) for t in (1.0, 1.2, 1.4)]
    lines.insert(1, "ODOM 0 0 0 0 0 0 1.1")
    with CarmenReader(write_log(tmp_path / "old.clf", lines)) as reader:
        assert reader.topics["/scan"].count == 3
        assert reader.topics["/odom"].count == 4
        assert reader.warnings == []


def test_robotlaser1_uses_its_own_geometry_and_range(tmp_path: Path) -> None:
    n = 5
    readings = " ".join(["1.0"] * n)
    stamps = (3.0, 3.1)
    lines = [
        f"ROBOTLASER1 0 -1.0 2.0 0.5 20.0 0.01 0 {n} {readings} 0 0.5 0.5 0.1 0.4 0.5 0.1 0.3 0.05 0 0 0 "
        f"{t} host {t}"
        for t in stamps
    ]
    records = read_all(write_log(tmp_path / "a.clf", lines))
    scan = only(Scan, records)[0]
    assert scan.angle_min == pytest.approx(-1.0)
    assert scan.angle_increment == pytest.approx(0.5)
    assert scan.range_max == pytest.approx(20.0)
    odom = only(Pose2D, records, Role.ODOMETRY)[0]
    assert (odom.x, odom.y, odom.yaw) == pytest.approx((0.4, 0.5, 0.1))


def test_rlaser_and_unknown_lines_are_ignored_and_counted(tmp_path: Path) -> None:
    lines = [*simple_log(n_scans=2), "RLASER 3 1 1 1 0 0 0 0 0 0 1.0 host 1.0", "NEFF 30", "SYNC x"]
    with CarmenReader(write_log(tmp_path / "a.log", lines)) as reader:
        assert reader.ignored_lines == {"NEFF": 1, "RLASER": 1, "SYNC": 1}


# ---- stamps


def test_stamps_are_parsed_exactly() -> None:
    assert parse_stamp_ns("1067590000.123456789") == 1_067_590_000_123_456_789
    assert parse_stamp_ns("0.110201") == 110_201_000
    assert parse_stamp_ns("1.0e-9") == 1
    assert parse_stamp_ns("3.44361e-86") == 0
    assert parse_stamp_ns("-1891.72") == -1
    assert parse_stamp_ns("nan") == -1
    with pytest.raises(ValueError, match="not a number"):
        parse_stamp_ns("pippo")


def test_backward_stamps_are_repaired_monotonic_with_a_warning(tmp_path: Path) -> None:
    lines = simple_log(n_scans=10, t0=100.0)
    lines[6] = lines[6].replace("100.500000", "99.000000")  # the ODOM line after the 3rd scan
    path = write_log(tmp_path / "a.log", lines)
    with CarmenReader(path) as reader:
        assert reader.stamp_method == "nudged"
        assert len(reader.warnings) == 1 and "out of order" in reader.warnings[0]
        assert reader.warnings[0].startswith(f"{path}: ")  # the manifests of the commands name the log
        raws = list(reader.raw_messages())
        scans = [r.log_time_ns for r in raws if r.topic == "/scan"]
    times = [r.log_time_ns for r in raws]
    assert times == sorted(times)
    assert scans == [100_000_000_000 + k * 200_000_000 for k in range(10)]  # scan stamps untouched
    odom_times = [r.log_time_ns for r in raws if r.topic == "/odom"]
    assert odom_times[5] == 100_500_000_000  # interpolated between its neighbours (100.4, 100.6)


def test_ten_second_resolution_stamps_are_synthesized_from_the_scan_rate(tmp_path: Path) -> None:
    lines = []
    for k in range(30):
        coarse = f"{1.06759e9 + 10 * (k // 50):.5e}"  # printed with %g: 10 s resolution
        lines.append(flaser([2.0] * 180, (0.0, 0.0, 0.0), coarse))
        lines.append(odom_line((0.0, 0.0, 0.0), coarse))
    path = write_log(tmp_path / "coarse.log", lines)
    config = DoorbatchConfig(io=IoConfig(carmen_scan_period_s=0.1))
    with CarmenReader(path, config=config) as r:
        assert r.stamp_method == "synthesized"
        assert "coarse" in r.warnings[0] and "synthesized" in r.warnings[0]
        raws = list(r.raw_messages(["/scan", "/odom"]))
    t0 = 1_067_590_000_000_000_000
    scans = [x.log_time_ns for x in raws if x.topic == "/scan"]
    assert scans == [t0 + k * 100_000_000 for k in range(30)]
    odom_lines = [x.log_time_ns for x in raws if x.topic == "/odom"][1::2]
    assert odom_lines[:2] == [t0 + 50_000_000, t0 + 150_000_000]  # halfway between their scans
    times = [x.log_time_ns for x in raws]
    assert times == sorted(times)


def test_unusable_stamps_are_synthesized(tmp_path: Path) -> None:
    lines = [flaser([2.0] * 180, (0.0, 0.0, 0.0), s) for s in ("0", "0", "6.9", "0", "-3", "1e-80", "0")]
    with CarmenReader(write_log(tmp_path / "a.log", lines)) as reader:
        assert reader.stamp_method == "synthesized"
        assert "unusable" in reader.warnings[0]
        assert reader.end_ns - reader.start_ns == 6 * 200_000_000


def coarse_simulator_log(n_scans: int = 250, period: float = 0.1, t0: float = 1_067_590_003.4,
                         logger: bool = True) -> list[str]:
    """A simulator log (ODOM, TRUEPOS, FLASER on one instant per scan) whose ipc stamps are floored to 10 s,
    with (``logger``) or without exact logger stamps (seconds since the logger started, a few ms apart within an
    instant as the logger received the three messages)."""
    lines = ["# message formats defined: PARAM SYNC ODOM FLASER TRUEPOS"]
    for k in range(n_scans):
        t = t0 + k * period
        ipc = f"{10 * math.floor(t / 10):.6f}"
        tails = [f" host {t - t0 + 0.5 + d:.6f}" if logger else "" for d in (0.001, 0.002, 0.003)]
        pose = (0.05 * k, 0.0, 0.0)
        lines += [" ".join(["ODOM", *(f"{v:g}" for v in pose), "0 0 0", ipc]) + tails[0],
                  " ".join(["TRUEPOS", *(f"{v:g}" for v in (*pose, *pose)), ipc]) + tails[1],
                  flaser([2.0] * 180, pose, ipc, host=False) + tails[2]]
    return lines


def _clock_of(path: Path) -> tuple[str, list[str], np.ndarray, np.ndarray, np.ndarray]:
    """Stamp method, warnings, and the stamps of the scans, the reference and the ODOM lines (ns)."""
    with CarmenReader(path) as reader:
        raws = list(reader.raw_messages(["/scan", "/ground_truth", "/odom"]))
        method, warnings = reader.stamp_method, list(reader.warnings)
    times = [r.log_time_ns for r in raws]
    assert times == sorted(times)
    scans, reference, odom = (np.array([r.log_time_ns for r in raws if r.topic == t], dtype=np.int64)
                              for t in ("/scan", "/ground_truth", "/odom"))
    return method, warnings, scans, reference, odom[~np.isin(odom, scans)]  # not the scans' odometry fields


def test_coarse_stamps_give_way_to_exact_logger_stamps_on_every_line(tmp_path: Path) -> None:
    """A user's log had ipc stamps floored to 10 s and exact logger stamps at 10 Hz: the stamps were synthesized at
    0.2 s (a 24.9 s log came out 49.8 s long), and the TRUEPOS lines spread between the scans, so evaluate found
    "no reference pose within 0.01 s of any estimated pose". The logger stamps are taken for every line instead."""
    from doorbatch.config import EvaluateConfig
    from doorbatch.pipeline.evaluate.trajectory_metrics import associate

    method, warnings, scans, reference, odom = _clock_of(write_log(tmp_path / "coarse.log", coarse_simulator_log()))
    assert method == "logger"
    assert len(warnings) == 2 and "coarse" in warnings[0] and "logger" in warnings[0]  # and the TRUEPOS note
    assert scans.size == reference.size == odom.size == 250
    np.testing.assert_allclose(np.diff(scans), 100_000_000, atol=1_000)
    assert scans[0] == 1_067_590_000_002_000_000  # from the first logged stamp, as a synthesized clock starts
    np.testing.assert_allclose(scans - reference, 1_000_000, atol=1_000)  # received 1 ms apart, not re-spread
    np.testing.assert_allclose(scans - odom, 2_000_000, atol=1_000)
    pairs = associate(reference, scans, EvaluateConfig().max_time_diff_s)
    assert len(pairs) == 250


def test_a_last_line_cut_in_its_logger_stamp_keeps_the_logger_clock(tmp_path: Path) -> None:
    """A killed logger cut the last line after its hostname: it still parses, without a logger stamp, and that one
    missing stamp had sent the whole log back to synthesized stamps. It takes a scan period after the line before."""
    lines = coarse_simulator_log()
    last = max(i for i, line in enumerate(lines) if line.startswith("FLASER"))
    lines = lines[:last + 1]
    lines[-1] = lines[-1].rsplit(" ", 1)[0]  # the logger stamp cut off
    method, _, scans, _, _ = _clock_of(write_log(tmp_path / "cut.log", lines))
    assert method == "logger"
    np.testing.assert_allclose(np.diff(scans), 100_000_000, atol=1_000)


def test_coarse_stamps_without_logger_stamps_are_synthesized_at_the_logs_own_rate(tmp_path: Path) -> None:
    """The same log without logger stamps: the scan rate its coarse stamps give (10 Hz), not
    io.carmen_scan_period_s (0.2 s), and the ODOM and TRUEPOS lines on the scans' clock."""
    path = write_log(tmp_path / "coarse.log", coarse_simulator_log(logger=False))
    method, warnings, scans, reference, odom = _clock_of(path)
    assert method == "synthesized"
    period = np.diff(scans)
    assert abs(float(period.mean()) - 100_000_000) < 1_000_000  # within 1 %: the first and last change of stamp
    assert np.ptp(period) <= 1
    assert "coarse" in warnings[0] and "rate of the logged stamps" in warnings[0]
    for other in (reference, odom):  # the same clock: each within the scan period before its scan
        gap = scans - other
        assert other.size == 250 and bool(np.all((gap > 0) & (gap < period.mean())))


def test_the_configured_scan_period_is_the_last_resort() -> None:
    """Logger stamps that go backwards are not used, and stamps too coarse to give a rate over
    io.carmen_rate_min_scans scans leave io.carmen_scan_period_s."""
    s = 1_000_000_000
    is_scan = np.ones(30, dtype=bool)
    coarse = np.full(30, 100 * s, dtype=np.int64)
    coarse[15:] = 110 * s  # one change of stamp: no span between two changes
    logger = np.arange(30, dtype=np.int64) * (s // 10)
    logger[7] = 0
    result = repair_stamps(coarse, is_scan, 0.2, logger)
    assert result.method == "synthesized" and "io.carmen_scan_period_s" in result.warnings[0]
    np.testing.assert_array_equal(np.diff(result.stamps_ns), 200_000_000)
    coarse[25:] = 120 * s  # two changes, 10 scans apart: fewer than io.carmen_rate_min_scans
    assert "io.carmen_scan_period_s" in repair_stamps(coarse, is_scan, 0.2, logger).warnings[0]
    few = IoConfig(carmen_rate_min_scans=10)
    result = repair_stamps(coarse, is_scan, 0.2, logger, few)
    assert "rate of the logged stamps" in result.warnings[0]
    np.testing.assert_array_equal(np.diff(result.stamps_ns), s)


def test_repair_keeps_scans_and_ignores_one_wild_stamp() -> None:
    s = 1_000_000_000
    stamps = np.array([1 * s, 2 * s, 900 * s, 3 * s, 4 * s, 5 * s, 6 * s], dtype=np.int64)
    result = repair_stamps(stamps, np.array([True, False, False, True, False, True, False]), 0.2)
    assert result.method == "nudged"
    np.testing.assert_array_equal(result.stamps_ns, [1 * s, 2 * s, 2 * s + s // 2, 3 * s, 4 * s, 5 * s, 6 * s])


def test_heaviest_nondecreasing_prefers_heavy_items() -> None:
    assert heaviest_nondecreasing([1, 5, 2, 3], [1, 1, 1, 1]) == [0, 2, 3]
    assert heaviest_nondecreasing([1, 5, 2, 3], [1, 10, 1, 1]) == [0, 1]
    assert heaviest_nondecreasing([], []) == []


@given(st.lists(st.integers(min_value=-5, max_value=10**12), min_size=1, max_size=60),
       st.data())
def test_repaired_stamps_are_always_non_decreasing(values: list[int], data: st.DataObject) -> None:
    is_scan = data.draw(st.lists(st.booleans(), min_size=len(values), max_size=len(values)))
    result = repair_stamps(np.array(values, dtype=np.int64), np.array(is_scan, dtype=bool), 0.2)
    assert result.stamps_ns.shape == (len(values),)
    assert np.all(np.diff(result.stamps_ns) >= 0)
    assert np.all(result.stamps_ns >= 0)
    assert (result.method == "logged") == (not result.warnings)


# ---- errors


def test_malformed_reading_names_the_file_and_line(tmp_path: Path) -> None:
    lines = simple_log(n_scans=3)
    lines[3] = lines[3].replace(" 1.01 ", " abc ", 1)
    path = write_log(tmp_path / "bad.log", lines)
    with pytest.raises(LogReadError, match=r"line 4: reading: 'abc' is not a number") as err:
        CarmenReader(path).__enter__()
    assert str(path) in str(err.value)


def test_wrong_field_count_names_the_line(tmp_path: Path) -> None:
    lines = simple_log(n_scans=3)
    lines[2] = "ODOM 1 2 3"
    with pytest.raises(LogReadError, match="line 3: ODOM line has 4 fields"), \
            open_log(write_log(tmp_path / "bad.log", lines)):
        pass


def test_flaser_with_missing_readings_names_the_line(tmp_path: Path) -> None:
    lines = simple_log(n_scans=2)
    lines[1] = lines[1].replace("FLASER 180", "FLASER 185")
    with pytest.raises(LogReadError, match="line 2: FLASER line has"), open_log(write_log(tmp_path / "b.log", lines)):
        pass


@pytest.mark.parametrize("content", ["# only a comment\n# another\n", "PARAM a 1\nNEFF 3\n", "\n\n"])
def test_a_log_without_scans_is_an_error(tmp_path: Path, content: str) -> None:
    path = tmp_path / "empty.log"
    path.write_text(content)
    with pytest.raises(LogReadError, match="no laser scans"), open_log(path):
        pass


def test_a_log_whose_last_line_is_cut_keeps_the_lines_before_it_with_a_warning(tmp_path: Path) -> None:
    """A logger killed mid-write leaves its last line cut short: a user's log of 1100 good lines was refused for
    it ("line 1110: FLASER line has 23 fields"). The line is dropped with a warning, and every later pass stops
    where the pre-pass did (the streaming pass used to reach the cut line and fail)."""
    lines = simple_log(n_scans=10)
    cut = flaser([1.0] * 180, (1.0, 0.0, 0.0), "102.000000")[:120]
    path = tmp_path / "cut.log"
    path.write_text("\n".join([*lines, cut]))  # no newline after the cut line
    with CarmenReader(path) as reader:
        assert reader.topics["/scan"].count == 10
        assert len(reader.warnings) == 1
        warning = reader.warnings[0]
        assert f"line {len(lines) + 1}: FLASER line has" in warning and f"the {len(lines)} lines before it" in warning
        raws = list(reader.raw_messages())
        assert len([r for r in raws if r.topic == "/scan"]) == 10
        assert reader.end_ns == max(r.log_time_ns for r in raws)
    assert len(scans_of(path)) == 10


def test_a_raw_only_log_whose_last_rawlaser1_line_is_cut_keeps_its_other_scans(tmp_path: Path) -> None:
    lines = [odom_line((0.0, 0.0, 0.0), "10.0"), rawlaser1(10.1), rawlaser1(10.3), rawlaser1(10.5)[:40]]
    path = tmp_path / "raw.log"
    path.write_text("\n".join(lines))
    with CarmenReader(path) as reader:
        assert reader.topics["/scan"].count == 2
        assert any("line 4: RAWLASER1" in w and "cut short" in w for w in reader.warnings)
    assert [s.stamp_ns for s in scans_of(path)] == [10_100_000_000, 10_300_000_000]


@pytest.mark.parametrize("bad", ["ODOM 1 2 3", "PARAM a"])
def test_a_malformed_line_before_the_last_is_still_an_error(tmp_path: Path, bad: str) -> None:
    lines = simple_log(n_scans=3)
    path = write_log(tmp_path / "bad.log", [*lines[:-1], bad, lines[-1]])
    with pytest.raises(LogReadError, match=f"line {len(lines)}: "), open_log(path):
        pass


def test_a_truncated_gzip_keeps_the_lines_before_the_cut_with_a_warning(tmp_path: Path) -> None:
    """A .gz cut at 200 kB was refused whole ("compressed log is truncated or corrupt after line 910"); the
    complete lines before the cut are read, by every pass alike."""
    full = write_log(tmp_path / "full.log.gz", simple_log(n_scans=200))
    cut = tmp_path / "cut.log.gz"
    cut.write_bytes(full.read_bytes()[: full.stat().st_size // 2])
    kept = 0  # the complete lines before the cut
    with gzip.open(cut, "rt") as f, pytest.raises(EOFError):
        for _ in f:
            kept += 1
    assert 10 < kept < 401
    n_flaser = sum(line.startswith("FLASER") for line in simple_log(n_scans=200)[:kept])
    with CarmenReader(cut) as reader:
        assert reader.topics["/scan"].count == n_flaser
        assert len(reader.warnings) == 1 and "ends early" in reader.warnings[0]
        assert f"the {kept} lines before the cut" in reader.warnings[0]
        assert len([r for r in reader.raw_messages() if r.topic == "/scan"]) == n_flaser
    assert len(scans_of(cut)) == n_flaser


def test_a_corrupt_gzip_is_still_a_read_error(tmp_path: Path) -> None:
    full = write_log(tmp_path / "full.log.gz", simple_log(n_scans=200))
    data = bytearray(full.read_bytes())
    data[-8] ^= 0xFF  # the checksum of the data
    bad = tmp_path / "bad.log.gz"
    bad.write_bytes(bytes(data))
    with pytest.raises(LogReadError, match="truncated or corrupt"), open_log(bad):
        pass


# ---- the real logs


def _real(name: str) -> Path:
    path = DATASETS / name
    if not path.exists():
        pytest.skip(f"{path} absent")
    return path


def _flaser_lines(path: Path) -> list[list[str]]:
    with gzip.open(path, "rt") as f:
        return [line.split() for line in f if line.startswith("FLASER ")]


@pytest.mark.parametrize("name", REAL_LOGS)
def test_real_log_scan_count_equals_flaser_count(name: str) -> None:
    path = _real(name)
    expected = len(_flaser_lines(path))
    with open_log(path) as reader:
        assert reader.topics["/scan"].count == expected
        scans = only(Scan, reader.messages([Role.SCAN]))
    assert len(scans) == expected
    assert all(s.ranges.shape[0] in (180, 181) for s in scans)


@pytest.mark.parametrize("name", REAL_LOGS)
def test_real_log_ground_truth_equals_flaser_pose(name: str) -> None:
    path = _real(name)
    poses = []
    for parts in _flaser_lines(path):
        n = int(parts[1])
        poses.append([float(v) for v in parts[2 + n : 5 + n]])
    expected = np.array(poses)
    with open_log(path) as reader:
        messages = list(reader.messages([Role.REFERENCE]))
    got = only(Pose2D, messages)
    assert len(got) == len(messages)
    assert all(p.frame_id == "map" for p in got)
    xy = np.array([[p.x, p.y] for p in got])
    np.testing.assert_allclose(xy, expected[:, :2], atol=1e-9)
    yaw_err = [abs(_wrap(p.yaw - e)) for p, e in zip(got, expected[:, 2], strict=True)]
    assert max(yaw_err) < 1e-9


@pytest.mark.parametrize("name", REAL_LOGS)
def test_real_log_roles_and_time_order(name: str) -> None:
    path = _real(name)
    with open_log(path) as reader:
        roles = reader.roles
        assert roles.topic(Role.SCAN) == "/scan"
        assert roles.topic(Role.ODOMETRY) == "/odom"
        assert roles.topic(Role.REFERENCE) == "/ground_truth"
        times = [r.log_time_ns for r in reader.raw_messages()]
        assert times == sorted(times)
        assert times[0] == reader.start_ns and times[-1] == reader.end_ns
        # these logs have zero or garbage stamps in places: the reader says so
        assert reader.warnings


def test_a_reference_read_from_a_repaired_log_carries_the_repair_warning(tmp_path: Path) -> None:
    """evaluate --reference LOG (or the log beside a run) records the reader's repairs in its manifest."""
    from doorbatch.io.run_reader import read_reference

    lines = simple_log(n_scans=10, t0=100.0)
    lines[6] = lines[6].replace("100.500000", "99.000000")
    reference = read_reference(write_log(tmp_path / "a.log", lines), DoorbatchConfig())
    assert len(reference.stamps_ns) == 10 and any("out of order" in w for w in reference.warnings)


def test_a_malformed_rawlaser1_line_in_a_raw_only_log_names_its_line(tmp_path: Path) -> None:
    lines = [odom_line((0.0, 0.0, 0.0), "10.0"), rawlaser1(10.1), rawlaser1(10.3)[:40], rawlaser1(10.5)]
    path = write_log(tmp_path / "raw.log", lines)
    with pytest.raises(LogReadError, match="line 3"), CarmenReader(path):  # on opening: later stamps would shift
        pass


def test_a_mount_needs_the_robot_to_have_turned(tmp_path: Path) -> None:
    """Driving straight, a corrected laser pose can keep a fixed offset from the odometry by chance; only over
    30 deg of turning does a fixed relative pose show a rigid mount."""
    mount = (0.2, 0.0, 0.0)
    straight = [(0.1 * k, 0.0, 0.0) for k in range(12)]
    lines = [robotlaser1(_mounted(r, mount), r, 3.0 + 0.1 * k) for k, r in enumerate(straight)]
    records = read_all(write_log(tmp_path / "straight.clf", lines))
    np.testing.assert_allclose(next(t for t in only(Transform, records) if t.static).translation, 0.0)


# ---- CARMEN's simulator: TRUEPOS lines


def truepos_line(truth: tuple[float, float, float], odom: tuple[float, float, float], stamp: str) -> str:
    return " ".join(["TRUEPOS", *(f"{v:g}" for v in (*truth, *odom)), stamp, "host", stamp])


def simulator_log(n_scans: int = 15, period: float = 0.2, t0: float = 100.0, order: str = "OTF"
                  ) -> tuple[list[str], np.ndarray]:
    """A log as CARMEN's simulator writes it: FLASER lines whose poses are the odometry (0.5 % short and
    turning 0.02 rad per scan off the truth), ODOM lines, and a TRUEPOS line with each, on the same stamps, in the
    file order ``order`` gives (O: ODOM, T: TRUEPOS, F: FLASER)."""
    lines = ["# message formats defined: PARAM SYNC ODOM FLASER TRUEPOS"]
    truth = np.array([[0.2 * k, 0.01 * k * k, 0.03 * k] for k in range(n_scans)])
    for k, (x, y, yaw) in enumerate(truth):
        odom = (0.995 * x, 0.995 * y, yaw - 0.02 * k)
        t = f"{t0 + k * period:.6f}"
        of_kind = {"O": odom_line(odom, t), "T": truepos_line((x, y, yaw), odom, t),
                   "F": flaser([2.0] * 180, odom, t)}
        lines += [of_kind[c] for c in order]
    return lines, truth


def test_truepos_lines_are_the_reference_and_the_laser_poses_are_not(tmp_path: Path) -> None:
    lines, truth = simulator_log()
    path = write_log(tmp_path / "sim.log", lines)
    records = read_all(path)
    reference = only(Pose2D, records, Role.REFERENCE)
    assert np.allclose([[p.x, p.y, p.yaw] for p in reference], truth, atol=1e-6)
    assert {p.frame_id for p in reference} == {"map"}
    with CarmenReader(path) as reader:
        assert reader.topics["/ground_truth"].count == len(truth)
        assert any("TRUEPOS" in w for w in reader.warnings)
    # the scans' stamps are the truth's: ODOM lines move off them, TRUEPOS lines stay
    assert [s.stamp_ns for s in scans_of(path)] == [p.stamp_ns for p in reference]


def test_a_simulator_log_has_a_reference_that_is_not_its_odometry(tmp_path: Path) -> None:
    lines, _ = simulator_log()
    with_truth = load_recording(write_log(tmp_path / "sim.log", lines), DoorbatchConfig())
    without = load_recording(write_log(tmp_path / "raw.log", [w for w in lines if not w.startswith("TRUEPOS")]),
                             DoorbatchConfig())
    assert not with_truth.reference_is_odometry and without.reference_is_odometry


@pytest.mark.parametrize("order", ["OTF", "FOT", "FTO", "TFO"])
def test_truepos_lines_keep_the_messages_in_time_order(tmp_path: Path, order: str) -> None:
    """ODOM lines on a scan's stamp move off it, between their neighbours; TRUEPOS lines keep their stamps and
    bound them, so the stream stays in log-time order and a time window holds every TRUEPOS line in it (a reviewer
    found FLASER, ODOM, TRUEPOS going back in time, and a window losing a reference pose)."""
    lines, truth = simulator_log(order=order)
    path = write_log(tmp_path / "sim.log", lines)
    with CarmenReader(path) as reader:
        times = [m.log_time_ns for m in reader.raw_messages()]
        assert times == sorted(times)
        stop = int(100.25e9)
        window = [m for m in reader.raw_messages(["/ground_truth"], stop_ns=stop)]
    assert len(window) == 2  # the truth at 100.0 and 100.2 s
    assert len(only(Pose2D, read_all(path), Role.REFERENCE)) == len(truth)


def test_a_malformed_truepos_line_is_an_error_that_names_it(tmp_path: Path) -> None:
    lines, _ = simulator_log(n_scans=3)
    lines[2] = "TRUEPOS 0.0 nan 0.0 0 0 0 100.000000 host 100.000000"
    with pytest.raises(LogReadError, match="line 3: true pose is not finite"):
        read_all(write_log(tmp_path / "bad.log", lines))
