"""The one entry point that opens any supported log, and the reader protocol behind it.

``open_log(path)`` picks a reader by suffix (or ``dir`` for a ROS 2 bag folder) after checking the file's
magic bytes, so a misnamed or non-log file gets a clear :class:`~doorbatch.errors.LogReadError`.
Readers stream: ``raw_messages`` deserializes one message at a time with rosbags; ``messages`` decodes the
topics of the requested roles into records (:mod:`doorbatch.records`).
"""

from __future__ import annotations

import importlib
import logging
from abc import ABC, abstractmethod
from collections import Counter
from collections.abc import Callable, Collection, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, Self, TypeVar

from rosbags.interfaces import Qos
from rosbags.typesys.store import Typestore

from doorbatch.config import DoorbatchConfig
from doorbatch.errors import DoorbatchError, LogContentError, LogReadError
from doorbatch.io import foxglove
from doorbatch.io import ros_messages as rm
from doorbatch.io.decode import TF_MESSAGE, decode
from doorbatch.io.roles import RoleAssignment, TopicInfo, assign_roles
from doorbatch.records import Role, RoleMessage, Transform

log = logging.getLogger(__name__)
E = TypeVar("E", bound=DoorbatchError)

MCAP_MAGIC = b"\x89MCAP"
BAG1_MAGIC = b"#ROSBAG V2.0"


@dataclass(frozen=True, slots=True)
class RawMessage:
    """One deserialized message as rosbags represents it; ``ros1`` says which type layout it has."""

    topic: str
    msgtype: str
    log_time_ns: int
    msg: Any
    ros1: bool
    store: Typestore | None = None  # the typestore whose classes built ``msg`` (None: ROS 2 Humble's)


MOUNTS_TOPIC = "/tf_static"  # where a copy of a log carries the mounts doorbatch reads off Foxglove scans


def most_are_bad(n_bad: int, n: int) -> bool:
    """Whether a topic whose ``n_bad`` of ``n`` messages cannot be decoded is unusable (an error) rather than
    usable with those skipped (a warning)."""
    return 2 * n_bad > n


class LogReader(ABC):
    """A context manager over one log: topics, time span, and streaming access to its messages."""

    storage: str = "unknown"

    def __init__(self, path: Path, config: DoorbatchConfig | None = None) -> None:
        config = config or DoorbatchConfig()
        self.path = path
        self.topics_config = config.topics
        self.frames = config.frames
        self.io_config = config.io
        self._roles: RoleAssignment | None = None
        self._scan_mounts: dict[str, Transform] | None = None
        self.warnings: list[str] = []  # repairs a reader made (e.g. CARMEN stamps), shown by inspect
        # per topic, the QoS profiles the log records its publishers offered (none: the log does not say)
        self.offered_qos: dict[str, list[Qos]] = {}

    def __enter__(self) -> Self:
        try:
            self.open()
        except DoorbatchError:
            self.close()
            raise
        except Exception as err:  # a library's own error for a corrupt file
            self.close()
            raise LogReadError(f"cannot open {self.storage} log: {err}", path=self.path) from err
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    @abstractmethod
    def open(self) -> None:
        """Open the file and read its topic index."""

    @abstractmethod
    def close(self) -> None:
        """Release the file."""

    @property
    @abstractmethod
    def topics(self) -> dict[str, TopicInfo]:
        """Topic name → :class:`TopicInfo`."""

    @property
    @abstractmethod
    def start_ns(self) -> int:
        """Log time of the first message (ns)."""

    @property
    @abstractmethod
    def end_ns(self) -> int:
        """Log time of the last message (ns)."""

    @abstractmethod
    def _raw(self, topics: Collection[str] | None, start_ns: int | None, stop_ns: int | None
             ) -> Iterator[RawMessage]:
        """Messages of ``topics`` (all when None) in log-time order within [start_ns, stop_ns)."""

    def raw_messages(self, topics: Collection[str] | None = None, start_ns: int | None = None,
                     stop_ns: int | None = None) -> Iterator[RawMessage]:
        """Deserialized messages in log-time order; library errors become :class:`LogReadError`. A message of a
        Foxglove schema comes as the ROS 2 message it stands for (:mod:`doorbatch.io.foxglove`); one that cannot
        be read is skipped as :meth:`messages` skips one that cannot be decoded."""
        topic = None
        seen: Counter[str] = Counter()
        bad: dict[str, list[LogContentError]] = {}
        mounts = self.scan_origin_mounts()  # before the pass: it reads each such topic's first message
        try:
            for raw in self._raw(topics, start_ns, stop_ns):
                topic = raw.topic
                kind = foxglove.foxglove_kind(raw.msgtype)
                if kind is not None:
                    seen[topic] += 1
                    try:
                        msgtype, msg = foxglove.as_ros_message(kind, raw.msg, topic, mounts.get(topic))
                    except LogContentError as err:
                        bad.setdefault(topic, []).append(self._named(err))
                        continue
                    raw = RawMessage(topic, msgtype, raw.log_time_ns, msg, False, None)
                yield raw
        except DoorbatchError as err:
            raise self._named(err) from None
        except Exception as err:
            raise LogReadError(f"log is truncated or corrupt ({type(err).__name__}: {err})",
                               path=self.path, topic=topic) from err
        self._skipped(bad, seen)

    def scan_origin_mounts(self) -> dict[str, Transform]:
        """Per topic of Foxglove scans whose origin lies off their frame's origin, the static transform to that
        origin (:func:`~doorbatch.io.foxglove.scan_mount`, from the topic's first readable message: an unreadable
        one before it is skipped here as the topic's own reading skips it); the readers of TF add these to the
        log's own transforms."""
        if self._scan_mounts is None:
            self._scan_mounts = {}
            for topic, info in self.topics.items():
                if foxglove.foxglove_kind(info.schema) == "LaserScan" and (mount := self._first_mount(topic)):
                    self._scan_mounts[topic] = mount
        return self._scan_mounts

    def copied_messages(self) -> Iterator[RawMessage]:
        """Every message (:meth:`raw_messages`) for a copy of the log (``doorbatch convert``, annotated.mcap),
        preceded, where Foxglove scans have an origin off their frame's, by one ``/tf_static`` message at the log's
        start holding those mounts (:meth:`scan_origin_mounts`): a copy's scans are in the origin frames, which only
        these transforms place."""
        mounts = list(self.scan_origin_mounts().values())
        if mounts:
            yield RawMessage(MOUNTS_TOPIC, TF_MESSAGE, self.start_ns, rm.tf_message(
                [rm.transform_stamped(self.start_ns, t.parent, t.child, t.translation.tolist(),
                                      t.rotation_xyzw.tolist()) for t in mounts]), False, None)
        yield from self.raw_messages()

    def _first_mount(self, topic: str) -> Transform | None:
        """:func:`~doorbatch.io.foxglove.scan_mount` of the first scan of ``topic`` that reads as a LaserScan with it
        (None: none does, or the log cannot be read: the topic's own reading reports either). A message the
        conversion refuses (bad JSON or protobuf, JSON that is not an object, no ranges, a tilted origin) is
        skipped here as the topic's reading skips it."""
        try:
            for raw in self._raw([topic], None, None):
                try:
                    mount = foxglove.scan_mount(raw.msg, topic)
                    foxglove.as_ros_message("LaserScan", raw.msg, topic, mount)
                except Exception:  # an unreadable scan: the topic's own reading counts it
                    continue
                return mount
        except Exception:
            return None
        return None

    def _skipped(self, bad: dict[str, list[LogContentError]], seen: Counter[str]) -> None:
        """After a complete pass: a topic whose messages could not be read raises the first one's error when they
        are most of its messages (:func:`most_are_bad`), else gets a warning in ``warnings``; a colour topic detected
        by its type (no ``topics.colors``) only gets a warning."""
        for topic, errors in bad.items():
            if most_are_bad(len(errors), seen[topic]):
                if self.roles.role_of().get(topic) is not Role.COLORS or self.topics_config.colors is not None:
                    raise errors[0]
                # beam colours are optional, and the one PointCloud2 taken for them may be a lidar's cloud
                self.warnings.append(f"{self.path}: {topic}, taken for beam colours by its type, is no colour cloud "
                                     f"({errors[0].reason}): no beam colours read (topics.colors names the topic)")
                continue
            self.warnings.append(f"{self.path}: {len(errors)} of {seen[topic]} messages on {topic} skipped, "
                                 f"unusable (first: {errors[0].reason})")

    @property
    def roles(self) -> RoleAssignment:
        """The role assignment for this log (config overrides, then detection)."""
        if self._roles is None:
            try:
                self._roles = assign_roles(self.topics, self.topics_config)
            except LogContentError as err:
                if err.path is not None:
                    raise
                raise LogContentError(err.reason, path=self.path, topic=err.topic) from err
            self.warnings += [f"{self.path}: {note}" for note in self._roles.notes]
        return self._roles

    def messages(self, roles: Iterable[Role] | None = None, start_ns: int | None = None,
                 stop_ns: int | None = None) -> Iterator[RoleMessage]:
        """Records of the requested roles (all assigned roles when None) in log-time order.

        A message that cannot be decoded (:class:`~doorbatch.errors.LogContentError`) is skipped; once the
        iteration is complete, a topic with such messages gets a warning in ``warnings``, or, when they are
        most of its messages, the first one's error is raised. A caller that stops early gets neither.

        A log without an odometry topic has none here: :func:`~doorbatch.io.recording.tf_odometry` derives it
        from the whole TF tree (DESIGN.md, Inputs: TF odom→base_link).
        """
        wanted = set(Role) if roles is None else set(roles)
        role_of = {t: r for t, r in self.roles.role_of().items() if r in wanted}
        if not role_of:
            return
        seen: Counter[str] = Counter()
        bad: dict[str, list[LogContentError]] = {}
        for raw in self.raw_messages(set(role_of), start_ns, stop_ns):
            role = role_of[raw.topic]
            seen[raw.topic] += 1
            try:
                records = list(decode(role, raw.msg, raw.msgtype, raw.log_time_ns, raw.topic,
                                      self.topics_config.reference_model))
            except LogContentError as err:  # one bad message: skipped, unless most of its topic is bad (below)
                bad.setdefault(raw.topic, []).append(self._named(err))
                continue
            except DoorbatchError as err:
                raise self._named(err) from None
            for record in records:
                yield RoleMessage(role, raw.topic, record)
        self._skipped(bad, seen)

    def _named(self, err: E) -> E:
        """``err`` naming this log's file when it names none yet."""
        if getattr(err, "path", "") is None:
            err.path = str(self.path)  # type: ignore[attr-defined]
            err.args = (f"{self.path}: {err.args[0]}",)
        return err


ReaderFactory = Callable[[Path, DoorbatchConfig | None], LogReader]
_READERS: dict[str, ReaderFactory] = {}


def register_reader(key: str, factory: ReaderFactory) -> None:
    """Register a reader for a suffix (``.mcap``) or ``dir`` (a folder)."""
    _READERS[key] = factory


def supported_formats() -> list[str]:
    """The registered suffixes (and ``dir``)."""
    return sorted(_READERS)


def _format_key(path: Path) -> str:
    """The registry key of a path, from its suffix and checked against its first bytes."""
    if path.is_dir():
        return "dir"
    suffixes = [s.lower() for s in path.suffixes]
    key = suffixes[-1] if suffixes else ""
    if key == ".gz" and len(suffixes) >= 2:
        key = suffixes[-2] + ".gz"
    try:
        with path.open("rb") as f:
            head = f.read(16)
    except OSError as err:
        raise LogReadError(f"cannot read: {err.strerror or err}", path=path) from err
    if not head:
        raise LogReadError("file is empty (0 bytes)", path=path)
    if head.startswith(MCAP_MAGIC):
        return ".mcap"
    if head.startswith(BAG1_MAGIC):
        return ".bag"
    if key in (".mcap", ".bag"):
        raise LogReadError(f"not a valid {key[1:].upper()} file (bad magic bytes)", path=path)
    if key == ".db3" and "dir" in _READERS:  # one file of a ROS 2 bag: the bag is its folder, metadata.yaml beside
        raise LogReadError(f"a ROS 2 bag's database file: give the bag's folder, {path.parent}", path=path)
    if key not in _READERS:
        raise LogReadError(
            f"not a log doorbatch can read (supported: {', '.join(supported_formats())})", path=path
        )
    return key


def open_log(path: Path | str, config: DoorbatchConfig | None = None) -> LogReader:
    """A reader for any supported log; use it as a context manager.

    Raises:
        LogReadError: missing, empty, or unrecognized file.
    """
    _register_builtin_readers()
    path = Path(path)
    if not path.exists():
        raise LogReadError("no such file or folder", path=path)
    return _READERS[_format_key(path)](path, config)


def _lazy(module: str, cls: str) -> ReaderFactory:
    """A factory that imports its reader module on first use (keeps ``import doorbatch`` light)."""

    def make(path: Path, config: DoorbatchConfig | None) -> LogReader:
        reader_cls = getattr(importlib.import_module(module), cls)
        reader: LogReader = reader_cls(path, config)
        return reader

    return make


def _register_builtin_readers() -> None:
    if _READERS:
        return
    register_reader(".mcap", _lazy("doorbatch.io.mcap_reader", "McapLogReader"))
    register_reader(".bag", _lazy("doorbatch.io.bag_reader", "Rosbag1Reader"))
    register_reader("dir", _lazy("doorbatch.io.bag_reader", "Rosbag2Reader"))
    for suffix in (".log", ".clf", ".log.gz", ".clf.gz"):
        register_reader(suffix, _lazy("doorbatch.io.carmen", "CarmenReader"))
