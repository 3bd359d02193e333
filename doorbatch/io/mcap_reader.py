"""MCAP logs through the ``mcap`` library; ROS 2 CDR and ROS 1 payloads deserialized by rosbags.

Each channel's schema (``ros2msg`` or ``ros1msg`` text) is parsed with rosbags into a typestore of the
reader's own; channels whose encoding is not ROS (json, protobuf, ...) are listed but not decoded.
"""

from __future__ import annotations

import logging
from collections.abc import Collection, Iterator
from typing import IO, Any

from mcap.reader import McapReader, make_reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from doorbatch.errors import LogReadError
from doorbatch.io.reader import LogReader, RawMessage
from doorbatch.io.roles import TopicInfo
from doorbatch.io.typestore import normalize_msgtype, ros1_typestore, ros2_typestore

log = logging.getLogger(__name__)

_ROS_ENCODINGS = {"cdr": False, "ros1": True}


class McapLogReader(LogReader):
    """A single ``.mcap`` file (as ``ros2 bag record -s mcap`` or Foxglove writes it)."""

    storage = "mcap"

    def open(self) -> None:
        self._file: IO[bytes] | None = self.path.open("rb")
        self._reader: McapReader = make_reader(self._file)
        summary = self._reader.get_summary()
        if summary is None:
            raise LogReadError("MCAP has no summary section (truncated, or written without one)",
                               path=self.path)
        self._stores = {False: get_typestore(Stores.EMPTY), True: get_typestore(Stores.EMPTY)}
        self._msgtype: dict[int, str] = {}
        self._ros1: dict[int, bool] = {}
        counts = summary.statistics.channel_message_counts if summary.statistics else {}
        topics: dict[str, TopicInfo] = {}
        for cid, channel in summary.channels.items():
            schema = summary.schemas.get(channel.schema_id)
            name = normalize_msgtype(schema.name) if schema else ""
            if channel.message_encoding in _ROS_ENCODINGS and schema is not None:
                ros1 = _ROS_ENCODINGS[channel.message_encoding]
                self._register_schema(ros1, name, schema.data.decode("utf-8", "replace"))
                self._msgtype[cid] = name
                self._ros1[cid] = ros1
            prev = topics.get(channel.topic)
            count = counts.get(cid, 0) + (prev.count if prev else 0)
            topics[channel.topic] = TopicInfo(channel.topic, name, count, channel.message_encoding)
        self._topics = topics
        stats = summary.statistics
        self._start = stats.message_start_time if stats else 0
        self._end = stats.message_end_time if stats else 0

    def _register_schema(self, ros1: bool, name: str, text: str) -> None:
        store = self._stores[ros1]
        if name in store.types:
            return
        base: Typestore = ros1_typestore() if ros1 else ros2_typestore()
        if text.strip():
            types = get_types_from_msg(text, name)
        elif name in base.fielddefs:  # schema-less channel of a well-known type
            types = {k: v for k, v in base.fielddefs.items() if k == name or k.split("/")[0] != ""}
        else:
            raise LogReadError(f"channel of type {name} has an empty schema", path=self.path)
        store.register({k: v for k, v in types.items() if k not in store.types})

    def close(self) -> None:
        f = getattr(self, "_file", None)
        if f is not None:
            f.close()
            self._file = None

    @property
    def topics(self) -> dict[str, TopicInfo]:
        return self._topics

    @property
    def start_ns(self) -> int:
        return int(self._start)

    @property
    def end_ns(self) -> int:
        return int(self._end)

    def _raw(self, topics: Collection[str] | None, start_ns: int | None, stop_ns: int | None
             ) -> Iterator[RawMessage]:
        stores = self._stores
        deser = {False: stores[False].deserialize_cdr, True: stores[True].deserialize_ros1}
        wanted = None if topics is None else list(topics)
        for _schema, channel, message in self._reader.iter_messages(
            topics=wanted, start_time=start_ns, end_time=stop_ns, log_time_order=True
        ):
            cid = channel.id
            msgtype = self._msgtype.get(cid)
            if msgtype is None:
                continue
            ros1 = self._ros1[cid]
            msg: Any = deser[ros1](message.data, msgtype)
            yield RawMessage(channel.topic, msgtype, message.log_time, msg, ros1, stores[ros1])
