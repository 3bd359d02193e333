"""The QoS a written log records for each topic: ``ros2 bag play`` replays /tf_static and the map latched only
when the bag says their publishers offered transient local durability; a copy of a log keeps the profiles its
input records (a latched /robot_description, a best-effort sensor topic)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer as McapWriter
from rosbags.convert.converter import migrate_message
from rosbags.highlevel import AnyReader
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag1 import Writer as Rosbag1Writer
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Rosbag2Writer
from rosbags.rosbag2.metadata import dump_qos_v8, parse_qos

from doorbatch.io import ros_messages
from doorbatch.io.annotated_mcap import write_annotated_mcap
from doorbatch.io.convert import convert_log
from doorbatch.io.log_writer import LogFormat, LogWriter
from doorbatch.io.split import copy_window
from doorbatch.io.typestore import ros1_typestore, ros2_typestore

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


# --- a copy keeps the QoS its input records (a latched /robot_description, a best-effort scan) ---------------------

def _profiles(latched: bool, best_effort: bool) -> list[Qos]:
    return [Qos(QosHistory.KEEP_LAST, 1 if latched else 5,
                QosReliability.BEST_EFFORT if best_effort else QosReliability.RELIABLE,
                QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE,
                QosTime(0, 0), QosTime(0, 0), QosLiveliness.AUTOMATIC, QosTime(0, 0), False)]


INPUT_QOS = {"/robot_description": _profiles(True, False), "/scan_grid": _profiles(False, True)}


def _input_messages() -> list[tuple[str, str, int, object]]:
    grid = ros_messages.occupancy_grid(1, "map", np.zeros((2, 2), dtype=np.int8), 0.1, 0.0, 0.0)
    text = ros2_typestore().types["std_msgs/msg/String"](data="<robot/>")
    return [("/robot_description", "std_msgs/msg/String", 1_000, text)] + [
        ("/scan_grid", "nav_msgs/msg/OccupancyGrid", 1_000_000_000 * k, grid) for k in range(1, 4)]


def _input_topics() -> dict[str, str]:
    return {topic: msgtype for topic, msgtype, _, _ in _input_messages()}


def _ros2_input(path: Path, plugin: StoragePlugin) -> Path:
    store = ros2_typestore()
    with Rosbag2Writer(path, version=8, storage_plugin=plugin) as bag:
        conns = {t: bag.add_connection(t, m, typestore=store, offered_qos_profiles=INPUT_QOS[t])
                 for t, m in _input_topics().items()}
        for topic, msgtype, t_ns, msg in _input_messages():
            bag.write(conns[topic], t_ns, store.serialize_cdr(msg, msgtype))
    return path


def _ros1_input(path: Path) -> Path:
    src, store = ros2_typestore(), ros1_typestore()
    with Rosbag1Writer(path) as bag:
        conns = {t: bag.add_connection(t, m, typestore=store, latching=1 if t == "/robot_description" else None)
                 for t, m in _input_topics().items()}
        for topic, msgtype, t_ns, msg in _input_messages():
            ros1 = migrate_message(src, store, msgtype, msgtype, {}, msg)
            bag.write(conns[topic], t_ns, store.serialize_ros1(ros1, msgtype))
    return path


def _mcap_input(path: Path) -> Path:
    store = ros2_typestore()
    with path.open("wb") as f:
        writer = McapWriter(f)
        writer.start(profile="ros2", library="another recorder")
        channels = {}
        for topic, msgtype, _, _ in _input_messages():
            if topic not in channels:
                schema = writer.register_schema(msgtype, "ros2msg",
                                                store.generate_msgdef(msgtype, ros_version=2)[0].encode())
                channels[topic] = writer.register_channel(topic, "cdr", schema, metadata={
                    "offered_qos_profiles": dump_qos_v8(INPUT_QOS[topic])})
        for topic, msgtype, t_ns, msg in _input_messages():
            writer.add_message(channels[topic], t_ns, bytes(store.serialize_cdr(msg, msgtype)), t_ns)
        writer.finish()
    return path


def _mcap_qos(path: Path) -> dict[str, list[Qos]]:
    with path.open("rb") as f:
        channels = make_reader(f).get_summary().channels.values()
    return {c.topic: parse_qos(c.metadata["offered_qos_profiles"]) for c in channels}


def _bag2_qos(path: Path) -> dict[str, list[Qos]]:
    with AnyReader([path]) as reader:
        return {c.topic: list(c.ext.offered_qos_profiles) for c in reader.connections}


def _kinds(qos: dict[str, list[Qos]]) -> dict[str, tuple[QosDurability, QosReliability]]:
    return {t: (p[0].durability, p[0].reliability) for t, p in qos.items()}


EXPECTED = {"/robot_description": (QosDurability.TRANSIENT_LOCAL, QosReliability.RELIABLE),
            "/scan_grid": (QosDurability.VOLATILE, QosReliability.BEST_EFFORT)}


@pytest.mark.parametrize("source", ["rosbag2-sqlite3", "rosbag2-mcap", "mcap"])
@pytest.mark.parametrize("fmt", [LogFormat.MCAP, LogFormat.ROSBAG2])
def test_a_converted_log_keeps_the_qos_its_input_records(tmp_path: Path, source: str, fmt: LogFormat) -> None:
    src = {"rosbag2-sqlite3": lambda: _ros2_input(tmp_path / "in", StoragePlugin.SQLITE3),
           "rosbag2-mcap": lambda: _ros2_input(tmp_path / "in", StoragePlugin.MCAP),
           "mcap": lambda: _mcap_input(tmp_path / "in.mcap")}[source]()
    out = tmp_path / ("out.mcap" if fmt is LogFormat.MCAP else "out")
    convert_log(src, out, fmt=fmt)
    got = _mcap_qos(out) if fmt is LogFormat.MCAP else _bag2_qos(out)
    assert _kinds(got) == EXPECTED


def test_a_ros1_latched_topic_stays_latched_in_the_copy(tmp_path: Path) -> None:
    out = tmp_path / "out.mcap"
    convert_log(_ros1_input(tmp_path / "in.bag"), out)
    durability = {t: p[0].durability for t, p in _mcap_qos(out).items()}
    assert durability == {"/robot_description": QosDurability.TRANSIENT_LOCAL, "/scan_grid": QosDurability.VOLATILE}


def test_an_annotated_mcap_keeps_the_input_qos(tmp_path: Path) -> None:
    out = tmp_path / "annotated.mcap"
    write_annotated_mcap(_ros2_input(tmp_path / "in", StoragePlugin.MCAP), out, [])
    assert _kinds(_mcap_qos(out)) == EXPECTED


def test_a_window_cut_from_a_log_carries_its_latched_message_and_qos(tmp_path: Path) -> None:
    """/robot_description, latched in the input and published once before the window, is in force inside it."""
    out = tmp_path / "window.mcap"
    written = copy_window(_ros2_input(tmp_path / "in", StoragePlugin.MCAP), out, 2_000_000_000, 4_000_000_000)
    assert written == 3  # the carried description and the grids at 2 s and 3 s
    assert _kinds(_mcap_qos(out)) == EXPECTED


def test_a_ros1_mcap_channel_marked_latching_stays_latched() -> None:
    """MCAP's ros1 profile records a latched connection as channel metadata `latching: "true"` (or "1")."""
    from doorbatch.io.qos import is_latched, mcap_channel_qos

    assert is_latched(mcap_channel_qos({"latching": "true", "callerid": "/robot_state_publisher"}))
    assert is_latched(mcap_channel_qos({"latching": "1"}))
    assert mcap_channel_qos({"latching": "false"}) == [] and mcap_channel_qos({}) == []
