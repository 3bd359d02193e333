"""Logs written without ROS: Foxglove's schemas in MCAP, as the Foxglove SDK writes them (protobuf) and as a
hand-written writer does with ``mcap`` (JSON), read as the same log in ROS messages reads."""

from __future__ import annotations

import base64
import json
import math
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest
from mcap.writer import Writer

from doorbatch.cli import main
from doorbatch.errors import LogContentError
from doorbatch.geometry.rotations import quaternion_to_matrix
from doorbatch.io import foxglove as fx
from doorbatch.io.annotated_mcap import write_annotated_mcap
from doorbatch.io.decode import decode_scan
from doorbatch.io.reader import open_log
from doorbatch.io.recording import Recording, load_recording
from doorbatch.records import CameraInfo, Image, Role, Scan, Transform
from tests.conftest import REPO, T0, Message, sample_messages

foxglove = pytest.importorskip("foxglove")  # the test extra's Foxglove SDK: the writer these logs come from

KEPT = ("/tf_static", "/tf", "/odom", "/ground_truth", "/scan", "/camera/image_raw", "/camera/camera_info")


def _time(stamp: Any) -> dict[str, int]:
    return {"sec": int(stamp.sec), "nsec": int(stamp.nanosec)}


def _xyz(v: Any) -> dict[str, float]:
    return {"x": float(v.x), "y": float(v.y), "z": float(v.z)}


def _quat(q: Any) -> dict[str, float]:
    return {**_xyz(q), "w": float(q.w)}


def _pose(p: Any) -> dict[str, Any]:
    return {"position": _xyz(p.position), "orientation": _quat(p.orientation)}


def as_foxglove(msgs: Iterable[Message]) -> list[tuple[str, str, int, dict[str, Any]]]:
    """The sample log as a non-ROS robot logs it with Foxglove's schemas, in their JSON form (bytes as base64):
    every transform on /tf (the mounts once, at the start), odometry as foxglove.Odometry, the reference as
    foxglove.PoseInFrame, scans, raw images and calibrations. Colors and detections have no Foxglove schema."""
    out: list[tuple[str, str, int, dict[str, Any]]] = []
    for topic, _msgtype, t, msg in msgs:
        if topic not in KEPT:
            continue
        if topic in ("/tf", "/tf_static"):
            out.append(("/tf", "FrameTransforms", t, {"transforms": [
                {"timestamp": _time(ts.header.stamp), "parent_frame_id": ts.header.frame_id,
                 "child_frame_id": ts.child_frame_id, "translation": _xyz(ts.transform.translation),
                 "rotation": _quat(ts.transform.rotation)} for ts in msg.transforms]}))
        elif topic == "/odom":
            out.append((topic, "Odometry", t, {"timestamp": _time(msg.header.stamp), "frame_id": msg.header.frame_id,
                                               "body_frame_id": msg.child_frame_id, "pose": _pose(msg.pose.pose)}))
        elif topic == "/ground_truth":
            out.append(("/pose", "PoseInFrame", t, {"timestamp": _time(msg.header.stamp),
                                                    "frame_id": msg.header.frame_id, "pose": _pose(msg.pose.pose)}))
        elif topic == "/scan":
            n = len(msg.ranges)
            out.append((topic, "LaserScan", t, {
                "timestamp": _time(msg.header.stamp), "frame_id": msg.header.frame_id,
                "start_angle": float(msg.angle_min), "end_angle": float(msg.angle_min + msg.angle_increment * (n - 1)),
                "ranges": [float(r) for r in msg.ranges], "intensities": []}))
        elif topic == "/camera/image_raw":
            out.append(("/camera/image", "RawImage", t, {
                "timestamp": _time(msg.header.stamp), "frame_id": msg.header.frame_id, "width": int(msg.width),
                "height": int(msg.height), "encoding": msg.encoding, "step": int(msg.step),
                "data": base64.b64encode(np.asarray(msg.data, dtype=np.uint8).tobytes()).decode()}))
        else:
            out.append(("/camera/calibration", "CameraCalibration", t, {
                "timestamp": _time(msg.header.stamp), "frame_id": msg.header.frame_id, "width": int(msg.width),
                "height": int(msg.height), "distortion_model": msg.distortion_model,
                "D": [float(v) for v in msg.d], "K": [float(v) for v in msg.k], "R": [float(v) for v in msg.r],
                "P": [float(v) for v in msg.p]}))
    return out


def _sdk_message(kind: str, d: dict[str, Any]) -> Any:
    """The Foxglove SDK's message of a JSON-form dict."""
    m = foxglove.messages

    def build(name: str, value: Any) -> Any:
        if name == "timestamp":
            return m.Timestamp(**value)
        if name in ("translation",):
            return m.Vector3(**value)
        if name in ("rotation", "orientation"):
            return m.Quaternion(**value)
        if name == "position":
            return m.Vector3(**value)
        if name == "pose":
            return m.Pose(**{k: build(k, v) for k, v in value.items()})
        if name == "transforms":
            return [m.FrameTransform(**{k: build(k, v) for k, v in tf.items()}) for tf in value]
        if name == "data":
            return base64.b64decode(value)
        return value

    return getattr(m, kind)(**{k: build(k, v) for k, v in d.items()})


def write_sdk(path: Path, msgs: list[tuple[str, str, int, dict[str, Any]]]) -> Path:
    """An MCAP written by the Foxglove SDK (protobuf), each message at its log time."""
    ctx = foxglove.Context()
    writer = foxglove.open_mcap(path, allow_overwrite=True, context=ctx)
    channels: dict[str, Any] = {}
    for topic, kind, t, d in msgs:
        if topic not in channels:
            channels[topic] = getattr(foxglove.channels, f"{kind}Channel")(topic, context=ctx)
        channels[topic].log(_sdk_message(kind, d), log_time=t)
    for ch in channels.values():
        ch.close()
    writer.close()
    return path


Entry = tuple[str, str, str, bytes, str, int, bytes]  # topic, schema, its encoding and data, encoding, time, payload


def write_mcap(path: Path, entries: Iterable[Entry]) -> Path:
    """An MCAP written by hand with ``mcap``: (topic, schema name, schema encoding, schema data, message encoding,
    log time, payload) per message, one schema and channel per topic."""
    with path.open("wb") as f:
        writer = Writer(f)
        writer.start(profile="", library="hand-written")
        channels: dict[str, int] = {}
        for topic, name, schema_encoding, schema_data, encoding, t, data in entries:
            if topic not in channels:
                channels[topic] = writer.register_channel(
                    topic, encoding, writer.register_schema(name, schema_encoding, schema_data))
            writer.add_message(channels[topic], log_time=t, data=data, publish_time=t)
        writer.finish()
    return path


def json_entries(msgs: list[tuple[str, str, int, dict[str, Any]]]) -> list[Entry]:
    """JSON messages under Foxglove's schema names (the schema text is the writer's business; the name is what
    readers go by)."""
    schema = json.dumps({"type": "object"}).encode()
    return [(topic, f"foxglove.{kind}", "jsonschema", schema, "json", t, json.dumps(d).encode())
            for topic, kind, t, d in msgs]


def write_json(path: Path, msgs: list[tuple[str, str, int, dict[str, Any]]]) -> Path:
    """The messages as JSON in an MCAP written by hand (:func:`json_entries`)."""
    return write_mcap(path, json_entries(msgs))


@pytest.fixture(params=["protobuf", "json"])
def foxglove_log(request: pytest.FixtureRequest, write_log: Callable[..., Path], tmp_path: Path
                 ) -> tuple[Path, Path]:
    """(the sample log in ROS messages, the same log in Foxglove's schemas)."""
    msgs = sample_messages(12)
    ros = write_log("ros.mcap", msgs)
    write = write_sdk if request.param == "protobuf" else write_json
    return ros, write(tmp_path / f"fox_{request.param}.mcap", as_foxglove(msgs))


def test_a_foxglove_log_loads_as_the_same_recording(foxglove_log: tuple[Path, Path]) -> None:
    ros, fox = foxglove_log
    a, b = load_recording(ros), load_recording(fox)
    np.testing.assert_array_equal(a.scans.stamps_ns, b.scans.stamps_ns)
    for ra, rb in zip(a.scans.ranges, b.scans.ranges, strict=True):
        np.testing.assert_array_equal(ra, rb)  # NaN (no information) and inf (no return) kept as they were
    np.testing.assert_allclose(a.scans.angle_min, b.scans.angle_min, atol=1e-6)
    np.testing.assert_allclose(a.scans.angle_increment, b.scans.angle_increment, atol=1e-7)
    # The laser mount, logged once on /tf as Foxglove logs it, holds at every scan (a constant edge).
    np.testing.assert_allclose(a.scans.laser_to_base, b.scans.laser_to_base, atol=1e-12)
    assert a.odometry is not None and b.odometry is not None
    np.testing.assert_array_equal(a.odometry.stamps_ns, b.odometry.stamps_ns)
    np.testing.assert_allclose(a.odometry.poses, b.odometry.poses, atol=1e-9)
    assert a.reference is not None and b.reference is not None
    np.testing.assert_allclose(a.reference.poses, b.reference.poses, atol=1e-9)
    assert np.isinf(b.scans.range_max).all()  # the schema states no maximum range


def test_foxglove_images_and_calibrations_read_as_ros_ones(foxglove_log: tuple[Path, Path]) -> None:
    ros, fox = foxglove_log

    def records(path: Path) -> tuple[list[Image], list[CameraInfo]]:
        with open_log(path) as reader:
            got = [item.record for item in reader.messages([Role.IMAGE, Role.CAMERA_INFO])]
        return [r for r in got if isinstance(r, Image)], [r for r in got if isinstance(r, CameraInfo)]

    (ia, ca), (ib, cb) = records(ros), records(fox)
    assert len(ia) == len(ib) == 12 and len(ca) == len(cb) == 1
    for x, y in zip(ia, ib, strict=True):
        assert (x.stamp_ns, x.frame_id, x.encoding) == (y.stamp_ns, y.frame_id, y.encoding)
        np.testing.assert_array_equal(x.pixels, y.pixels)
    np.testing.assert_array_equal(ca[0].k, cb[0].k)
    np.testing.assert_array_equal(ca[0].p, cb[0].p)


def test_inspect_names_the_foxglove_schema_and_the_role(foxglove_log: tuple[Path, Path],
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    _, fox = foxglove_log
    assert main(["inspect", str(fox), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    topics = {t["name"]: t for t in report["topics"]}
    assert topics["/scan"]["msgtype"] == "foxglove.LaserScan" and topics["/scan"]["role"] == "scan"
    assert "read as sensor_msgs/msg/LaserScan" in topics["/scan"]["why"]
    assert topics["/odom"]["role"] == "odometry" and topics["/pose"]["role"] == "reference"


def test_convert_writes_a_foxglove_log_as_ros_messages(foxglove_log: tuple[Path, Path], tmp_path: Path) -> None:
    _, fox = foxglove_log
    out = tmp_path / "converted.mcap"
    assert main(["convert", str(fox), "-o", str(out)]) == 0
    a, b = load_recording(fox), load_recording(out)
    for ra, rb in zip(a.scans.ranges, b.scans.ranges, strict=True):
        np.testing.assert_array_equal(ra, rb)
    assert a.odometry is not None and b.odometry is not None
    np.testing.assert_allclose(a.odometry.poses, b.odometry.poses, atol=1e-9)


def _scan_endpoints(scan: Scan) -> np.ndarray:
    hit = np.isfinite(scan.ranges)
    return np.stack([scan.ranges[hit] * np.cos(scan.angles[hit]), scan.ranges[hit] * np.sin(scan.angles[hit])], 1)


@pytest.mark.parametrize("axis,angle", [((0, 0, 1), 0.7), ((0, 0, 1), -2.5), ((1, 0, 0), math.pi),
                                        ((0, 1, 0), math.pi)])
def test_a_scan_origin_rotated_in_its_plane_puts_every_point_where_foxglove_draws_it(
        axis: tuple[int, int, int], angle: float) -> None:
    """Foxglove draws beam i at R(pose)·(r cos a_i, r sin a_i, 0): about z (any heading) or upside down (half turns
    about x or y), the scan read as a LaserScan puts each point there."""
    rng = np.random.default_rng(3)
    ranges = rng.uniform(0.5, 8.0, 37)
    ranges[5] = np.inf
    start, end = -1.9, 2.2
    s, c = math.sin(angle / 2), math.cos(angle / 2)
    q = {"x": axis[0] * s, "y": axis[1] * s, "z": axis[2] * s, "w": c}
    msg = {"timestamp": {"sec": 1, "nsec": 5}, "frame_id": "laser", "pose": {"orientation": q},
           "start_angle": start, "end_angle": end, "ranges": [float(r) for r in ranges]}
    scan = decode_scan(fx.as_ros("LaserScan", msg, "/scan"), 0, "/scan")
    a = np.linspace(start, end, 37)
    local = np.stack([ranges * np.cos(a), ranges * np.sin(a), np.zeros(37)], 1)[np.isfinite(ranges)]
    drawn = local @ quaternion_to_matrix([q["x"], q["y"], q["z"], q["w"]]).T
    np.testing.assert_allclose(_scan_endpoints(scan), drawn[:, :2], atol=1e-5)
    assert scan.stamp_ns == 1_000_000_005


def _scans_in_base_link(msgs: list[tuple[str, str, int, dict[str, Any]]], yaw: float, frame: str = "base_link"
                        ) -> list[tuple[str, str, int, dict[str, Any]]]:
    """The scans logged in base_link (named ``frame``) with the laser mount (0.2, 0, 0.3) as their origin, turned
    by ``yaw`` (the beam angles turned back, so the beams point where they did), and no base_link → laser
    transform."""
    out = []
    for topic, kind, t, d in msgs:
        if topic == "/tf":
            d = {"transforms": [x for x in d["transforms"] if x["child_frame_id"] != "laser"]}
            if not d["transforms"]:
                continue
        if topic == "/scan":
            d = {**d, "frame_id": frame, "start_angle": d["start_angle"] - yaw,
                 "end_angle": d["end_angle"] - yaw,
                 "pose": {"position": {"x": 0.2, "y": 0.0, "z": 0.3},
                          "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}}}
        out.append((topic, kind, t, d))
    return out


@pytest.mark.parametrize("writer", ["protobuf", "json"])
def test_a_scan_origin_off_its_frame_is_its_mount(write_log: Callable[..., Path], tmp_path: Path,
                                                  writer: str) -> None:
    """Scans logged in base_link with the mount as their origin (turned, too) put every hit where the log with a
    laser frame and a base_link → laser transform puts it; `convert` writes the mount as /tf_static."""
    msgs = sample_messages(6)
    ros = load_recording(write_log("ros.mcap", msgs))
    write = write_sdk if writer == "protobuf" else write_json
    path = write(tmp_path / f"origin_{writer}.mcap", _scans_in_base_link(as_foxglove(msgs), 0.4))
    converted = tmp_path / "converted.mcap"
    assert main(["convert", str(path), "-o", str(converted)]) == 0
    for fox in (load_recording(path), load_recording(converted)):
        assert fox.scans.frame_id == "base_link/scan_origin"
        _assert_same_hits(ros, fox)


def _assert_same_hits(ros: Recording, fox: Recording) -> None:
    assert len(fox.scans) == len(ros.scans)
    for i in range(len(ros.scans)):
        a, b = ros.scans.endpoints_base(i), fox.scans.endpoints_base(i)
        np.testing.assert_array_equal(a[1], b[1])
        np.testing.assert_allclose(a[0][a[1]], b[0][b[1]], atol=1e-5)


def test_a_ros1_style_frame_name_keeps_the_scan_origin_mount(write_log: Callable[..., Path], tmp_path: Path) -> None:
    """A frame named "/base_link" (a ROS 1 habit) is base_link, as in ROS messages: the origin frame hangs under
    base_link, and the scans read as with "base_link"."""
    msgs = sample_messages(6)
    ros = load_recording(write_log("ros.mcap", msgs))
    fox = load_recording(write_json(tmp_path / "slash.mcap", _scans_in_base_link(as_foxglove(msgs), 0.4,
                                                                                 "/base_link")))
    assert fox.scans.frame_id == "base_link/scan_origin"
    _assert_same_hits(ros, fox)


def test_the_mount_comes_from_the_first_scan_that_reads(write_log: Callable[..., Path], tmp_path: Path) -> None:
    """An unreadable first scan (bad JSON, JSON that is not an object, no ranges, or an origin tilted out of the
    plane) is skipped as any unreadable message is, and the mount comes from the next scan: the topic is not
    refused."""
    msgs = sample_messages(8)
    ros = load_recording(write_log("ros.mcap", msgs))
    entries = json_entries(_scans_in_base_link(as_foxglove(msgs), 0.4))
    first = next(i for i, e in enumerate(entries) if e[0] == "/scan")
    tilted = json.loads(entries[first][6])
    tilted["pose"]["orientation"] = {"x": math.sin(0.2), "y": 0.0, "z": 0.0, "w": math.cos(0.2)}
    for bad in (b"{not json", json.dumps(tilted).encode(), b"null", b"[]", b'{"ranges": []}'):
        broken = list(entries)
        broken[first] = (*entries[first][:6], bad)
        fox = load_recording(write_mcap(tmp_path / "first_bad.mcap", broken))
        assert fox.scans.frame_id == "base_link/scan_origin"
        assert any("1 of 8 messages on /scan skipped" in w for w in fox.warnings)
        assert fox.scans.stamps_ns.tolist() == ros.scans.stamps_ns[1:].tolist()
        for i in range(len(fox.scans)):
            a, b = ros.scans.endpoints_base(i + 1), fox.scans.endpoints_base(i)
            np.testing.assert_allclose(a[0][a[1]], b[0][b[1]], atol=1e-5)


def test_the_annotated_copy_of_a_log_carries_the_scan_origin_mount(write_log: Callable[..., Path],
                                                                  tmp_path: Path) -> None:
    """annotated.mcap copies the log in ROS messages: its scans are in the origin frame, so it holds the mount on
    /tf_static, and reads as the log does."""
    msgs = sample_messages(6)
    ros = load_recording(write_log("ros.mcap", msgs))
    path = write_json(tmp_path / "origin.mcap", _scans_in_base_link(as_foxglove(msgs), 0.4))
    out = tmp_path / "annotated.mcap"
    write_annotated_mcap(path, out, [])
    with open_log(out) as reader:
        assert reader.topics["/tf_static"].msgtype == "tf2_msgs/msg/TFMessage"
    copy = load_recording(out)
    assert copy.scans.frame_id == "base_link/scan_origin"
    _assert_same_hits(ros, copy)


def test_a_scan_origin_that_moves_is_a_clear_error(tmp_path: Path) -> None:
    msgs = _scans_in_base_link(as_foxglove(sample_messages(3)), 0.0)
    scans = [d for topic, _, _, d in msgs if topic == "/scan"]
    for d in scans[1:]:
        d["pose"] = {**d["pose"], "position": {"x": 0.25, "y": 0.0, "z": 0.3}}
    fox = write_json(tmp_path / "moving.mcap", msgs)
    with pytest.raises(LogContentError, match=r"origin \(0.250, 0.000, 0.300\) m in 'base_link' differs from the "
                                              r"topic's first scan's \(\(0.200, 0.000, 0.300\)") as err:
        load_recording(fox)
    assert str(fox) in str(err.value)


def test_json_nulls_and_zero_ranges_carry_no_hit(tmp_path: Path) -> None:
    """Strict JSON writes NaN as null; a zero reading (a driver's "no echo") is no hit, as in any log whose
    range_min is 0; with no maximum stated, any other finite reading is one."""
    msgs = as_foxglove(sample_messages(2))
    for topic, _, _, d in msgs:
        if topic == "/scan":
            d["ranges"] = [1.0, None, 0.0, 2.0, 1e9, *d["ranges"][5:]]
    rec = load_recording(write_json(tmp_path / "zeros.mcap", msgs))
    for i in range(2):
        _, hit = rec.scans.endpoints_base(i)
        assert hit[:5].tolist() == [True, False, False, True, True]


def test_the_sample_passes_logged_by_the_foxglove_sdk_map_to_the_same_doors(tmp_path: Path) -> None:
    """End to end: the three sample mapping passes rewritten as a robot without ROS logs them (protobuf, the mount
    once on /tf, the reference as foxglove.PoseInFrame) give `doorbatch map` the same grid and the same doors."""
    logs = sorted((REPO / "datasets" / "sample" / "logs").glob("map_pass*.mcap"))
    fox = []
    for log in logs:
        with open_log(log) as reader:
            msgs = [(r.topic, r.msgtype, r.log_time_ns, r.msg) for r in reader.raw_messages()]
        fox.append(write_sdk(tmp_path / log.name, as_foxglove(msgs)))
    for name, inputs in (("ros", logs), ("fox", fox)):
        assert main(["map", *map(str, inputs), "-o", str(tmp_path / name), "--stages", "grid", "-q"]) == 0
    doors = [pq.read_table(tmp_path / name / "doors.parquet") for name in ("ros", "fox")]
    assert doors[0].num_rows >= 5 and doors[0].equals(doors[1])
    assert (tmp_path / "ros" / "map.pgm").read_bytes() == (tmp_path / "fox" / "map.pgm").read_bytes()
    manifest = json.loads((tmp_path / "fox" / "manifest.json").read_text())
    assert manifest["extra"]["pose_source"] == "reference"


_FOXGLOVE_MSGS = {  # foxglove_msgs 3.x, as ros2 bag record puts their definitions in an MCAP
    "foxglove_msgs/msg/LaserScan": "builtin_interfaces/Time timestamp\nstring frame_id\ngeometry_msgs/Pose pose\n"
                                   "float64 start_angle\nfloat64 end_angle\nfloat64[] ranges\nfloat64[] intensities\n",
    "foxglove_msgs/msg/FrameTransform": "builtin_interfaces/Time timestamp\nstring parent_frame_id\n"
                                        "string child_frame_id\ngeometry_msgs/Vector3 translation\n"
                                        "geometry_msgs/Quaternion rotation\n",
    "foxglove_msgs/msg/CameraCalibration": "builtin_interfaces/Time timestamp\nstring frame_id\nuint32 width\n"
                                           "uint32 height\nstring distortion_model\nfloat64[] d\nfloat64[9] k\n"
                                           "float64[9] r\nfloat64[12] p\n",  # ROS 2's are lowercase
}


def test_foxglove_msgs_recorded_by_ros2_read_like_their_protobuf_form(tmp_path: Path) -> None:
    """A ROS 2 recording through a Foxglove bridge holds foxglove_msgs/msg/... in CDR: read as the same messages."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    for name, text in _FOXGLOVE_MSGS.items():
        store.register(get_types_from_msg(text, name))
    t = store.types
    stamp = t["builtin_interfaces/msg/Time"](sec=7, nanosec=250)
    quat = t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(0.3), w=math.cos(0.3))
    ranges = np.array([1.0, np.inf, 2.5, np.nan, 3.0])
    scan = t["foxglove_msgs/msg/LaserScan"](
        timestamp=stamp, frame_id="laser",
        pose=t["geometry_msgs/msg/Pose"](position=t["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0), orientation=quat),
        start_angle=-1.0, end_angle=1.0, ranges=ranges, intensities=np.zeros(0))
    mount = t["foxglove_msgs/msg/FrameTransform"](
        timestamp=stamp, parent_frame_id="base_link", child_frame_id="laser",
        translation=t["geometry_msgs/msg/Vector3"](x=0.1, y=0.0, z=0.2), rotation=quat)
    k = np.array([500.0, 0.0, 320.0, 0.0, 505.0, 240.0, 0.0, 0.0, 1.0])
    calibration = t["foxglove_msgs/msg/CameraCalibration"](
        timestamp=stamp, frame_id="camera", width=640, height=480, distortion_model="plumb_bob", d=np.zeros(5),
        k=k, r=np.eye(3).ravel(), p=np.concatenate([k.reshape(3, 3), np.zeros((3, 1))], 1).ravel())
    path = tmp_path / "bridge.mcap"
    with path.open("wb") as f:
        writer = Writer(f)
        writer.start(profile="ros2", library="test")
        for topic, name, msg in (("/tf", "foxglove_msgs/msg/FrameTransform", mount),
                                 ("/scan", "foxglove_msgs/msg/LaserScan", scan),
                                 ("/camera/calibration", "foxglove_msgs/msg/CameraCalibration", calibration)):
            sid = writer.register_schema(name, "ros2msg", store.generate_msgdef(name, ros_version=2)[0].encode())
            cid = writer.register_channel(topic, "cdr", sid)
            writer.add_message(cid, log_time=7_000_000_250, data=bytes(store.serialize_cdr(msg, name)),
                               publish_time=7_000_000_250)
        writer.finish()
    with open_log(path) as reader:
        assert reader.topics["/scan"].msgtype == "sensor_msgs/msg/LaserScan"
        assert reader.topics["/scan"].schema == "foxglove_msgs/msg/LaserScan"
        got = [item.record for item in reader.messages([Role.SCAN, Role.TRANSFORMS, Role.CAMERA_INFO])]
    scans = [r for r in got if isinstance(r, Scan)]
    expected = decode_scan(fx.as_ros("LaserScan", {
        "timestamp": {"sec": 7, "nsec": 250}, "frame_id": "laser", "start_angle": -1.0, "end_angle": 1.0,
        "pose": {"orientation": {"z": math.sin(0.3), "w": math.cos(0.3)}}, "ranges": ranges.tolist()}, "/scan"),
        0, "/scan")
    assert len(scans) == 1 and scans[0].stamp_ns == 7_000_000_250
    np.testing.assert_array_equal(scans[0].ranges, expected.ranges)
    assert scans[0].angle_min == pytest.approx(-1.0 + 0.6) and expected.angle_min == pytest.approx(-1.0 + 0.6)
    tfs = [r for r in got if isinstance(r, Transform)]
    assert [(x.parent, x.child) for x in tfs] == [("base_link", "laser")]
    np.testing.assert_allclose(tfs[0].translation, [0.1, 0.0, 0.2])
    infos = [r for r in got if isinstance(r, CameraInfo)]
    assert len(infos) == 1 and (infos[0].width, infos[0].height) == (640, 480)
    np.testing.assert_array_equal(infos[0].k, k.reshape(3, 3))


def test_a_foxglove_channel_that_cannot_be_read_is_listed_with_a_warning(tmp_path: Path,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """FlatBuffers, or a protobuf schema that does not parse: the channel stays unread, the log reads."""
    extra = [("/flat_scan", "foxglove.LaserScan", "flatbuffer", b"\x00" * 8, "flatbuffer", T0, b"\x00" * 8),
             ("/pb_scan", "foxglove.LaserScan", "protobuf", b"not a descriptor set", "protobuf", T0, b"\x01")]
    path = write_mcap(tmp_path / "mixed.mcap", [*json_entries(as_foxglove(sample_messages(4))), *extra])
    rec = load_recording(path)
    assert len(rec.scans) == 4
    assert any("/flat_scan" in w and "flatbuffer" in w for w in rec.warnings)
    assert any("/pb_scan" in w and "protobuf schema" in w for w in rec.warnings)
    assert main(["inspect", str(path), "--json"]) == 0
    topics = {t["name"]: t for t in json.loads(capsys.readouterr().out)["topics"]}
    assert topics["/flat_scan"]["role"] is None and topics["/scan"]["role"] == "scan"


def test_an_unreadable_foxglove_message_is_skipped_and_a_topic_of_them_is_an_error(tmp_path: Path) -> None:
    """As for ROS messages that do not decode: one bad scan of twelve is skipped with a warning; when most are
    bad, the first one's error names the file and the topic."""
    entries = json_entries(as_foxglove(sample_messages(12)))
    scans = [i for i, e in enumerate(entries) if e[0] == "/scan"]
    one = list(entries)
    one[scans[3]] = (*one[scans[3]][:6], b"{not json")
    rec = load_recording(write_mcap(tmp_path / "one.mcap", one))
    assert len(rec.scans) == 11
    assert any("1 of 12 messages on /scan skipped" in w and "JSONDecodeError" in w for w in rec.warnings)
    most = [(*e[:6], b"[1, 2]") if i in scans[:7] else e for i, e in enumerate(entries)]
    path = write_mcap(tmp_path / "most.mcap", most)
    with pytest.raises(LogContentError, match="JSON list, not an object") as err:
        load_recording(path)
    assert err.value.topic == "/scan" and str(path) in str(err.value)


def test_json_nulls_are_absent_fields_and_scans_of_one_or_no_beam() -> None:
    msgtype, scan = fx.as_ros_message("LaserScan", {"timestamp": {"sec": 3, "nsec": None}, "frame_id": None,
                                                    "start_angle": 0.5, "end_angle": None, "ranges": [2.0]},
                                      "/scan")
    assert msgtype == "sensor_msgs/msg/LaserScan" and scan.header.frame_id == ""
    one = decode_scan(scan, 0, "/scan")
    assert one.stamp_ns == 3_000_000_000 and one.angle_min == pytest.approx(0.5) and one.ranges.tolist() == [2.0]
    with pytest.raises(LogContentError, match="no ranges"):
        fx.as_ros_message("LaserScan", {"ranges": []}, "/scan")
    with pytest.raises(LogContentError, match=r"unreadable foxglove\.RawImage"):
        fx.as_ros_message("RawImage", {"width": 2, "height": 1, "encoding": "mono8", "step": 2, "data": "%%"},
                          "/img")


def test_transforms_without_timestamps_are_timed_by_their_log_time(write_log: Callable[..., Path], tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """A FrameTransform logged without ``timestamp`` (odometry from TF only): stamped 0, every odom → base_link
    would be one transform at 0; each is timed by its log time instead, as unset stamps of other messages are,
    and inspect says so."""
    msgs = [x for x in sample_messages(10) if x[0] != "/odom"]
    ros = load_recording(write_log("tf_odometry.mcap", msgs))
    fox_msgs = as_foxglove(msgs)
    for topic, _, _, d in fox_msgs:
        if topic == "/tf":
            for tf in d["transforms"]:
                tf.pop("timestamp")
    path = write_json(tmp_path / "unstamped_tf.mcap", fox_msgs)
    fox = load_recording(path)
    assert ros.odometry is not None and fox.odometry is not None and len(fox.odometry) == len(ros.odometry) == 10
    np.testing.assert_array_equal(fox.odometry.stamps_ns, ros.odometry.stamps_ns)
    np.testing.assert_allclose(fox.odometry.poses, ros.odometry.poses, atol=1e-9)
    assert any("header stamp 0 (unset): timed by their log time" in w and "odom→base_link (10 of 10)" in w
               for w in fox.warnings)
    assert main(["inspect", str(path)]) == 0
    assert "odom→base_link (10 of 10)" in capsys.readouterr().out
