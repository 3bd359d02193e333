"""MCAP logs through the ``mcap`` library; ROS 2 CDR and ROS 1 payloads deserialized by rosbags.

Each channel's schema (``ros2msg`` or ``ros1msg`` text, or ``ros2idl``) is parsed with rosbags into a typestore of
the reader's own. Channels of Foxglove's schemas (``foxglove.LaserScan``, ... in protobuf or JSON, as the Foxglove SDK
writes them; ``foxglove_msgs/msg/...`` in CDR or ROS 1) are read as the ROS 2 messages they stand for
(:mod:`doorbatch.io.foxglove`); other channels whose encoding is not ROS are listed but not decoded.
"""

from __future__ import annotations

import heapq
import logging
from collections.abc import Callable, Collection, Iterator
from typing import IO, Any

from mcap.exceptions import McapError
from mcap.reader import McapReader, NonSeekingReader, make_reader
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from doorbatch.errors import LogReadError
from doorbatch.io import foxglove
from doorbatch.io.qos import mcap_channel_qos
from doorbatch.io.reader import LogReader, RawMessage
from doorbatch.io.roles import TopicInfo
from doorbatch.io.typestore import normalize_msgtype, ros1_typestore, ros2_typestore, types_from_schema

log = logging.getLogger(__name__)

_ROS_ENCODINGS = {"cdr": False, "ros1": True}
# Messages held back to restore log-time order in a file read linearly (one without a summary section).
REORDER_WINDOW = 4096


class McapLogReader(LogReader):
    """A single ``.mcap`` file (as ``ros2 bag record -s mcap`` or Foxglove writes it)."""

    storage = "mcap"

    def open(self) -> None:
        self._file: IO[bytes] | None = self.path.open("rb")
        self._reader: McapReader = make_reader(self._file)
        try:
            summary = self._reader.get_summary()
        except McapError:  # a footer cut off, or summary offsets pointing past the end
            summary = None
        self._stores = {False: get_typestore(Stores.EMPTY), True: get_typestore(Stores.EMPTY)}
        self._other_stores: dict[tuple[bool, str, str], Typestore] = {}  # a second definition of a name
        self._store_of: dict[int, Typestore] = {}
        self._msgtype: dict[int, str] = {}
        self._ros1: dict[int, bool] = {}
        self._payload: dict[int, Callable[[bytes], Any]] = {}  # protobuf and JSON channels' decoders
        if summary is None:
            schemas, channels, counts, self._start, self._end = self._scan_unindexed()
        else:
            schemas, channels = summary.schemas, summary.channels
            counts = summary.statistics.channel_message_counts if summary.statistics else {}
            stats = summary.statistics
            self._start = stats.message_start_time if stats else 0
            self._end = stats.message_end_time if stats else 0
        self._unindexed = summary is None
        topics: dict[str, TopicInfo] = {}
        for cid, channel in channels.items():
            schema = schemas.get(channel.schema_id)
            name = normalize_msgtype(schema.name) if schema else ""
            kind = foxglove.foxglove_kind(name)
            if channel.message_encoding in _ROS_ENCODINGS and schema is not None:
                ros1 = _ROS_ENCODINGS[channel.message_encoding]
                try:
                    self._store_of[cid] = self._register_schema(ros1, name, schema.data.decode("utf-8", "replace"),
                                                                schema.encoding)
                    self._msgtype[cid] = name
                    self._ros1[cid] = ros1
                except LogReadError as err:  # a custom type recorded without its definition: listed, not read
                    self.warnings.append(f"{self.path}: {channel.topic}: {err.reason}; not read")
            elif kind is not None and schema is not None:
                try:
                    self._payload[cid] = foxglove.payload_decoder(schema, channel.message_encoding)
                    self._msgtype[cid] = name
                except LogReadError as err:  # the channel is listed, unread, as any channel we cannot decode
                    self.warnings.append(f"{self.path}: {channel.topic}: {err.reason}; not read")
            if (offered := mcap_channel_qos(channel.metadata)) and channel.topic not in self.offered_qos:
                self.offered_qos[channel.topic] = offered
            prev = topics.get(channel.topic)
            count = counts.get(cid, 0) + (prev.count if prev else 0)
            topics[channel.topic] = foxglove.topic_info(channel.topic, name, count, channel.message_encoding,
                                                        cid in self._msgtype)
        self._topics = topics

    def _linear_messages(self, topics: list[str] | None, start_ns: int | None, stop_ns: int | None
                         ) -> Iterator[tuple[Schema | None, Channel, Message]]:
        """The messages of an MCAP without a summary in log-time order, up to where the file breaks off.

        A recorder writes them nearly in time order; a heap of ``REORDER_WINDOW`` messages puts them in order
        (NonSeekingReader's own ordering sorts the whole file first, so a file cut off yields nothing).
        """
        assert self._file is not None
        self._file.seek(0)
        heap: list[tuple[int, int, tuple[Schema | None, Channel, Message]]] = []
        source = NonSeekingReader(self._file).iter_messages(topics, log_time_order=False, starting_at=start_ns,
                                                            ending_before=stop_ns)
        try:
            for k, item in enumerate(source):
                heapq.heappush(heap, (item[2].log_time, k, item))
                if len(heap) > REORDER_WINDOW:
                    yield heapq.heappop(heap)[2]
        except (McapError, ValueError, EOFError):  # where the unfinished file breaks off (open() warned)
            pass
        while heap:
            yield heapq.heappop(heap)[2]

    def _scan_unindexed(self) -> tuple[dict[int, Schema], dict[int, Channel], dict[int, int], int, int]:
        """Schemas, channels, message counts and time span of an MCAP without a summary section (a recorder
        killed before it finished the file) from one pass over its records, up to where the file breaks off.

        Raises:
            LogReadError: not one message could be read.
        """
        schemas: dict[int, Schema] = {}
        channels: dict[int, Channel] = {}
        counts: dict[int, int] = {}
        start, end, n = 0, 0, 0
        assert self._file is not None
        self._file.seek(0)
        try:
            for record in StreamReader(self._file, skip_magic=False).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    counts[record.channel_id] = counts.get(record.channel_id, 0) + 1
                    start = record.log_time if n == 0 else min(start, record.log_time)
                    end = max(end, record.log_time)
                    n += 1
            cut = ""
        except (McapError, ValueError, EOFError) as err:  # the last record is incomplete
            cut = f", the file breaks off there ({type(err).__name__})"
        if n == 0:
            raise LogReadError(f"MCAP has no summary section and no readable message{cut}", path=self.path)
        self.warnings.append(f"{self.path}: MCAP has no summary section (a writer may leave it out; a recording "
                             f"cut off has none either): read linearly, {n} messages over "
                             f"{(end - start) / 1e9:.1f} s{cut}")
        return schemas, channels, counts, start, end

    def _register_schema(self, ros1: bool, name: str, text: str, encoding: str) -> Typestore:
        """The store that decodes a schema's messages. One MCAP may hold two schemas of one name (logs of two
        ROS distributions written into one file): the second definition gets a store of its own."""
        store = self._stores[ros1]
        if name in store.types:
            if not text.strip() or _same_definition(store, name, text, ros1, encoding):
                return store
            key = (ros1, name, text)
            if key not in self._other_stores:
                other = get_typestore(Stores.EMPTY)
                types = types_from_schema(text, name, encoding)
                other.register(types)
                self._other_stores[key] = other
            return self._other_stores[key]
        base: Typestore = ros1_typestore() if ros1 else ros2_typestore()
        if text.strip():
            types = types_from_schema(text, name, encoding)
        elif name in base.fielddefs:  # schema-less channel of a well-known type
            types = {k: v for k, v in base.fielddefs.items() if k == name or k.split("/")[0] != ""}
        else:
            raise LogReadError(f"channel of type {name} has an empty schema (no definition) and is not a type "
                               "doorbatch knows", path=self.path)
        store.register({k: v for k, v in types.items() if k not in store.types})
        return store

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
        wanted = None if topics is None else list(topics)
        if self._unindexed:  # linearly from the start: the summary the seeking reader looks for is not there
            messages = self._linear_messages(wanted, start_ns, stop_ns)
        else:
            messages = self._reader.iter_messages(topics=wanted, start_time=start_ns, end_time=stop_ns,
                                                  log_time_order=True)
        for _schema, channel, message in messages:
            cid = channel.id
            msgtype = self._msgtype.get(cid)
            if msgtype is None:
                continue
            payload = self._payload.get(cid)
            if payload is not None:  # a Foxglove schema in protobuf or JSON: decoded where it is read as ROS
                yield RawMessage(channel.topic, msgtype, message.log_time, foxglove.Payload(payload, message.data),
                                 False, None)
                continue
            ros1, store = self._ros1[cid], self._store_of[cid]
            msg: Any = (store.deserialize_ros1 if ros1 else store.deserialize_cdr)(message.data, msgtype)
            yield RawMessage(channel.topic, msgtype, message.log_time, msg, ros1, store)


def _same_definition(store: Typestore, name: str, text: str, ros1: bool, encoding: str) -> bool:
    """Whether a schema's text decodes as ``store`` already defines ``name``: the same text, or the same field
    layout once parsed (writers format definitions differently)."""
    own = store.generate_msgdef(name, ros_version=1 if ros1 else 2)[0]
    if own.strip() == text.strip():
        return True
    try:
        theirs = get_typestore(Stores.EMPTY)
        theirs.register(types_from_schema(text, name, encoding))
        return bool(theirs.generate_msgdef(name, ros_version=1 if ros1 else 2)[0] == own)
    except Exception:  # a schema rosbags cannot parse again here: decode it with a store of its own
        return False
