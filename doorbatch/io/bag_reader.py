"""ROS 1 ``.bag`` files and ROS 2 bag folders (sqlite3 or mcap storage) through rosbags' AnyReader."""

from __future__ import annotations

from collections.abc import Collection, Iterator
from typing import Any

from rosbags.highlevel import AnyReader
from rosbags.interfaces import Connection, ConnectionExtRosbag1, ConnectionExtRosbag2, Qos

from doorbatch.errors import LogReadError
from doorbatch.io import foxglove
from doorbatch.io.qos import ros1_latched_qos
from doorbatch.io.reader import LogReader, RawMessage
from doorbatch.io.roles import TopicInfo
from doorbatch.io.typestore import normalize_msgtype, ros1_typestore, ros2_typestore


def _recorded_qos(conn: Connection) -> list[Qos]:
    """The QoS profiles a bag records for a connection: a ROS 2 bag's ``offered_qos_profiles``, a ROS 1 bag's
    ``latching`` flag as one (:func:`~doorbatch.io.qos.ros1_latched_qos`)."""
    if isinstance(conn.ext, ConnectionExtRosbag2):
        return list(conn.ext.offered_qos_profiles)
    if isinstance(conn.ext, ConnectionExtRosbag1):
        return ros1_latched_qos(conn.ext.latching)
    return []


class _AnyBagReader(LogReader):
    _ros1 = False

    def open(self) -> None:
        store = ros1_typestore() if self._ros1 else ros2_typestore()
        self._reader: AnyReader | None = AnyReader([self.path], default_typestore=store)
        self._reader.open()
        if self._reader.connections:
            self.storage = self._storage_name()
        topics: dict[str, TopicInfo] = {}
        known = self._reader.typestore.fielddefs
        # a type the bag does not define and the store does not know (a Humble bag's custom message): its topic is
        # listed, not read, as an MCAP channel without a schema is (rosbag2 itself skips such topics when it plays)
        self._unread = {c.topic: c.msgtype for c in self._reader.connections if c.msgtype not in known}
        for topic, msgtype in self._unread.items():
            self.warnings.append(f"{self.path}: {topic}: type {msgtype} is neither defined in the bag nor a type "
                                 "doorbatch knows; not read")
        for conn in self._reader.connections:
            if (offered := _recorded_qos(conn)) and conn.topic not in self.offered_qos:
                self.offered_qos[conn.topic] = offered
            prev = topics.get(conn.topic)
            count = conn.msgcount + (prev.count if prev else 0)
            # foxglove_msgs, as a Foxglove bridge records them, are listed under the ROS 2 type they are read as
            topics[conn.topic] = foxglove.topic_info(conn.topic, normalize_msgtype(conn.msgtype), count,
                                                     "ros1" if self._ros1 else "cdr", conn.topic not in self._unread)
        self._topics = topics

    def _storage_name(self) -> str:
        return "rosbag1"

    def close(self) -> None:
        reader = getattr(self, "_reader", None)
        self._reader = None
        if reader is not None and reader.stack:  # a failed open() leaves AnyReader closed already
            reader.close()

    @property
    def topics(self) -> dict[str, TopicInfo]:
        return self._topics

    @property
    def start_ns(self) -> int:
        return int(self._reader.start_time) if self._reader and self._topics else 0

    @property
    def end_ns(self) -> int:
        return int(self._reader.end_time) if self._reader and self._topics else 0

    def _raw(self, topics: Collection[str] | None, start_ns: int | None, stop_ns: int | None
             ) -> Iterator[RawMessage]:
        reader = self._reader
        if reader is None:
            raise LogReadError("reader is not open", path=self.path)
        conns = [c for c in reader.connections if (topics is None or c.topic in topics) and c.topic not in self._unread]
        if not conns:
            return
        for conn, log_time, data in reader.messages(connections=conns, start=start_ns, stop=stop_ns):
            try:
                msg: Any = reader.deserialize(data, conn.msgtype)
            except Exception as err:  # a layout the bag does not define (Foxy-era rosbag2 folders carry none)
                raise LogReadError(f"cannot decode a {conn.msgtype} message ({type(err).__name__}: {err}); its "
                                   f"definition may differ from ROS 2 Humble's", path=self.path,
                                   topic=conn.topic) from err
            yield RawMessage(conn.topic, normalize_msgtype(conn.msgtype), int(log_time), msg, self._ros1,
                             reader.typestore)


class Rosbag1Reader(_AnyBagReader):
    """A ROS 1 ``.bag`` file (format 2.0)."""

    storage = "rosbag1"
    _ros1 = True

    def open(self) -> None:
        try:
            super().open()
        except Exception as err:  # rosbags' ReaderError; an unclosed bag has no index to read
            if "index" not in str(err).lower():
                raise
            raise LogReadError(f"bag has no readable index ({err}): a recording that was not closed (a .bag.active "
                               "file, a killed rosbag record)? `rosbag reindex` rebuilds it", path=self.path) from err


class Rosbag2Reader(_AnyBagReader):
    """A ROS 2 bag folder with ``metadata.yaml`` (sqlite3 or mcap storage)."""

    storage = "rosbag2"

    def open(self) -> None:
        if not (self.path / "metadata.yaml").exists():
            files = sorted(self.path.glob("*.mcap"))
            db3 = sorted(self.path.glob("*.db3"))
            hint = (f"; a recording stopped before it wrote metadata.yaml leaves its MCAP readable as a file: "
                    f"give {files[0]}" if len(files) == 1 else "; a recording stopped before it wrote metadata.yaml: "
                    f"`ros2 bag reindex {self.path}` writes it" if db3 else "")
            raise LogReadError(f"folder is not a ROS 2 bag (no metadata.yaml){hint}", path=self.path)
        try:
            super().open()
        except KeyError as err:  # rosbags 0.11 maps a definition's encoding by name: rosbag2 writes 'unknown'
            if err.args != ("unknown",):
                raise
            raise LogReadError("its message_definitions give the encoding 'unknown' (rosbag2 writes that for a "
                               "type it found no definition of while recording, a custom message), which the "
                               "rosbags library cannot open: record with that message package sourced, or convert "
                               "the bag leaving the topic out (ros2 bag convert, exclude_topics)",
                               path=self.path) from err

    def _storage_name(self) -> str:
        reader = self._reader
        ident = "unknown"
        if reader is not None:
            sub = reader.readers[0]
            ident = str(getattr(getattr(sub, "metadata", None), "get", lambda *_: None)("storage_identifier")
                        or "")
            if not ident:
                files = [p.suffix for p in self.path.iterdir()]
                ident = "mcap" if ".mcap" in files else "sqlite3"
        return f"rosbag2 ({ident})"
