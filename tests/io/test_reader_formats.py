"""The same content written as MCAP, ROS 1 bag and ROS 2 bag (sqlite3, mcap) reads back identically."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from mcap.writer import Writer as McapWriter

from doorbatch.config import DoorPoseConfig
from doorbatch.errors import LogReadError
from doorbatch.io.annotated_mcap import Annotation, write_annotated_mcap
from doorbatch.io.convert import convert_log
from doorbatch.io.reader import RawMessage, open_log
from doorbatch.io.typestore import ros1_typestore
from doorbatch.records import Role, RoleMessage, class_name
from tests.conftest import REPO, sample_messages

FORMATS = {"mcap": "log.mcap", "bag": "log.bag", "rosbag2": "log_sqlite3", "rosbag2-mcap": "log_mcapstore"}


def _read(path: Path) -> tuple[dict[Role, tuple[str, ...]], list[RoleMessage]]:
    with open_log(path) as reader:
        return reader.roles.topics, list(reader.messages())


def _assert_same_records(a: list[RoleMessage], b: list[RoleMessage]) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert (x.role, x.topic, type(x.record)) == (y.role, y.topic, type(y.record))
        for name in x.record.__slots__:  # type: ignore[union-attr]
            va, vb = getattr(x.record, name), getattr(y.record, name)
            if isinstance(va, np.ndarray):
                np.testing.assert_array_equal(va, vb, err_msg=f"{x.topic}.{name}")
            elif name == "detections":  # a ROS 1 bag's ids are indices ("0"), resolved by the label list
                names = DoorPoseConfig().class_names
                assert [replace(d, class_id=class_name(d.class_id, names)) for d in va] == [
                    replace(d, class_id=class_name(d.class_id, names)) for d in vb], f"{x.topic}.{name}"
            else:
                assert va == vb, f"{x.topic}.{name}: {va!r} != {vb!r}"


def _rewrite_mcap(src: Path, path: Path, profile: str, schema: Callable[[RawMessage], tuple[str, str, str]]) -> None:
    """Every message of ``src`` into the MCAP ``path``, with each topic's schema (name, encoding, text) from
    ``schema`` and payloads serialized for ``profile`` (``ros1``, or ``ros2``: CDR)."""
    with open_log(src) as reader, path.open("wb") as f:
        writer = McapWriter(f)
        writer.start(profile=profile, library="test")
        channels: dict[str, int] = {}
        for raw in reader.raw_messages():
            if raw.topic not in channels:
                name, encoding, text = schema(raw)
                sid = writer.register_schema(name, encoding, text.encode())
                channels[raw.topic] = writer.register_channel(raw.topic, "ros1" if profile == "ros1" else "cdr", sid)
            store = raw.store
            data = (store.serialize_ros1(raw.msg, raw.msgtype) if profile == "ros1"  # type: ignore[union-attr]
                    else store.serialize_cdr(raw.msg, raw.msgtype))  # type: ignore[union-attr]
            writer.add_message(channels[raw.topic], log_time=raw.log_time_ns, publish_time=raw.log_time_ns, data=data)
        writer.finish()


@pytest.mark.parametrize("fmt", ["bag", "rosbag2", "rosbag2-mcap"])
def test_every_format_reads_back_like_mcap(write_log: Callable[..., Path], fmt: str) -> None:
    ref_roles, ref = _read(write_log(FORMATS["mcap"]))
    roles, records = _read(write_log(FORMATS[fmt], fmt=fmt))
    assert roles == ref_roles
    assert set(ref_roles) == set(Role)  # every role was detected
    _assert_same_records(records, ref)


def test_records_hold_the_written_values(write_log: Callable[..., Path]) -> None:
    messages = sample_messages(n_scans=5, beams=91)
    with open_log(write_log("a.mcap", messages)) as reader:
        scans = [rm.record for rm in reader.messages([Role.SCAN])]
        dets = [rm.record for rm in reader.messages([Role.DETECTIONS])]
    written = [msg for topic, _, _, msg in messages if topic == "/scan"]
    assert len(scans) == 5
    for scan, msg in zip(scans, written, strict=True):
        assert scan.stamp_ns == msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        np.testing.assert_array_equal(scan.ranges, msg.ranges)
        assert scan.frame_id == "laser"
        # own copies: a view into the message's buffer kept every scan's whole message (intensities too) alive
        assert scan.ranges.flags.owndata and (scan.intensities is None or scan.intensities.flags.owndata)
    assert [d.class_id for d in dets[0].detections] == ["door", "handle"]
    assert dets[0].detections[0].center_x == 30.0


def test_ros1_messages_inside_mcap_read_like_ros2(write_log: Callable[..., Path], tmp_path: Path) -> None:
    """An MCAP holding ROS 1 payloads (ros1msg schemas), as the ROS 1 mcap recorder writes."""
    bag = write_log("src.bag", fmt="bag")
    store = ros1_typestore()
    path = tmp_path / "ros1.mcap"

    def schema(raw: RawMessage) -> tuple[str, str, str]:
        text, _ = raw.store.generate_msgdef(raw.msgtype, ros_version=1)  # type: ignore[union-attr]
        return raw.msgtype.replace("/msg/", "/"), "ros1msg", text

    _rewrite_mcap(bag, path, "ros1", schema)
    assert store is not None
    _, ref = _read(bag)
    _, records = _read(path)
    _assert_same_records(records, ref)


_SEP = "=" * 80 + "\n"
# sensor_msgs/msg/LaserScan as rosbag2 writes a ros2idl schema: the type's IDL, then its dependencies'.
LASERSCAN_ROS2IDL = (
    f"{_SEP}IDL: sensor_msgs/msg/LaserScan\n"
    "module sensor_msgs { module msg { struct LaserScan { std_msgs::msg::Header header; float angle_min;\n"
    "  float angle_max; float angle_increment; float time_increment; float scan_time; float range_min;\n"
    "  float range_max; sequence<float> ranges; sequence<float> intensities; }; }; };\n"
    f"{_SEP}IDL: std_msgs/msg/Header\n"
    "module std_msgs { module msg { struct Header { builtin_interfaces::msg::Time stamp; string frame_id; }; }; };\n"
    f"{_SEP}IDL: builtin_interfaces/msg/Time\n"
    "module builtin_interfaces { module msg { struct Time { int32 sec; uint32 nanosec; }; }; };\n"
)


def test_a_ros2idl_schema_reads_like_its_msg_text(write_log: Callable[..., Path], tmp_path: Path) -> None:
    """rosbag2 and Foxglove write some channels' schemas as IDL (``ros2idl``) instead of .msg text."""
    src = write_log("src.mcap")
    path = tmp_path / "idl.mcap"

    def schema(raw: RawMessage) -> tuple[str, str, str]:
        if raw.msgtype == "sensor_msgs/msg/LaserScan":
            return raw.msgtype, "ros2idl", LASERSCAN_ROS2IDL
        return raw.msgtype, "ros2msg", raw.store.generate_msgdef(raw.msgtype)[0]  # type: ignore[union-attr]

    _rewrite_mcap(src, path, "ros2", schema)
    ref_roles, ref = _read(src)
    roles, records = _read(path)
    assert roles == ref_roles and Role.SCAN in roles
    _assert_same_records(records, ref)


def test_a_ros1_bag_with_tf_tfmessage_reads_like_tf2(write_log: Callable[..., Path], tmp_path: Path) -> None:
    """Bags of ROS 1 before Hydro (many public datasets) carry /tf as ``tf/tfMessage``: the same layout as
    ``tf2_msgs/TFMessage`` under an older name."""
    from rosbags.convert.converter import migrate_message
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from doorbatch.io.log_writer import LogWriter
    from doorbatch.io.typestore import ros2_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf/msg/tfMessage"))
    legacy = store.types["tf/msg/tfMessage"]
    cache: dict[str, object] = {}
    path = tmp_path / "old.bag"
    with LogWriter(path, "bag") as writer:
        for topic, msgtype, t, msg in sample_messages():
            if msgtype == "tf2_msgs/msg/TFMessage":
                stamped = "geometry_msgs/msg/TransformStamped"
                ros1 = [migrate_message(ros2_typestore(), store, stamped, stamped, cache, x) for x in msg.transforms]
                writer.write(topic, "tf/msg/tfMessage", t, legacy(transforms=ros1), store)
            else:
                writer.write(topic, msgtype, t, msg)
    ref_roles, ref = _read(write_log("new.bag", fmt="bag"))
    roles, records = _read(path)
    assert roles == ref_roles and Role.TRANSFORMS in roles
    _assert_same_records(records, ref)
    # converted to MCAP, the ROS 1-only type takes ROS 2's Header (no seq) and reads back the same
    convert_log(path, tmp_path / "old.mcap")
    _assert_same_records(_read(tmp_path / "old.mcap")[1], ref)


def test_a_multi_echo_scan_reads_as_its_first_echoes(write_log: Callable[..., Path]) -> None:
    """sensor_msgs/MultiEchoLaserScan (Cartographer's Deutsches Museum bags): every beam's first echo, as
    Cartographer takes it; a later echo (0.5 m behind) is ignored."""
    from doorbatch.io.typestore import ros2_typestore

    types = ros2_typestore().types
    multi, echo = types["sensor_msgs/msg/MultiEchoLaserScan"], types["sensor_msgs/msg/LaserEcho"]
    messages = []
    for topic, msgtype, t, msg in sample_messages():
        if msgtype == "sensor_msgs/msg/LaserScan":
            msgtype = "sensor_msgs/msg/MultiEchoLaserScan"
            msg = multi(header=msg.header, angle_min=msg.angle_min, angle_max=msg.angle_max,
                        angle_increment=msg.angle_increment, time_increment=msg.time_increment,
                        scan_time=msg.scan_time, range_min=msg.range_min, range_max=msg.range_max,
                        ranges=[echo(echoes=np.array([r, r + 0.5], dtype=np.float32)) for r in msg.ranges],
                        intensities=[echo(echoes=np.array([i, 0.0], dtype=np.float32)) for i in msg.intensities])
        messages.append((topic, msgtype, t, msg))
    ref_roles, ref = _read(write_log("single.mcap"))
    roles, records = _read(write_log("multi.mcap", messages))
    assert roles == ref_roles
    _assert_same_records(records, ref)


@pytest.mark.parametrize("fmt", ["bag", "rosbag2"])
def test_convert_to_mcap_keeps_every_record(write_log: Callable[..., Path], tmp_path: Path, fmt: str) -> None:
    src = write_log(FORMATS[fmt], fmt=fmt)
    summary = convert_log(src, tmp_path / "out.mcap")
    assert summary.messages == len(sample_messages())
    _, ref = _read(src)
    _, records = _read(tmp_path / "out.mcap")
    _assert_same_records(records, ref)


def test_annotated_mcap_keeps_inputs_and_adds_annotations(write_log: Callable[..., Path], tmp_path: Path) -> None:
    from doorbatch.io import ros_messages as m

    src = write_log("in.bag", fmt="bag")
    t0 = sample_messages()[2][2]
    notes = [Annotation("/doorbatch/pose", "geometry_msgs/msg/PoseWithCovarianceStamped", t0 + k,
                        m.pose_with_covariance_stamped(t0 + k, "map", 1.0 * k, 2.0, 0.5, np.eye(6)))
             for k in range(3)]
    out = tmp_path / "annotated.mcap"
    count = write_annotated_mcap(src, out, notes).written
    assert count == len(sample_messages()) + 3
    with open_log(out) as reader:
        assert reader.topics["/doorbatch/pose"].count == 3
        raws = list(reader.raw_messages(["/doorbatch/pose"]))
        times = [r.log_time_ns for r in reader.raw_messages()]
    assert [r.msg.pose.pose.position.x for r in raws] == [0.0, 1.0, 2.0]
    assert times == sorted(times)
    _, ref = _read(src)
    _, records = _read(out)
    _assert_same_records(records, ref)


def test_an_mcap_without_summary_reads_the_messages_before_the_cut_in_time_order(tmp_path: Path) -> None:
    whole = REPO / "datasets" / "sample" / "logs" / "loc_open.mcap"
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(whole.read_bytes()[: int(whole.stat().st_size * 0.6)])
    with open_log(whole) as reader:
        full = [(m.topic, m.log_time_ns) for m in reader.raw_messages()]
    with open_log(cut) as reader:
        assert any("no summary section" in w for w in reader.warnings)
        got = [(m.topic, m.log_time_ns) for m in reader.raw_messages()]
        assert sum(t.count for t in reader.topics.values()) == len(got)
    assert len(full) * 0.3 < len(got) < len(full)
    assert [t for _, t in got] == sorted(t for _, t in got)
    assert sorted(got) == sorted(full[: len(got)])  # the log's first messages, nothing invented or lost before the cut


def _recompress_bag1(src: Path, dst: Path, mode: str) -> None:
    """``src`` chunk by chunk into ``dst`` as ``rosbag record --bz2`` / ``--lz4`` writes it."""
    from rosbags.rosbag1 import Reader, Writer

    writer = Writer(dst)
    writer.set_compression(Writer.CompressionFormat[mode])
    with Reader(src) as reader, writer:
        conns = {c.id: writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest,
                                             callerid=c.ext.callerid, latching=c.ext.latching)
                 for c in reader.connections}
        for conn, t, data in reader.messages():
            writer.write(conns[conn.id], t, data)


def _recompress_bag2(src: Path, dst: Path, mode: str) -> None:
    """``src`` into a ROS 2 bag with zstd compression per file or per message (``ros2 bag record
    --compression-mode``)."""
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, Reader, Writer

    writer = Writer(dst, version=8)
    writer.set_compression(CompressionMode[mode], CompressionFormat.ZSTD)
    with Reader(src) as reader, writer:
        conns = {c.id: writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, rihs01=c.digest,
                                             serialization_format=c.ext.serialization_format)
                 for c in reader.connections}
        for conn, t, data in reader.messages():
            writer.write(conns[conn.id], t, data)


def _rechunk_mcap(src: Path, dst: Path, mode: str) -> None:
    """``src`` (zstd chunks) into ``dst`` with lz4 chunks, uncompressed chunks, or no chunks at all."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType

    with src.open("rb") as f, dst.open("wb") as g:
        writer = McapWriter(g, compression=CompressionType[mode if mode != "UNCHUNKED" else "NONE"],
                            use_chunking=mode != "UNCHUNKED")
        writer.start(profile="ros2", library="other writer")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(channel.topic, channel.message_encoding,
                                                               schemas[channel.schema_id], channel.metadata)
            writer.add_message(channels[channel.id], message.log_time, message.data, message.publish_time,
                               message.sequence)
        writer.finish()


@pytest.mark.parametrize(("fmt", "mode"), [("bag", "BZ2"), ("bag", "LZ4"), ("rosbag2", "FILE"),
                                           ("rosbag2", "MESSAGE"), ("mcap", "LZ4"), ("mcap", "NONE"),
                                           ("mcap", "UNCHUNKED")])
def test_compressed_logs_read_like_plain_ones(write_log: Callable[..., Path], tmp_path: Path, fmt: str,
                                             mode: str) -> None:
    """Recorders compress: ROS 1 chunks in bz2 or lz4, ROS 2 bags in zstd per file or per message, MCAP chunks
    in lz4 or zstd or not at all. The same messages read back from every such log as from ours."""
    plain = write_log(FORMATS[fmt], fmt=fmt)
    packed = tmp_path / f"packed_{mode.lower()}{'' if fmt == 'rosbag2' else '.' + fmt}"
    {"bag": _recompress_bag1, "rosbag2": _recompress_bag2, "mcap": _rechunk_mcap}[fmt](plain, packed, mode)
    if fmt == "bag":  # really compressed: smaller than the plain bag
        assert packed.stat().st_size < plain.stat().st_size
    elif fmt == "rosbag2":
        assert f"compression_mode: {mode.lower()}" in (packed / "metadata.yaml").read_text()
    ref_roles, ref = _read(plain)
    roles, records = _read(packed)
    assert roles == ref_roles
    _assert_same_records(records, ref)


def _with_custom_topic(src: Path, dst: Path, fmt: str) -> None:
    """``src`` (a ROS 2 bag folder) copied to ``dst`` with a /battery2 topic of a custom type whose definition the
    log does not hold, as rosbag2 records one where the message package was not sourced: ``humble``, a bag folder
    of Humble's layout (metadata version 5: no definitions stored at all); ``unknown``, Jazzy's (a definition of
    encoding 'unknown', empty); ``mcap``, an MCAP whose channel has an empty schema."""
    import sqlite3

    import yaml
    from rosbags.rosbag2 import Reader, Writer

    custom, payload = "my_robot_msgs/msg/BatteryState2", b"\x00\x01\x00\x00" + bytes(8)
    with Reader(src) as reader:
        messages = list(reader.messages())
        if fmt == "mcap":
            with dst.open("wb") as f:
                writer = McapWriter(f)
                writer.start(profile="ros2", library="test")
                ids = {c.id: writer.register_channel(c.topic, "cdr", writer.register_schema(
                    c.msgtype, "ros2msg", c.msgdef.data.encode())) for c in reader.connections}
                battery_id = writer.register_channel("/battery2", "cdr", writer.register_schema(custom, "ros2msg", b""))
                for k, (conn, t, data) in enumerate(messages):
                    writer.add_message(ids[conn.id], log_time=t, publish_time=t, data=data)
                    if k % 10 == 0:
                        writer.add_message(battery_id, log_time=t, publish_time=t, data=payload)
                writer.finish()
            return
        with Writer(dst, version=8) as bag:
            conns = {c.id: bag.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, rihs01=c.digest,
                                              serialization_format="cdr") for c in reader.connections}
            battery = bag.add_connection("/battery2", custom, msgdef="float32 voltage\nfloat32 current",
                                         rihs01="RIHS01_" + "ab" * 32, serialization_format="cdr")
            for k, (conn, t, data) in enumerate(messages):
                bag.write(conns[conn.id], t, data)
                if k % 10 == 0:
                    bag.write(battery, t, payload)
    db = next(dst.glob("*.db3"))
    meta = yaml.safe_load((dst / "metadata.yaml").read_text())
    info = meta["rosbag2_bagfile_information"]
    with sqlite3.connect(db) as c:
        if fmt == "unknown":
            c.execute("update message_definitions set encoding='unknown', encoded_message_definition='' "
                      "where topic_type=?", (custom,))
        else:  # Humble's layout: no definitions, no type hashes, schema version 3
            c.execute("drop table message_definitions")
            c.execute("create table topics2(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, "
                      "serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL)")
            c.execute("insert into topics2 select id, name, type, serialization_format, offered_qos_profiles "
                      "from topics")
            c.execute("drop table topics")
            c.execute("alter table topics2 rename to topics")
            c.execute("update schema set schema_version=3, ros_distro='humble'")
            c.execute("drop table metadata")
            info["version"] = 5
            for t in info["topics_with_message_count"]:
                topic = t["topic_metadata"]
                topic.pop("type_description_hash", None)
                topic["offered_qos_profiles"] = yaml.safe_dump(topic["offered_qos_profiles"])
            info.pop("custom_data", None)
            info.pop("ros_distro", None)
    (dst / "metadata.yaml").write_text(yaml.safe_dump(meta, sort_keys=False))


@pytest.mark.parametrize("fmt", ["humble", "mcap"])
def test_a_topic_of_a_custom_type_without_definition_is_skipped_with_a_warning(write_log: Callable[..., Path],
                                                                               tmp_path: Path, fmt: str) -> None:
    """A robot's own message type, recorded where its package was not sourced: the log holds no definition of it.
    The log is read as without the topic, with a warning naming it (every command had refused the whole log)."""
    plain = write_log(FORMATS["rosbag2"], fmt="rosbag2")
    custom = tmp_path / ("custom" if fmt == "humble" else "custom.mcap")
    _with_custom_topic(plain, custom, fmt)
    roles, records = _read(custom)
    assert roles == _read(plain)[0]
    _assert_same_records(records, _read(plain)[1])
    with open_log(custom) as reader:
        list(reader.raw_messages())  # a copy of the log (annotated.mcap, convert) reads every topic it can
        assert reader.topics["/battery2"].msgtype == "my_robot_msgs/msg/BatteryState2"
        said = [w for w in reader.warnings if "/battery2" in w]
    assert len(said) == 1 and "not read" in said[0]
    from doorbatch.io.inspect import inspect_log

    listed = {t.name: t for t in inspect_log(custom).topics}["/battery2"]
    assert listed.count == reader.topics["/battery2"].count > 0  # the index's count, not 0 (it is not read)


def test_a_jazzy_bag_with_an_unknown_definition_is_refused_with_the_reason(write_log: Callable[..., Path],
                                                                           tmp_path: Path) -> None:
    """rosbag2 on Jazzy records a type it found no definition of with the encoding 'unknown', which the rosbags
    library cannot open (a KeyError: 'unknown' had been the whole message). The error says what and what to do."""
    custom = tmp_path / "custom"
    _with_custom_topic(write_log(FORMATS["rosbag2"], fmt="rosbag2"), custom, "unknown")
    with pytest.raises(LogReadError, match=r"encoding 'unknown'.*exclude_topics"):
        _read(custom)
