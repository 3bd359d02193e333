"""The annotated MCAP: every message of the input log, plus doorbatch's own topics under ``/doorbatch/``.

Input messages are copied (ROS 1 ones converted to ROS 2 CDR) and merged in log-time order with the
annotations, so the file plays back in Foxglove with the robot's data and doorbatch's estimates together.
"""

from __future__ import annotations

import heapq
from collections.abc import Collection, Iterable, Iterator, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from doorbatch.config import DoorbatchConfig
from doorbatch.errors import UsageError
from doorbatch.io.decode import TF_MESSAGE
from doorbatch.io.log_clock import LogClock
from doorbatch.io.log_writer import LogFormat, LogWriter
from doorbatch.io.reader import RawMessage, open_log

ANNOTATION_PREFIX = "/doorbatch/"


@dataclass(frozen=True, slots=True)
class Annotation:
    """One message doorbatch adds: a ROS 2 message object on a ``/doorbatch/...`` topic (or ``/tf``)."""

    topic: str
    msgtype: str
    log_time_ns: int
    msg: Any


def _check(annotations: Iterable[Annotation]) -> Iterator[Annotation]:
    for a in annotations:
        if not (a.topic.startswith(ANNOTATION_PREFIX) or a.topic == "/tf"):
            raise UsageError(f"annotation topic {a.topic} must be under {ANNOTATION_PREFIX} (or be /tf)")
        yield a


def on_log_clock(annotations: Iterable[Annotation], clock: LogClock | None) -> Iterator[Annotation]:
    """The annotations logged on the recorder's clock of a log whose header stamps are on another one (sim time;
    ``Recording.log_clock``), their messages' header stamps unchanged; as they are when ``clock`` is None or one
    clock."""
    for a in annotations:
        yield a if clock is None or not clock.log_ns.size else replace(a, log_time_ns=clock.log_time_at(a.log_time_ns))


@dataclass(frozen=True, slots=True)
class AnnotatedCopy:
    """What :func:`write_annotated_mcap` wrote: messages, and the log's own transforms it left out (``replaced_tf``)."""

    written: int
    replaced_transforms: int = 0


def _without_edges(raw: RawMessage, edges: Collection[tuple[str, str]]) -> tuple[RawMessage | None, int]:
    """A /tf message without its transforms on ``edges`` (parent, child; a ROS 1 leading slash ignored), and how
    many it lost; None where it held nothing else."""
    kept = [t for t in raw.msg.transforms
            if (t.header.frame_id.lstrip("/"), t.child_frame_id.lstrip("/")) not in edges]
    lost = len(raw.msg.transforms) - len(kept)
    if not lost:
        return raw, 0
    return (replace(raw, msg=replace(raw.msg, transforms=kept)) if kept else None), lost


def write_annotated_mcap(source: Path | Sequence[Path], output: Path, annotations: Iterable[Annotation],
                         config: DoorbatchConfig | None = None,
                         replaced_tf: Collection[tuple[str, str]] = ()) -> AnnotatedCopy:
    """Copy ``source`` (one log, or several, e.g. the passes of a mapping run) into ``output`` with
    ``annotations`` merged by log time; returns what was written. ``replaced_tf``: the transforms (parent, child)
    the annotations publish on /tf; the log's own on those edges (another localizer's map→odom) are left out of the
    copy, else a viewer's frame flips between the two every message. The copy is
    :meth:`~doorbatch.io.reader.LogReader.copied_messages`: Foxglove scans come with the mounts their frames need, and
    each topic keeps the QoS its log records.

    ``annotations`` must come in non-decreasing log time (each stage produces them in time order).
    """
    config = config or DoorbatchConfig()
    sources = [source] if isinstance(source, Path) else list(source)
    written = replaced = 0
    edges = {(p.lstrip("/"), c.lstrip("/")) for p, c in replaced_tf}
    with ExitStack() as stack:
        readers = [stack.enter_context(open_log(path, config)) for path in sources]
        writer = stack.enter_context(LogWriter(output, LogFormat.MCAP))
        for reader in readers:
            writer.keep_offered_qos(reader.offered_qos)
        inputs: Iterator[tuple[int, int, RawMessage | Annotation]] = heapq.merge(
            *(((raw.log_time_ns, 0, raw) for raw in reader.copied_messages()) for reader in readers),
            key=lambda t: t[0])
        added: Iterator[tuple[int, int, RawMessage | Annotation]] = (
            (a.log_time_ns, 1, a) for a in _check(annotations)
        )
        for _, _, item in heapq.merge(inputs, added, key=lambda t: (t[0], t[1])):
            if isinstance(item, RawMessage):
                if edges and item.msgtype == TF_MESSAGE and not item.topic.rstrip("/").endswith("tf_static"):
                    copied, lost = _without_edges(item, edges)
                    replaced += lost
                    if copied is None:
                        continue
                    item = copied
                writer.write_raw(item)
            else:
                writer.write(item.topic, item.msgtype, item.log_time_ns, item.msg)
            written += 1
    return AnnotatedCopy(written, replaced)
